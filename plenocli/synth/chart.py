"""A test chart of coloured letters and numbers (like the paper's), drawn with OpenCV."""

from __future__ import annotations

import string
from dataclasses import dataclass

import cv2
import numpy as np

SYMBOLS = string.ascii_uppercase + string.digits


def test_chart(rows: int, cols: int, *, seed: int = 0, cells_across: int = 12) -> np.ndarray:
    """A chart image (rows, cols, 3) float32 in [0, 1], RGB (see :func:`test_chart_u8`)."""
    return test_chart_u8(rows, cols, seed=seed, cells_across=cells_across).astype(
        np.float32) / 255.0


def test_chart_u8(rows: int, cols: int, *, seed: int = 0, cells_across: int = 12) -> np.ndarray:
    """A chart image (rows, cols, 3) uint8, RGB.

    A grid of ``cells_across`` square cells (fewer down when the chart is wider than tall), each
    with a pale random background and a large saturated letter or digit; thin black grid lines,
    and a red disc at the centre (the optical axis when the chart is centred on it).
    """
    if rows < 16 or cols < 16:
        raise ValueError(f"chart size {rows} x {cols} too small; give at least 16 x 16 pixels")
    if cells_across < 1:
        raise ValueError(f"cells_across {cells_across} must be >= 1")
    rng = np.random.default_rng(seed)
    cell = cols / cells_across
    cells_down = max(1, int(round(rows / cell)))
    img = np.full((rows, cols, 3), 255, dtype=np.uint8)  # OpenCV draws text on 8-bit images
    font = cv2.FONT_HERSHEY_SIMPLEX
    for r in range(cells_down):
        for c in range(cells_across):
            y0, y1 = int(r * rows / cells_down), int((r + 1) * rows / cells_down)
            x0, x1 = int(c * cell), int((c + 1) * cell)
            img[y0:y1, x0:x1] = np.round(255 * (0.75 + 0.25 * rng.random(3))).astype(np.uint8)
            text = SYMBOLS[int(rng.integers(len(SYMBOLS)))]
            colour = rng.random(3)
            colour[int(rng.integers(3))] = 0.05  # saturated: one channel nearly off
            h = y1 - y0
            scale = max(h / 40.0, 0.2)
            thick = max(1, int(h / 14))
            (tw, th), _ = cv2.getTextSize(text, font, scale, thick)
            org = (x0 + (x1 - x0 - tw) // 2, y0 + (h + th) // 2)
            cv2.putText(img, text, org, font, scale, tuple(int(255 * v) for v in colour), thick,
                        cv2.LINE_AA)
            cv2.rectangle(img, (x0, y0), (x1 - 1, y1 - 1), (0, 0, 0), max(1, thick // 3))
    cv2.circle(img, (cols // 2, rows // 2), max(2, int(cell / 8)), (255, 0, 0), -1,
               cv2.LINE_AA)
    return img


@dataclass(frozen=True)
class ChartPatch:
    """One patch of :func:`colour_chart`: its name, linear sRGB colour and pixel box."""

    name: str
    rgb: tuple[float, float, float]
    box: tuple[int, int, int, int]  # row0, row1, col0, col1 (end exclusive)


COLOURCHECKER = "ColorChecker24 - After November 2014"
GREY_CARD = "neutral 5 (.70 D)"


def colour_chart(rows: int, cols: int, *, surround: float = 0.03
                 ) -> tuple[np.ndarray, list[ChartPatch]]:
    """A 6 x 4 ColorChecker chart in linear sRGB (D65) with its known patch colours.

    The patch colours are the X-Rite ColorChecker 24 (after November 2014) chromaticities
    published with colour-science, adapted from D50 to D65 (CAT02) and clipped to [0, 1]. Patches
    fill 80 % of their cell; the rest is a dark ``surround``. Patch 22 (neutral 5) is the grey card.

    Returns
    -------
    image : ndarray float32, (rows, cols, 3)
        Linear sRGB scene.
    patches : list of ChartPatch
        In chart order (dark skin ... black).
    """
    if rows < 48 or cols < 72:
        raise ValueError(f"chart size {rows} x {cols} too small; give at least 48 x 72 pixels")
    checker = _colourchecker()
    image = np.full((rows, cols, 3), surround, np.float32)
    patches = []
    for k, (name, rgb) in enumerate(checker):
        i, j = divmod(k, 6)
        r0, r1 = int(rows * (i + 0.1) / 4), int(rows * (i + 0.9) / 4)
        c0, c1 = int(cols * (j + 0.1) / 6), int(cols * (j + 0.9) / 6)
        image[r0:r1, c0:c1] = rgb
        patches.append(ChartPatch(name, tuple(float(v) for v in rgb), (r0, r1, c0, c1)))
    return image, patches


def _colourchecker() -> list[tuple[str, np.ndarray]]:
    import warnings

    with warnings.catch_warnings():  # colour-science warns about optional plotting packages
        warnings.simplefilter("ignore")
        import colour

        checker = colour.CCS_COLOURCHECKERS[COLOURCHECKER]
        out = []
        for name, xyy in checker.data.items():
            rgb = colour.XYZ_to_RGB(colour.xyY_to_XYZ(xyy), "sRGB",
                                    illuminant=checker.illuminant,
                                    chromatic_adaptation_transform="CAT02")
            out.append((name, np.clip(rgb, 0.0, 1.0).astype(np.float32)))
    return out


def camera_sampled(scene: np.ndarray, factor: int) -> np.ndarray:
    """What a camera's pixels record of a ``scene`` rendered ``factor`` times finer: each pixel
    integrates its own area (box mean of factor x factor), then a 4-spot optical low-pass filter
    (the birefringent plate of most Bayer cameras) averages each pixel with its neighbours one
    pixel right, down and diagonally.

    ``scene`` (rows * factor, cols * factor[, channels]) -> (rows, cols[, channels]) float32.
    """
    if factor < 1:
        raise ValueError(f"factor must be >= 1, got {factor}")
    img = np.asarray(scene, np.float32)
    rows, cols = img.shape[0] // factor, img.shape[1] // factor
    img = img[:rows * factor, :cols * factor]
    pixels = img.reshape(rows, factor, cols, factor, *img.shape[2:]).mean(axis=(1, 3))
    shifted = np.pad(pixels, [(0, 1), (0, 1)] + [(0, 0)] * (pixels.ndim - 2), mode="edge")
    return (0.25 * (shifted[:-1, :-1] + shifted[1:, :-1] + shifted[:-1, 1:] + shifted[1:, 1:])
            ).astype(np.float32)
