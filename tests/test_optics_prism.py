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


# ---------------------------------------------------------------------------------------------
# An independent trace of the prism: the simulator and the stitcher share plenocli.optics.prism,
# so the rig tests cannot see an error in it. Here Snell's law is written out by hand (textbook
# forms, not the library's refract) and the prism is built from its faces' slopes.

def _snell(d: np.ndarray, face_normal: np.ndarray, n_in: float, n_out: float) -> np.ndarray:
    """Vector Snell's law for one unit ray (3,), tangential form: the component of n d along
    the surface is kept, the normal component is what makes the refracted ray a unit vector on
    the far side of the surface."""
    normal = face_normal / np.linalg.norm(face_normal)
    normal = normal * np.sign(d @ normal)  # along the light
    tangential = (n_in / n_out) * (d - (d @ normal) * normal)
    out = tangential + math.sqrt(1 - tangential @ tangential) * normal
    # Snell's law as stated: n sin(angle to the normal) is the same on both sides, and the
    # refracted ray stays in the plane of incidence
    assert n_in * np.linalg.norm(np.cross(d, normal)) == pytest.approx(
        n_out * np.linalg.norm(np.cross(out, normal)), abs=1e-12)
    assert np.cross(d, normal) @ out == pytest.approx(0.0, abs=1e-12)
    return out


def _faces(apex_deg: float, towards: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Normals of the entrance and exit faces: planes z = -/+ tan(A / 2) (sx x + sy y), i.e.
    each face slopes by A / 2 along every axis the prism acts on (glass thicker towards
    (sx, sy)); a normal is the cross product of two vectors lying in the face."""
    t = math.tan(math.radians(apex_deg) / 2)
    sx, sy = towards
    entrance = np.cross([1.0, 0.0, -sx * t], [0.0, 1.0, -sy * t])
    exit_ = np.cross([1.0, 0.0, sx * t], [0.0, 1.0, sy * t])
    return entrance, exit_


def _by_hand(d: np.ndarray, n: float, apex_deg: float, towards: tuple[int, int]) -> np.ndarray:
    entrance, exit_ = _faces(apex_deg, towards)
    return _snell(_snell(d, entrance, 1.0, n), exit_, n, 1.0)


@pytest.mark.parametrize("n, apex", [(1.74, 16.7), (1.5, 30.0)])
def test_principal_section_matches_the_textbook_prism(n, apex):
    """Rays in the principal section: the signed-angle form of Snell's law at each face
    (sin(a - phi) = n sin(b - phi), phi the face normal's angle) gives the deviation, towards
    the thick side of the prism, and its minimum 2 asin(n sin(A / 2)) - A."""
    a = math.radians(apex)
    for alpha in np.radians([-20.0, -12.0, -6.0, 0.0, 5.0, 15.0]):
        beta = a / 2 + math.asin(math.sin(alpha - a / 2) / n)  # inside: entrance normal at +A/2
        gamma = -a / 2 + math.asin(n * math.sin(beta + a / 2))  # out: exit normal at -A/2
        d = np.array([[math.sin(alpha), 0.0, math.cos(alpha)]])
        out = deviate(d, n=n, apex_deg=apex, towards=(1, 0))[0]
        assert math.atan2(out[0], out[2]) == pytest.approx(gamma, abs=1e-12)
        assert out[1] == pytest.approx(0.0, abs=1e-15)
        assert gamma - alpha >= 2 * math.asin(n * math.sin(a / 2)) - a - 1e-12  # >= minimum


@pytest.mark.parametrize("towards", [(1, 0), (0, -1), (-1, 1), (1, 1)])
def test_skew_rays_match_snells_law_traced_by_hand(towards):
    """Skew rays through the dual-pixel prisms and the corner prisms of the quad-pixel
    pyramid (paper values n = 1.74, A = 16.7 deg), against the hand trace."""
    rng = np.random.default_rng(4)
    d = np.c_[rng.uniform(-0.3, 0.3, (12, 2)), np.ones(12)]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    out = deviate(d, n=1.74, apex_deg=16.7, towards=towards)
    expected = np.array([_by_hand(ray, 1.74, 16.7, towards) for ray in d])
    np.testing.assert_allclose(out, expected, atol=1e-12)
    # the light bends towards the thick side, about (n - 1) A on each axis the prism acts on
    bend = np.degrees(np.arctan2(out[:, :2], out[:, 2:]) - np.arctan2(d[:, :2], d[:, 2:]))
    for axis in range(2):
        assert np.all(np.sign(bend[:, axis]) == towards[axis]) or towards[axis] == 0
        if towards[axis]:
            assert np.abs(bend[:, axis]).min() > 0.74 * 16.7 * 0.9


def test_scene_hits_follow_the_hand_traced_ray():
    """scene_hits (what the simulator renders and the rig undistortion inverts): the ray from
    the sensor point through the pupil point towards its thin-lens conjugate, bent by the
    prism by hand, meets the scene plane where the library says."""
    dist, z = image_distance_mm(6.16, 2000.0), 2000.0
    sensors = np.array([[0.3, -0.2], [-1.1, 0.4], [0.0, 0.0]])
    pupil = pupil_centroid_mm(3.09, (1, 0))
    hits = scene_hits(sensors, pupil, image_distance_mm=dist, object_distance_mm=z,
                      prism=(1.74, 16.7), towards=(1, 0))
    for s, hit in zip(sensors, hits, strict=True):
        conjugate = -s * z / dist
        d = np.r_[conjugate - pupil, z]
        out = _by_hand(d / np.linalg.norm(d), 1.74, 16.7, (1, 0))
        np.testing.assert_allclose(hit, pupil + out[:2] * z / out[2], atol=1e-9)
