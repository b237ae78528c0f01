"""Non-finite pixels, and camera metadata that is not what its field must be."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io import tiffio
from plenocli.io.dng import write_dng
from tests.bad_inputs.files import (
    assert_one_line,
    plenocli_tiff,
    run_bad,
)

# ------------------- non-finite pixels: NaN is a clipped or unknown pixel, +-Inf is refused
# wherever a stage reads views (tiffio.read_image), naming the view



@pytest.mark.parametrize("args", [
    ["flat", "{d}/views.tif", "--white", "{d}/clean.tif", "-o", "{o}/x.tif"],
    ["flat", "{d}/clean.tif", "--white", "{d}/views.tif", "-o", "{o}/x.tif"],
    ["sai", "{d}/frame.tif", "-n", "2", "-o", "{o}/x.tif"],
    ["refocus", "{d}/rt_frames.tif", "--grid", "{i}/rt/grid.yaml", "-o", "{o}/x.tif"],
    ["crosstalk", "{d}/views.tif", "-o", "{o}/x.json"],
    ["unmix", "{d}/mono.tif", "--mixing", "{d}/mixing.tif", "-o", "{o}/x.tif"],
    ["stitch", "{d}/mono.tif", "-o", "{o}/x.tif"],
    ["develop", "{d}/views.tif", "--view", "B", "--wb", "1,1,1", "--matrix", "none", "-o",
     "{o}/x.jpg"],
    ["calibrate", "{d}/frame.tif", "-o", "{o}/x.yaml"],
    ["decode", "{d}/sensor.tif", "-o", "{o}/x.tif"],
], ids=lambda a: a[0] + ("-white" if "{d}/clean.tif" == a[1] else ""))
def test_infinite_pixels_are_refused_by_every_stage_that_reads_views(args, inputs, infinite,
                                                                      tmp_path):
    result = run_bad(inputs, tmp_path / "out", [a.replace("{d}", str(infinite)) for a in args])
    assert_one_line(result, 1, ("infinite",))


# ------------------- camera metadata that is not what its field must be: dropped with a warning
# where it is read (io/rawmeta via tiffio.read_image and decode), never an internal error

@pytest.mark.parametrize("change,code,words", [
    ({"colour": {"as_shot_wb": [0, 1, 1]}}, 1, ("as-shot white balance [0, 1, 1]", "--wb")),
    ({"colour": {"as_shot_wb": [float("nan"), 1, 1]}}, 1, ("as-shot white balance",)),
    ({"colour": {"as_shot_wb": [-1, 1, 1]}}, 1, ("as-shot white balance",)),
    ({"colour": {"as_shot_wb": [1, 1]}}, 1, ("as-shot white balance",)),
    ({"colour": {"as_shot_wb": "abc"}}, 1, ("as-shot white balance 'abc'",)),
    ({"colour": {"as_shot_wb": [1e30, 1, 1.5]}}, 1, ("more than 100 times another", "--wb")),
    ({"colour": {"as_shot_wb": [1e-30, 1, 1.5]}}, 1, ("more than 100 times another",)),
    ({"colour": [1, 2]}, 1, ("colour metadata [1, 2] is not a mapping",)),
    ({"exif": {"ISO": 10 ** 7}}, 0, ("EXIF ISO 10000000",)),
    ({"exif": {"ISO": -5}}, 0, ("EXIF ISO -5",)),
    ({"exif": {"DateTimeOriginal": "2024:01:01 12:00:0\u00e9"}}, 0, ("DateTimeOriginal",)),
    ({"exif": {"Make": "Canon\u00e9"}}, 0, ("EXIF Make",)),
    ({"exif": {"FNumber": float("inf")}}, 0, ("EXIF FNumber inf",)),
    ({"exif": {"ExposureTime": "1/100"}}, 0, ("EXIF ExposureTime",)),
    ({"exif": [1, 2]}, 0, ("EXIF metadata [1, 2] is not a mapping",)),
], ids=lambda v: json.dumps(v, ensure_ascii=True)[:40] if isinstance(v, dict) else str(v))
@pytest.mark.parametrize("suffix", [".jpg", ".tif"])
def test_bad_camera_metadata_is_dropped_with_a_warning(change, code, words, suffix, inputs,
                                                       tmp_path, caplog):
    frames, meta = tiffio.read_image(inputs / "biased.tif")
    good = {"colour": {"as_shot_wb": [2.0, 1.0, 1.5], "xyz_to_camera": np.eye(3).tolist()},
            "exif": {"Model": "Test", "ISO": 100}}
    edited = {**meta, **good, **change}
    path = tmp_path / "edited.tif"
    tifffile.imwrite(path, frames, photometric="minisblack", metadata=None,
                     description=json.dumps({tiffio.FORMAT_KEY: 1, **edited}))
    out = tmp_path / "out"
    out.mkdir()
    result = CliRunner().invoke(cli, ["develop", str(path), "--view", "S", "-o",
                                      str(out / f"x{suffix}")])
    assert "internal error" not in result.stderr and "Traceback" not in result.output
    assert result.exit_code == code, result.stderr
    said = result.stderr + caplog.text  # the log goes to the handler of the first configure()
    assert all(w in said for w in words), said
    written = sorted(p.name for p in out.iterdir())
    assert written == ([] if code else [f".x{suffix}.plenocli.json", f"x{suffix}"])


def test_a_dng_with_a_zero_as_shot_neutral_decodes_without_a_white_balance(tmp_path, caplog):

    raw = np.full((1, 16, 16), 1000, np.uint16)
    write_dng(tmp_path / "x.dng", raw, cfa="RGGB", black_levels=[0], white_level=4095,
              active_area=[0, 0, 16, 16], as_shot_neutral=[0.5, 1.0, 0.0])
    result = CliRunner().invoke(cli, ["decode", str(tmp_path / "x.dng"), "-o",
                                      str(tmp_path / "f.tif")])
    assert result.exit_code == 0 and "as-shot white balance" in result.stderr + caplog.text
    assert tiffio.read_meta(tmp_path / "f.tif")["colour"]["as_shot_wb"] is None


@pytest.mark.parametrize("site,words", [((0, 0), ("no R pixel",)), ((1, 1), ("no B pixel",)),
                                        ((0, 1), ("no G (first green) pixel",))])
@pytest.mark.parametrize("command", [
    ["develop", "{i}/emptied.tif", "--view", "A", "--wb", "1,1,1", "--matrix", "none", "-o",
     "{o}/x.tif"],
    ["stitch", "{i}/emptied.tif", "--views", "A,B", "-o", "{o}/x.tif"],
], ids=["develop", "stitch"])
def test_a_cfa_site_without_a_known_pixel_is_refused_not_rebuilt(command, site, words,
                                                                 tmp_path):
    # audit 12: a red plane all NaN (a flat-field that emptied it) was filled with the frame's
    # median, then rebuilt as a clipped highlight from green and blue: R 54 % off, exit 0
    rng = np.random.default_rng(12)
    views = (0.2 + 0.6 * rng.random((2, 64, 96))).astype(np.float32)
    views[:, site[0]::2, site[1]::2] = np.nan
    folder = tmp_path / "in"
    folder.mkdir()
    plenocli_tiff(folder / "emptied.tif", views, cfa="RGGB", views=["A", "B"])
    result = run_bad(folder, tmp_path / "out", command)
    assert_one_line(result, 1, ("emptied.tif: view A", *words, "cannot be rebuilt"))
