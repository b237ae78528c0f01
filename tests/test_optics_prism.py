"""The one prism ray model (plenocli.optics.prism) against closed forms."""

import math

import numpy as np
import pytest

from plenocli.optics.prism import (
    deviate,
    image_distance_mm,
    prism_deviation_deg,
    pupil_centroid_mm,
    scene_hits,
)


def test_pupil_centroid_is_the_half_and_quarter_disk_centroid():
    rng = np.random.default_rng(0)
    r = 1.5 * np.sqrt(rng.random(400_000))  # uniform over a disk of radius 1.5
    phi = 2 * math.pi * rng.random(r.size)
    x, y = r * np.cos(phi), r * np.sin(phi)
    half = x > 0
    quarter = (x < 0) & (y > 0)
    np.testing.assert_allclose(pupil_centroid_mm(3.0, (1, 0)), [x[half].mean(), 0.0], atol=3e-3)
    np.testing.assert_allclose(pupil_centroid_mm(3.0, (-1, 1)),
                               [x[quarter].mean(), y[quarter].mean()], atol=5e-3)
    assert pupil_centroid_mm(3.0, (1, 0))[0] == pytest.approx(4 * 1.5 / (3 * math.pi))


@pytest.mark.parametrize("n, apex", [(1.74, 16.7), (1.5, 30.0)])
def test_symmetric_passage_gives_the_minimum_deviation(n, apex):
    # at minimum deviation the ray crosses the prism parallel to its base: it meets the first
    # face (leaning by A/2) at incidence (D_min + A) / 2, i.e. it travels at D_min / 2 off +z
    # towards the thick edge, and leaves at D_min / 2 towards the thin edge
    d_min = math.radians(prism_deviation_deg(n, apex)["minimum_deg"])
    start = np.array([[-math.sin(d_min / 2), 0.0, math.cos(d_min / 2)]])
    out = deviate(start, n=n, apex_deg=apex, towards=(1, 0))
    np.testing.assert_allclose(out, [[math.sin(d_min / 2), 0.0, math.cos(d_min / 2)]],
                               atol=1e-12)


def test_reverse_undoes_the_prism_and_total_reflection_is_nan():
    rng = np.random.default_rng(1)
    d = np.c_[rng.uniform(-0.3, 0.3, (50, 2)), np.ones(50)]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for towards in ((1, 0), (0, -1), (1, 1), (-1, 1)):
        out = deviate(d, n=1.74, apex_deg=16.7, towards=towards)
        np.testing.assert_allclose(deviate(out, n=1.74, apex_deg=16.7, towards=towards,
                                           reverse=True), d, atol=1e-12)
    steep = np.array([[0.8, 0.0, 0.6]])  # meets the exit face beyond its critical angle
    assert np.isnan(deviate(steep, n=1.9, apex_deg=60.0, towards=(1, 0))).all()


def test_without_prism_the_thin_lens_images_the_conjugate_point():
    d = image_distance_mm(6.16, 2000.0)
    assert 1 / d + 1 / 2000.0 == pytest.approx(1 / 6.16)
    s = np.array([[0.3, -0.2], [1.0, 0.5]])
    for pupil in ((0.0, 0.0), (0.6, -0.4)):  # in focus: every pupil point meets the same point
        hits = scene_hits(s, np.array(pupil), image_distance_mm=d, object_distance_mm=2000.0)
        np.testing.assert_allclose(hits, -s * 2000.0 / d, atol=1e-9)
    tangents = scene_hits(s, np.zeros(2), image_distance_mm=6.16, object_distance_mm=math.inf)
    np.testing.assert_allclose(tangents, -s / 6.16, atol=1e-12)
