"""Exact ray tracing: paraxial limits, an analytic plano-convex lens, Snell's law, geometry."""

import math

import numpy as np
import pytest

from plenocli.optics.analysis import image_distance, paraxial
from plenocli.optics.glass import refractive_index
from plenocli.optics.lens import Lens, Surface, intersect_conic, refract, trace

N_BK7 = refractive_index("N-BK7")


def parallel_rays(heights, z=-1.0):
    h = np.asarray(heights, dtype=float)
    return np.stack([0 * h, h, np.full_like(h, z)], 1), np.tile([0.0, 0.0, 1.0], (len(h), 1))


def axis_crossing(bundle):
    """z where each ray meets the axis (y = 0)."""
    return bundle.position[:, 2] - bundle.position[:, 1] * bundle.direction[:, 2] \
        / bundle.direction[:, 1]


@pytest.mark.parametrize("r1, r2, thickness", [(100.0, -100.0, 0.5), (60.0, -200.0, 1.0),
                                               (80.0, math.inf, 0.8)])
def test_thin_singlet_matches_lensmaker(r1, r2, thickness):
    lens = Lens((Surface(r1, thickness, "N-BK7", 12.0), Surface(r2, 50.0, "air", 12.0)))
    n = N_BK7
    c1, c2 = 1 / r1, (0.0 if math.isinf(r2) else 1 / r2)
    power = (n - 1) * (c1 - c2 + (n - 1) * thickness * c1 * c2 / n)  # thick lensmaker
    efl = 1 / power
    bfd = efl * (1 - (n - 1) * thickness * c1 / n)
    par = paraxial(lens)
    assert par["efl_mm"] == pytest.approx(efl, rel=1e-12)
    assert par["bfd_mm"] == pytest.approx(bfd, rel=1e-12)
    # A real ray at a tiny height crosses the axis at the paraxial focus.
    pos, d = parallel_rays([1e-4])
    out = trace(lens, pos, d, to_image=False)
    assert axis_crossing(out)[0] - lens.vertex_z_mm[-1] == pytest.approx(bfd, rel=1e-6)
    # And the thin-lens limit: 1/f = (n - 1)(1/R1 - 1/R2) within the thickness term.
    assert abs(power - (n - 1) * (c1 - c2)) < (n - 1) ** 2 * thickness * abs(c1 * c2) / n + 1e-15


@pytest.mark.parametrize("h", [1.0, 5.0, 10.0, 14.0])
def test_plano_convex_matches_analytic_trace(h):
    radius, thick, n = 50.0, 5.0, N_BK7
    lens = Lens((Surface(radius, thick, "N-BK7", 30.0), Surface(math.inf, 90.0, "air", 30.0)))
    out = trace(lens, *parallel_rays([h]), to_image=False)
    # Closed form: refraction at the sphere, then at the flat back (scalar Snell in the plane).
    i = math.asin(h / radius)
    r = math.asin(math.sin(i) / n)
    slope = i - r  # ray angle to the axis inside the glass (towards the axis)
    sag = radius - math.sqrt(radius ** 2 - h ** 2)
    y_back = h - (thick - sag) * math.tan(slope)
    out_angle = math.asin(n * math.sin(slope))
    z_cross = thick + y_back / math.tan(out_angle)
    assert out.alive[0]
    assert out.position[0, 1] == pytest.approx(y_back, abs=1e-9)
    assert axis_crossing(out)[0] == pytest.approx(z_cross, abs=1e-9)


def random_rays(rng, count, spread=0.15, radius=1.5):
    r = radius * np.sqrt(rng.random(count))
    phi = 2 * np.pi * rng.random(count)
    pos = np.stack([r * np.cos(phi), r * np.sin(phi), np.full(count, -1.0)], 1)
    d = np.column_stack([rng.normal(0, spread, (count, 2)), np.ones(count)])
    return pos, d / np.linalg.norm(d, axis=1, keepdims=True)


def table2():
    from plenocli.io.lensfile import read_lens
    from tests.conftest import ROOT

    return read_lens(ROOT / "configs" / "lenses" / "paper_table2.yaml")


def test_snell_and_surface_geometry_on_the_aspheric_lens():
    lens = table2()
    rng = np.random.default_rng(3)
    pos, d = random_rays(rng, 4000)
    out = trace(lens, pos, d, record=True)
    assert out.alive.mean() > 0.5
    n = lens.indices()
    alive = out.alive
    for k, (s, z0) in enumerate(zip(lens.surfaces, lens.vertex_z_mm, strict=True)):
        hit = out.hits[k][alive]
        r = np.hypot(hit[:, 0], hit[:, 1])
        assert np.all(np.abs(hit[:, 2] - z0 - s.sag(r)) < 1e-9)  # on the surface
        assert np.all(r <= s.diameter_mm / 2 + 1e-12)  # inside the clear aperture
        nrm, din, dout = out.normals[k][alive], out.directions_in[k][alive], \
            out.directions_out[k][alive]
        assert np.allclose(np.linalg.norm(dout, axis=1), 1.0, atol=1e-12)
        # n1 (d_in x N) = n2 (d_out x N): tangential momentum kept (Snell) and coplanarity.
        lhs = n[k] * np.cross(din, nrm)
        rhs = n[k + 1] * np.cross(dout, nrm)
        assert np.max(np.abs(lhs - rhs)) < 1e-9
        assert np.all(np.sum(dout * nrm, axis=1) * np.sum(din * nrm, axis=1) > 0)  # no reflection
    # Every survivor reaches the image plane; every other ray is accounted as stopped.
    assert np.all(np.isfinite(out.position[alive]))
    assert np.allclose(out.position[alive, 2], lens.image_z_mm)
    assert np.all(np.isnan(out.position[~alive]))


def test_apertures_stop_rays_outside_them():
    lens = Lens((Surface(math.inf, 1.0, "air", 2.0, stop=True),
                 Surface(20.0, 2.0, "N-BK7", 10.0), Surface(-20.0, 10.0, "air", 10.0)))
    pos, d = parallel_rays([0.0, 0.5, 0.99, 1.01, 3.0])
    out = trace(lens, pos, d)
    assert out.alive.tolist() == [True, True, True, False, False]
    assert trace(lens, pos, d, clip=False).alive.all()
    masked = trace(lens, pos, d, stop_mask=lambda x, y: y < 0.7)
    assert masked.alive.tolist() == [True, True, False, False, False]


def test_total_internal_reflection_is_stopped():
    d = np.array([[math.sin(math.radians(50)), 0.0, math.cos(math.radians(50))]])
    _, ok = refract(d, np.array([[0.0, 0.0, -1.0]]), 1.5, 1.0)  # critical angle 41.8 deg
    assert not ok[0]
    _, ok = refract(d, np.array([[0.0, 0.0, -1.0]]), 1.0, 1.5)
    assert ok[0]


@pytest.mark.parametrize("conic", [-18.73, -4.97, -1.0, 0.0, 0.1747, 5.13])
def test_conic_intersection_from_far_away_lands_on_the_vertex_sheet(conic):
    radius = 3.8
    h = 0.9 * radius / math.sqrt(max(1 + conic, 1.0))  # inside the conic's reach
    rng = np.random.default_rng(1)
    pos = np.column_stack([rng.uniform(-h, h, (200, 2)) * 0.5, np.full(200, -5.0)])
    d = np.column_stack([rng.normal(0, 0.05, (200, 2)), np.ones(200)])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    hit, ok = intersect_conic(pos, d, radius_mm=radius, conic=conic, vertex_z_mm=0.0)
    surf = Surface(radius, conic=conic)
    r = np.hypot(hit[ok, 0], hit[ok, 1])
    assert ok.mean() > 0.9
    assert np.all(np.abs(hit[ok, 2] - surf.sag(r)) < 1e-9)


def test_image_distance_for_a_near_object_follows_the_thin_lens_equation():
    lens = Lens((Surface(100.0, 0.01, "N-BK7", 1.0), Surface(-100.0, 0.0, "air", 1.0)))
    f = paraxial(lens)["efl_mm"]
    assert image_distance(lens, object_distance_mm=2000.0) == pytest.approx(
        1 / (1 / f - 1 / 2000.0), rel=1e-4)


def test_invalid_conic_for_the_diameter_is_refused():
    with pytest.raises(ValueError, match="does not reach"):
        Lens((Surface(-2.6425, 1.0, "air", 3.38069, conic=18.7316),))


@pytest.mark.parametrize("thickness, crosses", [(1.0, True), (2.0, True), (2.05, False)])
def test_surfaces_that_cross_inside_their_apertures_are_refused(thickness, crosses):
    # A biconvex singlet R = +-50 mm, 20 mm across: each rim's sag is 50 - sqrt(50^2 - 10^2),
    # so the glass is 2 * 1.0102 mm thinner at the rim than on the axis.
    rim_sag = 50.0 - math.sqrt(50.0 ** 2 - 10.0 ** 2)
    surfaces = (Surface(50.0, thickness, "N-BK7", 20.0), Surface(-50.0, 40.0, "air", 20.0))
    if not crosses:
        Lens(surfaces)
        return
    with pytest.raises(ValueError, match=rf"surfaces 1 and 2 cross 10 mm off axis \(the gap "
                                         rf"between them is {thickness - 2 * rim_sag:.4g} mm"):
        Lens(surfaces)


def test_surfaces_touching_within_a_printed_prescriptions_rounding_are_taken():
    # Table 2's surfaces 3 and 4 meet 0.67 um inside their 1.69 mm rims: less than the
    # 1.8 um the rounding of its printed radius -2.6425 mm leaves at that rim.
    s3 = Surface(-2.6425, 0.07071, "air", 3.38069, conic=-18.7316)
    s4 = Surface(-2.1581, 0.43551, "F5", 3.38110, conic=-11.9393)
    gap = 0.07071 + s4.sag(np.array([1.690345]))[0] - s3.sag(np.array([1.690345]))[0]
    assert -1e-3 < gap < 0  # they do cross, by under a micrometre
    Lens((s3, s4))


def test_compiled_tracer_matches_the_numpy_tracer():
    from plenocli.optics.crosstalk import stop_mask
    from plenocli.optics.fasttrace import trace_fast

    lens = table2()
    pos, d = random_rays(np.random.default_rng(5), 5000)
    for quarter, width in ((None, 0.0), ((1, -1), 0.0), ((-1, 1), 0.3), (None, 0.3)):
        signs = {(1, 1): "++", (1, -1): "+-", (-1, 1): "-+", (-1, -1): "--"}
        ref = trace(lens, pos, d, stop_mask=stop_mask(
            quarter=signs[quarter] if quarter else None, cross_width_mm=width))
        p, dd, alive = trace_fast(lens, pos, d, quarter=quarter, cross_half_width_mm=width / 2)
        assert np.array_equal(alive, ref.alive)
        assert np.nanmax(np.abs(p - ref.position)) < 1e-12
        assert np.nanmax(np.abs(dd - ref.direction)) < 1e-12


def test_serial_and_parallel_kernels_are_distinct_cached_functions():
    """numba caches by Python function: one function compiled twice (serial and parallel)
    would share one cache entry (numba issue 6845)."""
    from plenocli.optics import fasttrace

    serial, parallel = fasttrace._serial_kernel, fasttrace._parallel_kernel
    assert serial.py_func is not parallel.py_func
    assert serial.py_func.__qualname__ != parallel.py_func.__qualname__
    assert not serial.targetoptions.get("parallel") and parallel.targetoptions["parallel"]
    lens = table2()
    pos, d = random_rays(np.random.default_rng(6), 2000)
    one = fasttrace.trace_fast(lens, pos, d, parallel=False)
    two = fasttrace.trace_fast(lens, pos, d, parallel=True)
    for a, b in zip(one, two, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("surface, match", [
    (dict(thickness_mm=-0.5), "thickness_mm -0.5"), (dict(thickness_mm=math.inf), "thickness"),
    (dict(radius_mm=math.nan), "radius_mm is NaN"), (dict(conic=math.inf), "conic"),
    (dict(glass=0.9), "refractive index"), (dict(diameter_mm=math.nan), "diameter_mm is NaN")])
def test_impossible_surfaces_are_refused(surface, match):
    with pytest.raises(ValueError, match=match):
        Lens((Surface(**surface),))
    with pytest.raises(ValueError, match="image_distance_mm"):
        Lens((Surface(),), image_distance_mm=math.nan)


def _table2_doc():
    import yaml

    from tests.conftest import ROOT

    return yaml.safe_load((ROOT / "configs" / "lenses" / "paper_table2.yaml").read_text())


@pytest.mark.parametrize("change, match", [
    (lambda d: d["surfaces"][1].__setitem__("radius", 0.0), r"surface 2: radius 0 is no surface"),
    (lambda d: d["surfaces"].pop(0), "no surface has 'stop: true'"),
    (lambda d: d["surfaces"][3].__setitem__("stop", True), "surfaces 1, 4 all have 'stop"),
    (lambda d: d["surfaces"][0].__setitem__("stop", "no"), "stop 'no' must be true or false"),
    (lambda d: d.__setitem__("focal", 6.0), "unknown key.s. focal"),
    (lambda d: d["surfaces"][1].__setitem__("glass", 7.0), "surface 2: refractive index 7.0"),
])
def test_a_lens_file_that_is_no_prescription_is_refused(change, match):
    from plenocli.errors import ConfigError
    from plenocli.io.lensfile import lens_from_dict

    doc = _table2_doc()
    change(doc)
    with pytest.raises(ConfigError, match=match):
        lens_from_dict(doc)


def test_a_near_afocal_lens_has_no_focal_length():
    """Radii of 1e12 mm leave a y-nu slope of rounding: EFL 7e23 mm for an 8.7 mm lens."""
    from plenocli.io.lensfile import lens_from_dict

    doc = _table2_doc()
    for row in doc["surfaces"][1:]:
        row["radius"] = 1e12
    with pytest.raises(ValueError, match="afocal.*1e.04 times its size"):
        paraxial(lens_from_dict(doc))
    weak = Lens((Surface(5000.0, 2.0, "N-BK7", 25.0, stop=True), Surface(math.inf, 0.0, "air")),
                image_distance_mm=9000.0)
    assert paraxial(weak)["efl_mm"] == pytest.approx(5000.0 / (N_BK7 - 1), rel=1e-3)
