"""Stage ``refocus``: frames TIFF + lens grid -> refocused image(s) by Lanczos splatting (Eq. 3)."""

from __future__ import annotations

import warnings
from dataclasses import replace
from functools import partial

import numpy as np

from plenocli import refocus as rf
from plenocli.depth.lenslet import CLEAR_MATCH, central_match, sensor_grey
from plenocli.depth.mapcheck import sources
from plenocli.errors import ConfigError, InputError, OptionError
from plenocli.io import tiffio
from plenocli.io.framing import frame_grid
from plenocli.io.preview import write_png
from plenocli.io.views import check_black_subtracted
from plenocli.model.provenance import sha256_file, stage_record
from plenocli.model.views import CHANNELS, ViewNames, colour_page, split_sweep, sweep_page
from plenocli.pipeline.fits import (
    beyond_grid,
    centred_on,
    check_fits,
    warn_unchecked,
    weak_match,
)
from plenocli.progress import log, shown

MAX_FALLOFF = 0.10  # micro-images darker at their rims by more: the sweep's score leans low
MIN_COVERED = 0.25  # share of the output that must be covered (as depth's MIN_KNOWN)
PATTERN = (": a sensor sample covers a lens period of the output, the score would rate the "
           "splatting's pattern, not focus")


def run(input: str, output: str, *, grid: str, s: float = 0.2, g: str | float = "4",
        view: str = "full", mask_width: float = 2.0, kernel: str = "lanczos3",
        radius: float | None = None, min_weight: float = 0.25,
        preview: str | None = None, depth: str | None = None) -> None:
    """Refocus every page of ``input`` at each g; one output page per (g, channel). With
    ``depth`` (a ``plenocli depth`` output on this grid), each lens at its own g
    (all-in-focus); lenses of unknown depth take the map's median g, ``g`` is not used."""
    try:
        g_values = rf.parse_g(g)
    except ValueError as err:
        raise ConfigError(f"--g: {err}") from err
    try:  # refuse bad values before any file is read
        rf.check_options(s=s, g=g_values[0], view=view, mask_width=mask_width, kernel=kernel,
                         radius=radius, cfa=None, min_weight=min_weight)
    except ValueError as err:
        raise ConfigError(f"refocus: {err}") from err
    data, meta = tiffio.read_image(input)
    check_black_subtracted(input, meta, "refocused views record no black level: theirs would "
                           "pass as light")
    framing = frame_grid(grid, meta, data.shape[1:], frames_path=input)
    if view != "full":
        try:
            rf.check_mask_width(mask_width, framing.grid.pitch_px)
        except ValueError as err:
            raise OptionError(f"--mask-width: {err}") from err
    try:
        rf.check_output_size((framing.bottom - framing.top, framing.right - framing.left), s,
                             pages=len(g_values) * data.shape[0] * (3 if framing.cfa else 1))
    except ValueError as err:
        raise ConfigError(f"refocus: {err}") from err
    cfa = framing.cfa
    grey = sensor_grey(framing.crop(data[:1]), mosaic=bool(cfa))
    checked = check_fits(grey, framing.grid, grid, frames_path=input,
                         whole=partial(beyond_grid, framing, data[:1], mosaic=bool(cfa)))
    lens_grid, moved = centred_on(grey, framing.grid, grid)
    _check_match(grey, lens_grid, grid, g=None if depth else g_values[0], checked=checked)
    if not checked:
        warn_unchecked(grid)
    framing = replace(framing, grid=lens_grid)
    if depth:
        frames = sources(meta, sha256_file(input))
        options = {"lens_g": _lens_g(depth, grid, framing, s, frames)}
    else:
        options = {}
    pages = list(ViewNames.of(meta, data.shape[0]).pages)
    sweep = len(g_values) > 1
    period = s * framing.grid.pitch_px
    out_pages, names, scores = _refocus_pages(
        data, pages, framing, g_values, s=s, view=view, mask_width=mask_width, kernel=kernel,
        radius=radius, min_weight=min_weight, **options)
    best = _best_g(scores, sweep=sweep)
    if sweep:
        _warn_vignetted(input, grey, framing.grid)
    params = dict(grid=grid, s=s, g=g, view=view, mask_width=mask_width, kernel=kernel,
                  radius=radius, min_weight=min_weight, depth=depth)
    record = stage_record("refocus", params, {"input": input, "grid": grid, "depth": depth})
    stack = np.stack(out_pages).astype(np.float32)
    covered = _covered(stack, framing.grid.pitch_px)
    out_meta = tiffio.derived_meta(
        meta, record, views=names, cfa=None, origin=None, black_level=None, white_level=None,
        active_area=[0, 0, stack.shape[1], stack.shape[2]], masked_areas=[],
        refocus={"equation": "(X, Y) = s * (g * ((x, y) - c_ij) + c_ij)", "s": s,
                 "g": g_values, "view": view, "mask_width": mask_width, "kernel": kernel,
                 "radius": radius, "crop_sensor_origin": list(framing.sensor_origin),
                 "grid_moved_px": None if moved is None else list(moved),
                 "grid_checked": checked, "covered_fraction": covered},
        sharpness={"measure": "mean(Lap(I_s)^2) / var(I_s), I_s = Gaussian(sigma = s * pitch / 2)",
                   "lens_period_px": period, "scores": scores, "best_g": best})
    protect = (input, grid) + ((depth,) if depth else ())
    tiffio.write_image(output, stack, out_meta, protect=protect)
    log.info("refocus: %s -> %s (%d page(s) of %d x %d, view %s, %.1f %% covered%s)",
             shown(input), shown(output), stack.shape[0], stack.shape[2], stack.shape[1], view,
             100 * covered,
             f", sharpest g = {best:g}" if sweep and best is not None else "")
    if preview:
        if sweep and best is None:
            log.info("refocus: the preview shows g = %g (no plane judged)", g_values[0])
        write_png(preview, _best_picture(stack, names, g_values, best, rgb=bool(cfa)),
                  protect=protect, colour=meta.get("colour"))


def _warn_vignetted(path: str, grey: np.ndarray, grid) -> None:
    falloff = _micro_image_falloff(grey, grid)
    if falloff > MAX_FALLOFF:
        log.warning("refocus: the micro-images of %s darken by %.0f %% towards their rims: "
                    "that vignetting pulls the sharpest g of a sweep towards smaller g (by "
                    "0.2-0.5 on the simulator's planes); flat-field the frames with a white "
                    "image first, or measure g with plenocli depth", shown(path), 100 * falloff)


def _micro_image_falloff(grey: np.ndarray, grid) -> float:
    """How much darker the mean micro-image is at the rim of its usable disc than at its
    brightest (0: flat-fielded, or vignetting divided out otherwise)."""
    from plenocli.depth.lenslet import lens_table, micro_profile

    _, centres = lens_table(grid, grey.shape)
    try:
        profile, *_ = micro_profile(np.ascontiguousarray(grey, np.float32), centres,
                                    grid.pitch_px)
    except ValueError:  # too few or too dark micro-images to say
        return 0.0
    values = profile[np.isfinite(profile)]
    return float(1.0 - values.min() / values.max()) if values.size else 0.0


def _covered(stack: np.ndarray, pitch_px: float) -> float:
    """The share of the output covered, or InputError under MIN_COVERED."""
    covered = float(np.isfinite(stack).mean())
    if covered < MIN_COVERED:
        raise InputError(f"refocus: only {100 * covered:.1f} % of the output is covered (the "
                         f"rest has no pixel of a micro-image within reach); --radius, "
                         "--view, --mask-width or --s leave too few pixels of the "
                         f"{pitch_px:.3g} px micro-images: use more of them (a larger "
                         "--radius, a smaller --s); nothing was written")
    return covered


def _refocus_pages(data: np.ndarray, pages: list[str], framing, g_values: list[float], *,
                   s: float, **options) -> tuple[list[np.ndarray], list[str], list[dict]]:
    """Every page refocused at every g: the output pages (g-major), their names, and the
    sharpness score of each g."""
    cfa, sweep = framing.cfa, len(g_values) > 1
    period = s * framing.grid.pitch_px
    out_pages, names, scores = [], [], []
    for g_value in g_values:
        per_g = []
        for page, name in zip(data, pages, strict=True):
            image, _ = rf.refocus(framing.crop(page), framing.grid, s=s, g=g_value, cfa=cfa,
                                  **options)
            channels = image if cfa else image[np.newaxis]
            labels = list(CHANNELS) if cfa else [name]
            if cfa and len(pages) > 1:
                labels = [colour_page(name, c) for c in CHANNELS]
            for chan, label in zip(channels, labels, strict=True):
                if not np.isfinite(chan).any():
                    raise InputError(
                        f"{label} at g = {g_value:g}: the refocused image holds no valid pixel "
                        "(all NaN): the input is NaN under the grid, or g (paper: 4), "
                        "--mask-width or --radius leave no pixel of the "
                        f"{framing.grid.pitch_px:.3g} px micro-images; check them")
                per_g.append(chan)
                names.append(sweep_page(label, g_value) if sweep else label)
        scores.append(_score(np.stack(per_g), g_value, framing.grid.pitch_px, period,
                             depth="lens_g" in options, mosaic=bool(cfa)))
        out_pages.extend(per_g)
    return out_pages, names, scores


def _score(pages: np.ndarray, g: float, pitch_px: float, period: float, *,
           depth: bool, mosaic: bool) -> dict:
    """The sharpness entry of one g, logged: a score, or None with why it is not judged (a
    depth map's lenses each have their own g, which the plane's score does not rest on)."""
    reason = None if depth else rf.unjudged(g, pitch_px, mosaic=mosaic)
    score = None if reason else rf.sharpness(pages, lens_period_px=period)
    if score is not None and not np.isfinite(score):
        score, reason = None, "fewer than 16 covered pixels"
    label = "g from the depth map" if depth else f"g = {g:g}"
    if reason:
        log.info("refocus: %s  sharpness not judged (%s)", label, reason)
        return {"g": g, "sharpness": None, "not_judged": reason}
    log.info("refocus: %s  sharpness %.5g", label, score)
    return {"g": g, "sharpness": score}


def _best_g(scores: list[dict], *, sweep: bool) -> float | None:
    """The judged g of the highest score; a sweep warns when it leaves planes unjudged."""
    judged = [sc for sc in scores if sc["sharpness"] is not None]
    best = max(judged, key=lambda sc: sc["sharpness"])["g"] if judged else None
    by_reason: dict[str, list[str]] = {}
    for sc in scores:
        if sc["sharpness"] is None:
            by_reason.setdefault(sc["not_judged"], []).append(f"{sc['g']:g}")
    if sweep and by_reason:
        why = "; ".join(f"g = {', '.join(gs)} ({reason}{PATTERN if 'pitch' in reason else ''})"
                        for reason, gs in by_reason.items())
        log.warning("refocus: %d plane(s) of the sweep not judged: %s; %s",
                    len(scores) - len(judged), why,
                    f"sharpest g = {best:g} among the others" if best is not None else
                    "no sharpest g is named: sweep g nearer 0 than the pitch")
    return best


def _check_match(grey: np.ndarray, lens_grid, grid_path: str, *, g: float | None,
                 checked: bool) -> None:
    """Refused: g of the sign the frames' micro-images contradict (``g`` None: the depth map
    gives each lens its g), or a grid the frames cannot check on which the micro-images
    match their neighbours only weakly (another camera's, a few per cent off)."""
    if g is None and checked:
        return
    match = central_match(grey, lens_grid, 1.0 if g is None else g)
    if match is None:
        return
    if g is not None and match.evidence is not None:
        raise InputError(f"refocus: --g {g:g}: {match.evidence}; refocus at g of that sign "
                         f"(e.g. --g {-g:g})")
    if not checked and match.best < CLEAR_MATCH:
        raise weak_match("refocus", grid_path, match.best, CLEAR_MATCH)


def _best_picture(stack: np.ndarray, names: list[str], g_values: list[float],
                  best: float | None, *, rgb: bool) -> np.ndarray:
    """The pages of the sharpest g: RGB for colour channels (several views: (views, rows, cols,
    3), shown side by side), else their mean."""
    per = len(stack) // len(g_values)
    k = g_values.index(best) if best is not None else 0
    chunk = stack[k * per:(k + 1) * per]
    rgb = rgb or [split_sweep(n)[0] for n in names[:per]] == list(CHANNELS)
    if rgb:  # pages R, G, B, or VIEW.R, VIEW.G, VIEW.B per view
        views = np.moveaxis(chunk.reshape(-1, 3, *chunk.shape[1:]), 1, -1)
        return views[0] if len(views) == 1 else views
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns stay NaN
        return np.nanmean(chunk, axis=0)


def _lens_g(depth: str, grid: str, framing, s: float, frames: set[str]
            ) -> tuple[np.ndarray, int, int]:
    """Each lens's g from a depth map made of the same capture (``frames``: the input's
    sources) on the same grid and s (all-in-focus)."""
    from plenocli.depth.lenslet import lens_g_table
    from plenocli.depth.mapcheck import depth_misfit

    data, meta = tiffio.read_image(depth)
    names = list(meta.get("views") or [])
    if "g" not in names:
        raise InputError(f"{depth} holds no page g; give a `plenocli depth --grid` output")
    expected = rf.output_shape(framing.shape, s)
    if data.shape[1:] != expected:
        raise InputError(f"{depth} is {data.shape[2]} x {data.shape[1]} but refocus at s = "
                         f"{s:g} makes {expected[1]} x {expected[0]}; make the depth with the "
                         "same --grid and --s")
    misfit = depth_misfit(data, meta, grid_sha256=sha256_file(grid), s=s,
                          sensor_origin=framing.sensor_origin, frames=frames)
    if misfit:
        raise InputError(f"{depth} does not fit this refocus: {misfit}")
    try:
        return lens_g_table(framing.grid, framing.shape, data[names.index("g")], s)
    except ValueError as err:
        raise InputError(f"{depth}: {err}") from err

