"""plenocli optics end to end."""

import json

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
    assert res.exit_code == 1 and "no such lens file" in res.output
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
                                         "thickness_mm nan")])
def test_impossible_prescriptions_are_one_line(tmp_path, row, words):
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"surfaces:\n  - {row}\n  - {{radius: -3.0, thickness: 5}}\n")
    out = tmp_path / "out.json"
    res = CliRunner().invoke(cli, ["optics", str(bad), "--json", str(out)])
    assert res.exit_code == 1, res.output
    assert words in res.output and len(res.output.strip().splitlines()) == 1
    assert not out.exists()


def test_a_stop_that_does_not_limit_the_pupil_is_one_line(tmp_path):
    lens = tmp_path / "wide_stop.yaml"
    lens.write_text(open(TABLE2).read().replace("{stop: true, diameter: 3.09",
                                               "{stop: true, diameter: 10.0"))
    out = tmp_path / "out.json"
    res = CliRunner().invoke(cli, ["optics", str(lens), "--crosstalk", "--json", str(out)])
    assert res.exit_code == 1, res.output
    assert "the stop must be the limiting aperture" in res.output
    assert len(res.output.strip().splitlines()) == 1 and not out.exists()
