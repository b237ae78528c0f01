"""Stage ``develop``: views TIFF -> a colour photograph (TIFF 16-bit, JPEG or PNG) with ICC
profile, the camera's EXIF and provenance; optionally the scene-referred linear RGB as float TIFF.
"""

from __future__ import annotations

import cv2
import numpy as np

from plenocli import dualpixel
from plenocli.colour import balance
from plenocli.colour import develop as dev
from plenocli.colour.demosaic import DEFAULT_METHOD, METHODS
from plenocli.errors import ConfigError, InputError, OptionError
from plenocli.io import photo as export
from plenocli.io import tiffio
from plenocli.io.atomic import outputs_together, write_bytes
from plenocli.io.framing import active_area
from plenocli.model import colour as colour_matrix
from plenocli.model import orientation
from plenocli.model.provenance import json_safe, stage_record
from plenocli.model.views import ViewNames
from plenocli.progress import log, shown

PREVIEW_SIDE = 1024


def run(input: str, output: str, *, view: str | None = None, method: str = DEFAULT_METHOD,
        wb: str = "as-shot", wb_from: str | None = None, matrix: str = "as-shot",
        space: str = "srgb", exposure: float = 0.0, quality: int = 95,
        recover_highlights: str | None = None, linear: str | None = None,
        preview: str | None = None) -> None:
    """Develop one colour view of ``input`` into ``output`` (see ``plenocli develop --help``)."""
    if method not in METHODS:
        raise ConfigError(f"--method {method}: choose one of {', '.join(METHODS)}")
    if space not in colour_matrix.OUTPUT_SPACES:
        raise ConfigError(f"--space {space}: choose one of "
                          f"{', '.join(colour_matrix.OUTPUT_SPACES)}")
    try:
        fmt = export.output_format(output)
    except ValueError as err:
        raise ConfigError(str(err)) from err
    data, meta, cfa, names = _read(input)
    try:
        views = dev.colour_views(names, cfa=cfa, view_colours=meta.get("view_colours"))
    except ValueError as err:
        hint = ("" if meta.get("provenance") else "; a plain (not plenocli) TIFF: `plenocli "
                "decode` it first, which names an RGB image's pages R, G, B")
        raise InputError(f"{input}: {err}{hint}") from err
    chosen = _choose(views, view, input)
    if recover_highlights and chosen.name == "A":
        raise OptionError("--recover-highlights rebuilds S and B from A where only S clipped; "
                          "view A is what it reads and comes out unchanged: drop the option, "
                          "or develop --view S or B")
    rebuilt = None
    if recover_highlights:
        data, rebuilt = _recover(data, names, cfa, recover_highlights, input, meta)
    gains, gains_from = _gains(wb, wb_from, meta, chosen, input)
    to_srgb = None if _developed(meta) else _camera_matrix(matrix, meta, input)
    try:
        camera = dev.camera_rgb(data, chosen, method=method, gains=gains)
        del data
        scene = dev.scene_rgb(camera, gains=gains, camera_to_srgb=to_srgb, in_place=True)
        scale = dev.exposure_scale(scene, exposure_ev=exposure)
        blown = dev.blown_highlights(scene, whole_frame=not {"stitch", "refocus"} & meta.keys())
        encoded = dev.output_encoded(scene, space, scale, in_place=not linear)
        encoded[blown] = 1.0
    except ValueError as err:
        raise InputError(f"{input}: view {chosen.name}: {err}") from err
    # the photograph stands as the camera was held (turned where it is written, io/photo);
    # the --linear TIFF stays in sensor order and carries the value (checked where read)
    turned = meta.get("orientation")
    params = dict(view=chosen.name, method=method if chosen.cfa else None, wb=wb,
                  wb_from=wb_from, matrix=matrix, space=space, exposure=exposure,
                  quality=quality, recover_highlights=recover_highlights,
                  rebuilt_pixels=None if rebuilt is None else int(rebuilt.sum()),
                  gains=gains.tolist(), scale=scale,
                  camera_to_srgb=None if to_srgb is None else to_srgb.tolist(),
                  orientation=turned,
                  turned=None if turned is None else orientation.TURNS[turned])
    record = stage_record("develop", params, {"input": input, "wb_from": wb_from,
                                              "recover_highlights": recover_highlights})
    description = json_safe({"plenocli": record, "history": tiffio.history_of(meta)})
    try:
        body = export.image_bytes(encoded, fmt, space=space, exif=meta.get("exif"),
                                  description=description, quality=quality,
                                  orientation=turned or 1)
        preview_body = (_preview_bytes(encoded, space, description, turned or 1)
                        if preview else None)
    except ValueError as err:
        raise ConfigError(str(err)) from err
    protect = (input,) + tuple(p for p in (wb_from, recover_highlights) if p)
    if linear and rebuilt is not None:  # the mask plane: 1 where S (and B) were rebuilt
        scene = np.concatenate([scene, rebuilt[..., np.newaxis].astype(np.float32)], axis=-1)
    _write_together(output, body, linear, scene, meta, record, preview, preview_body, protect)
    log.info("develop: %s view %s -> %s (%s, %s, gains %s%s)", shown(input), chosen.name,
             shown(output), fmt, space, ",".join(f"{g:.3f}" for g in gains),
             f", {orientation.TURNS[turned]}" if turned not in (None, 1) else "")


def _read(path: str) -> tuple[np.ndarray, dict, str | None, list[str]]:
    """A views file as DN above black over its active area: pages, metadata, the area's CFA
    and the view names."""
    data, meta = tiffio.read_image(path)
    framing = active_area(meta, data.shape[1:])
    names = list(ViewNames.of(meta, data.shape[0]).pages)
    return framing.crop(_levels(data, meta)), meta, framing.cfa, names


def _levels(data: np.ndarray, meta: dict) -> np.ndarray:
    """Raw frames (decode output: integers, or a float DNG's samples) as DN above black, NaN
    where they reached the white level; processed (float) views are returned as they are."""
    made = (meta.get("provenance") or {}).get("stage")
    if data.dtype.kind not in "ui" and made != "decode":
        return data
    out = data.astype(np.float32)
    blacks = meta.get("black_level") or [[0.0] * 4] * len(data)
    whites = tiffio.white_levels(meta, len(data))
    for k, frame in enumerate(out):
        np.copyto(frame, np.nan, where=data[k] >= whites[k])
        for p in range(4):
            frame[p // 2::2, p % 2::2] -= np.float32(blacks[k][p])
    return out


def _developed(meta: dict) -> bool:
    """Whether the views are develop's own --linear TIFF: white-balanced and in linear sRGB
    already (an older one still carries the camera's as-shot gains and matrix)."""
    records = [*meta.get("history", []), meta.get("provenance") or {}]
    return any(r.get("stage") == "develop" for r in records if isinstance(r, dict))


def _stages(meta: dict) -> list[str]:
    records = [*meta.get("history", []), meta.get("provenance") or {}]
    return [r.get("stage") for r in records if r.get("stage") in ("bias", "flat")]


def _recover(data: np.ndarray, names: list[str], cfa: str | None, white_path: str,
             path: str, meta: dict) -> tuple[np.ndarray, np.ndarray]:
    """Dual-pixel highlight recovery: S (and B) rebuilt from A where only S clipped."""
    white, white_meta, white_cfa, white_names = _read(white_path)
    for label, views_, file in (("views", names, path), ("white image", white_names, white_path)):
        if not {"A", "B", "S"} <= set(views_):
            raise InputError(f"--recover-highlights: {file} ({label}) has views "
                             f"{', '.join(views_) or 'unnamed'}; dual-pixel A, B and S are needed "
                             "(bias output)")
    if _stages(white_meta) != _stages(meta):
        raise InputError(f"--recover-highlights {white_path}: the white image went through "
                         f"{' -> '.join(_stages(white_meta)) or 'no bias/flat'} but {path} "
                         f"through {' -> '.join(_stages(meta)) or 'no bias/flat'}; the A/S "
                         "split must be measured in the same units (process both alike)")
    if white.shape[1:] != data.shape[1:] or white_cfa != cfa:
        raise InputError(f"--recover-highlights {white_path}: the white image "
                         f"({white.shape[2]}x{white.shape[1]}, CFA {white_cfa}) does not match "
                         f"{path} ({data.shape[2]}x{data.shape[1]}, CFA {cfa}); process both alike")
    try:
        split = dualpixel.highlight_split(white[white_names.index("A")],
                                          white[white_names.index("S")], cfa=cfa)
    except ValueError as err:
        raise InputError(f"--recover-highlights {white_path}: {err}") from err
    ia, ib, is_ = (names.index(v) for v in "ABS")
    _check_split(data[ia], data[is_], split, white_path, path)
    rebuilt_views, rebuilt = dualpixel.recover_highlights(data[ia], data[is_], split)
    out = data.astype(np.float32, copy=True)
    out[ia], out[ib], out[is_] = rebuilt_views
    log.info("develop: %d clipped S pixels rebuilt from A", int(rebuilt.sum()))
    return out, rebuilt


SPLIT_TOLERANCE = 0.1  # the capture's median A/S this far from the white's: another lens
SPLIT_STRIPS = 4  # the split falls off from left to right: judged in this many column strips


def _check_split(a: np.ndarray, s: np.ndarray, split: np.ndarray, white_path: str,
                 path: str) -> None:
    """The white's A/S split must be the capture's: its lit, unclipped pixels show their own
    A/S, which scatters with defocus but centres on the split of this lens and aperture, strip
    by strip across the frame (the split falls off from left to right). A white of another
    lens or aperture (or an edited one: A at 0.01 S rebuilt highlights 20 x too bright; A and B
    swapped, a mirrored fall-off of the same median, 20 % off, audit 24-25) is far off in some
    strip."""
    lit = np.isfinite(a) & np.isfinite(s) & np.isfinite(split)
    if lit.any():
        lit &= s > 0.1 * np.nanpercentile(np.where(lit, s, np.nan), 99)
    cols = a.shape[1]
    for k in range(SPLIT_STRIPS):
        strip = (slice(None), slice(k * cols // SPLIT_STRIPS, (k + 1) * cols // SPLIT_STRIPS))
        here = lit[strip]
        if here.sum() < 256:
            continue   # too little unclipped light there to tell
        a_k, s_k, split_k = a[strip][here], s[strip][here], split[strip][here]
        if abs(float(np.median(a_k / (s_k * split_k))) - 1) > SPLIT_TOLERANCE:
            raise InputError(
                f"--recover-highlights {white_path}: its A/S split (median "
                f"{float(np.median(split_k)):.3g} in column strip {k + 1} of {SPLIT_STRIPS}) is "
                f"not {path}'s, whose unclipped pixels there split "
                f"{float(np.median(a_k / s_k)):.3g} (median): a white of another lens or "
                "aperture; use a white of this camera, lens and aperture, processed alike")


def _choose(views: list[dev.ColourView], name: str | None, path: str) -> dev.ColourView:
    if name is None:
        if len(views) == 1:
            return views[0]
        raise ConfigError(f"{path} holds {len(views)} colour views "
                          f"({', '.join(v.name for v in views)}); choose one with --view")
    for v in views:
        if v.name == name:
            return v
    raise ConfigError(f"--view {name}: no such view in {path} "
                      f"(views: {', '.join(v.name for v in views)})")


def _gains(wb: str, wb_from: str | None, meta: dict, chosen: dev.ColourView, path: str
           ) -> tuple[np.ndarray, str]:
    """White-balance gains from --wb-from, --wb R,G,B or the raw's as-shot metadata; for
    develop's linear TIFF, as shot is as developed (1, 1, 1), and --wb a correction on top
    (--wb-from on it is refused with the kinds of the inputs, pipeline/kinds.EXCLUDED)."""
    if wb_from is not None:
        if wb != "as-shot":
            raise ConfigError("give --wb or --wb-from, not both")
        return _gains_from_white(wb_from, chosen, meta), "white image"
    if wb != "as-shot":
        try:
            return balance.normalised_gains([float(v) for v in wb.split(",")]), "--wb"
        except ValueError as err:
            raise ConfigError(f"--wb {wb}: give three positive gains R,G,B (e.g. 2.1,1,1.6) "
                              "or as-shot") from err
    as_shot = (meta.get("colour") or {}).get("as_shot_wb")
    if _developed(meta):
        return np.ones(3), "as developed"
    if as_shot is None:
        raise InputError(f"{path}: no as-shot white balance in the metadata; give --wb R,G,B "
                         "or --wb-from WHITE.tif")
    return balance.normalised_gains(as_shot), "as shot"


def _gains_from_white(path: str, chosen: dev.ColourView, input_meta: dict) -> np.ndarray:
    """Gains from the white image's view of the same name; for a view the white does not have
    (a panorama or refocused image made from its views), its full-pupil sum S or its only
    colour view. Gains are per colour, so a Bayer white serves a demosaiced view and back. A
    white of another camera is refused: camera gains are the sensor's response to the light
    (audit 24: another model's white left red 18 % and blue 13 % off, exit 0)."""
    data, meta, cfa, names = _read(path)
    for key in ("Make", "Model"):
        theirs, ours = ((m.get("exif") or {}).get(key) for m in (meta, input_meta))
        if theirs and ours and theirs != ours:
            raise InputError(f"--wb-from {path}: a white of another camera ({key} {theirs}; "
                             f"the input's is {ours}): white-balance gains are the sensor's "
                             "own; use a white or grey card taken with this camera")
    try:
        views = dev.colour_views(names, cfa=cfa, view_colours=meta.get("view_colours"))
        by_name = {v.name: v for v in views}
        white = by_name.get(chosen.name) or by_name.get("S") or (
            views[0] if len(views) == 1 else None)
        if white is None:
            raise ValueError(f"no view {chosen.name} (nor a sum view S) among its colour views "
                             f"({', '.join(by_name)}); use a white image processed like the "
                             "input")
        if white.cfa:
            return balance.gains_from_mosaic(data[white.pages[0]], white.cfa)
        return balance.gains_from_rgb(np.stack([data[k] for k in white.pages], axis=-1))
    except ValueError as err:
        raise InputError(f"--wb-from {path}: {err}") from err


def _camera_matrix(choice: str, meta: dict, path: str) -> np.ndarray | None:
    if choice == "none":
        return None
    if choice != "as-shot":
        raise ConfigError(f"--matrix {choice}: choose as-shot or none")
    xyz_to_camera = (meta.get("colour") or {}).get("xyz_to_camera")
    if xyz_to_camera is None:
        raise InputError(f"{path}: no camera colour matrix in the metadata; use --matrix none "
                         "to take camera RGB as linear sRGB")
    try:
        return colour_matrix.camera_to_srgb(xyz_to_camera)
    except ValueError as err:
        raise InputError(f"{path}: {err}") from err


def _preview_bytes(encoded: np.ndarray, space: str, description: dict,
                   turned: int) -> bytes:
    scale = max(encoded.shape[:2]) / PREVIEW_SIDE
    small = encoded
    if scale > 1:
        size = (round(encoded.shape[1] / scale), round(encoded.shape[0] / scale))
        small = cv2.resize(encoded.astype(np.float32), size, interpolation=cv2.INTER_AREA)
    return export.image_bytes(small, "png", space=space, exif=None, description=description,
                              orientation=turned)


def _write_together(output, body, linear, scene, meta, record, preview, preview_body,
                    protect) -> None:
    """All outputs land together or none (the stage edge also checks they are distinct)."""
    with outputs_together():
        write_bytes(output, body, protect=protect)
        if preview:
            write_bytes(preview, preview_body, protect=protect)
        if linear:
            linear_meta = tiffio.derived_meta(
                meta, record, views=["R", "G", "B", "rebuilt"][:scene.shape[-1]], cfa=None,
                view_colours=None, black_level=None, white_level=None, colour=None,
                active_area=[0, 0, *scene.shape[:2]], masked_areas=[], origin=None,
                colour_space="linear sRGB (D65), scene-referred, camera units")
            tiffio.write_image(linear, np.moveaxis(scene, -1, 0), linear_meta, protect=protect)
