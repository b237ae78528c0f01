"""Every --preview of a colour capture is a colour picture (issue 10, part 5): an RGB capture
(the simulated quad-pixel sensor, decoded as pages R, G, B) through decode, flat and sai."""

from __future__ import annotations

import cv2
import numpy as np

from plenocli.colour.demosaic import mosaic
from plenocli.io import tiffio
from plenocli.io.preview import colour_pages, view_mosaic
from plenocli.pipeline.stages import decode, flat, sai, simulate


def _is_colour_picture_of(png_path, rgb):
    """The PNG's channels follow the image's R, G, B (not one grey level)."""
    png = cv2.imread(str(png_path))[..., ::-1].astype(float)
    assert png.shape[:2] == rgb.shape[:2]
    finite = np.isfinite(rgb).all(axis=-1)
    for ch in range(3):
        assert np.corrcoef(png[..., ch][finite], rgb[..., ch][finite])[0, 1] > 0.9
    assert np.abs(png[..., 0] - png[..., 2])[finite].mean() > 5


def test_rgb_capture_previews_are_in_colour(tmp_path):
    simulate.simulate("quadpixel-pyramid", tmp_path / "capture", pixels=128)
    simulate.simulate("quadpixel-white", tmp_path / "white", pixels=128)
    for name in ("capture", "white"):
        decode.run(str(tmp_path / name / "capture.tif"), str(tmp_path / f"{name}.tif"),
                   preview=str(tmp_path / f"{name}.png"))
    frames, meta = tiffio.read_image(tmp_path / "capture.tif")
    assert meta["views"] == ["R", "G", "B"]
    _is_colour_picture_of(tmp_path / "capture.png", np.moveaxis(frames, 0, -1).astype(float))
    flat.run(str(tmp_path / "capture.tif"), str(tmp_path / "flat.tif"),
             white=str(tmp_path / "white.tif"), median=1, preview=str(tmp_path / "flat.png"))
    corrected, _ = tiffio.read_image(tmp_path / "flat.tif")
    _is_colour_picture_of(tmp_path / "flat.png", np.moveaxis(corrected, 0, -1))
    sai.run(str(tmp_path / "capture.tif"), str(tmp_path / "views.tif"), n=2,
            preview=str(tmp_path / "views.png"))
    views, meta = tiffio.read_image(tmp_path / "views.tif")
    rgb = colour_pages(views, meta["views"])  # (4, 64, 64, 3) in S00, S01, S10, S11 order
    assert rgb.shape == (4, 64, 64, 3)
    arranged = np.concatenate([np.concatenate(list(rgb[:2]), axis=1),
                               np.concatenate(list(rgb[2:]), axis=1)], axis=0)
    _is_colour_picture_of(tmp_path / "views.png", arranged)


def test_colour_pages_groups_rgb_triplets_only():
    pages = np.arange(6 * 4, dtype=np.float32).reshape(6, 2, 2)
    out = colour_pages(pages, ["A.R", "A.G", "A.B", "B.R", "B.G", "B.B"])
    np.testing.assert_array_equal(out[1, ..., 2], pages[5])
    assert colour_pages(pages[:3], ["R", "G", "B"]).shape == (2, 2, 3)
    assert colour_pages(pages[:3], ["A", "B", "S"]) is None
    assert colour_pages(pages, ["A.R", "A.G", "A.B", "B.G", "B.R", "B.B"]) is None


def test_quad_bayer_sais_are_shown_in_colour():
    """Each SAI of a quad-Bayer sensor is a (half-resolution) mosaic of its own: the N x N
    arrangement shows every view in its colour."""
    colour = np.array([0.2, 0.5, 0.8], np.float32)
    stack = np.stack([mosaic(np.broadcast_to(colour, (16, 24, 3)), "GRBG")] * 4)
    picture = view_mosaic(stack, 2, ["raw"], cfa="GRBG")
    assert picture.shape == (16, 24, 3)  # 2 x 2 views of 8 x 12 RGB pixels
    np.testing.assert_allclose(picture.reshape(-1, 3), np.tile(colour, (16 * 24, 1)), atol=1e-6)
