"""Stage ``calibrate``: a white (or scene) image -> lens grid YAML (+ Raytrix XML, preview)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from plenocli import hexgrid
from plenocli.errors import InputError
from plenocli.io import gridfile, raytrix, tiffio
from plenocli.model.cfa import shift_pattern
from plenocli.model.provenance import stage_record
from plenocli.progress import log, shown


def load_image(path: str) -> tuple[np.ndarray, str | None, float, dict]:
    """The 2-D image to calibrate on: a plenocli frames TIFF (views summed, its CFA and black
    level used) or a plain TIFF/PNG/BMP (colour channels summed). Returns image, cfa, black
    level (DN, summed over views) and the metadata."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    if p.suffix.lower() in (".tif", ".tiff"):
        views, meta = tiffio.read_image(p)
    else:
        import cv2

        data = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        if data is None:
            raise InputError(f"{p}: unreadable image; pass a TIFF, PNG or BMP white image")
        views = np.moveaxis(data[..., :3], -1, 0) if data.ndim == 3 else data[np.newaxis]
        meta = {}
    if views.ndim != 3 or views.shape[1] == 0 or views.shape[2] == 0:
        raise InputError(f"{p}: image of shape {views.shape}; expected (rows, cols) or views")
    image = views.astype(np.float32).sum(axis=0)
    cfa = meta.get("cfa")
    top, left = 0, 0
    area = meta.get("active_area")
    if area and meta.get("camera") in ("canon-dp", "dng"):
        top, left, bottom, right = area
        image = image[top:bottom, left:right]
    cfa = shift_pattern(cfa, top, left)
    blacks = meta.get("black_level") or []
    black = float(sum(np.mean(b) for b in blacks)) if blacks else 0.0
    return image, cfa, black, meta


def run(input: str, output: str, *, lattice: str = "hex", xml: str | None = None,
        preview: str | None = None, compare: str | None = None) -> dict:
    """Calibrate the lens grid of ``input``; write ``output`` (YAML), optionally ``xml``
    (RayCalibData) and ``preview`` (PNG with the centres drawn). Returns the report dict."""
    image, cfa, black, meta = load_image(input)
    other = gridfile.read_grid(compare, image_shape=image.shape) if compare else None
    grid, report = hexgrid.calibrate(image, lattice=lattice, cfa=cfa, black_level=black)
    extra: dict = {"residuals": report.to_dict()}
    if other is not None:
        extra["compare"] = {"grid": str(compare),
                            **hexgrid.compare_grids(grid, other, image.shape)}
    params = dict(lattice=lattice, xml=xml, preview=preview, compare=compare)
    record = stage_record("calibrate", params, {"input": input, "compare": compare})
    protect = tuple(p for p in (input, compare) if p)
    gridfile.write_grid(output, grid, record, extra=extra, protect=protect)
    if xml:
        template = meta.get("raytrix_calib")
        if lattice != "hex":
            raise InputError("--xml writes a Raytrix (hexagonal) calibration; use --lattice hex")
        raytrix.write_calib(xml, raytrix.calib_from_grid(grid, template=template),
                            protect=protect)
    if preview:
        write_preview(preview, image, grid, cfa=cfa, protect=protect)
    log.info("calibrate: %s -> %s: %s pitch %.4f px, angle %.4f deg, offset (%.3f, %.3f); "
             "%d lenses, residual RMS %.4f px, max %.4f px", shown(input), shown(output), lattice,
             grid.pitch_px, np.degrees(grid.angle_rad), *grid.offset_xy, report.lenses_total,
             report.residual_rms_px, report.residual_max_px)
    if other is not None:
        c = extra["compare"]
        log.info("compare with %s: RMS %.4f px, max %.4f px over %d lenses, mean shift "
                 "(%.3f, %.3f) px", compare, c["rms_px"], c["max_px"], c["lenses"],
                 *c["mean_shift_xy"])
    return extra


def write_preview(path: str, image: np.ndarray, grid, *, cfa: str | None,
                  protect: tuple = ()) -> None:
    """The image (display-stretched) with every lens centre drawn as a red dot."""
    import cv2

    from plenocli.io.atomic import atomic_path
    from plenocli.io.preview import to_display

    flat = hexgrid.flatten(image, cfa=cfa, scale_px=max(grid.pitch_px, 8.0))
    grey = to_display(flat, gamma=1.0)
    scale = min(1.0, 2048 / max(grey.shape))
    if scale < 1:
        grey = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    bgr = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
    _, centres = grid.lens_centres()
    shift = 4  # sub-pixel drawing
    for x, y in centres * scale:
        cv2.circle(bgr, (int(round(x * (1 << shift))), int(round(y * (1 << shift)))),
                   max(1, int(grid.pitch_px * scale / 8)) << shift, (0, 0, 255), -1,
                   cv2.LINE_AA, shift)
    ok, buf = cv2.imencode(".png", bgr)
    if not ok:
        raise OSError(f"could not encode PNG for {path}")
    with atomic_path(path, protect=protect) as tmp:
        tmp.write_bytes(buf.tobytes())
