"""Menon, Andriani & Calvagno (2007) demosaicing (DDFAPD with refining) on OpenCV float32
filters.

colour-demosaicing's ``demosaicing_CFA_Bayer_Menon2007`` is the reference implementation of
this algorithm; it works in float64 with scipy filters and takes about 50 s for one
6880 x 4544 frame here, 20 times LibRaw's whole development. This module does the same steps,
in the same order and with the same borders, with OpenCV's float32 filters (about 1 s); the test
suite checks that both agree within float32 rounding.
"""

from __future__ import annotations

import cv2
import numpy as np

_MIRROR = cv2.BORDER_REFLECT_101  # scipy's "mirror" and numpy's "reflect"
_H0 = np.array([0.0, 0.5, 0.0, 0.5, 0.0], np.float32)
_H1 = np.array([-0.25, 0.0, 0.5, 0.0, -0.25], np.float32)
_PAIR = np.array([0.5, 0.0, 0.5], np.float32)
_MEAN3 = np.full(3, 1.0 / 3.0, np.float32)
_CLASSIFIER = np.array([[0, 0, 1, 0, 1], [0, 0, 0, 1, 0], [0, 0, 3, 0, 3],
                        [0, 0, 0, 1, 0], [0, 0, 1, 0, 1]], np.float32)


def _h(x: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Along rows (symmetric kernels only: correlation = convolution)."""
    return cv2.filter2D(x, cv2.CV_32F, kernel[np.newaxis, :], borderType=_MIRROR)


def _v(x: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Along columns (symmetric kernels only)."""
    return cv2.filter2D(x, cv2.CV_32F, kernel[:, np.newaxis], borderType=_MIRROR)


def menon2007(cfa: np.ndarray, pattern: str) -> np.ndarray:
    """RGB (rows, cols, 3) float32 of a Bayer mosaic ``cfa`` with 2 x 2 ``pattern``.

    Every masked update of the reference (``np.where`` over the whole frame with a CFA mask) is
    done on the 2 x 2 phase it concerns (a strided view), and a difference of two filters is the
    filter of the difference: the same numbers, several times fewer passes over memory.
    """
    cfa = np.asarray(cfa, np.float32)
    k_r, k_b = pattern.index("R"), pattern.index("B")
    red, blue = (k_r // 2, k_r % 2), (k_b // 2, k_b % 2)
    g_red_row, g_blue_row = (red[0], blue[1]), (blue[0], red[1])  # the two green phases

    def at(x, phase):
        return x[phase[0]::2, phase[1]::2]

    h_sum = _H0 + _H1
    g_h, g_v = cfa.copy(), cfa.copy()
    full_h, full_v = _h(cfa, h_sum), _v(cfa, h_sum)
    c_h, c_v = np.zeros_like(cfa), np.zeros_like(cfa)
    for phase in (red, blue):
        at(g_h, phase)[...] = at(full_h, phase)
        at(g_v, phase)[...] = at(full_v, phase)
        at(c_h, phase)[...] = at(cfa, phase) - at(g_h, phase)
        at(c_v, phase)[...] = at(cfa, phase) - at(g_v, phase)
    del full_h, full_v
    d_h = np.abs(c_h - np.pad(c_h, ((0, 0), (0, 2)), mode="reflect")[:, 2:])
    d_v = np.abs(c_v - np.pad(c_v, ((0, 2), (0, 0)), mode="reflect")[2:, :])
    del c_h, c_v
    # scipy's convolve flips the kernel; OpenCV's filter2D correlates: flip it here
    d_h = cv2.filter2D(d_h, cv2.CV_32F, _CLASSIFIER[::-1, ::-1].copy(),
                       borderType=cv2.BORDER_CONSTANT)
    d_v = cv2.filter2D(d_v, cv2.CV_32F, _CLASSIFIER.T[::-1, ::-1].copy(),
                       borderType=cv2.BORDER_CONSTANT)
    horizontal = d_v >= d_h
    del d_h, d_v
    g = g_v  # equal to g_h on the green phases
    for phase in (red, blue):
        at(g, phase)[...] = np.where(at(horizontal, phase), at(g_h, phase), at(g, phase))
    del g_h
    r, b = np.zeros_like(cfa), np.zeros_like(cfa)
    at(r, red)[...] = at(cfa, red)
    at(b, blue)[...] = at(cfa, blue)

    def directional(x, phase, kernel):
        return np.where(at(horizontal, phase), at(_h(x, kernel), phase),
                        at(_v(x, kernel), phase))

    at(r, g_red_row)[...] = at(g, g_red_row) + at(_h(r - g, _PAIR), g_red_row)
    at(r, g_blue_row)[...] = at(g, g_blue_row) + at(_v(r - g, _PAIR), g_blue_row)
    at(b, g_blue_row)[...] = at(g, g_blue_row) + at(_h(b - g, _PAIR), g_blue_row)
    at(b, g_red_row)[...] = at(g, g_red_row) + at(_v(b - g, _PAIR), g_red_row)
    at(r, blue)[...] = at(b, blue) + directional(r - b, blue, _PAIR)
    at(b, red)[...] = at(r, red) + directional(b - r, red, _PAIR)

    # the refining step (colour-demosaicing's refining_step_Menon2007)
    r_g_red = directional(r - g, red, _MEAN3)
    b_g_blue = directional(b - g, blue, _MEAN3)
    at(g, red)[...] = at(r, red) - r_g_red
    at(g, blue)[...] = at(b, blue) - b_g_blue
    r_g, b_g = r - g, b - g
    at(r, g_blue_row)[...] = at(g, g_blue_row) + at(_v(r_g, _PAIR), g_blue_row)
    at(r, g_red_row)[...] = at(g, g_red_row) + at(_h(r_g, _PAIR), g_red_row)
    at(b, g_red_row)[...] = at(g, g_red_row) + at(_v(b_g, _PAIR), g_red_row)
    at(b, g_blue_row)[...] = at(g, g_blue_row) + at(_h(b_g, _PAIR), g_blue_row)
    del r_g, b_g
    r_b = r - b
    at(r, blue)[...] = at(b, blue) + directional(r_b, blue, _MEAN3)
    at(b, red)[...] = at(r, red) - directional(r_b, red, _MEAN3)
    return np.stack([r, g, b], axis=-1)
