"""Stage ``stitch``: 2 or 4 views (from one or more TIFFs) -> extended-FOV panorama + report.

Views are found by page name (:class:`plenocli.model.views.ViewNames`: a page ``VIEW.CHANNEL``
is one channel of view ``VIEW``; pages exactly ``R, G, B`` are one colour view; any other page is
a view of its own; unnamed pages are ``view0``, ``view1``, ...; ``--views`` takes a page number
too). A file that holds a single view (e.g. a left or right refocused image) names it after the
file (``left.tif`` -> ``left``). A single-page Bayer view is made camera RGB as develop makes it
(``plenocli.colour.develop.camera_rgb``: the default demosaic, pixels clipped in some channels
rebuilt, and left out of the exposure gains) and stitched at full resolution; pixels clipped
in every channel stay NaN. The panorama keeps the capture's colour metadata, so ``develop``
gives it the camera's white balance and colour matrix, and none of the records of the input's
pixels.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from plenocli import stitch as stitch_lib
from plenocli.colour.develop import ColourView, camera_rgb
from plenocli.colour.highlights import Estimated
from plenocli.errors import InputError
from plenocli.io import tiffio
from plenocli.io.atomic import write_text
from plenocli.io.framing import active_area
from plenocli.io.preview import write_png
from plenocli.io.rigfile import read_rig
from plenocli.io.tiffcanvas import image_canvas
from plenocli.io.transformfile import read_transform, write_transform
from plenocli.io.views import check_named_once
from plenocli.model.cfa import shift_pattern
from plenocli.model.provenance import json_safe, stage_record
from plenocli.model.views import CHANNELS, ViewNames, single_view_name, view_of
from plenocli.progress import log, shown
from plenocli.stitch import verify
from plenocli.stitch.views import layout_of_names


def _page_pattern(meta: dict, page: int, top: int, left: int) -> str | None:
    """The 2 x 2 Bayer pattern of one page at the crop's pixel (0, 0) (the page's own in
    ``view_colours``, e.g. quad-Bayer SAIs, else the file's ``cfa``), or None: not a mosaic."""
    colours = meta.get("view_colours")
    pattern = colours[page] if colours and page < len(colours) else meta.get("cfa")
    if not pattern or len(str(pattern)) != 4:
        return None
    return shift_pattern(pattern, top, left)


def _held_views(inputs: list[str]) -> list[str]:
    """Every view the inputs hold (a file of one view: ``single_view_name``), to say which
    --views a saved transform's names could be."""
    held: list[str] = []
    for path in inputs:
        meta = tiffio.read_meta(path)
        views = meta.get("views") or []
        held += list(dict.fromkeys(view_of(str(v)) for v in views)) if len(views) > 1 \
            else [single_view_name(meta, path)]
    return held


def load_views(inputs: list[str], views: str | None
               ) -> tuple[np.ndarray, list[str], list[float] | None, dict, list]:
    """Views of ``inputs`` as (V, rows, cols) or (V, C, rows, cols) float32 (colour channels
    interleaved in memory), their names, when any was a Bayer mosaic (demosaiced at full
    resolution) each view's median level as stored (None otherwise), the first file's
    metadata, and per view the channels its demosaic estimated (:class:`Estimated`; None for
    a view that was not a mosaic). Only the views wanted are demosaiced, one at a time,
    straight into the stack."""
    found: list[tuple[str, tuple]] = []  # (view name, (path, page data, pages, cfa, as-shot wb))
    first_meta = None
    for path in inputs:
        data, meta = tiffio.read_image(path)
        if first_meta is None:
            first_meta = meta
        framing = active_area(meta, data.shape[1:])  # the light-sensitive area only
        data, top, left = framing.crop(data), framing.top, framing.left
        for name, pages in ViewNames.of(meta, data.shape[0]).groups(
                single_view_name(meta, path)):
            cfa = _page_pattern(meta, pages[0], top, left) if len(pages) == 1 else None
            wb = (meta.get("colour") or {}).get("as_shot_wb")
            found.append((name, (path, data, pages, cfa, wb)))
    if views:
        by_name = dict(found)
        # a page number (one input file) picks the view holding that page
        numbers = {str(src[2][0]): name for name, src in found} if len(inputs) == 1 else {}
        wanted = [v.strip() for v in views.split(",") if v.strip()]
        wanted = [v if v in by_name else numbers.get(v, v) for v in wanted]
        check_named_once(wanted)
        missing = [v for v in wanted if v not in by_name]
        if missing:
            raise InputError(f"view {missing[0]!r} is not in the input (views: "
                             f"{','.join(n for n, _ in found)}); pass --views with those names")
        found = [(v, by_name[v]) for v in wanted]
    shapes = [_view_shape(*source) for _, source in found]
    if len(set(shapes)) > 1:
        listing = ", ".join(f"{n} {'x'.join(map(str, shape))}"
                            for (n, _), shape in zip(found, shapes, strict=True))
        raise InputError(f"the views differ in size or colour channels ({listing}); stitch "
                         "views of one capture, processed the same way")
    if len(shapes[0]) == 3:  # colour: channels interleaved (as demosaiced), so the stitch
        # resamples each pixel's channels in one pass
        stack = np.moveaxis(np.empty((len(found),) + shapes[0][1:] + shapes[0][:1],
                                     np.float32), -1, 1)
    else:
        stack = np.empty((len(found),) + shapes[0], np.float32)
    estimated = [_fill_view(stack[k], name, *source) for k, (name, source) in enumerate(found)]
    # a demosaic clips negative values to 0: a negated view is told as such from its mosaic
    levels = [_level(data, pages) for _, (_, data, pages, _, _) in found] \
        if any(s[3] for _, s in found) else None
    return stack, [n for n, _ in found], levels, first_meta, estimated


LEVEL_STRIDE = 3  # odd: every CFA phase is in the sample; a ninth of the pixels tells the sign


def _level(data: np.ndarray, pages: list[int]) -> float:
    """The median of a view's pages as stored, sampled every 3 px (0 where none is finite)."""
    # strided page by page: data[pages] would copy the whole pages first (126 MB a 6876 view)
    sample = np.stack([data[p, ::LEVEL_STRIDE, ::LEVEL_STRIDE] for p in pages])
    return float(np.nanmedian(sample)) if np.isfinite(sample).any() else 0.0


def _view_shape(path: str, data: np.ndarray, pages: list[int], cfa: str | None, wb) -> tuple:
    """The shape of a view once loaded: (3, rows, cols) demosaiced, else its pages'."""
    if cfa:
        return (3,) + data.shape[1:]
    return data.shape[1:] if len(pages) == 1 else (len(pages),) + data.shape[1:]


def _fill_view(out: np.ndarray, name: str, path: str, data: np.ndarray, pages: list[int],
               cfa: str | None, wb) -> Estimated | None:
    """Write one view into ``out``: its pages, or its mosaic made camera RGB as develop makes it
    (balanced by the capture's as-shot white balance while interpolating, when the metadata has
    one; pixels clipped in some channels only rebuilt, so a panorama keeps their colour, and
    the channels so estimated returned: the exposure gains leave them out)."""
    if not cfa:
        out[...] = data[pages[0]] if len(pages) == 1 else data[pages]
        return None
    estimated = Estimated(out.shape[1:])
    try:  # demosaiced straight into the stack (its channels interleaved): no full-size copy
        camera_rgb(data, ColourView(name, (pages[0],), cfa), gains=wb,
                   out=np.moveaxis(out, 0, -1), estimated=estimated)
    except ValueError as err:
        raise InputError(f"{path}: view {name}: {err}") from err
    return estimated


def run(inputs: list[str], output: str, *, views: str | None = None, layout: str = "auto",
        model: str = "auto", distortion: float = 0.0, transform_in: str | None = None,
        transform_out: str | None = None, blend: str = "feather", report: str | None = None,
        preview: str | None = None, rig: str | None = None, overlap: float | None = None,
        overlap_tolerance: float = 0.1, gains: str = "match") -> None:
    """Stitch the views found in ``inputs`` into ``output``; optional report, transform and
    preview."""
    inputs = [inputs] if isinstance(inputs, str) else list(inputs)
    stack, names, levels, meta, estimated = load_views(inputs, views)
    placed = layout if transform_in or rig else _verified(layout_of_names, names, layout)
    # views whose names place them are not told to take another --layout
    named = None if transform_in or rig or layout_of_names(names, "auto") == "auto" else names
    held = _held_views(inputs) if transform_in else []
    transform = read_transform(transform_in, names, held=held) if transform_in else None
    named_after_files = names == [Path(p).stem for p in inputs]
    if transform is not None:
        _verified(verify.check_transform_names, transform, names, layout,
                  named_after_files=named_after_files, held=held)
    prism_rig = read_rig(rig) if rig else None
    if rig or (transform or {}).get("rig"):
        _check_uncropped(inputs, rig or transform_in)
    protect = tuple(p for p in (*inputs, transform_in, rig) if p)
    with image_canvas(output, protect=protect) as canvas:  # blended straight into the file
        _, result = _verified(stitch_lib.stitch, stack, layout=placed, model=model,
                              distortion_k1=distortion, transform=transform, blend=blend,
                              rig=prism_rig, overlap=overlap,
                              overlap_tolerance=overlap_tolerance, out=canvas.allocate,
                              match_gain=gains == "match", named=named, levels=levels,
                              estimated=estimated,
                              claim=_claim(transform_in, rig, distortion))
        params = dict(views=views, layout=layout, model=model, distortion=distortion,
                      transform_in=transform_in, blend=blend, rig=rig, overlap=overlap,
                      overlap_tolerance=overlap_tolerance, gains=gains)
        record = stage_record("stitch", params, {"inputs": inputs, "transform_in": transform_in,
                                                 "rig": rig})
        rep = {**dataclasses.asdict(result), "input_views": names,
               "bayer_demosaiced": levels is not None}
        n_pages, height, width = canvas.shape
        page_names = (list(CHANNELS) if n_pages == 3 else ["panorama"]
                      if n_pages == 1 else [f"C{c}" for c in range(n_pages)])
        canvas.finish(tiffio.derived_meta(
            _of_the_camera(meta), record, views=page_names, cfa=None, view_colours=None,
            active_area=None, masked_areas=None, origin=None, **_levels(meta, len(page_names)),
            stitch={k: rep[k] for k in ("model", "layout", "shifts_px", "residual_px",
                                        "origin_px")}))
        if preview:  # from the file's pages: the panorama was never held whole
            pano = canvas.pixels()
            write_png(preview, np.moveaxis(pano, 0, -1) if n_pages == 3 else pano[0],
                      protect=protect, colour=meta.get("colour"))
    if report:
        write_text(report, json.dumps(json_safe({**rep, "provenance": record}), indent=2,
                                      allow_nan=False), protect=protect)
    if transform_out:
        write_transform(transform_out, rep["transform"], names, record, protect=protect)
    log.info("stitch: %s -> %s (%s, layout %s, views %s, %d x %d px, residual %.3f px)",
             " + ".join(shown(p) for p in inputs), shown(output), rep["model"], rep["layout"],
             ",".join(names), width, height, rep["residual_px"])


def _bias_crop(meta: dict) -> str | None:
    """The ``bias --crop`` (ROWSxCOLS) that cut a file's views out of the sensor's active area,
    from its record (its own or its history's), or None."""
    for record in (*(meta.get("history") or []), meta.get("provenance")):
        if isinstance(record, dict) and record.get("stage") == "bias":
            crop = (record.get("parameters") or {}).get("crop")
            if crop:
                return str(crop)
    return None


def _check_uncropped(inputs: list[str], side_file: str) -> None:
    """Refuse views cut out of the sensor by ``bias --crop`` when a rig places them: a rig
    describes the whole active area (optical axis at its centre, ``sensor_mm`` across its
    width), and a crop's file records its sensor origin but not the active area it was cut
    from, so the rig cannot be put on it (nor can the views be registered without it: their
    overlap is the prism's)."""
    for path in inputs:
        meta = tiffio.read_meta(path)
        crop = _bias_crop(meta)
        if crop:
            raise InputError(f"{path}: its views are a `bias --crop {crop}` crop (sensor origin "
                             f"{meta.get('origin')}), and the rig of {side_file} describes the "
                             "sensor's whole active area: stitch the views of `bias` without "
                             "--crop with it")


def _claim(transform_in: str | None, rig: str | None, distortion: float = 0.0
           ) -> tuple[str, str]:
    """What placed the views, as the seam check's refusal names it (the side file by its
    name), and what to do if they do not line up. A side file may make the panorama refused,
    never wrong; a registration is checked the same way (a weak false match lines up
    nowhere)."""
    if rig and distortion:  # the user's K1 moves the views the rig places
        return (f"the rig {rig} on views with --distortion {distortion:g} removed",
                "check --distortion, or leave it out (the rig places the views as the camera "
                "recorded them); else register the views without the rig")
    what, remedy = verify.default_claim(transform=bool(transform_in), rig=bool(rig))
    if transform_in or rig:
        what = f"the transform {transform_in}" if transform_in else f"the rig {rig}"
    return what, remedy


# what a panorama keeps of its first input's metadata: what describes the camera, not the
# input's pixels (an `sai` block's micro-lens layout and crop origin, bias's row levels, the
# input's clipped-pixel count, a flat's masked gain: none of them is the panorama's)
_CAMERA_KEYS = ("plenocli_format", "colour", "camera", "exif", "orientation", "provenance",
                "history")


def _of_the_camera(meta: dict) -> dict:
    """The part of the input's metadata that a panorama made from it carries on."""
    return {k: v for k, v in meta.items() if k in _CAMERA_KEYS}


def _levels(meta: dict, pages: int) -> dict:
    """The black and white levels of the panorama's pages: the views' common ones (each page
    mixes every view), none where the views differ."""
    out = {}
    for key in ("black_level", "white_level"):
        levels = meta.get(key)
        same = isinstance(levels, list) and levels and all(v == levels[0] for v in levels)
        out[key] = [levels[0]] * pages if same else None
    return out


def _verified(call, *args, **kwargs):
    """``call``'s result; the library's ValueError (a refusal) as the one-line user error."""
    try:
        return call(*args, **kwargs)
    except ValueError as err:
        raise InputError(str(err)) from err


