"""Real lenslet frames: no-hint calibration is right or refused; --start refines a camera XML."""

from __future__ import annotations

import functools
from dataclasses import replace

import cv2
import numpy as np
import pytest

from plenocli import calibration
from plenocli.errors import CalibrationError
from plenocli.io import raytrix
from plenocli.model.lensgrid import LensGrid

pytestmark = pytest.mark.realdata


@functools.cache
def _no_hint(path: str):
    """calibrate() of the frame at ``path``, once per session (several tests read it)."""
    return calibration.calibrate(_load(path))


def _load(path):
    return cv2.imread(str(path), cv2.IMREAD_UNCHANGED)[..., :3].astype(np.float32).sum(-1)


def _png(realdata, name):
    return str(next((realdata / "raytrix" / name).glob("*.png")))


def _frame(realdata, name):
    folder = realdata / "raytrix" / name
    image = _load(_png(realdata, name))
    xml = raytrix.grid_from_calib(raytrix.read_calib(next(folder.glob("*.xml"))), image.shape)
    return image, xml


def _mean_micro_image(image: np.ndarray, centres: np.ndarray, *, half: int) -> np.ndarray:
    """Average of the micro-images around ``centres`` (K, 2), resampled bilinearly on a
    (2 half + 1)^2 grid centred on each centre: its symmetry centre is the grid's bias."""
    rows, cols = image.shape
    offs = np.arange(-half, half + 1, dtype=np.float32)
    acc = np.zeros((len(offs), len(offs)), np.float64)
    img = np.asarray(image, np.float32)
    keep = ((centres[:, 0] > half + 1) & (centres[:, 0] < cols - half - 2)
            & (centres[:, 1] > half + 1) & (centres[:, 1] < rows - half - 2))
    for x, y in centres[keep]:
        mapx = (x + offs)[None, :].repeat(len(offs), 0).astype(np.float32)
        mapy = (y + offs)[:, None].repeat(len(offs), 1).astype(np.float32)
        acc += cv2.remap(img, mapx, mapy, cv2.INTER_LINEAR)
    return acc / max(int(keep.sum()), 1)


def _symmetry_centre(patch: np.ndarray, *, radius: float) -> tuple[float, float]:
    """Point-symmetry centre (dx, dy) of a patch relative to its middle pixel (px), found
    independently of the calibration's own centre estimators.

    Minimises sum over |r| < radius of (P(c + r) - P(c - r))^2 over sub-pixel c (bilinear
    resampling, Nelder-Mead)."""
    from scipy.optimize import minimize

    n = patch.shape[0]
    mid = (n - 1) / 2
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float32) - np.float32(mid)
    inside = np.hypot(xx, yy) < radius
    p = patch.astype(np.float32)

    def cost(c):
        fwd = cv2.remap(p, (mid + c[0] + xx).astype(np.float32),
                        (mid + c[1] + yy).astype(np.float32), cv2.INTER_CUBIC)
        back = cv2.remap(p, (mid + c[0] - xx).astype(np.float32),
                         (mid + c[1] - yy).astype(np.float32), cv2.INTER_CUBIC)
        return float(np.sum((fwd - back)[inside] ** 2))

    res = minimize(cost, np.zeros(2), method="Nelder-Mead",
                   options={"xatol": 1e-4, "fatol": 1e-12, "maxiter": 400})
    return float(res.x[0]), float(res.x[1])


def _symmetry_offsets(flat, centres, pitch, shape):
    """Per 3 x 3 region: the point-symmetry centre of the region's mean micro-image relative to
    the given centres (px), found independently of the calibration (Nelder-Mead on the
    resampled mean micro-image)."""
    rows, cols = shape
    half = int(pitch // 2)
    out = []
    for r in range(3):
        for c in range(3):
            sel = (centres[:, 1] // (rows / 3) == r) & (centres[:, 0] // (cols / 3) == c)
            mean = _mean_micro_image(flat, centres[sel], half=half)
            out.append(np.hypot(*_symmetry_centre(mean, radius=0.45 * pitch)))
    return np.array(out)


@pytest.mark.parametrize("name", ["origami", "fujita2"])
def test_no_hint_matches_the_camera_xml(realdata, name):
    image, xml = _frame(realdata, name)
    grid, report = _no_hint(_png(realdata, name))
    # measured +0.070 % / +0.008 %; origami's XML pitch is not its frame's (next test)
    assert abs(grid.pitch_px / xml.pitch_px - 1) <= (0.0008 if name == "origami" else 0.0005)
    step = np.pi / 3
    dang = (grid.angle_rad - xml.angle_rad + step / 2) % step - step / 2
    assert abs(np.degrees(dang)) <= 0.02
    assert report.verdict.contrast > 0
    if name == "origami":   # its XML offset lines up with the micro-images
        assert calibration.compare_grids(grid, xml, image.shape)["max_px"] <= 2.0
    assert report.lens_types is not None   # both are multi-focus (Raytrix) arrays
    # scenes: pitch and angle from the border repetition, with its standard errors
    assert not report.fit.centres_refined
    assert 0 < report.fit.pitch_se_px < 0.001 and 0 < report.fit.angle_se_rad < 1e-4


def test_origami_pitch_is_the_frames_not_the_xmls(realdata):
    """The independent point-symmetry check places the micro-images of the eight outer 3 x 3
    regions on our pitch (0.07 % above the XML's), and 0.4-0.6 px off a lattice of the XML's
    pitch with our offset and angle: the XML does not describe this frame's pitch to 0.05 %."""
    image, xml = _frame(realdata, "origami")
    grid, _ = _no_hint(_png(realdata, "origami"))
    flat = calibration.flatten(image, scale_px=grid.pitch_px)
    offsets = []
    for pitch in (grid.pitch_px, xml.pitch_px):
        lattice = LensGrid(pitch, grid.angle_rad, grid.offset_xy, image_shape=image.shape)
        offsets.append(_symmetry_offsets(flat, lattice.lens_centres()[1], grid.pitch_px,
                                         image.shape))
    ours, theirs = (np.delete(o, 4) for o in offsets)   # the middle region is on both
    assert ours.max() <= 0.25 and theirs.min() >= 0.35, (ours, theirs)


def _boys2(realdata):
    folder = realdata / "raytrix" / "boys2_galilean"
    image = _load(folder / "frame0.png")
    cfg = dict(map(str.strip, line.split(":")) for line
               in (folder / "tlct_calib.cfg").read_text().splitlines() if ":" in line)
    corner = {k: float(v) for k, v in cfg.items() if "MICenter" in k}
    corners = np.array([[corner[f"{n}MICenterX"], corner[f"{n}MICenterY"]]
                        for n in ("LeftTop", "RightTop", "LeftBottom", "RightBottom")])
    return image, corners


def test_boys2_galilean_pitch_against_the_hand_picked_corners(realdata):
    image, corners = _boys2(realdata)
    # rows are horizontal; a row step is sqrt(3) pitches; 32 steps from left to right
    steps = np.hypot(*(corners[1] - corners[0])) + np.hypot(*(corners[3] - corners[2]))
    corner_pitch = steps / 2 / 32 / np.sqrt(3)
    grid, _ = _no_hint(_png(realdata, "boys2_galilean"))
    assert abs(grid.pitch_px / corner_pitch - 1) <= 0.003
    step = np.pi / 3
    assert abs(np.degrees((grid.angle_rad - np.pi / 6 + step / 2) % step - step / 2)) <= 0.05


def _corner_lattice(corners):
    """The least-squares hex lattice through the four hand-picked corner centres (rows
    horizontal: 32 row steps of sqrt(3) pitches across, 41 pitch steps down; with b1 down and
    b2 = b1 turned 60 deg, a row step is b1 - 2 b2)."""
    idx = np.array([[0, 0], [32, -64], [41, 0], [73, -64]])
    return LensGrid(*calibration.fit_lattice(idx, corners), "hex")


def test_boys2_galilean_centres_on_the_corner_lattice(realdata):
    image, corners = _boys2(realdata)
    grid, report = _no_hint(_png(realdata, "boys2_galilean"))
    # the four corners do not lie on one similarity lattice (the best one misses them by up
    # to 4.2 px, least-max 3.5 px): compare every lens with the lattice through them
    far = calibration.compare_grids(grid, _corner_lattice(corners), image.shape)
    assert far["max_px"] <= 3.0, far   # measured 1.4 px (32 px before the 6-fold choice)
    assert report.lens_centre.rival_asymmetry >= 3 * report.lens_centre.asymmetry


def test_r42_crop_right_or_refused(realdata):
    image, xml = _frame(realdata, "r42_crop")
    try:
        grid, _ = calibration.calibrate(image)
    except CalibrationError as err:
        assert "pass --pitch" in str(err)
        return
    assert abs(grid.pitch_px / xml.pitch_px - 1) <= 0.0005


def test_r42_crop_with_its_xml_is_right(realdata):
    """The R42 crop is devignetted (no gaps, no vignetting): only where the content jumps
    between micro-images shows the lattice. Its XML's pitch and rotation are confirmed by the
    match judge (confidence 0.90, rivals at most 0.65; the match peaks within 0.1 % of the
    XML's pitch) and kept; the lens centre is measured 2.8 px from the XML's (the crop is the
    sensor's middle: the XML offset nearly applies; the holes are 20 px away)."""
    image, xml = _frame(realdata, "r42_crop")
    grid, report = calibration.calibrate(image, start=xml)
    assert report.decision.judge == "match" and grid.pitch_px == xml.pitch_px
    assert calibration.compare_grids(grid, xml, image.shape)["max_px"] <= 0.1 * xml.pitch_px
    # another R42's XML (35.01 px, 0.4 % off: corner lenses 0.08 pitch out) is refused
    other = realdata / "raytrix" / "xml_only" / "UnicornLinearCam__calib.xml"
    start = raytrix.grid_from_calib(raytrix.read_calib(other), image.shape)
    with pytest.raises(CalibrationError, match="best at a pitch -0.[3-6]"):
        calibration.calibrate(image, start=start)



def test_r42_crop_with_its_nominal_pitch_is_right(realdata):
    """--pitch 34.86: the match judge measures pitch and rotation near the hint (the
    midpoint of its falls) and the lens centre: 34.816 px (-0.14 % from the XML; the border
    signal folded on trial pitches peaks at 34.83-34.88), -0.01 deg. Apart: the lattice puts
    the corner lenses within 0.05 pitch of the XML's lattice about our lens centre (measured
    0.93 px), and that centre is within 0.1 pitch of an XML lens (measured 2.75 px). (The
    former parabola through the top of the match gave 34.883 px here, and +0.26 % on the
    Raytrix scene simulator: test_calibration_match.py.)"""
    image, xml = _frame(realdata, "r42_crop")
    grid, report = calibration.calibrate(image, pitch_hint=34.86)
    assert report.decision.judge == "match" and report.lattice_from != calibration.KEPT
    assert abs(grid.pitch_px / xml.pitch_px - 1) <= 0.003
    step = np.pi / 3
    turn = (grid.angle_rad - xml.angle_rad + step / 2) % step - step / 2
    corners = np.hypot(*image.shape) / 2 * (abs(grid.pitch_px / xml.pitch_px - 1) + abs(turn))
    assert corners <= 0.05 * xml.pitch_px, corners
    nearest = xml.lattice_xy(*xml.nearest_index(*grid.offset_xy))
    assert np.hypot(*(np.asarray(grid.offset_xy) - nearest)) <= 0.1 * xml.pitch_px


@pytest.mark.parametrize("name", ["origami", "fujita2"])
def test_start_from_xml_lands_on_the_symmetry_centres(realdata, name):
    image, xml = _frame(realdata, name)
    grid, _ = calibration.calibrate(image, start=xml)
    flat = calibration.flatten(image, scale_px=grid.pitch_px)
    _, ours = grid.lens_centres()
    mine = _symmetry_offsets(flat, ours, grid.pitch_px, image.shape)
    i, j = xml.nearest_index(ours[:, 0], ours[:, 1])
    theirs = _symmetry_offsets(flat, xml.lattice_xy(i, j), grid.pitch_px, image.shape)
    # measured: ours 0.01-0.15 px (origami), 0.03-0.14 px (Fujita2) per region; the XML's
    # 0.26-1.38 px (origami), 0.05-0.39 px (Fujita2)
    assert mine.max() <= 0.2, mine
    assert np.sum(theirs > mine) >= 6, (theirs, mine)


def test_a_lossy_compressed_frame_calibrates_like_the_original(realdata, tmp_path):
    """Fujita2 saved as JPEG at quality 60 (8x8 block artefacts on every micro-image)."""
    image, xml = _frame(realdata, "fujita2")
    rgb = cv2.imread(_png(realdata, "fujita2"), cv2.IMREAD_COLOR)
    cv2.imwrite(str(tmp_path / "f.jpg"), rgb, [cv2.IMWRITE_JPEG_QUALITY, 60])
    grid, _ = calibration.calibrate(_load(tmp_path / "f.jpg"))
    original, _ = _no_hint(_png(realdata, "fujita2"))
    assert abs(grid.pitch_px / xml.pitch_px - 1) <= 0.0005
    assert calibration.compare_grids(grid, original, image.shape)["max_px"] <= 0.5


def _qp48(realdata, name):
    """The VVC QP 48 encode of a shared frame (borders smeared) and its camera XML."""
    image = _load(realdata / "raytrix" / "compressed" / f"{name.split('_')[0]}_qp48.png")
    folder = realdata / "raytrix" / name
    return image, raytrix.grid_from_calib(raytrix.read_calib(folder / "calib.xml"), image.shape)


def _same_grid(grid, reference, shape):
    """Pitch within 0.1 %, angle within 0.02 deg, every lens within 0.1 pitch (lattices)."""
    step = np.pi / 3
    dang = (grid.angle_rad - reference.angle_rad + step / 2) % step - step / 2
    lattice = LensGrid(reference.pitch_px, reference.angle_rad, reference.offset_xy,
                       image_shape=shape)
    far = calibration.compare_grids(grid, lattice, shape)
    return (abs(grid.pitch_px / reference.pitch_px - 1) <= 1e-3 and abs(np.degrees(dang)) <= 0.02
            and far["max_px"] <= 0.1 * reference.pitch_px), far


def test_fujita2_qp48_right_with_no_hint_the_nominal_pitch_and_its_xml(realdata):
    """Refused three ways before (issue 19): the fold judge decides where the smeared borders
    no longer do, the regions' mean micro-images pin the pitch."""
    image, xml = _qp48(realdata, "fujita2")
    reference, _ = _no_hint(_png(realdata, "fujita2"))
    for hints in ({}, {"pitch_hint": 23.2}, {"start": xml}):
        grid, report = calibration.calibrate(image, **hints)
        right, far = _same_grid(grid, reference, image.shape)
        assert right, (hints, far)   # measured: pitch -0.03 %, max 1.7 px
        assert report.decision.judge == "fold"
    flat = calibration.flatten(image, scale_px=grid.pitch_px)
    _, ours = grid.lens_centres()
    mine = _symmetry_offsets(flat, ours, grid.pitch_px, image.shape)
    i, j = xml.nearest_index(ours[:, 0], ours[:, 1])
    theirs = _symmetry_offsets(flat, xml.lattice_xy(i, j), grid.pitch_px, image.shape)
    # measured with --start: 0.06-0.24 px per region (the XML's 0.10-0.36 px)
    assert mine.max() <= 0.3 and np.sum(theirs > mine) >= 6, (mine, theirs)


def test_boys2_nominal_xml_start_converges(realdata):
    """Its calib.xml is nominal (70 px, the frame's pitch is 70.36): it was refused."""
    image, corners = _boys2(realdata)
    xml = raytrix.grid_from_calib(raytrix.read_calib(
        realdata / "raytrix" / "boys2_galilean" / "calib.xml"), image.shape)
    grid, report = calibration.calibrate(image, start=xml)
    far = calibration.compare_grids(grid, _corner_lattice(corners), image.shape)
    assert far["max_px"] <= 3.0, far
    moved = calibration.moved_from_start(grid, xml, report)
    assert moved["pitch"]["moved_percent"] == pytest.approx(0.51, abs=0.05)


def test_wrong_hints_on_a_real_frame_are_refused(realdata):
    image, _ = _frame(realdata, "origami")
    for factor in (0.7, 1.3):
        with pytest.raises(CalibrationError, match="contradicts the image: .*hex 23.2"):
            calibration.calibrate(image, pitch_hint=23.2 * factor)
    other = realdata / "raytrix" / "xml_only" / "ChessPieces-MovingCamera__calib.xml"
    start = raytrix.grid_from_calib(raytrix.read_calib(other), image.shape)
    with pytest.raises(CalibrationError, match="start grid .* does not fit this image"):
        calibration.calibrate(image, start=start)


def _assert_right_or_refused(crop, whole, top: int, left: int) -> None:
    """A crop of a frame is calibrated on the whole frame's lattice (pitch within 0.2 %, every
    lens within 1.5 px) or refused by the regions' mean micro-images."""
    try:
        grid, _ = calibration.calibrate(crop)
    except CalibrationError as err:
        assert "regions' mean micro-images" in str(err)
        return
    moved = replace(whole, image_shape=None, centres_xy=None, indices=None,
                    offset_xy=(whole.offset_xy[0] - left, whole.offset_xy[1] - top))
    far = calibration.compare_grids(grid, moved, crop.shape)
    assert abs(grid.pitch_px / whole.pitch_px - 1) <= 0.002 and far["max_px"] <= 1.5, far


def test_a_crop_whose_texture_misleads_the_border_repetition(realdata):
    """Audit 18 W1: a 600 px crop of origami (a scene) was written at 22.835 px (+-0.028 px
    claimed; the whole frame, its XML and other crops: 23.21 px), lenses up to 7.3 px off,
    with exit 0: the far border peaks had locked onto the texture. The regions' mean
    micro-images contradict such a lattice (0.30 pitch apart); now right or refused."""
    image, _ = _frame(realdata, "origami")
    whole, _ = _no_hint(_png(realdata, "origami"))
    top, left = 401, 517
    crop = np.ascontiguousarray(image[top:top + 600, left:left + 600])
    _assert_right_or_refused(crop, whole, top, left)


@pytest.mark.parametrize(("png", "top", "left", "size"), [
    ("fujita2/frame0.png", 172, 677, 600), ("compressed/fujita2_qp48.png", 1648, 0, 400)])
def test_crops_with_few_round_regions_are_right_or_refused(realdata, png, top, left, size):
    """Audit 18 W1, second round: crops of Fujita2 whose regions are mostly not round (2 and
    9 of 16: the earlier check could not run) were written +0.68 % / -1.44 % in pitch, lenses
    3.2 / 6.3 px off the whole frame's lattice, +-0.018 / 0.040 px claimed. The round regions,
    however few, see it; now right or refused."""
    whole, _ = _no_hint(_png(realdata, "fujita2"))
    image = _load(realdata / "raytrix" / png)
    crop = np.ascontiguousarray(image[top:top + size, left:left + size])
    _assert_right_or_refused(crop, whole, top, left)
