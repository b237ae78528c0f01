"""The panorama blended band by band, trimmed before it is blended, written straight into its
TIFF (``compose.covered_box``, ``compose.blend``, ``io.tiffcanvas``), and the luminance the
registration works on."""

from __future__ import annotations

import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.errors import InputError
from plenocli.io import tiffio
from plenocli.stitch import compose, stitch
from plenocli.stitch.quality import bounding_box
from plenocli.stitch.views import luminance
from plenocli.synth.rig import make_rig


def _views_with_holes() -> np.ndarray:
    """Two colour views whose second has no data along its far edge and in a blob: the
    coverage of that edge, hence the trim, comes from the holes, not from the view's box."""
    views, _, _ = make_rig(layout="1x2", view_shape=(150, 200), overlap=0.3, seed=3)
    colour = np.stack([views * g for g in (1.0, 0.8, 0.6)], axis=1).astype(np.float32)
    colour[1, :, :, -7:] = np.nan
    colour[1, :, 40:60, 120:150] = np.nan
    colour[0, :, :3, :] = np.nan
    return colour


def _trimmed_to_coverage(panorama: np.ndarray) -> bool:
    covered = np.isfinite(panorama).all(axis=0)
    box = bounding_box(covered)
    return box == (slice(0, covered.shape[0]), slice(0, covered.shape[1]))


def test_the_panorama_does_not_depend_on_its_bands(monkeypatch):
    views = _views_with_holes()
    whole, report = stitch(views, layout="1x2")
    monkeypatch.setattr(compose, "BLEND_BAND_PIXELS", 2000)  # ~5 rows a band: many bands
    banded, banded_report = stitch(views, layout="1x2")
    assert np.array_equal(whole, banded, equal_nan=True)
    assert banded_report.coverage_fraction == report.coverage_fraction
    assert _trimmed_to_coverage(whole)


@pytest.mark.parametrize("blend", ["feather", "multiband"])
def test_the_panorama_is_trimmed_to_what_the_views_cover_before_it_is_blended(blend):
    views = _views_with_holes()
    panorama, report = stitch(views, layout="1x2", blend=blend)
    assert _trimmed_to_coverage(panorama)
    assert list(panorama.shape[1:]) == report.panorama_shape
    # the origin moves with the trim: view 0's first covered row (row 3) is panorama row
    # origin + 3, the first of the panorama when view 0 lies above view 1
    assert report.origin_px[1] + 3 >= 0


def test_the_file_holds_what_the_library_blends_and_lands_whole(tmp_path):
    views = _views_with_holes()
    path = tmp_path / "v.tif"
    tiffio.write_image(path, views.reshape(6, *views.shape[2:]),
                       {"views": ["A.R", "A.G", "A.B", "B.R", "B.G", "B.B"]})
    result = CliRunner().invoke(cli, ["stitch", str(path), "--layout", "1x2", "-o",
                                      str(tmp_path / "p.tif"), "--preview",
                                      str(tmp_path / "p.png")])
    assert result.exit_code == 0, result.output
    pano, meta = tiffio.read_image(tmp_path / "p.tif")
    expected, report = stitch(views, layout="1x2")
    assert np.array_equal(pano, expected, equal_nan=True)
    assert meta["views"] == ["R", "G", "B"] and meta["provenance"]["stage"] == "stitch"
    assert meta["stitch"]["origin_px"] == report.origin_px
    assert {"p.png", "p.tif"} <= {p.name for p in tmp_path.iterdir()}
    assert not list(tmp_path.glob("*.part")) and not list(tmp_path.glob(".*.part"))


def test_a_panorama_the_disk_cannot_hold_is_one_line_and_leaves_nothing(tmp_path):
    views = _views_with_holes()
    tiffio.write_image(tmp_path / "v.tif", views.reshape(6, *views.shape[2:]),
                       {"views": ["A.R", "A.G", "A.B", "B.R", "B.G", "B.B"]})
    script = ("import resource, sys; resource.setrlimit(resource.RLIMIT_FSIZE, (65536, 65536));"
              "from plenocli.cli.main import cli; sys.argv = ['plenocli'] + sys.argv[1:]; cli()")
    result = subprocess.run([sys.executable, "-c", script, "stitch", "v.tif", "--layout", "1x2",
                             "-o", "out/p.tif"], cwd=tmp_path, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 1, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "p.tif" in result.stderr
    assert sorted(p.name for p in Path(tmp_path).iterdir()) == ["v.tif"]


def _canvas_bands(tmp_path, bands: list[np.ndarray]) -> Path:
    """The bands (2, rows, 5) written one after the other through an image canvas."""
    from plenocli.io.tiffcanvas import image_canvas

    path = tmp_path / "c.tif"
    rows = sum(b.shape[1] for b in bands)
    with image_canvas(path) as canvas:
        write_rows = canvas.allocate((2, rows, 5))
        first = 0
        for band in bands:
            write_rows(slice(first, first + band.shape[1]), band)
            first += band.shape[1]
        canvas.finish({"views": ["A", "B"]})
    return path


def test_the_canvas_holds_the_bands_where_they_were_written(tmp_path):
    rng = np.random.default_rng(0)
    bands = [rng.random((2, n, 5)).astype(np.float32) for n in (3, 1, 4)]
    data, meta = tiffio.read_image(_canvas_bands(tmp_path, bands))
    assert np.array_equal(data, np.concatenate(bands, axis=1))
    assert meta["views"] == ["A", "B"]


@pytest.mark.parametrize("bad, words", [("inf", "view B of the result holds 2 infinite pixels "
                                                "(first at row 3, col 1)"),
                                        ("nan", "view B of the result holds no valid pixel")])
def test_the_canvas_refuses_what_write_image_refuses_and_leaves_nothing(tmp_path, bad, words):
    bands = [np.ones((2, 3, 5), np.float32), np.ones((2, 4, 5), np.float32)]
    if bad == "inf":
        bands[1][1, 0, 1] = bands[1][1, 2, 2] = np.inf
    else:
        for band in bands:
            band[1] = np.nan
    with pytest.raises(InputError, match=re.escape(words)):
        _canvas_bands(tmp_path, bands)
    assert list(tmp_path.iterdir()) == []


def test_the_luminance_is_the_channel_mean_and_nanmean_where_channels_lack_data():
    rng = np.random.default_rng(1)
    stack = np.moveaxis(rng.random((2, 20, 30, 3), np.float32), -1, 1)  # interleaved RGB
    stack[0, 1, 3, 4] = np.nan
    stack[1, :, 5, 6] = np.nan
    luma = luminance(stack)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        expected = np.nanmean(stack.astype(np.float64), axis=1)
    assert np.allclose(luma, expected, rtol=1e-6, equal_nan=True)
    assert np.isnan(luma[1, 5, 6]) and np.isfinite(luma[0, 3, 4])
