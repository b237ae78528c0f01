"""PNG previews: a quick look at a result, never an input to another stage."""

from __future__ import annotations

import os
import zlib

import cv2
import numpy as np

from plenocli.io.atomic import write_bytes
from plenocli.model.cfa import half_size_rgb
from plenocli.model.colour import camera_to_srgb, gains_from_neutral, normalised_gains
from plenocli.model.views import ViewNames

_FONT = cv2.FONT_HERSHEY_SIMPLEX
# the tEXt chunk every preview carries: decode refuses a picture that says it is a preview
# (display-stretched 8-bit levels are not the light a sensor recorded)
PREVIEW_TEXT = ("Software", "plenocli preview")
BAR_ROWS = 120  # a depth preview's height at least: its scale bar's labels apart, none cut
_PNG_HEADER = 8 + 25   # the signature and the IHDR chunk, always first


def is_preview(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a PNG that says it is a plenocli preview (:data:`PREVIEW_TEXT`)."""
    from PIL import Image

    try:
        with Image.open(path) as image:
            return image.info.get(PREVIEW_TEXT[0]) == PREVIEW_TEXT[1]
    except Exception:  # any failure of this probe: the file's reader says what it is
        return False


def to_display(image: np.ndarray, *, low: float = 0.5, high: float = 99.5,
               gamma: float = 2.2) -> np.ndarray:
    """Stretch an image to uint8 between two percentiles, with a display gamma; NaN shows black."""
    finite = image[np.isfinite(image)]
    if finite.size == 0:
        return np.zeros(image.shape, np.uint8)
    lo, hi = np.percentile(finite, [low, high])
    scaled = np.clip((np.nan_to_num(image, nan=lo) - lo) / max(hi - lo, 1e-12), 0.0, 1.0)
    return np.round(255.0 * scaled ** (1.0 / gamma)).astype(np.uint8)


def views_side_by_side(views: np.ndarray, cfa: str | None = None, *, gap: int = 4) -> np.ndarray:
    """Views (views, rows, cols), or RGB views (views, rows, cols, 3), as one picture, left to
    right, with NaN gaps between them (Bayer views of pattern ``cfa`` as half-size RGB)."""
    tiles = [half_size_rgb(v, cfa) if cfa else np.asarray(v, np.float32) for v in views]
    spacer = np.full((tiles[0].shape[0], gap, *tiles[0].shape[2:]), np.nan, np.float32)
    out = [tiles[0]]
    for tile in tiles[1:]:
        out += [spacer, tile]
    return np.concatenate(out, axis=1)


def colour_pages(pages: np.ndarray, names: list[str] | None) -> np.ndarray | None:
    """Pages (P, rows, cols) named R, G, B (one colour view) or VIEW.R, VIEW.G, VIEW.B (views
    in page order) as RGB (rows, cols, 3) or (views, rows, cols, 3); None for other pages."""
    if not names or len(names) != len(pages):
        return None
    views = ViewNames(tuple(names)).rgb_views()
    if views is None:
        return None
    if views == [""]:
        return np.stack(list(pages), axis=-1)
    return np.moveaxis(np.asarray(pages).reshape(len(views), 3, *pages.shape[1:]), 1, -1)


def view_mosaic(stack: np.ndarray, n: int, channels: list[str], *,
                cfa: str | None = None) -> np.ndarray:
    """N x N sub-aperture views (view-major pages of ``len(channels)`` channels each) in their
    N x N arrangement: an RGB picture when the channels are R, G, B or each view is a Bayer
    mosaic of pattern ``cfa`` (half-size RGB), else their mean."""
    tiles = stack.reshape(n * n, len(channels), *stack.shape[1:]).astype(np.float32)
    if cfa and len(channels) == 1:
        tiles = np.stack([half_size_rgb(t[0], cfa) for t in tiles])
    elif channels == ["R", "G", "B"]:
        tiles = np.moveaxis(tiles, 1, -1)
    else:
        tiles = tiles.mean(axis=1)
    rows = [np.concatenate(list(tiles[i * n:(i + 1) * n]), axis=1) for i in range(n)]
    return np.concatenate(rows, axis=0)


def write_png(path: str | os.PathLike, image: np.ndarray, *, cfa: str | None = None,
              max_side: int = 2048, protect: tuple = (), colour: dict | None = None) -> None:
    """Write a display PNG of a 2-D frame (Bayer if ``cfa``), an (rows, cols, 3) camera RGB
    image, (views, rows, cols) views or (views, rows, cols, 3) RGB views side by side. Colour
    (Bayer or RGB) is shown in the camera's colour: white balance and matrix from ``colour``
    (the frames' metadata), else grey-world balanced."""
    if image.ndim == 4 or (image.ndim == 3 and image.shape[-1] != 3):
        image, cfa = views_side_by_side(image, cfa), None
    img = np.asarray(half_size_rgb(image, cfa) if cfa and image.ndim == 2 else image, np.float32)
    scale = max(img.shape[:2]) / max_side
    if scale > 1:  # shrink first: the stretch below then works on a few megapixels, not 60
        # a side never below a pixel (a 4 x 20000 frame: 0.4 rows)
        size = (max(1, round(img.shape[1] / scale)), max(1, round(img.shape[0] / scale)))
        img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    if img.ndim == 3:
        img = display_colour(img, colour)
    else:
        img = to_display(img)
    write_picture(path, img[..., ::-1] if img.ndim == 3 else img, protect=protect)


def write_picture(path: str | os.PathLike, picture: np.ndarray, *, protect: tuple = ()) -> None:
    """Write a ready-made uint8 picture, grey (rows, cols) or BGR (rows, cols, 3), as PNG:
    the one PNG encoder of plenocli (atomic, never over an input)."""
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(picture, np.uint8))
    if not ok:
        raise OSError(f"could not encode PNG for {path}")
    write_bytes(path, with_text(buf.tobytes(), *PREVIEW_TEXT), protect=protect)


def with_text(png: bytes, keyword: str, text: str) -> bytes:
    """``png`` with a tEXt chunk ``keyword`` = ``text`` after its header."""
    body = b"tEXt" + keyword.encode("latin-1") + b"\0" + text.encode("latin-1")
    chunk = (len(body) - 4).to_bytes(4, "big") + body + zlib.crc32(body).to_bytes(4, "big")
    return png[:_PNG_HEADER] + chunk + png[_PNG_HEADER:]


def write_heat_map(path: str | os.PathLike, maps: list[np.ndarray], titles: list[str], *,
                   protect: tuple = ()) -> None:
    """Write ratio maps (e.g. cross-talk r per tile) side by side as a heat map PNG."""
    write_picture(path, heat_map(maps, titles), protect=protect)


def heat_map(maps: list[np.ndarray], titles: list[str], min_side: int = 240) -> np.ndarray:
    """BGR uint8 picture: each map of ratios as a heat map (viridis, NaN grey) under its
    title, with a colour bar in percent. The scale runs from 0 to the next 5 % above the
    largest value, so a uniform map reads as its value, not as "maximum"."""
    finite = [float(np.nanmax(m)) for m in maps if np.isfinite(m).any()]
    top = max(0.05, np.ceil(max(finite + [0.0]) * 20) / 20)
    tiles = [_heat_tile(m, title, top, min_side) for m, title in zip(maps, titles, strict=True)]
    height = max(t.shape[0] for t in tiles)
    padded = [np.pad(t, ((0, height - t.shape[0]), (0, 8), (0, 0)), constant_values=255)
              for t in tiles]
    return np.hstack([*padded, *_colour_bar(height, top)])


def _heat_tile(ratios: np.ndarray, title: str, top: float, min_side: int) -> np.ndarray:
    scaled = np.clip(np.nan_to_num(ratios / top, nan=0.0), 0, 1)
    img = cv2.applyColorMap(np.round(255 * scaled).astype(np.uint8), cv2.COLORMAP_VIRIDIS)
    img[~np.isfinite(ratios)] = 128
    cell = max(1, int(np.ceil(min_side / max(ratios.shape))))
    img = np.repeat(np.repeat(img, cell, axis=0), cell, axis=1)
    label = np.full((24, img.shape[1], 3), 255, np.uint8)
    cv2.putText(label, title, (4, 17), _FONT, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    return np.vstack([label, img])


def _colour_bar(height: int, top: float) -> tuple[np.ndarray, np.ndarray]:
    """The viridis bar from ``top`` down to 0 and its tick labels in percent."""
    bar_values = np.linspace(1, 0, height - 24)[:, None]
    bar = cv2.applyColorMap(np.round(255 * np.repeat(bar_values, 16, axis=1)).astype(np.uint8),
                            cv2.COLORMAP_VIRIDIS)
    bar = np.vstack([np.full((24, 16, 3), 255, np.uint8), bar])
    ticks = np.full((height, 56, 3), 255, np.uint8)
    for frac in (0.0, 0.5, 1.0):
        y = 24 + int(round((1 - frac) * (height - 25)))
        cv2.putText(ticks, f"{100 * frac * top:.0f} %", (4, min(max(y + 4, 32), height - 2)),
                    _FONT, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    return bar, ticks


def display_colour(camera: np.ndarray, colour: dict | None = None, *,
                   white_percentile: float = 99.0) -> np.ndarray:
    """uint8 sRGB (rows, cols, 3) of camera RGB (rows, cols, 3); NaN shows black.

    ``colour`` is the frames' ``colour`` metadata (``as_shot_wb``, ``xyz_to_camera``); missing
    parts fall back to a grey-world balance and no matrix, so a preview never fails. The black
    point is the 0.5th percentile of the darkest channel (never below 0) when that is under half
    the highlights: raw frames still hold their black level.
    """
    rgb = np.asarray(camera, np.float32)
    finite = np.isfinite(rgb).all(axis=-1)
    if not finite.any():
        return np.zeros(rgb.shape, np.uint8)
    # raw frames still hold their black level: a low percentile is the preview's black point
    # (taken off only when it is well below the highlights: a uniform white keeps its level)
    black = max(0.0, float(np.percentile(rgb[finite].min(axis=-1), 0.5)))
    if black < 0.5 * float(np.percentile(rgb[finite].max(axis=-1), 99.0)):
        rgb = rgb - np.float32(black)
    colour = colour or {}
    try:
        gains = normalised_gains(colour["as_shot_wb"])
    except (KeyError, TypeError, ValueError):
        try:
            gains = gains_from_neutral(rgb[finite].mean(axis=0))
        except ValueError:
            gains = np.ones(3)
    combined = np.diag(gains)
    try:
        combined = camera_to_srgb(colour["xyz_to_camera"]) @ combined
    except (KeyError, TypeError, ValueError):
        pass
    out = np.nan_to_num(rgb @ combined.T.astype(np.float32), nan=0.0)
    reference = float(np.percentile(out[finite], white_percentile))
    out = np.clip(out / max(reference, 1e-12), 0.0, 1.0)
    out = np.where(out <= 0.0031308, 12.92 * out, 1.055 * np.power(out, 1 / 2.4) - 0.055)
    return np.round(255 * out).astype(np.uint8)


def write_grid_overlay(path: str | os.PathLike, flat: np.ndarray, centres: np.ndarray,
                       pitch_px: float, *, protect: tuple = ()) -> None:
    """A flattened image (display-stretched, at most 2048 px) with every lens centre (K, 2)
    (x, y) px drawn as a red dot: a wrong grid shows at a glance."""
    grey = to_display(flat, gamma=1.0)
    scale = min(1.0, 2048 / max(grey.shape))
    if scale < 1:
        grey = cv2.resize(grey, (max(1, round(grey.shape[1] * scale)),
                                 max(1, round(grey.shape[0] * scale))),
                          interpolation=cv2.INTER_AREA)
    bgr = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
    shift = 4  # sub-pixel drawing
    radius = max(1, int(pitch_px * scale / 8)) << shift
    for x, y in np.asarray(centres) * scale:
        cv2.circle(bgr, (int(round(x * (1 << shift))), int(round(y * (1 << shift)))), radius,
                   (0, 0, 255), -1, cv2.LINE_AA, shift)
    write_picture(path, bgr, protect=protect)


def depth_picture(values: np.ndarray, confidence: np.ndarray, *, label: str = "g",
                  bar_width: int = 72) -> np.ndarray:
    """BGRA uint8 picture of a depth map: turbo colours from the 2nd to the 98th percentile of
    the confident values (confidence >= 0.5, else all known; low = blue), alpha = confidence
    (NaN fully transparent), and an opaque scale bar with three labelled ticks on the right."""
    values = np.asarray(values, float)
    known = np.isfinite(values)
    sure = known & (np.nan_to_num(np.asarray(confidence, float), nan=0.0) >= 0.5)
    scaled_from = values[sure] if sure.sum() >= 16 else values[known]
    lo, hi = (np.percentile(scaled_from, (2, 98)) if scaled_from.size else (0.0, 1.0))
    hi = hi if hi > lo else lo + 1e-6
    scaled = np.clip(np.nan_to_num((values - lo) / (hi - lo), nan=0.0), 0, 1)
    bgr = cv2.applyColorMap(np.round(255 * scaled).astype(np.uint8), cv2.COLORMAP_TURBO)
    alpha = np.where(known, np.clip(np.nan_to_num(confidence, nan=0.0), 0, 1), 0.0)
    image = _tall_enough(np.dstack([bgr, np.round(255 * alpha).astype(np.uint8)]))
    rows = image.shape[0]
    bar = np.full((rows, bar_width, 4), 255, np.uint8)
    ramp = np.linspace(1, 0, max(rows - 24, 2))[:, None]
    colours = cv2.applyColorMap(np.round(255 * np.repeat(ramp, 14, axis=1)).astype(np.uint8),
                                cv2.COLORMAP_TURBO)
    bar[12:12 + len(ramp), 4:18, :3] = colours[:rows - 24]
    for frac in (0.0, 0.5, 1.0):
        y = 12 + int(round((1 - frac) * (len(ramp) - 1)))
        cv2.putText(bar, f"{lo + frac * (hi - lo):.3g}", (21, min(max(y + 4, 10), rows - 2)),
                    _FONT, 0.35, (0, 0, 0, 255), 1, cv2.LINE_AA)
    cv2.putText(bar, label[:10], (2, rows - 4), _FONT, 0.3, (0, 0, 0, 255), 1, cv2.LINE_AA)
    bar[..., 3] = 255
    return np.hstack([image, bar])


def _tall_enough(image: np.ndarray, rows: int = BAR_ROWS, max_cols: int = 2048) -> np.ndarray:
    """``image`` (rows, cols, 4) enlarged by a whole factor (each pixel a block) to at least
    ``rows`` tall where its width allows, then padded below with transparent rows to that."""
    height, width = image.shape[:2]
    factor = max(1, min(-(-rows // height), max_cols // max(width, 1)))
    if factor > 1:
        image = np.repeat(np.repeat(image, factor, axis=0), factor, axis=1)
    if image.shape[0] < rows:
        image = np.pad(image, ((0, rows - image.shape[0]), (0, 0), (0, 0)))
    return image


def write_depth_png(path: str | os.PathLike, values: np.ndarray, confidence: np.ndarray, *,
                    label: str = "g", protect: tuple = ()) -> None:
    """Write :func:`depth_picture` as a PNG with transparency."""
    write_picture(path, depth_picture(values, confidence, label=label), protect=protect)
