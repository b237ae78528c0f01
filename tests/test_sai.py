"""Sub-aperture images: Eq. 1 demultiplexing, colour layouts, approximate S-hat."""

from __future__ import annotations

import numpy as np
import pytest

from plenocli.model.lensgrid import LensGrid
from plenocli.sai import approximate_sai, demultiplex, sai_colours, view_names


def interleave(views: np.ndarray, n: int) -> np.ndarray:
    """The sensor image of an ideal N x N sensor whose SAIs are ``views`` (n*n, R, C)."""
    _, rows, cols = views.shape
    frame = np.empty((rows * n, cols * n), views.dtype)
    for i in range(n):
        for j in range(n):
            frame[i::n, j::n] = views[i * n + j]
    return frame


@pytest.mark.parametrize("n", [1, 2, 3, 4])
@pytest.mark.parametrize("dtype", [np.uint16, np.float32])
def test_demultiplex_returns_the_views_exactly(n, dtype):
    rng = np.random.default_rng(n)
    views = (rng.random((n * n, 13, 17)) * 4000).astype(dtype)
    frame = interleave(views, n)
    out = demultiplex(frame, n)
    assert out.dtype == dtype
    assert np.array_equal(out, views)
    assert view_names(n)[-1] == f"S{n - 1}{n - 1}"


def test_demultiplex_is_eq1():
    frame = np.arange(8 * 10).reshape(8, 10)
    out = demultiplex(frame, 2)
    assert out.shape == (4, 4, 5)
    for i in range(2):
        for j in range(2):
            for k in range(4):
                for m in range(5):
                    assert out[i * 2 + j, k, m] == frame[k * 2 + i, m * 2 + j]


@pytest.mark.parametrize("shape,n,words", [
    ((512, 512), 7, ["not a whole number", "511 rows and 511 columns"]),
    ((509, 511), 2, ["not a whole number", "508 rows and 510 columns"]),
    ((3, 3), 2, ["1 x 1 micro-images", "at least 4 x 4"]),
    ((8, 40), 4, ["10 x 2 micro-images"]),
])
def test_demultiplex_refuses_partial_or_too_few_micro_images(shape, n, words):
    with pytest.raises(ValueError) as err:
        demultiplex(np.zeros(shape, np.float32), n)
    for word in words:
        assert word in str(err.value)


@pytest.mark.parametrize("bad", [0, -1, 1.5, True])
def test_demultiplex_refuses_bad_n(bad):
    with pytest.raises(ValueError, match="n must"):
        demultiplex(np.zeros((4, 4)), bad)


@pytest.mark.parametrize("cfa", ["RGGB", "GBRG"])
@pytest.mark.parametrize("n", [2, 3])
def test_quad_bayer_sais_are_bayer_mosaics_with_the_block_pattern(cfa, n):
    rows, cols = 8 * n, 12 * n
    r, c = np.mgrid[0:rows, 0:cols]
    colour = np.array([cfa[((rr // n) % 2) * 2 + (cc // n) % 2]
                       for rr, cc in zip(r.ravel(), c.ravel(), strict=True)]).reshape(rows, cols)
    codes = np.vectorize("RGB".index)(colour)
    views = demultiplex(codes, n)
    expected = sai_colours(cfa, n, layout="micro-image")
    for view, pattern in zip(views, expected, strict=True):
        tile = np.array([["RGB".index(pattern[2 * a + b]) for b in (0, 1)] for a in (0, 1)])
        assert np.array_equal(view, np.tile(tile, (view.shape[0] // 2, view.shape[1] // 2)))


@pytest.mark.parametrize("n", [2, 3, 4])
def test_per_pixel_bayer_colours(n):
    cfa = "RGGB"
    r, c = np.mgrid[0:6 * n, 0:6 * n]
    codes = np.vectorize(lambda rr, cc: "RGB".index(cfa[(rr % 2) * 2 + cc % 2]))(r, c)
    views = demultiplex(codes, n)
    for view, desc in zip(views, sai_colours(cfa, n, layout="pixel"), strict=True):
        if len(desc) == 1:  # one colour per SAI (even n)
            assert np.all(view == "RGB".index(desc))
        else:
            assert view[0, 0] == "RGB".index(desc[0]) and view[1, 1] == "RGB".index(desc[3])


def test_approximate_sai_with_an_integer_pitch_is_eq1():
    rng = np.random.default_rng(2)
    views = rng.random((4, 10, 12)).astype(np.float32)
    frame = interleave(views, 2)
    grid = LensGrid(pitch_px=2.0, angle_rad=0.0, offset_xy=(0.5, 0.5), lattice="square",
                    image_shape=frame.shape)
    out, _ = approximate_sai(frame, grid, 2)
    assert np.array_equal(out, views)


def test_approximate_sai_takes_the_nearest_pixel_for_a_non_integer_pitch():
    rng = np.random.default_rng(3)
    frame = rng.random((60, 70)).astype(np.float32)
    pitch = 2.6
    grid = LensGrid(pitch_px=pitch, angle_rad=0.0, offset_xy=(1.2, 1.4), lattice="square",
                    image_shape=frame.shape)
    out, centres = approximate_sai(frame, grid, 2)
    for i in range(2):
        for j in range(2):
            x = np.rint(centres[..., 0] + (j - 0.5) * pitch / 2)
            y = np.rint(centres[..., 1] + (i - 0.5) * pitch / 2)
            ok = (x >= 0) & (x < 70) & (y >= 0) & (y < 60)
            assert ok.mean() > 0.9
            np.testing.assert_array_equal(out[i * 2 + j][ok],
                                          frame[y[ok].astype(int), x[ok].astype(int)])
            assert np.all(np.isnan(out[i * 2 + j][~ok]))


def test_approximate_sai_refuses_a_hex_grid():
    grid = LensGrid(pitch_px=20.0, angle_rad=0.0, offset_xy=(0, 0), image_shape=(50, 50))
    with pytest.raises(ValueError, match="square"):
        approximate_sai(np.zeros((50, 50)), grid, 2)
