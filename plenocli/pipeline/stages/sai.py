"""Stage ``sai``: frames TIFF -> N x N sub-aperture images (Eq. 1, or S-hat with a grid)."""

from __future__ import annotations

import numpy as np

from plenocli import sai as sai_mod
from plenocli.errors import ConfigError, InputError
from plenocli.io import tiffio
from plenocli.io.framing import active_area, frame_grid
from plenocli.io.preview import view_mosaic, write_png
from plenocli.io.views import check_black_subtracted
from plenocli.model.provenance import stage_record
from plenocli.model.views import ViewNames
from plenocli.progress import log, shown


def run(input: str, output: str, *, n: int = 2, grid: str | None = None,
        cfa_layout: str = "pixel", preview: str | None = None) -> None:
    """Demultiplex every page of ``input`` into n * n views (S00, S01, ...)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ConfigError(f"-n must be a positive integer (pixels per micro-image side), got {n}")
    if cfa_layout not in sai_mod.CFA_LAYOUTS:
        raise ConfigError(f"unknown --cfa-layout {cfa_layout!r}; choose one of "
                          f"{', '.join(sai_mod.CFA_LAYOUTS)}")
    data, meta = tiffio.read_image(input)
    check_black_subtracted(input, meta, "sub-aperture images record no black level: theirs "
                           "would pass as light")
    pages = list(ViewNames.of(meta, data.shape[0]).pages)
    _check_sensor_image(input, meta, pages, cfa_layout)
    if grid is None and (meta.get("camera") == "raytrix" or "raytrix_calib" in meta):
        raise InputError(f"{input}: frames of a focused plenoptic (Raytrix) camera, whose "
                         "micro-images are not N x N pixel blocks: Eq. 1 gives no sub-aperture "
                         "images of them; render views with plenocli refocus (--view left/right)")
    # ideal sensor: micro-image (0, 0) starts at the active area's top-left pixel
    framing = (frame_grid(grid, meta, data.shape[1:], frames_path=input) if grid
               else active_area(meta, data.shape[1:]))
    if grid is None:
        _check_microimage_phase(input, meta, framing.sensor_origin, n)
    cfa = framing.cfa
    per_page = []
    for page in data:
        crop = framing.crop(page)
        if framing.grid is not None:
            try:
                out, _ = sai_mod.approximate_sai(crop.astype(np.float32), framing.grid, n)
            except ValueError as err:
                raise ConfigError(f"{grid}: {err}") from err
        else:
            try:
                out = sai_mod.demultiplex(crop, n)
            except ValueError as err:
                raise InputError(f"{input}: {err}") from err
        per_page.append(out)
    if framing.grid is not None and cfa:
        raise InputError(f"{input}: a Bayer mosaic ({cfa}); with a pitch that is not N pixels "
                         "the pixel nearest each sub-aperture centre falls on another colour "
                         "from lens to lens, so approximate SAIs (--grid) would mix colours: "
                         "give frames of one colour per pixel (monochrome or RGB)")
    # view-major pages: the channels of one view are consecutive, named VIEW.CHANNEL
    stack = np.stack(per_page, axis=1).reshape(-1, *per_page[0].shape[1:])
    names = (sai_mod.view_names(n) if len(pages) == 1
             else [f"{v}.{name}" for v in sai_mod.view_names(n) for name in pages])
    colours = [c for c in sai_mod.sai_colours(cfa, n, layout=cfa_layout) for _ in pages]
    same = len(set(colours)) == 1 and colours[0] is not None and len(colours[0]) == 4
    params = dict(n=n, grid=grid, cfa_layout=cfa_layout)
    record = stage_record("sai", params, {"input": input, "grid": grid})
    out_meta = tiffio.derived_meta(
        meta, record, views=names, cfa=colours[0] if same else None, view_colours=colours,
        origin=None, active_area=[0, 0, stack.shape[1], stack.shape[2]], masked_areas=[],
        **_levels(meta, len(pages), len(names)),
        sai={"n": n, "approximate": framing.grid is not None, "cfa_layout": cfa_layout,
             "crop_sensor_origin": list(framing.sensor_origin)})
    protect = (input,) + ((grid,) if grid else ())
    tiffio.write_image(output, stack, out_meta, protect=protect)
    log.info("sai: %s -> %s (%d views%s of %d x %d%s)", shown(input), shown(output), n * n,
             f" x {len(pages)} channels" if len(pages) > 1 else "", stack.shape[2],
             stack.shape[1], ", approximate S-hat" if framing.grid else "")
    if preview:
        write_png(preview, view_mosaic(stack, n, pages, cfa=colours[0] if same else None),
                  protect=protect, colour=meta.get("colour"))


def _check_microimage_phase(path: str, meta: dict, first: tuple[int, int], n: int) -> None:
    """An ideal sensor's micro-image (0, 0) starts at the sensor's active area (recorded by
    bias as ``active_origin``); a frame cropped into the micro-images (bias --crop with a
    margin that is not a multiple of n) starts inside one, and every view would be named after
    another sub-aperture."""
    start = meta.get("active_origin")
    if start is None:
        return
    if not (isinstance(start, list) and len(start) == 2
            and all(isinstance(v, int) and not isinstance(v, bool) for v in start)):
        raise InputError(f"{path}: its metadata's active_origin ({str(start)[:40]}) is not "
                         "two whole numbers (row, column); make the file again with plenocli")
    into = [(first[k] - int(start[k])) % n for k in (0, 1)]
    if any(into):
        raise InputError(f"{path}: its first pixel lies {into[0]} row(s) and {into[1]} "
                         f"column(s) into a {n} x {n} micro-image (a crop, bias --crop, of a "
                         f"margin that is not a multiple of {n}): each view would be another "
                         f"sub-aperture's; crop with a margin (the uncropped size less the "
                         f"crop, halved) that is a multiple of {n}, or not at all")


def _check_sensor_image(path: str, meta: dict, pages: list[str], cfa_layout: str) -> None:
    """Sub-aperture images are cut from a sensor image, not from views made from one."""
    made = next((key for key in ("sai", "refocus") if key in meta), None)
    if made is not None:
        raise InputError(f"{path}: already {made} views (made by plenocli {made}); pass the "
                         "frames they were made from (plenocli decode or bias output)")
    if {"A", "B"} <= set(pages):
        raise InputError(f"{path}: holds the dual-pixel views {', '.join(pages)}, already one "
                         "sub-aperture image each; sai is for N x N pixel sensors")
    if cfa_layout == "micro-image" and not meta.get("cfa"):
        raise ConfigError(f"--cfa-layout micro-image: {path} has no CFA pattern (monochrome "
                          "or RGB frames); leave --cfa-layout at pixel")


def _levels(meta: dict, pages: int, views: int) -> dict:
    """The SAIs' levels: each output page is pixels of one input page, so it keeps that page's
    white level (develop then masks what clipped); the black level is 0 (checked above)."""
    if meta.get("white_level") is None:
        return {"black_level": None, "white_level": None}
    whites = tiffio.white_levels(meta, pages)
    return {"black_level": [[0.0] * 4] * views,
            "white_level": [whites[k % pages] for k in range(views)]}
