"""Refocus of Bayer frames gives RGB at the refocused image's full resolution (each colour
splatted alone), which develop and stitch take as a colour view, with a colour preview
(issue 10, part 3). Truth: the simulator's texture, filtered as the refocused pixels see it."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from plenocli.colour.metrics import delta_e_2000
from plenocli.io import tiffio
from plenocli.pipeline.stages import develop, refocus, simulate, stitch
from plenocli.refocus import output_shape

ROWS, COLS = 240, 320


@pytest.fixture(scope="module")
def refocused(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("refocus_colour")
    truth = simulate.simulate("raytrix-scene", tmp / "sim", seed=4, rows=ROWS, cols=COLS,
                              cfa="GBRG")
    refocus.run(str(tmp / "sim" / "frames.tif"), str(tmp / "rgb.tif"),
                grid=str(tmp / "sim" / "grid.yaml"), s=truth["s"], g=str(truth["g_true"]),
                preview=str(tmp / "rgb.png"))
    return tmp, truth


def test_bayer_refocus_is_rgb_at_full_resolution(refocused):
    tmp, truth = refocused
    image, meta = tiffio.read_image(tmp / "rgb.tif")
    texture, _ = tiffio.read_image(tmp / "sim" / "texture.tif")
    assert meta["views"] == ["R", "G", "B"] and meta.get("cfa") is None
    assert image.shape == (3, *output_shape((ROWS, COLS), truth["s"]))  # not half-size
    covered = np.isfinite(image).all(axis=0)
    covered[:4], covered[-4:], covered[:, :4], covered[:, -4:] = False, False, False, False
    assert covered.mean() > 0.6
    for ch in range(3):
        err = image[ch][covered] - texture[ch][covered]
        assert 10 * np.log10(1 / np.mean(err**2)) >= 50.0  # PSNR, peak 1 (measured 60-64 dB)


def test_develop_takes_the_refocused_rgb(refocused):
    tmp, _ = refocused
    develop.run(str(tmp / "rgb.tif"), str(tmp / "rgb.jpg"), wb="1,1,1", matrix="none",
                linear=str(tmp / "linear.tif"))
    linear, _ = tiffio.read_image(tmp / "linear.tif")
    texture, _ = tiffio.read_image(tmp / "sim" / "texture.tif")
    inner = (slice(4, -4), slice(4, -4))
    measured = np.moveaxis(linear, 0, -1)[inner].reshape(-1, 3)
    expected = np.moveaxis(texture, 0, -1)[inner].reshape(-1, 3)
    keep = np.isfinite(measured).all(axis=1)
    assert keep.mean() > 0.6
    de = delta_e_2000(measured[keep], expected[keep])
    assert de.mean() < 0.3 and np.percentile(de, 95) < 0.5  # measured 0.08, 0.18
    assert cv2.imread(str(tmp / "rgb.jpg")).shape[:2] == linear.shape[1:]


def test_stitch_takes_refocused_rgb_as_one_colour_view(refocused):
    tmp, _ = refocused
    stack, names, levels, _, _ = stitch.load_views([str(tmp / "rgb.tif")], None)
    assert names == ["rgb"] and levels is None and stack.shape[:2] == (1, 3)


def test_refocus_preview_is_in_colour(refocused):
    tmp, _ = refocused
    image, _ = tiffio.read_image(tmp / "rgb.tif")
    png = cv2.imread(str(tmp / "rgb.png"))[..., ::-1].astype(float)
    assert png.shape == (*image.shape[1:], 3)
    # the preview's channels follow the texture's own colours, not one grey level
    finite = np.isfinite(image).all(axis=0)
    for ch in range(3):
        assert np.corrcoef(png[..., ch][finite], image[ch][finite])[0, 1] > 0.9
    assert np.abs(png[..., 0] - png[..., 2])[finite].mean() > 3


def test_preview_of_several_bayer_views_shows_each_in_colour():
    """Refocused A, B (pages A.R, A.G, A.B, B.R, ...) preview as two RGB views side by side."""
    stack = np.arange(2 * 6 * 4 * 5, dtype=np.float32).reshape(12, 4, 5)  # two g values
    names = [f"{v}.{c}@g{g}" for g in (3, 4) for v in "AB" for c in "RGB"]
    views = refocus._best_picture(stack, names, [3.0, 4.0], 4.0, rgb=True)
    assert views.shape == (2, 4, 5, 3)
    np.testing.assert_array_equal(views[1, ..., 0], stack[9])  # B.R at g = 4
