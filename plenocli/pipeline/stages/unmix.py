"""Stage ``unmix``: views TIFF(s) + mixing file -> views without sub-aperture cross-talk.

The pages the mixing names are solved per pixel (``plenocli.unmix``). The sum view S of a
dual-pixel file cannot be copied: it would keep the ghosts the others lost (1.5 x the clean sum
at r = 0.5). Where it is A + B (bias writes B = S - A) it is made again from the unmixed A and B
(NaN where either is); after ``flat`` it is not (each view divided by its own white), nothing
here can make it right, and it is left out (the log says so). Any other page is copied
unchanged, so the output keeps the input's metadata and ``stitch`` takes it as it is. A file
that holds a single view (a left or right refocused image) is named by ``--views``, in the
inputs' order, else as stitch names it (``single_view_name``: the pupil part refocus made it
of, else the file's name).
"""

from __future__ import annotations

import numpy as np

from plenocli import unmix as unmix_lib
from plenocli.errors import CalibrationError, InputError
from plenocli.io import tiffio
from plenocli.io.framing import Framing, active_area
from plenocli.io.mixingfile import read_mixing
from plenocli.io.preview import write_png
from plenocli.io.views import check_black_subtracted
from plenocli.model.provenance import processing_of, stage_record
from plenocli.model.views import (
    ViewNames,
    colour_page,
    pupil_views,
    refocused_part,
    single_view_name,
    view_of,
)
from plenocli.progress import log, shown

MAX_CONDITION = 1e3  # beyond this M amplifies noise 1000x: refuse unless regularised


def _load(inputs: list[str], views: str | None) -> tuple[np.ndarray, list[str], dict]:
    """All pages of ``inputs`` (P, rows, cols) float32, their names, the first file's meta.
    A file of one view is named by ``views`` (one name per input), else by its record."""
    pages, names, first = [], [], None
    given = views.split(",") if views else [None] * len(inputs)
    for path, named in zip(inputs, given, strict=True):
        data, meta = tiffio.read_image(path)
        check_black_subtracted(path, meta, "the mixing acts on light: a black level would be "
                               "unmixed as light")
        first = first if first is not None else meta
        held = ViewNames.of(meta, data.shape[0])
        own, own_name = list(held.pages), named or single_view_name(meta, path)
        part = refocused_part(meta)
        if named and part not in (None, named):
            raise InputError(f"--views names {path} {named}, but refocus made it of the "
                             f"{part} part of the pupil (--view {part}); name it {part}")
        if len(inputs) > 1 and data.shape[0] == 1:
            own = [own_name]
        elif len(inputs) > 1 and held.is_rgb:   # the colours of one view, named after the file
            own = [colour_page(own_name, c) for c in own]
        elif views:
            raise InputError(f"{path} holds views {','.join(own)}, not one: --views names the "
                             "views of files of one view each; leave it out")
        if pages and data.shape[1:] != pages[0].shape[1:]:
            raise InputError(f"{path} is {data.shape[2]} x {data.shape[1]} but {inputs[0]} is "
                             f"{pages[0].shape[2]} x {pages[0].shape[1]}; unmix views of one "
                             "capture")
        pages.append(data.astype(np.float32, copy=False))
        names += own
    if len(set(names)) != len(names):
        raise InputError(f"the inputs have repeated view names ({','.join(names)}); give each "
                         "view once")
    return np.concatenate(pages), names, first


def _check_parts(names: list[str], info: dict, mixing: str, inputs: list[str]) -> None:
    """Every pupil part of the views leaks light into the others: a mixing over some of them
    leaves the rest's light in the solved views and the others ghosted."""
    left_out = [v for v in pupil_views(names) if v not in info["views"]]
    if left_out:
        raise InputError(f"{mixing} mixes views {','.join(info['views'])} only, but "
                         f"{', '.join(inputs)} also holds {','.join(left_out)}: every pupil "
                         "part leaks into the others; measure one masked white per part "
                         "(crosstalk --mixing-out with all of them)")


def _plan(names: list[str], info: dict, inputs: list[str], views: str | None
          ) -> list[list[int]]:
    """Page indices to solve together: one list (in the mixing's view order) per colour plane
    (channels layout) or a single list (cfa / mono)."""
    expected = info["views"]
    wanted = ([[colour_page(v, c) for v in expected] for c in info["colours"]]
              if info["layout"] == "channels" else [expected])
    for group in wanted:
        missing = [n for n in group if n not in names]
        if missing:
            colour = info["layout"] != "channels" and colour_page(missing[0], "R") in names
            unnamed = len(inputs) == len(expected) > 1 and not views
            raise InputError(f"{', '.join(inputs)} has no view {missing[0]!r} (views: "
                             f"{','.join(names)}); the mixing expects {','.join(expected)}"
                             + (" per channel (VIEW.R, VIEW.G, VIEW.B)"
                                if info["layout"] == "channels" else "")
                             + (" of one plane, measured on masked whites without colour "
                                "pages: measure it on colour ones" if colour else "")
                             + ("; files of one view each are named after the files, or by "
                                f"--views (e.g. --views {','.join(expected)})"
                                if unnamed else ""))
    return [[names.index(n) for n in group] for group in wanted]


def _check_geometry(field, info: dict, framing: Framing, mixing: str,
                    inputs: list[str]) -> None:
    rows, cols = framing.shape
    if (rows, cols) != tuple(field.shape):
        raise InputError(f"the views are {cols} x {rows} but {mixing} was measured on "
                         f"{field.shape[1]} x {field.shape[0]}; measure the mixing on masked "
                         "whites processed like these views")
    cfa = framing.cfa
    expected = info.get("cfa") if info["layout"] == "cfa" else None
    if (cfa or None) != (expected or None):
        raise InputError(f"{', '.join(inputs)}: CFA {cfa or 'none'} but {mixing} was measured "
                         f"on CFA {expected or 'none'}; measure the mixing on masked whites "
                         "processed like these views")


def _check_processing(mix_meta: dict, mixing: str, inputs: list[str]) -> None:
    """The mixing describes views made as the ones it measured (flat-fielded or not, refocused
    with the same mask): other views carry other shares of light, and ghosts stay. Mixing
    files of before this record name only the last stage of their whites (their history)."""
    made = mix_meta["mixing"].get("views_made_by")
    whites = sorted({r.get("stage") for r in mix_meta.get("history") or []
                     if isinstance(r, dict)} - {None})
    for path in inputs:
        steps = processing_of(tiffio.read_meta(path))
        if not steps:
            continue  # no plenocli record: taken as it is
        if made is not None:
            differs, said = steps != list(made), " > ".join(made) or "no plenocli stage"
        else:
            differs, said = bool(whites) and [steps[-1]] != whites, " or ".join(whites)
        if differs:
            raise InputError(f"{mixing} was measured on views made by {said}, but {path} was "
                             f"made by {' > '.join(steps)}; measure the mixing on masked "
                             "whites processed as these views")


def _check_condition(field, mixing: str, regularise: float) -> np.ndarray:
    if not np.isfinite(field.nodes).all():
        raise CalibrationError(f"{mixing}: the mixing field has non-finite values; measure it "
                               "again with plenocli crosstalk --mixing-out")
    cond = unmix_lib.node_condition(field)
    if regularise == 0 and not np.all(cond <= MAX_CONDITION):
        c, a, b = np.unravel_index(int(np.argmax(np.where(np.isfinite(cond), cond, np.inf))),
                                   cond.shape)
        raise CalibrationError(f"{mixing}: the mixing matrix is singular or nearly so "
                               f"(condition number {cond[c, a, b]:.3g} at node row {a}, col {b}, "
                               f"colour {field.colours[c]}); re-measure it, or pass "
                               "--regularise (e.g. 0.05) to damp those pixels")
    return cond


NEGATIVE_SHARE = 0.005  # of a view's pixels: far more than hot pixels' ghosts or stray outliers
NEGATIVE_BLOCK_SHARE = 0.25  # of one block's pixels: an over-correction confined to a region


def _check_light(res, observed: np.ndarray, names: list[str], mixing: str,
                 inputs: list[str], *, mosaic: bool) -> None:
    """Light cannot be negative: unmixed views below zero beyond their noise (and the
    mixing's tolerance) over a share of the frame, or of one block, mean the mixing removes
    more light than the other views gave (``unmix_lib.negative_light``)."""
    found = unmix_lib.negative_light(res.views, observed, res.noise_gain, mosaic=mosaic)
    bad = (found.share > NEGATIVE_SHARE) | (found.worst_block > NEGATIVE_BLOCK_SHARE)
    if not bad.any():
        return
    k = int(np.argmax(np.where(bad, found.share + found.worst_block, -1.0)))
    level = float(np.nanmedian(observed))
    raise CalibrationError(
        f"{mixing} removes more light than {', '.join(inputs)} holds: {found.share[k]:.1%} of "
        f"view {names[k]}'s pixels{' of one colour' if mosaic else ''} (up to "
        f"{found.worst_block[k]:.0%} of a {unmix_lib.NEGATIVE_BLOCK} px block) come out below "
        f"zero beyond their noise, down to {np.nanmin(res.views[k]):.4g} (median level "
        f"{level:.4g}); "
        "the mixing does not describe this capture: measured on another rig or on whites "
        "too dark (r too high or noisy), or the leaked light forms another image than the "
        "views' (content out of focus, docs/crosstalk.md); measure it on well-exposed masked "
        "whites of this rig, processed as these views, and unmix in-focus captures")


def run(inputs: tuple[str, ...] | list[str], output: str, *, mixing: str,
        views: str | None = None, regularise: float = 0.0, noise_map: str | None = None,
        preview: str | None = None) -> None:
    """Remove the cross-talk described by ``mixing`` from the views of ``inputs``."""
    inputs = [inputs] if isinstance(inputs, str) else list(inputs)
    if not inputs:
        raise InputError("no input given; pass the views TIFF (or one TIFF per view)")
    field, mix_meta = read_mixing(mixing)
    info = mix_meta["mixing"]
    pages, names, meta = _load(inputs, views)
    groups = _plan(names, info, inputs, views)
    _check_parts(names, info, mixing, inputs)
    framing = active_area(meta, pages.shape[1:])
    _check_geometry(field, info, framing, mixing, inputs)
    _check_processing(mix_meta, mixing, inputs)
    cond = _check_condition(field, mixing, regularise)
    cfa = framing.cfa
    out = pages.copy()
    gains = np.empty((sum(len(g) for g in groups), *framing.shape), np.float32)
    singular = 0
    for c, group in enumerate(groups):
        if info["layout"] == "cfa":
            pattern = np.array([field.colours.index(ch) for ch in cfa.upper()]).reshape(2, 2)
        else:
            pattern = np.full((2, 2), c)
        res = unmix_lib.unmix(framing.crop(pages[group]), field,
                              colour_pattern=pattern, regularise=regularise, noise_gain=True)
        framing.crop(out)[group] = res.views
        gains[c * len(group):(c + 1) * len(group)] = res.noise_gain
        singular += res.singular_pixels
        if not res.singular_pixels:
            _check_light(res, framing.crop(pages[group]), [names[k] for k in group], mixing,
                         inputs, mosaic=info["layout"] == "cfa")
    if singular:
        raise CalibrationError(f"{mixing}: the mixing matrix cannot be inverted at {singular} "
                               "pixels; re-measure it, or pass --regularise (e.g. 0.05)")
    solved = [k for g in groups for k in g]
    kept = _sum_again(out, pages, names, solved)
    if not np.isfinite(out[solved]).any():
        raise InputError(f"{', '.join(inputs)}: every unmixed pixel is NaN; check the views")
    summary = _summary(gains, [names[k] for k in solved], cond, regularise)
    params = dict(mixing=mixing, views=views, regularise=regularise)
    record = stage_record("unmix", params, {"inputs": inputs, "mixing": mixing})
    per_view = {key: [meta[key][k] for k in kept] for key in PER_VIEW_KEYS
                if isinstance(meta.get(key), list) and len(meta[key]) == len(names)}
    out_meta = tiffio.derived_meta(meta, record, views=[names[k] for k in kept], unmix=summary,
                                   **per_view)
    protect = (*inputs, mixing)
    tiffio.write_image(output, out[kept], out_meta, protect=protect)
    if noise_map:
        tiffio.write_image(noise_map, gains, _noise_meta(meta, params, inputs, mixing, framing,
                                                         [names[k] for k in solved], summary),
                           protect=protect)
    if preview:
        write_png(preview, _preview_views(framing.crop(out), groups, info),
                  cfa=cfa if info["layout"] == "cfa" else None, protect=protect,
                  colour=meta.get("colour"))
    log.info("unmix: %s -> %s (%s; noise gain median %.3g, max %.3g; condition number up to "
             "%.3g%s)", ", ".join(shown(p) for p in inputs), shown(output),
             ",".join(info["views"]), summary["noise_gain_median"], summary["noise_gain_max"],
             summary["condition_max"], f", Tikhonov {regularise:g}" if regularise else "")


PER_VIEW_KEYS = ("black_level", "white_level", "view_colours")  # metadata listed view by view


def _noise_meta(meta: dict, params: dict, inputs: list[str], mixing: str, framing: Framing,
                names: list[str], summary: dict) -> dict:
    """The noise-gain map's metadata: a record of its own (``unmix-noise-gain``, so that no
    stage takes it for views, as ``flat-gain`` for a gain), its pages' names, the active area
    it covers and no light levels (a gain has none)."""
    record = stage_record(NOISE_STAGE, params, {"inputs": inputs, "mixing": mixing})
    colours = meta.get("view_colours")
    return tiffio.derived_meta(
        meta, record, views=names, cfa=framing.cfa, origin=list(framing.sensor_origin),
        active_area=[0, 0, *framing.shape], masked_areas=[], black_level=None,
        white_level=None, unmix=summary,
        view_colours=[colours[meta["views"].index(n)] for n in names]
        if isinstance(colours, list) and meta.get("views") else None,
        content="noise gain per view: output noise std for unit independent noise in every "
                "input view")


NOISE_STAGE = "unmix-noise-gain"


def _sum_again(out: np.ndarray, pages: np.ndarray, names: list[str],
               solved: list[int]) -> list[int]:
    """Make a dual-pixel file's S pages again as the sums of its unmixed A and B pages
    (channel by channel: ``S.R`` = ``A.R`` + ``B.R``) where the input's S is their sum; the
    pages to write (an S that is not, after flat, left out)."""
    kept = list(range(len(names)))
    if "S" in pupil_views(names) or not {"A", "B", "S"} <= {view_of(n) for n in names}:
        return kept
    for k, name in enumerate(names):
        parts = [names.index(v + name[1:]) for v in "AB" if v + name[1:] in names]
        if view_of(name) != "S" or len(parts) != 2 or not set(parts) <= set(solved):
            continue
        total = pages[parts[0]] + pages[parts[1]]
        known = np.isfinite(total) & np.isfinite(pages[k])
        if np.allclose(pages[k][known], total[known], rtol=1e-5, atol=0):
            out[k] = out[parts[0]] + out[parts[1]]
        else:
            kept.remove(k)
            log.info("unmix: %s left out: it is not %s + %s here (flat-fielded views), so it "
                     "cannot be unmixed; sum the unmixed views if you need it", name,
                     names[parts[0]], names[parts[1]])
    return kept


def _preview_views(pages: np.ndarray, groups: list[list[int]], info: dict) -> np.ndarray:
    """The unmixed views to show: (views, rows, cols, 3) when the groups are the R, G, B planes
    of the views, else the pages of the first group."""
    if info["layout"] == "channels" and list(info["colours"]) == ["R", "G", "B"]:
        return np.stack([pages[g] for g in groups], axis=-1)
    return pages[groups[0]]


def _summary(gains: np.ndarray, names: list[str], cond: np.ndarray, regularise: float) -> dict:
    per_view = {}
    for name, g in zip(names, gains, strict=True):
        q = np.percentile(g, [50, 99])
        per_view[name] = {"median": float(q[0]), "p99": float(q[1]), "max": float(g.max())}
    finite = cond[np.isfinite(cond)]
    return {"regularise": regularise, "noise_gain": per_view,
            "noise_gain_median": float(np.median(gains)), "noise_gain_max": float(gains.max()),
            "condition_min": float(finite.min()) if finite.size else float("inf"),
            "condition_median": float(np.median(finite)) if finite.size else float("inf"),
            "condition_max": float(cond.max()),
            "definition": "noise gain of view k = ||row k of the solve matrix||_2: output noise "
                          "std per unit independent input noise; condition = 2-norm condition "
                          "number of M at the mixing nodes"}
