"""The whole pipeline on simulated captures: simulate -> decode -> sai -> stitch (small size).

Assembled by the lead after merging: it runs when plenocli.stitch (and plenocli.sai) exist.
"""

import numpy as np
import pytest

from plenocli.io.raw import decode
from plenocli.synth import prismcam


def _views(frames, n=2):
    try:
        from plenocli.sai import demultiplex
    except ImportError:
        return np.stack([np.stack([f[i::n, j::n] for i in range(n) for j in range(n)])
                         for f in frames])
    return np.stack([demultiplex(f, n) for f in frames])


def test_quadpixel_pyramid_stitches_to_twice_the_field(tmp_path):
    stitch = pytest.importorskip("plenocli.stitch")
    truth = prismcam.write_quadpixel(tmp_path, pixels=256, seed=0)
    frames, meta = decode(tmp_path / truth["files"]["capture"])
    views = _views(frames.astype(np.float32))  # (3 colours, 4 views, rows, cols)
    green = views[1]
    panorama, report = stitch.stitch(green, layout="2x2", model="translation")
    rows, cols = green.shape[1:]
    # The four views overlap by a sliver only (64 deg stitched vs 2 x 32.6): the panorama is
    # close to twice a view in each direction.
    assert panorama.shape[-2] > 1.7 * rows and panorama.shape[-1] > 1.7 * cols
    assert truth["stitched_field_deg"]["x"] == pytest.approx(2 * truth["main_lens_field_deg"],
                                                             rel=0.05)
    assert isinstance(report, dict)


def test_dualpixel_prism_stitches_a_wider_image(tmp_path):
    stitch = pytest.importorskip("plenocli.stitch")
    truth = prismcam.write_dualpixel(tmp_path, pixels=384, seed=2, noise_dn=0.0)
    frames, meta = decode(tmp_path / truth["files"]["capture"])
    top, left, bottom, right = meta["active_area"]
    black = truth["black_level"]
    s = frames[0, top:bottom, left:right].astype(np.float32) - black
    a = frames[1, top:bottom, left:right].astype(np.float32) - black
    b = s - a
    # Green pixels of each 2 x 2 cell: a grey picture of each view. The raw image is inverted,
    # so A (deviated towards +x on the chart) is the left part of the panorama.
    views = np.stack([a[0::2, 1::2], b[0::2, 1::2]])
    panorama, report = stitch.stitch(views, layout="1x2", model="translation")
    cols = views.shape[-1]
    expected = cols + truth["overlap_shift_px"] / 2  # green sub-grid: half the pixels
    assert panorama.shape[-1] == pytest.approx(expected, abs=4)
