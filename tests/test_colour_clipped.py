"""Pixels clipped in some channels only keep their colour (chroma propagation), known answer: a
warm sky recorded by the simulated Canon 5D Mark IV, overexposed so that one camera channel clips
around the sun while the sun itself clips in all three."""

from __future__ import annotations

import warnings

import numpy as np

from plenocli.colour import develop as dev
from plenocli.colour import highlights
from plenocli.colour.demosaic import demosaic
from plenocli.model.colour import camera_to_srgb, gains_from_neutral, rgb_to_xyz
from plenocli.synth.natural import natural_capture

PEAK = 4.0  # the sun's camera green at 4 x the white level: the sky around it clips in one channel


def _sunset(rows=256, cols=384) -> np.ndarray:
    """An orange sky (uint8 sRGB), brightest around a white sun: known colour everywhere."""
    rr, cc = np.mgrid[0:rows, 0:cols] / np.array([rows, cols])[:, None, None]
    d = np.hypot(rr - 0.55, (cc - 0.5) * 1.5)
    light = 0.35 + 0.65 * np.exp(-(d / 0.35) ** 2)
    sky = np.stack([np.ones_like(d), 0.30 + 0.25 * (1 - rr), 0.08 + 0.10 * (1 - rr)], -1)
    linear = sky * light[..., None]
    linear[d < 0.06] = 1.0
    encoded = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    return np.round(np.clip(encoded, 0, 1) * 255).astype(np.uint8)


def _lab(rgb):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour

        return colour.XYZ_to_Lab(colour.RGB_to_XYZ(np.asarray(rgb, np.float64), "sRGB",
                                                   apply_cctf_decoding=False))


def test_one_channel_clipped_keeps_its_hue_and_all_clipped_stays_white():
    cap = natural_capture(_sunset(), seed=4, peak=PEAK)
    # ground truth from the generator's own exposure rule: camera DN of every channel per pixel
    to_camera = cap.xyz_to_camera @ rgb_to_xyz("srgb")
    dn = cap.truth.astype(np.float64) @ to_camera.T * (cap.dn_per_unit
                                                       / to_camera.sum(axis=1).max())
    level = cap.white - cap.black
    over, under = dn > 1.05 * level, dn < 0.9 * level
    one = (over.sum(-1) == 1) & (under.sum(-1) == 2)
    every = (dn > 1.05 * level).all(-1)
    assert one.sum() > 2000 and every.sum() > 500

    frame = cap.raw.astype(np.float32) - cap.black
    frame[cap.raw >= cap.white] = np.nan
    gains = gains_from_neutral(cap.as_shot_neutral)
    to_srgb = camera_to_srgb(cap.xyz_to_camera)
    view = dev.ColourView("S", (0,), "RGGB")
    camera = dev.camera_rgb(frame[np.newaxis], view, gains=gains)
    scene = dev.scene_rgb(camera, gains=gains, camera_to_srgb=to_srgb)
    today = dev.scene_rgb(demosaic(frame, "RGGB", gains=gains), gains=gains,
                          camera_to_srgb=to_srgb)
    unit = cap.dn_per_unit * cap.as_shot_neutral[1]  # developed DN of the scene's white
    scene, today = scene / unit, today / unit
    for image in (scene, today):  # what develop shows: every still-masked pixel white
        image[~np.isfinite(image).all(-1)] = np.nanpercentile(image, 99)

    truth = _lab(cap.truth[one])
    figures = {}
    for label, image in (("rebuilt", scene), ("today", today)):
        lab = _lab(image[one])
        turn = np.arctan2(lab[:, 2], lab[:, 1]) - np.arctan2(truth[:, 2], truth[:, 1])
        hue = np.degrees(np.abs(np.angle(np.exp(1j * turn))))
        chroma = np.hypot(lab[:, 1], lab[:, 2]) / np.hypot(truth[:, 1], truth[:, 2])
        figures[label] = (np.median(hue), np.percentile(hue, 90), np.median(chroma))
    hue_median, hue_p90, chroma = figures["rebuilt"]
    # docs/colour.md: median 1.4 deg, 90th percentile 2.6 deg, chroma 1.00 (today: white)
    assert hue_median <= 3.0 and hue_p90 <= 5.0 and 0.8 <= chroma <= 1.25, figures
    assert figures["today"][2] < 0.1, figures  # today's white has no chroma at all
    assert not np.isfinite(camera[every]).any()  # clipped in every channel: still masked


def test_bands_change_nothing(monkeypatch):
    cap = natural_capture(_sunset(96, 128), seed=5, peak=PEAK)
    frame = cap.raw.astype(np.float32) - cap.black
    frame[cap.raw >= cap.white] = np.nan
    gains = gains_from_neutral(cap.as_shot_neutral)
    whole = demosaic(frame, "RGGB", gains=gains)
    banded = whole.copy()
    assert highlights.rebuild_partly_clipped(whole, frame, "RGGB", gains) > 500
    monkeypatch.setattr(highlights, "BAND_ROWS", 8)
    highlights.rebuild_partly_clipped(banded, frame, "RGGB", gains)
    np.testing.assert_array_equal(banded, whole)


def test_two_channels_clipped_are_never_pink():
    """audit 19 W3: where red and green clipped over a measured blue, both were floored at
    their own clip levels, as unequal as the white balance: pink (hue 45 deg off the orange
    sky at the median). The clipped channels now share one white-balanced floor: equal, above
    the measured one (a yellow-white, as LibRaw's clip mode), never pink or magenta."""
    cap = natural_capture(_sunset(), seed=4, peak=6.0)
    to_camera = cap.xyz_to_camera @ rgb_to_xyz("srgb")
    dn = cap.truth.astype(np.float64) @ to_camera.T * (cap.dn_per_unit
                                                       / to_camera.sum(axis=1).max())
    level = cap.white - cap.black
    two = ((dn > 1.05 * level).sum(-1) == 2) & ((dn < 0.9 * level).sum(-1) == 1)
    assert two.sum() > 10000
    frame = cap.raw.astype(np.float32) - cap.black
    frame[cap.raw >= cap.white] = np.nan
    gains = gains_from_neutral(cap.as_shot_neutral)
    camera = dev.camera_rgb(frame[np.newaxis], dev.ColourView("S", (0,), "RGGB"), gains=gains)
    balanced = np.sort(camera[two] * gains, axis=-1)
    shown = np.isfinite(balanced).all(axis=-1)
    assert shown.mean() > 0.9
    top_two = balanced[shown][:, 2] / balanced[shown][:, 1]
    assert np.median(top_two) < 1.01  # before: 2 (the gains' ratio), pink
    scene = dev.scene_rgb(camera, gains=gains, camera_to_srgb=camera_to_srgb(cap.xyz_to_camera))
    rgb = scene[two][shown]
    assert np.mean(rgb[:, 1] < rgb[:, [0, 2]].min(axis=-1) * 0.95) < 0.01  # not magenta
