"""plenocli optics end to end."""

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from tests.conftest import ROOT

TABLE2 = str(ROOT / "configs" / "lenses" / "paper_table2.yaml")


def test_prints_the_figures_and_writes_json(tmp_path):
    out = tmp_path / "t2.json"
    res = CliRunner().invoke(cli, ["optics", TABLE2, "--sensor-mm", "3.6", "--json", str(out)])
    assert res.exit_code == 0, res.output
    for words in ("effective focal length    6.165", "field of view", "max |distortion|",
                  "exit pupil", "RMS spot radius", "prism n 1.74"):
        assert words in res.output
    doc = json.loads(out.read_text())
    assert abs(doc["efl_mm"] - 6.165) < 1e-3
    assert doc["provenance"]["stage"] == "optics"
    assert doc["provenance"]["inputs"][0]["name"] == "paper_table2.yaml"


def test_the_figures_are_printed_only_once_the_json_landed(tmp_path, monkeypatch):
    # audit 8 E8 (every command): the report was printed, then the JSON's landing failed
    import errno
    import os

    from plenocli.pipeline import records

    def disk_full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(tmp_path / "rec"))

    monkeypatch.setattr(records, "write_records", disk_full)
    out = tmp_path / "t2.json"
    res = CliRunner().invoke(cli, ["optics", TABLE2, "--sensor-mm", "3.6", "--json", str(out)])
    assert res.exit_code == 1 and "no space left" in res.output
    assert "effective focal length" not in res.output and not out.exists()


def test_bad_lens_file_is_one_line_and_leaves_nothing(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("surfaces:\n  - {radius: 3.0, glass: unobtainium, thickness: 1}\n")
    out = tmp_path / "out.json"
    res = CliRunner().invoke(cli, ["optics", str(bad), "--json", str(out)])
    assert res.exit_code == 1
    assert "unknown glass" in res.output and len(res.output.strip().splitlines()) == 1
    assert not out.exists()


def test_missing_file_and_usage_error(tmp_path):
    res = CliRunner().invoke(cli, ["optics", str(tmp_path / "nope.yaml")])
    assert res.exit_code == 1 and "no such file (the YAML lens" in res.output
    res = CliRunner().invoke(cli, ["optics", TABLE2, "--sensor-mm", "wide"])
    assert res.exit_code == 2


def test_crosstalk_figures_in_the_text_and_the_json(tmp_path):
    out = tmp_path / "ct.json"
    res = CliRunner().invoke(cli, ["optics", TABLE2, "--crosstalk", "--mask-width", "0.1",
                                   "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert "cross-talk (quarter ++ open" in res.output
    ct = json.loads(out.read_text())["crosstalk"]
    assert 0.02 < ct["no_mask"]["ratio"] < 0.2  # pupil aberration leaks light off-axis
    assert ct["cross_mask"]["ratio"] < ct["no_mask"]["ratio"]
    assert ct["cross_mask"]["cross_width_mm"] == pytest.approx(0.1 * 3.09, rel=1e-3)
    assert ct["microlens_pitch_um"] == pytest.approx(2.3981, abs=0.003)  # Table 1's phi
    assert f"r = {100 * ct['no_mask']['ratio']:.1f} %" in res.output


@pytest.mark.parametrize("option, value", [("--sensor-mm", "nan"), ("--sensor-mm", "-1"),
                                           ("--pixel-um", "inf"), ("--mask-width", "1"),
                                           ("--prism-apex-deg", "nan")])
def test_non_finite_or_out_of_range_options_are_usage_errors(option, value):
    res = CliRunner().invoke(cli, ["optics", TABLE2, option, value])
    assert res.exit_code == 2 and option in res.output


@pytest.mark.parametrize("row, words", [("{radius: 3.0, glass: N-BK7, thickness: -1}",
                                         "thickness_mm -1"),
                                        ("{radius: .nan, glass: N-BK7, thickness: 1}",
                                         "radius_mm is NaN"),
                                        ("{radius: 3.0, glass: N-BK7, thickness: .nan}",
                                         "thickness_mm nan"),
                                        ("{radius: 50, glass: N-BK7, thickness: 0.5, "
                                         "diameter: 20}", "surfaces 1 and 2 cross 2.969 mm off")])
def test_impossible_prescriptions_are_one_line(tmp_path, row, words):
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"surfaces:\n  - {row}\n  - {{radius: -3.0, thickness: 5}}\n")
    out = tmp_path / "out.json"
    res = CliRunner().invoke(cli, ["optics", str(bad), "--json", str(out)])
    assert res.exit_code == 1, res.output
    assert words in res.output and len(res.output.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.parametrize("stop_mm", [10.0, 1e6])
def test_a_stop_wider_than_the_lens_is_refused(stop_mm, tmp_path):
    """The first element (3.54 mm across, right behind the stop) would clip a wider beam: the
    f-number and pupils computed from such a stop are not the lens's."""
    lens = tmp_path / "wide_stop.yaml"
    lens.write_text(Path(TABLE2).read_text().replace("{stop: true, diameter: 3.09",
                                                     f"{{stop: true, diameter: {stop_mm}"))
    out = tmp_path / "out.json"
    res = CliRunner().invoke(cli, ["optics", str(lens), "--crosstalk", "--json", str(out)])
    assert res.exit_code == 1 and len(res.output.strip().splitlines()) == 1, res.output
    assert "surface 2 (clear aperture 3.53718 mm)" in res.output
    assert "the stop must limit the pupil" in res.output and not out.exists()


def test_object_distances_the_trace_cannot_vouch_for(tmp_path):
    """Nearer than the focal length there is no real image to focus on (the message names the
    distance, not the lens); beyond 1e9 mm the board is at infinity and the rays lose their
    precision (1e15 mm moved r by half a point): a usage error."""
    near = CliRunner().invoke(cli, ["optics", TABLE2, "--crosstalk", "--object-distance-mm", "7"])
    assert near.exit_code == 1 and "Error: --object-distance-mm 7: the lens forms no real " \
        "image" in near.output and len(near.output.strip().splitlines()) == 1
    far = CliRunner().invoke(cli, ["optics", TABLE2, "--crosstalk", "--object-distance-mm",
                                   "1e15"])
    assert far.exit_code == 2 and "'--object-distance-mm'" in far.output


@pytest.mark.parametrize("distance", ["1e9", "20"])
def test_a_sensor_nowhere_near_focus_is_refused(distance, tmp_path):
    """audit 7 W4: image_distance_mm 1e9 gave a figure sheet of zeros (field of view 0.00 deg,
    spots of 1.8e11 um) with exit 0; an image plane more than a focal length from focus is
    refused."""
    import yaml

    doc = yaml.safe_load(Path(TABLE2).read_text())
    doc["image_distance_mm"] = float(distance)
    lens = tmp_path / "far.yaml"
    lens.write_text(yaml.safe_dump(doc))
    out = tmp_path / "far.json"
    res = CliRunner().invoke(cli, ["optics", str(lens), "--json", str(out)])
    assert res.exit_code == 1 and "nowhere near focus" in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1 and not out.exists()


def _scaled(doc, factor):
    """The prescription with every length but image_distance_mm times ``factor``."""
    rows = [{k: (v * factor if k in ("thickness", "radius", "diameter") else v)
             for k, v in row.items()} for row in doc["surfaces"]]
    return {**doc, "surfaces": rows}


@pytest.mark.parametrize("blur_mm, refused", [(1.5, False), (2.5, True)])
def test_a_sensor_whose_axial_blur_is_wider_than_it_is_refused(blur_mm, refused, tmp_path):
    """audit 10 W1: Table 2 in micrometres (every length x 1000 but image_distance_mm) put the
    sensor 956 mm before a 6165 mm focus, within the focal length, and printed spots of 18 cm
    on a 3.6 mm sensor with exit 0. A point on the axis spreads over |offset| / N: an image
    plane where that is wider than the sensor is refused (here a 2 mm sensor behind Table 2,
    f/1.995, focus 0.9573 mm behind the last vertex)."""
    import yaml

    doc = yaml.safe_load(Path(TABLE2).read_text())
    f_number = 6.16541 / 3.09
    doc["image_distance_mm"] = 0.95731 + blur_mm * f_number
    lens = tmp_path / "defocused.yaml"
    lens.write_text(yaml.safe_dump(doc))
    res = CliRunner().invoke(cli, ["optics", str(lens), "--sensor-mm", "2"])
    if not refused:
        assert res.exit_code == 0, res.output
        return
    assert res.exit_code == 1 and f"spread over {blur_mm:.4g} mm" in res.output, res.output
    assert "wider than the 2 mm sensor" in res.output
    assert len(res.output.strip().splitlines()) == 1
    micrometres = tmp_path / "um.yaml"
    micrometres.write_text(yaml.safe_dump(_scaled(yaml.safe_load(Path(TABLE2).read_text()),
                                                  1000.0)))
    res = CliRunner().invoke(cli, ["optics", str(micrometres)])
    assert res.exit_code == 1 and "-956.2" in res.output and "in mm" in res.output, res.output


def test_prism_figures_that_do_not_exist_are_said_so():
    """audit 10 W3: --prism-n 1.0001 printed 'A for alpha = half field: 162752.59 deg' and an
    apex of 60 deg 'nan deg at normal incidence', with exit 0."""
    res = CliRunner().invoke(cli, ["optics", TABLE2, "--prism-n", "1.0001"])
    assert res.exit_code == 0 and "none (a prism of index 1.0001 deviates" in res.output, res.output
    res = CliRunner().invoke(cli, ["optics", TABLE2, "--prism-apex-deg", "60"])
    assert res.exit_code == 0 and "none at normal incidence (totally reflected" in res.output
    assert "nan" not in res.output


def test_a_sensor_corner_the_lens_vignettes_completely_is_refused(tmp_path):
    """audit 10 W3: --sensor-mm 5 printed field and distortion at the 28.8 deg corner and an
    RMS spot of 'nan um' there: only the chief ray reaches it."""
    res = CliRunner().invoke(cli, ["optics", TABLE2, "--sensor-mm", "5", "--json",
                                   str(tmp_path / "t.json")])
    assert res.exit_code == 1 and "vignettes it completely" in res.output, res.output
    assert "28.8 deg off axis" in res.output and not (tmp_path / "t.json").exists()


@pytest.mark.parametrize("width, code, words", [
    ("0.7", 1, "Error: --mask-width 0.7: a cross that wide leaves no traced ray"),
    ("0.7071", 2, "'--mask-width'")])
def test_a_cross_that_covers_a_quarter_is_refused_naming_the_option(width, code, words):
    """audit 10 E7: --mask-width 0.7 failed with numpy's 'zero-size array to reduction
    operation maximum', blamed on the lens file."""
    res = CliRunner().invoke(cli, ["optics", TABLE2, "--crosstalk", "--mask-width", width])
    assert res.exit_code == code and words in res.output, res.output
