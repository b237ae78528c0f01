"""Refocus a real Raytrix-type lenslet image (MPEG "Origami", frame 0) with its RayCalibData XML.

Sharpness measure (plenocli.refocus.sharpness): normalised Laplacian energy of the refocused
luminance after a Gaussian of sigma = s * pitch / 2 removes the micro-lens pattern. At g = 1
the "refocused" image is the lenslet image shrunk 5 times (each micro-image a blob); a proper
plane must beat it.
"""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io import tiffio
from plenocli.io.gridfile import read_grid
from plenocli.io.preview import write_png
from plenocli.refocus import refocus, sharpness

SHAPE = (2048, 2048)


def origami_grid(realdata):
    return read_grid(realdata / "raytrix" / "origami" / "calib.xml", image_shape=SHAPE)


@pytest.mark.realdata
def test_origami_refocuses_sharper_than_g1(realdata, tmp_path):
    import cv2

    grid = origami_grid(realdata)
    assert grid.pitch_px == pytest.approx(23.2023, abs=1e-3)
    bgr = cv2.imread(str(realdata / "raytrix" / "origami" / "frame0.png"))
    assert bgr.shape[:2] == SHAPE
    luminance = bgr.astype(np.float32).mean(axis=2)
    period = 0.2 * grid.pitch_px
    scores = {}
    for g in (1.0, 2.5, 3.0, 3.5, 4.0):
        image, _ = refocus(luminance, grid, s=0.2, g=g)
        assert np.isfinite(image).mean() > 0.98
        scores[g] = sharpness(image, lens_period_px=period)
        write_png(tmp_path / f"origami_g{g:g}.png", image)
    best = max(scores, key=scores.get)
    assert best != 1.0
    assert scores[best] > 1.3 * scores[1.0], scores
    assert (tmp_path / f"origami_g{best:g}.png").stat().st_size > 10_000


def _shift_px(image, reference):
    """(cols, rows) shift of ``image`` relative to ``reference`` (phase correlation, windowed,
    the border of the refocused images left out)."""
    import cv2

    a, b = (np.nan_to_num(im[20:-20, 20:-20]).astype(np.float64) for im in (reference, image))
    (dx, dy), _ = cv2.phaseCorrelate(a, b, cv2.createHanningWindow(a.shape[::-1], cv2.CV_64F))
    return dx, dy


@pytest.mark.realdata
def test_origami_left_view_sees_the_scene_from_the_left(realdata):
    """The left/right disparity has the sign of (v - g) (see the module docstring): measured
    +2.2 px at g = 2.5 and -2.2 px at g = 5, crossing zero near the sharpest plane (g ~ 3.8)."""
    import cv2

    grid = origami_grid(realdata)
    bgr = cv2.imread(str(realdata / "raytrix" / "origami" / "frame0.png"))
    luminance = bgr.astype(np.float32).mean(axis=2)
    for g, sign in ((2.5, +1), (5.0, -1)):
        left, right = (refocus(luminance, grid, s=0.2, g=g, view=v, mask_width=2)[0]
                       for v in ("left", "right"))
        dx, dy = _shift_px(left, right)
        assert sign * dx > 1.5, (g, dx)  # measured 2.2 px: a disparity halved fails
        assert abs(dy) < 1.0, (g, dy)  # the baseline is horizontal


@pytest.mark.realdata
def test_origami_stereo_pair_through_the_cli(realdata, tmp_path):
    folder = realdata / "raytrix" / "origami"
    runner = CliRunner()
    frames = tmp_path / "frames.tif"
    assert runner.invoke(cli, ["decode", str(folder / "frame0.png"), "-o", str(frames)]
                         ).exit_code == 0
    for view in ("left", "right"):
        out = tmp_path / f"{view}.tif"
        result = runner.invoke(cli, ["refocus", str(frames), "--grid", str(folder / "calib.xml"),
                                     "--s", "0.2", "--g", "3.5", "--view", view,
                                     "--mask-width", "2", "-o", str(out),
                                     "--preview", str(tmp_path / f"{view}.png")])
        assert result.exit_code == 0, result.output
        image, meta = tiffio.read_image(out)
        assert image.shape == (3, 410, 410) and meta["views"] == ["R", "G", "B"]
        assert np.isfinite(image).mean() > 0.95
