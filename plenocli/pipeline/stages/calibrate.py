"""Stage ``calibrate``: a white (or scene) image -> lens grid YAML (+ Raytrix XML, preview)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from plenocli import calibration
from plenocli.errors import CalibrationError, InputError, not_a_file
from plenocli.io import gridfile, raytrix, tiffio
from plenocli.io.plainimage import is_tiff, read_plain_image
from plenocli.io.preview import write_grid_overlay
from plenocli.model.cfa import phase_balance, shift_pattern
from plenocli.model.provenance import stage_record
from plenocli.progress import log, shown, significant


def load_image(path: str) -> tuple[np.ndarray, str | None, float, tuple[int, int], dict]:
    """The 2-D image to calibrate on: a plenocli frames TIFF (views summed, its CFA and black
    level used) or a plain TIFF/PNG/BMP (colour channels summed). Returns image, cfa, black
    level (DN, summed over views), the full-sensor (row, col) of the image's pixel (0, 0) and
    the metadata."""
    p = Path(path)
    if not p.is_file():
        raise not_a_file(p)
    if is_tiff(p):   # by its first bytes, not its name (as decode)
        views, meta = tiffio.read_image(p)
    else:
        data = read_plain_image(p, tiffio.MAX_PAGE_PIXELS)
        views = np.moveaxis(data[..., :3], -1, 0) if data.ndim == 3 else data[np.newaxis]
        meta = {}
    if views.ndim != 3 or views.shape[1] == 0 or views.shape[2] == 0:
        raise InputError(f"{p}: image of shape {views.shape}; expected (rows, cols) or views")
    image = views[0].astype(np.float32)
    for view in views[1:]:   # one plane at a time: no float copy of every view
        image += view
    cfa = meta.get("cfa")
    top, left = 0, 0
    area = meta.get("active_area")
    if area and meta.get("camera") in ("canon-dp", "dng"):
        top, left, bottom, right = area
        image = image[top:bottom, left:right]
    cfa = shift_pattern(cfa, top, left)
    blacks = meta.get("black_level") or []
    black = float(sum(np.mean(b) for b in blacks)) if blacks else 0.0
    o_row, o_col = (int(v) for v in (meta.get("origin") or (0, 0)))
    return image, cfa, black, (o_row + top, o_col + left), meta


# A mono sensor's pixel phases hold their 2 x 2 block's light within 0.4 % on every real
# lenslet image in ../shared/realdata; a Bayer white's hold 0.7-1.2. The calibration of a
# mosaic taken for mono is off by a fraction of a pixel (0.28 px RMS at 30 %).
MOSAIC_LIMIT = 0.02
# A colour filter puts its phase off the same way in (nearly) every block: 0.89-1.0 of the
# bright blocks on Bayer whites; the rims of a mono white of an even whole-pixel pitch along
# the pixel axes (every lens at one pixel phase) put a phase off by up to 17 % too, but half
# the blocks either way (0.50-0.63): its sign follows the side of the lens, not the pixel grid
MOSAIC_ALIKE = 0.75


def _refuse_hidden_mosaic(path: str, image: np.ndarray) -> None:
    """An image without a CFA pattern whose pixel phases differ like a Bayer mosaic's is
    refused: its micro-images would be measured through the colour filters. Phases alike but
    off 1 together (a 1-bit image's medians) are no mosaic, nor is an imbalance whose sign
    turns from block to block (the micro-images' own rims at the 2-px scale)."""
    gains, alike = phase_balance(image)
    gains = gains / gains.mean()   # phases that differ from each other: alike is no mosaic
    worst = np.unravel_index(np.argmax(np.abs(gains - 1.0)), gains.shape)
    if abs(gains[worst] - 1.0) > MOSAIC_LIMIT and alike[worst] >= MOSAIC_ALIKE:
        shares = ", ".join(f"{g:.3f}" for g in gains.ravel())
        raise InputError(f"{path} looks like a 2 x 2 Bayer mosaic but names no CFA pattern: its "
                         f"four pixel phases hold {shares} of their blocks' light (a mono "
                         "sensor's hold 1), the same way in "
                         f"{100 * alike[worst]:.0f} % of the blocks; decode it with --cfa "
                         "PATTERN (and --black) and calibrate the decoded frames")


def _refuse_unusable(path: str, image: np.ndarray, cfa: str | None) -> None:
    """An image too small to hold a lattice (said first), with unknown pixels, or a mosaic
    that names no CFA pattern."""
    try:
        calibration.check_size(image.shape)
    except CalibrationError as err:
        raise CalibrationError(f"{path}: {err}") from err
    _refuse_unknown_pixels(path, image)
    if cfa is None:
        _refuse_hidden_mosaic(path, image)


def _refuse_unknown_pixels(path: str, image: np.ndarray) -> None:
    """The lattice search reads every pixel (a spectrum, the micro-images' borders): NaN pixels
    (clipped by bias, below flat's --floor) cannot be measured around, so they are refused with
    the file that has none (inf too: no reader makes it)."""
    unknown = int(np.count_nonzero(~np.isfinite(image)))
    if unknown:
        raise InputError(f"{path}: {unknown} pixel(s) are unknown (NaN: clipped, or below "
                         "flat's --floor); calibrate reads every pixel: give the decode output "
                         "of this capture (its black level is subtracted here)")


def _is_xml(path: str) -> bool:
    with open(path, "rb") as f:
        return Path(path).suffix.lower() == ".xml" or f.read(64).lstrip().startswith(b"<")


def run(input: str, output: str, *, lattice: str = "auto", pitch: float | None = None,
        start: str | None = None, xml: str | None = None, compare: str | None = None,
        preview: str | None = None) -> dict:
    """Calibrate the lens grid of ``input``; write ``output`` (YAML), optionally ``xml``
    (RayCalibData) and ``preview`` (PNG with the centres drawn). ``start`` (YAML or XML) is a
    grid to refine instead of searching. Returns the report dict."""
    if xml and lattice == "square":
        raise InputError("--xml writes a Raytrix (hexagonal) calibration; "
                         "use --lattice hex or auto")
    image, cfa, black, origin, meta = load_image(input)
    _refuse_unusable(input, image, cfa)
    other = gridfile.read_grid(compare, image_shape=image.shape) if compare else None
    first = gridfile.read_grid(start, image_shape=image.shape) if start else None
    try:
        grid, report = calibration.calibrate(image, lattice=lattice, cfa=cfa, black_level=black,
                                             pitch_hint=pitch, start=first)
    except ValueError as err:
        raise InputError(f"{input}: {err}") from err
    grid = replace(grid, sensor_origin=origin)  # where the white lay: refocus frames it there
    if xml and grid.lattice != "hex":
        raise CalibrationError(f"{input}: the array is square; --xml writes hexagonal Raytrix "
                               "calibrations only, drop --xml")
    extra: dict = {"residuals": report.to_dict()}
    template = meta.get("raytrix_calib")
    if first is not None:
        extra["moved_from_start"] = {"grid": str(start),
                                     **calibration.moved_from_start(grid, first, report)}
        if _is_xml(start):   # what the image cannot measure is kept from the camera's file
            template = raytrix.read_calib(start)
            extra["moved_from_start"]["kept"] = (
                "lens_border, tcp, distortion, lens types' depth ranges and k_matrix of the "
                "start file (in --xml)" if xml else "nothing (no --xml written)")
            extra["moved_from_start"]["lens_types"] = (report.lens_types or {}).get(
                "source") or (report.lens_types or {}).get("start_types") or "none in the file"
    if other is not None:
        extra["compare"] = {"grid": str(compare),
                            **calibration.compare_grids(grid, other, image.shape)}
    params = dict(lattice=lattice, pitch=pitch, start=start, xml=xml, preview=preview,
                  compare=compare)
    record = stage_record("calibrate", params, {"input": input, "compare": compare,
                                                "start": start})
    protect = tuple(p for p in (input, compare, start) if p)
    gridfile.write_grid(output, grid, record, extra=extra, protect=protect)
    if xml:
        raytrix.write_calib(xml, raytrix.calib_from_grid(grid, template=template),
                            protect=protect)
    if preview:
        flat = calibration.flatten(image, cfa=cfa, scale_px=max(grid.pitch_px, 8.0))
        write_grid_overlay(preview, flat, grid.lens_centres()[1], grid.pitch_px,
                           protect=protect)
    fit = report.fit
    centres = (f"residual RMS {fit.residual_rms_px:.4f} px" if fit.centres_refined else
               "centres from the start's lattice on the lens centre the match judge measured"
               if report.lattice_from == calibration.KEPT else
               f"a scene: centres from the lattice of {report.lattice_from}"
               f"{_pitch_error(fit.pitch_se_px)}; "
               f"the content moves the micro-images' own centres by {fit.residual_rms_px:.2f} "
               "px RMS")
    log.info("calibrate: %s -> %s: %s pitch %.4f px, angle %.4f deg, offset (%.3f, %.3f); "
             "%d lenses, %s, contrast %.3f", shown(input), shown(output), grid.lattice,
             grid.pitch_px, np.degrees(grid.angle_rad), *grid.offset_xy, fit.lenses_total,
             centres, report.verdict.contrast)
    if report.decision is not None:
        log.info("calibrate: lattice decided by the %s", report.decision.describe())
    if first is not None:
        m = extra["moved_from_start"]
        log.info("moved from the start grid: offset (%.3f, %.3f) px (measured), pitch %+.4f "
                 "px, rotation %+.4f deg (%s)", *m["offset"]["moved_px"], m["pitch"]["moved_px"],
                 m["rotation"]["moved_deg"], m["pitch"]["source"])
    for key in ("moved_from_start", "compare"):
        if key in extra:
            c = extra[key]
            log.info("%s %s: RMS %.4f px, max %.4f px over %d lenses, mean shift (%.3f, %.3f) px",
                     key.replace("_", " "), c["grid"], c["rms_px"], c["max_px"], c["lenses"],
                     *c["mean_shift_xy"])
    return extra


def _pitch_error(se_px: float) -> str:
    """The pitch's standard error as measured (two significant digits), or nothing when
    there is none to show (0: the fit had no residual to tell it)."""
    return f" (pitch +-{significant(se_px)} px)" if 0 < se_px < np.inf else ""
