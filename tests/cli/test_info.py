"""`plenocli info`: raws, plenocli TIFFs, lens grids, configs and XML, as text and JSON."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io.dng import write_dng
from plenocli.synth.dualpixel import dng_options, dualpixel_capture

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures"


def _info(*args):
    return CliRunner().invoke(cli, ["info", *map(str, args)])


def test_raw_dng(tmp_path):
    raw, truth = dualpixel_capture(seed=3, rows=32, cols=48, top=8, left=16)
    write_dng(tmp_path / "c.dng", raw, **dng_options(truth))
    result = _info(tmp_path / "c.dng", "--json")
    assert result.exit_code == 0, result.output
    info = json.loads(result.stdout)
    assert info["kind"] == "raw" and info["frames"] == 2 and info["views"] == ["S", "A"]
    assert (info["rows"], info["cols"]) == (40, 64) and info["cfa"] == "RGGB"
    assert info["active_area"] == truth["geometry"]["active_area"]
    assert info["masked_areas"] == truth["geometry"]["masked_areas"]
    assert info["white_level"] == [15000.0, 15000.0]
    assert [b[0] for b in info["black_level"]] == [2048.0, 2036.0]
    assert info["active_stats"][0]["max"] == int(raw[0, 8:, 16:].max())
    text = _info(tmp_path / "c.dng").stdout
    assert "raw capture (dng)" in text and "masked areas" in text and "5D Mark IV" in text


def test_plenocli_tiff_shows_provenance_and_history(tmp_path):
    raw, truth = dualpixel_capture(seed=3, rows=32, cols=48, top=8, left=16)
    write_dng(tmp_path / "c.dng", raw, **dng_options(truth))
    runner = CliRunner()
    runner.invoke(cli, ["decode", str(tmp_path / "c.dng"), "-o", str(tmp_path / "f.tif")])
    runner.invoke(cli, ["bias", str(tmp_path / "f.tif"), "--smooth", "3",
                        "-o", str(tmp_path / "b.tif")])
    info = json.loads(_info(tmp_path / "b.tif", "--json").stdout)
    assert info["kind"] == "plenocli-tiff" and info["pages"] == 3
    assert info["views"] == ["A", "B", "S"] and (info["rows"], info["cols"]) == (32, 48)
    assert info["provenance"]["stage"] == "bias"
    assert info["provenance"]["parameters"]["smooth"] == 3
    assert [h["stage"] for h in info["history"]] == ["decode"]
    text = _info(tmp_path / "b.tif").stdout
    assert "plenocli image from stage bias" in text and "history 1      decode" in text


def test_a_preview_is_named_so_with_the_record_beside_it(tmp_path):
    # audit 9 E4: a preview PNG was a "sensor image" of views R, G, B, without provenance
    raw, truth = dualpixel_capture(seed=3, rows=32, cols=48, top=8, left=16)
    write_dng(tmp_path / "c.dng", raw, **dng_options(truth))
    runner = CliRunner()
    runner.invoke(cli, ["decode", str(tmp_path / "c.dng"), "-o", str(tmp_path / "f.tif")])
    result = runner.invoke(cli, ["bias", str(tmp_path / "f.tif"), "--smooth", "3", "-o",
                                 str(tmp_path / "b.tif"), "--preview", str(tmp_path / "b.png")])
    assert result.exit_code == 0, result.output
    info = json.loads(_info(tmp_path / "b.png", "--json").stdout)
    assert info["kind"] == "preview" and info["format"] == "PNG" and info["mode"] == "RGB"
    assert info["record"]["stage"] == "bias" and info["record"]["role"] == "preview"
    assert info["record"]["parameters"]["smooth"] == 3
    assert list(info["record"]["inputs"]) == ["input"]
    text = _info(tmp_path / "b.png").stdout
    assert "plenocli preview (PNG, display-stretched 8-bit levels, not sensor data; of a bias " \
           "output)" in text and "made by        plenocli" in text
    assert "sensor image" not in text


@pytest.mark.parametrize("suffix,fmt", [(".jpg", "JPEG"), (".tif", "TIFF"), (".png", "PNG")])
def test_a_photograph_shows_develop_and_every_stage_before(suffix, fmt, tmp_path):
    """develop's record and history, the stage that made its input included (bias here)."""
    raw, truth = dualpixel_capture(seed=3, rows=32, cols=48, top=8, left=16)
    write_dng(tmp_path / "c.dng", raw, **dng_options(truth))
    runner = CliRunner()
    for args in (["decode", tmp_path / "c.dng", "-o", tmp_path / "f.tif"],
                 ["bias", tmp_path / "f.tif", "-o", tmp_path / "b.tif"],
                 ["develop", tmp_path / "b.tif", "--view", "S", "--wb", "1,1,1", "--matrix",
                  "none", "-o", tmp_path / f"p{suffix}"]):
        assert runner.invoke(cli, [str(a) for a in args]).exit_code == 0
    result = _info(tmp_path / f"p{suffix}", "--json")
    assert result.exit_code == 0, result.output
    info = json.loads(result.stdout)
    assert info["kind"] == "photo" and info["format"] == fmt
    assert (info["rows"], info["cols"]) == (32, 48)
    assert info["provenance"]["stage"] == "develop"
    assert [h["stage"] for h in info["history"]] == ["decode", "bias"]
    assert f"photograph ({fmt})" in _info(tmp_path / f"p{suffix}").stdout


def test_lens_grid_yaml(tmp_path):
    from plenocli.io.gridfile import write_grid
    from plenocli.model.lensgrid import LensGrid

    grid = LensGrid(pitch_px=20.2, angle_rad=0.01, offset_xy=(3.0, 4.0), image_shape=(100, 120))
    write_grid(tmp_path / "g.yaml", grid, {"stage": "calibrate", "version": "0.1.0"})
    info = json.loads(_info(tmp_path / "g.yaml", "--json").stdout)
    assert info["kind"] == "lens-grid" and info["pitch_px"] == 20.2
    assert info["offset_xy"] == [3.0, 4.0] and info["provenance"]["stage"] == "calibrate"
    assert "pitch px       20.2" in _info(tmp_path / "g.yaml").stdout


def test_other_xml_generic_fields(tmp_path):
    xml = tmp_path / "calib.xml"
    xml.write_text('<TSPCCalibData version="1.0"><offset units="pix"><x>1.5</x><y>-2</y>'
                   '</offset><diameter units="pix">23.2</diameter><lens_type id="0"/>'
                   '<lens_type id="1"/></TSPCCalibData>')
    info = json.loads(_info(xml, "--json").stdout)
    assert info["root"] == "TSPCCalibData" and info["attributes"] == {"version": "1.0"}
    assert info["fields"]["offset"] == {"units": "pix", "x": 1.5, "y": -2.0}
    assert info["fields"]["diameter"] == {"value": 23.2, "units": "pix"}
    assert len(info["fields"]["lens_type"]) == 2


def test_incomplete_raycalibdata_is_one_line(tmp_path):
    xml = tmp_path / "calib.xml"
    xml.write_text('<RayCalibData version="1.0"><diameter>23.2</diameter></RayCalibData>')
    result = _info(xml)
    assert result.exit_code == 1 and len(result.output.strip().splitlines()) == 1


@pytest.mark.realdata
def test_real_raytrix_xml(realdata):
    info = json.loads(_info(realdata / "raytrix/origami/calib.xml", "--json").stdout)
    assert info["kind"] == "raytrix-calibration"
    assert info["calibration"]["diameter"] == pytest.approx(23.2023, abs=1e-4)
    text = _info(realdata / "raytrix/origami/calib.xml").stdout
    assert "lens pitch     23.2023 px" in text


@pytest.mark.parametrize("content, message", [
    (b"\x00\x01garbage", "does not know this kind of file"),
    (None, "no such file"),
])
def test_errors_are_one_line(tmp_path, content, message):
    path = tmp_path / "x.bin"
    if content is not None:
        path.write_bytes(content)
    result = _info(path)
    assert result.exit_code == 1
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1


def _strict_json(text: str):
    def refuse(constant):
        raise ValueError(f"{constant} is not JSON")

    return json.loads(text, parse_constant=refuse)


def test_a_float_image_without_white_level_records_null_not_infinity(tmp_path):
    """audit 7 P2: a float image decoded without --white has no white level; the file's
    ImageDescription and info --json held `Infinity`, which strict JSON readers refuse."""
    import numpy as np
    import tifffile

    rng = np.random.default_rng(4)
    tifffile.imwrite(tmp_path / "f32.tif", rng.random((24, 32), np.float32) * 100,
                     photometric="minisblack", metadata=None)
    runner = CliRunner()
    for args in (["decode", "f32.tif", "-o", "frames.tif"],
                 ["bias", "frames.tif", "-o", "biased.tif"]):
        result = runner.invoke(cli, [str(tmp_path / a) if a.endswith(".tif") else a
                                     for a in args])
        assert result.exit_code == 0, result.output
    for name in ("frames.tif", "biased.tif"):
        with tifffile.TiffFile(tmp_path / name) as tif:
            meta = _strict_json(tif.pages[0].description)
        assert meta["white_level"] == [None]
        result = _info(tmp_path / name, "--json")
        assert result.exit_code == 0, result.output
        assert _strict_json(result.stdout)["white_level"] == [None]


@pytest.mark.parametrize("body, refused", [
    ("steps:\n  decode: {input: c.dng, output: f.tif}\n", None),
    ("base: 1\nsteps:\n  decode: {input: c.dng, output: f.tif}\n", "unknown top-level key 'base'"),
    ("steps:\n  bias: {input: f.tif, output: v.tif, smoth: 3}\n",
     "unknown key 'smoth' for stage bias"),
    ("steps:\n  decode: {input: \"{capture}\", output: \"{out}/{name}.tif\"}\n", None)])
def test_a_config_says_whether_run_refuses_it(tmp_path, body, refused):
    # own-9 (round 10): info described configs that run refuses as plain pipeline configs
    (tmp_path / "c.yaml").write_text(body)
    text = CliRunner().invoke(cli, ["info", str(tmp_path / "c.yaml")])
    doc = json.loads(CliRunner().invoke(cli, ["info", str(tmp_path / "c.yaml"), "--json"]).output)
    assert text.exit_code == 0 and doc["kind"] == "pipeline-config"
    if refused is None:
        assert doc["refused"] is None and "run refuses it" not in text.output
    else:
        assert refused in doc["refused"] and "run refuses it: " in text.output
