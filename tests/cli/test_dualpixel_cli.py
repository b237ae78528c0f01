"""The dual-pixel path from the command line, and every bad input it must refuse cleanly."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import tifffile
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io.dng import write_dng
from plenocli.io.tiffio import read_image
from plenocli.model.provenance import sha256_file
from plenocli.synth.dualpixel import dng_options, dualpixel_capture

ROOT = Path(__file__).resolve().parents[2]
FIX = ROOT / "fixtures" / "dualpixel"


def invoke(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    return result


@pytest.fixture
def biased(tmp_path):
    """Decoded and bias-corrected capture and white image of the shipped fixture."""
    for name in ("capture", "white"):
        assert invoke("decode", FIX / f"{name}.dng", "-o", tmp_path / f"{name}_f.tif",
                      "-q").exit_code == 0
        assert invoke("bias", tmp_path / f"{name}_f.tif", "-o", tmp_path / f"{name}_b.tif",
                      "--smooth", 9, "-q").exit_code == 0
    return tmp_path


def test_decode_bias_flat_end_to_end(biased):
    out = biased / "views.tif"
    result = invoke("flat", biased / "capture_b.tif", "--white", biased / "white_b.tif",
                    "-o", out, "--preview", biased / "p.png", "--save-gain", biased / "g.tif")
    assert result.exit_code == 0, result.output
    views, meta = read_image(out)
    assert meta["views"] == ["A", "B", "S"] and views.shape == (3, 192, 256)
    prov = meta["provenance"]
    assert prov["stage"] == "flat" and prov["parameters"]["median"] == 5
    hashes = {i["role"]: i["sha256"] for i in prov["inputs"]}
    assert hashes["white"] == sha256_file(biased / "white_b.tif")
    assert [r["stage"] for r in meta["history"]] == ["decode", "bias"]
    # the capture flattened by the independent white against the generator's known vignetting
    # and A/S split: one constant per view and CFA colour. Measured mean deviation 0.45-0.68 %
    # (photon and read noise through the white's 5 x 5 median); the limit is 1.5 x that.
    arrays = np.load(FIX / "truth.npz")
    for k, name in enumerate(("A", "B")):
        split = arrays["capture_split"] if name == "A" else 1 - arrays["capture_split"]
        ratio = views[k] / (arrays[f"capture_{name}"]
                            / (arrays["capture_vignetting"] * split))
        for r in range(2):
            for c in range(2):
                plane = ratio[r::2, c::2][np.isfinite(ratio[r::2, c::2])]
                deviation = np.abs(plane / np.median(plane) - 1).mean()
                assert deviation < 0.01, (name, r, c, deviation)
    # the saved gain, reused, flattens the capture the same way
    assert invoke("flat", biased / "capture_b.tif", "--gain", biased / "g.tif",
                  "-o", biased / "again.tif").exit_code == 0
    np.testing.assert_array_equal(read_image(biased / "again.tif")[0], views)
    truth = json.loads((FIX / "truth.json").read_text())
    assert truth["captures"]["capture"]["clipped_S_pixels"] == int(np.isnan(views[1]).sum())


def test_bias_origin_and_cfa_phase_after_crop(biased):
    out = biased / "crop.tif"
    result = invoke("bias", biased / "capture_f.tif", "--crop", "100x64", "-o", out)
    assert result.exit_code == 0, result.output
    _, meta = read_image(out)
    # active area starts at (16, 64); the central 100 x 64 crop of 192 x 256 starts at (46, 96)
    assert meta["origin"] == [16 + 46, 64 + 96]
    assert meta["cfa"] == "RGGB"  # even offsets keep the phase


def output_files(folder):
    return sorted(p.name for p in Path(folder).iterdir())


def check_refused(result, folder, before, *, code=1, message=""):
    assert result.exit_code == code, result.output
    lines = [ln for ln in result.output.strip().splitlines() if ln.strip()]
    if code == 1:
        assert len(lines) == 1, result.output
        assert "Traceback" not in result.output
        assert message in lines[0], lines[0]
    assert output_files(folder) == before  # nothing new, nothing half-written


def test_not_a_raw(tmp_path):
    bad = tmp_path / "photo.dng"
    bad.write_text("this is not a raw file")
    before = output_files(tmp_path)
    check_refused(invoke("decode", bad, "-o", tmp_path / "f.tif"), tmp_path, before,
                  message="not a raw capture")


def test_truncated_raw(tmp_path):
    cut = tmp_path / "cut.dng"
    cut.write_bytes((FIX / "capture.dng").read_bytes()[:50_000])
    before = output_files(tmp_path)
    check_refused(invoke("decode", cut, "-o", tmp_path / "f.tif"), tmp_path, before,
                  message="truncated")


def test_missing_input(tmp_path):
    before = output_files(tmp_path)
    check_refused(invoke("decode", tmp_path / "nope.CR2", "-o", tmp_path / "f.tif"), tmp_path,
                  before, message="no such file")


def test_white_of_another_size(biased, tmp_path):
    raw, truth = dualpixel_capture(seed=9, rows=96, cols=128, scene="white")
    write_dng(tmp_path / "small.dng", raw, **dng_options(truth))
    invoke("decode", tmp_path / "small.dng", "-o", tmp_path / "small_f.tif")
    invoke("bias", tmp_path / "small_f.tif", "-o", tmp_path / "small_b.tif")
    before = output_files(tmp_path)
    result = invoke("flat", biased / "capture_b.tif", "--white", tmp_path / "small_b.tif",
                    "-o", tmp_path / "out.tif")
    check_refused(result, tmp_path, before, message="white image is 128x96")


def test_white_of_another_cfa(biased, tmp_path):
    raw, truth = dualpixel_capture(seed=9, scene="white", cfa="GRBG")
    write_dng(tmp_path / "w.dng", raw, **dng_options(truth))
    invoke("decode", tmp_path / "w.dng", "-o", tmp_path / "w_f.tif")
    invoke("bias", tmp_path / "w_f.tif", "-o", tmp_path / "w_b.tif")
    before = output_files(tmp_path)
    result = invoke("flat", biased / "capture_b.tif", "--white", tmp_path / "w_b.tif",
                    "-o", tmp_path / "out.tif")
    check_refused(result, tmp_path, before, message="has CFA GRBG")


def test_config_with_unknown_key(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"steps:\n  decode:\n    input: {FIX / 'capture.dng'}\n"
                   "    output: f.tif\n    camra: auto\n")
    before = output_files(tmp_path)
    check_refused(invoke("run", cfg), tmp_path, before, message="did you mean 'camera'")


def test_usage_error_exits_2(tmp_path):
    result = invoke("decode", FIX / "capture.dng")  # no -o
    assert result.exit_code == 2


def test_inputs_never_modified(tmp_path):
    src = tmp_path / "capture.tif"  # a DNG is a TIFF: a name the output option takes
    shutil.copy(FIX / "capture.dng", src)
    digest = sha256_file(src)
    check_refused(invoke("decode", src, "-o", src), tmp_path, ["capture.tif"],
                  message="also an input")
    assert sha256_file(src) == digest


def test_debug_shows_the_traceback(tmp_path):
    bad = tmp_path / "x.txt"
    bad.write_text("nope")
    result = invoke("decode", bad, "-o", tmp_path / "f.tif", "--debug")
    assert result.exit_code == 1 and result.exc_info is not None


def test_outputs_open_in_any_tiff_reader(biased):
    data = tifffile.imread(biased / "capture_b.tif", key=0)
    assert data.dtype == np.float32 and data.shape == (192, 256)
