"""Synthetic focused-plenoptic captures: Eq. 3 read backwards, files and truth."""

from __future__ import annotations

import json

import numpy as np
import pytest

from plenocli.io import tiffio
from plenocli.io.gridfile import read_grid
from plenocli.pipeline.stages.simulate import simulate
from plenocli.synth import kinds
from plenocli.synth.focused import raytrix_scene, simulate_raytrix_scene, texture_at


def test_scene_is_a_pure_function_of_the_seed():
    a = raytrix_scene(seed=5, rows=120, cols=160)
    b = raytrix_scene(seed=5, rows=120, cols=160)
    c = raytrix_scene(seed=6, rows=120, cols=160)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[2], b[2])
    assert not np.array_equal(a[0], c[0])


def test_each_pixel_shows_the_texture_at_eq3():
    sensor, grid, truth, info = raytrix_scene(seed=1, rows=100, cols=120)
    texture = {k: np.asarray(v) for k, v in info["texture"].items()}
    s, g = info["s"], info["g_true"]
    for r, c in [(10, 10), (50, 77), (99, 3)]:
        i, j = grid.nearest_index(c, r)
        cx, cy = grid.lattice_xy(i, j)
        expected = texture_at(texture, s * (g * (c - cx) + cx), s * (g * (r - cy) + cy),
                              box=s * g)
        assert sensor[r, c] == pytest.approx(expected, rel=1e-6)


def test_pixel_filter_is_the_box_average():
    _, _, _, info = raytrix_scene(seed=2, rows=40, cols=40)
    texture = {k: np.asarray(v) for k, v in info["texture"].items()}
    box = 0.8
    sub = (np.arange(64) + 0.5) / 64 * box - box / 2
    xs, ys = np.meshgrid(3.3 + sub, 7.1 + sub)
    brute = texture_at(texture, xs, ys).mean()
    assert texture_at(texture, 3.3, 7.1, box=box) == pytest.approx(brute, rel=1e-4)


@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_write_raytrix_scene(tmp_path, cfa):
    truth = simulate("raytrix-scene", tmp_path, seed=3, rows=96, cols=128, cfa=cfa)
    frames, meta = tiffio.read_image(tmp_path / "frames.tif")
    assert frames.shape == (1, 96, 128) and meta["cfa"] == cfa
    grid = read_grid(tmp_path / "grid.yaml")
    assert grid.pitch_px == pytest.approx(truth["pitch_px"])
    texture, _ = tiffio.read_image(tmp_path / "texture.tif")
    assert texture.shape[0] == (3 if cfa else 1)
    assert json.loads((tmp_path / "truth.json").read_text())["g_true"] == truth["g_true"]


def test_registered_as_a_simulation_kind():
    assert kinds()["raytrix-scene"] is simulate_raytrix_scene
