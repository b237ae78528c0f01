"""Stage ``decode``: a raw capture or sensor image -> frames TIFF (margins kept)."""

from __future__ import annotations

from plenocli.errors import OptionError
from plenocli.io import raw, tiffio
from plenocli.io.framing import active_area
from plenocli.io.preview import colour_pages, write_png
from plenocli.model.provenance import stage_record
from plenocli.progress import log, shown


def run(input: str, output: str, *, camera: str = "auto", frames: str | None = None,
        black: float | None = None, white: float | None = None, cfa: str | None = None,
        calib: str | None = None, preview: str | None = None) -> None:
    """Decode ``input`` into ``output`` (one page per frame, uint16 for raws)."""
    _check_overrides(input, camera, black=black, white=white, cfa=cfa)
    names = [n.strip() for n in frames.split(",")] if frames else None
    data, meta = raw.decode(input, camera=camera, frame_names=names, black=black, white=white,
                            cfa=cfa, calib=calib)
    if calib is not None:
        _check_calib(calib, data, meta)
    params = dict(camera=camera, frames=frames, black=black, white=white, cfa=cfa, calib=calib)
    record = stage_record("decode", params, {"input": input, "calib": calib})
    tiffio.write_image(output, data, tiffio.derived_meta(meta, record), protect=(input,))
    log.info("decode: %s -> %s (%s, %d frame(s) %s of %d x %d, CFA %s)",
             shown(input), shown(output), meta["camera"], data.shape[0],
             ",".join(meta["views"]), data.shape[2], data.shape[1], meta.get("cfa") or "none")
    if preview:
        area = active_area(meta, data.shape[1:])
        rgb = colour_pages(area.crop(data), meta.get("views"))  # an RGB image: its colours
        write_png(preview, (area.crop(data[0]) if rgb is None else rgb).astype("float32"),
                  cfa=area.cfa, protect=(input,), colour=meta.get("colour"))



def _check_overrides(path: str, camera: str, **given) -> None:
    """--black, --white and --cfa are for plain images: a raw (DNG, CR2) records its own per
    frame; one value over them would silently replace what the camera wrote (a wrong black level
    for every frame, R and B swapped by a wrong pattern)."""
    options = [f"--{name}" for name, value in given.items() if value is not None]
    if not options:
        return
    kind = raw.sniff(path) if camera == "auto" else camera
    if kind in ("canon-dp", "dng"):
        raise OptionError(f"{' and '.join(options)}: {path} is a raw ({kind}) that records its "
                          "own black and white levels and CFA pattern; leave "
                          f"{' and '.join(options)} out (they are for plain TIFF/PNG/BMP images)")


def _check_calib(calib: str, data, meta: dict) -> None:
    """The RayCalibData stored with the frames must describe them, as refocus --grid checks it:
    another camera's XML would misinform every reader of the metadata."""
    from plenocli.depth.lenslet import sensor_grey
    from plenocli.io.framing import frame_grid
    from plenocli.pipeline.fits import check_fits

    framing = frame_grid(calib, meta, data.shape[1:])
    check_fits(sensor_grey(framing.crop(data[:1]).astype("float32"), mosaic=bool(framing.cfa)),
               framing.grid, calib, stored_only=True)
