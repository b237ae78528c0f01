"""Decoding sensor captures into frames (views, rows, cols) with the metadata later stages need.

Supported inputs:

- Canon dual-pixel raw (5D Mark IV DPRAW, ``.CR2``): LibRaw (rawpy) reads frame 0 (A+B sum, "S")
  and frame 1 (A). Frame selection is verified: the two frames must differ.
- DNG with one or more raw IFDs (top level or SubIFDs): read IFD by IFD with tifffile, because
  LibRaw returns only one of them whatever ``shot_select`` says (checked by the test suite).
- Plain sensor images (TIFF, PNG, BMP; 8 or 16 bit; mono, Bayer or RGB) with levels given by the
  caller.

Frames keep their over-scan (masked) areas; ``active_area`` and ``masked_areas`` say where they are.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np
import tifffile

from plenocli.errors import InputError, OptionError, library_words, not_a_file, numbers
from plenocli.io import dngtags, rawmeta, tiffio
from plenocli.io.plainimage import TIFF_MAGIC, is_tiff, read_plain_levels
from plenocli.io.tiffsegments import TRANSPARENCY_MASK
from plenocli.model import orientation as turns
from plenocli.model.cfa import check_pattern, is_bayer, shift_pattern
from plenocli.progress import log

CAMERAS = ("auto", "canon-dp", "dng", "raytrix", "image")
PHOTOMETRIC_CFA = 32803
PHOTOMETRIC_LINEAR_RAW = 34892

# Canon 5D Mark IV optical-black geometry (DESIGN.md): the first columns and rows of the raw are
# not usable, even inside the margins; keep off them.
CANON_OB_FIRST = 2


def sniff(path: str | os.PathLike) -> str:
    """Guess the kind of a capture from its first bytes: canon-dp, dng, image or unknown."""
    p = Path(path)
    if not p.is_file():
        raise not_a_file(p)
    with open(p, "rb") as fh:
        head = fh.read(16)
    if head[:4] in TIFF_MAGIC:
        if head[8:10] == b"CR":
            return "canon-dp"
        try:
            with tiffio.open_tiff(p) as tif:
                if 50706 in tif.pages[0].tags or _declares_raw(tif.pages[0]):
                    return "dng"
        except tiffio.READ_ERRORS as err:
            raise InputError(f"{p}: a TIFF header but an unreadable file ({library_words(err)}); "
                             "is it truncated?") from err
        return "image"
    if head[:8] == b"\x89PNG\r\n\x1a\n" or head[:2] == b"BM":
        return "image"
    return "unknown"


def _declares_raw(page) -> bool:
    """A TIFF whose main image declares raw samples (Photometric CFA, as TIFF/EP writes, or
    LinearRaw) without DNGVersion: its CFARepeatPatternDim, CFAPattern and level tags are the
    ones DNG took from TIFF/EP, so it is read by the DNG rules (as LibRaw reads it); read as a
    grey image its mosaic and black level would be lost."""
    return int(page.photometric) in (PHOTOMETRIC_CFA, PHOTOMETRIC_LINEAR_RAW)


def decode(path: str | os.PathLike, *, camera: str = "auto", frame_names: list[str] | None = None,
           black: float | None = None, white: float | None = None,
           cfa: str | None = None, calib: str | os.PathLike | None = None
           ) -> tuple[np.ndarray, dict]:
    """Decode a capture.

    ``camera="raytrix"``: a sensor image (TIFF/PNG/BMP) whose RayCalibData XML ``calib`` is
    parsed into ``meta["raytrix_calib"]`` (see ``plenocli.io.raytrix``).

    Returns
    -------
    frames : ndarray, (frames, rows, cols)
        The raw data as stored (uint16 for raws), margins included.
    meta : dict
        ``views``, ``cfa``, ``origin``, ``black_level`` (per view, per 2 x 2 position, DN),
        ``white_level`` (per view, DN), ``active_area``, ``masked_areas``, ``camera``; for a
        raw, ``orientation`` (1-8, how the stored frames stand upright; they stay as stored).
    """
    if camera not in CAMERAS:
        raise InputError(f"unknown camera {camera!r}; choose one of {', '.join(CAMERAS)}")
    kind = sniff(path) if camera == "auto" else _check_camera(path, camera)
    if kind == "unknown":
        raise InputError(f"{path}: not a raw capture or sensor image plenocli can read "
                         "(expected CR2, DNG, TIFF, PNG or BMP)")
    if kind == "canon-dp":
        frames, meta = _decode_canon(path, require_dual=camera == "canon-dp")
    elif kind == "dng":
        frames, meta = _decode_dng(path)
    else:
        frames, meta = _decode_image(path, cfa=cfa, named=len(frame_names or ()))
    if kind == "raytrix":
        from plenocli.io import raytrix

        if calib is None:
            raise InputError(f"{path}: --camera raytrix needs the RayCalibData XML (--calib XML)")
        meta["raytrix_calib"] = raytrix.read_calib(calib)
    elif calib is not None:
        raise OptionError(f"--calib goes with --camera raytrix and {path} is read as "
                          f"{KIND_NAMES[kind]}: give --camera raytrix for a Raytrix sensor "
                          "image, or leave --calib out")
    if frame_names and _names_its_frames(kind, meta["views"]):
        raise OptionError(f"--frames: {path} is {KIND_NAMES[kind]} that names its own frames "
                          f"({','.join(meta['views'])}); other names would relabel which frame "
                          "is which: leave --frames out")
    tops = meta.pop("sample_top", None)  # a plain TIFF's: not recorded, its white says it
    _apply_user_values(path, frames, meta, frame_names=frame_names, cfa=cfa, black=black,
                       white=white, tops=tops)
    _check_levels(path, meta["black_level"], meta["white_level"], frames.dtype, tops=tops,
                  given=tuple(name for name, value in (("--black", black), ("--white", white))
                              if value is not None))
    _check_some_light(path, frames, meta, given=tuple(("--black",) if black is not None else ()))
    tiffio.check_no_infinity(path, frames, meta.get("views"))
    tiffio.check_geometry(path, {k: meta.get(k) for k in ("active_area", "masked_areas")},
                          frames.shape)
    meta["camera"] = kind
    warn = functools.partial(_warn, path)
    if kind in ("canon-dp", "dng"):
        meta["exif"] = rawmeta.clean_exif(rawmeta.camera_exif(path), warn)
    if meta.get("colour") is not None:
        meta["colour"] = rawmeta.clean_colour(meta["colour"], warn)
    return frames, meta


def _names_its_frames(kind: str, names: list[str]) -> bool:
    """A CR2's frames are S (A+B) and A by the format; a DNG's are named by its IFDs'
    descriptions when they hold names (else frame0, frame1, ...: --frames may name them)."""
    return kind == "canon-dp" or (
        kind == "dng" and names != [f"frame{k}" for k in range(len(names))])


KIND_NAMES = {"canon-dp": "a Canon CR2 raw", "dng": "a DNG", "raytrix": "a Raytrix sensor image",
              "image": "a plain image (TIFF, PNG or BMP)"}


def _check_camera(path, camera: str) -> str:
    """``camera`` when the file's first bytes agree (a Raytrix image is a plain image); else an
    InputError that says what the file is, not that it is damaged."""
    found = sniff(path)
    if found == camera or (camera == "raytrix" and found == "image"):
        return camera
    if found == "unknown":
        return found   # refused below as no raw or image plenocli reads
    raise InputError(f"{path} is {KIND_NAMES[found]}, not {KIND_NAMES[camera]}: use --camera "
                     f"{found} or auto")


def _warn(path, message: str) -> None:
    log.warning("%s: %s", path, message)


def _apply_user_values(path, frames: np.ndarray, meta: dict, *, frame_names, cfa, black,
                       white, tops=None) -> None:
    """Frame names, CFA and levels given by the user (they win over the file's), and the
    defaults of a file that has none: white the largest level its samples can hold (``tops``,
    per frame, from a TIFF's BitsPerSample or MaxSampleValue; else the sample type's)."""
    if frame_names:
        if len(set(frame_names)) != len(frame_names) or not all(frame_names):
            raise InputError(f"frame names {','.join(frame_names)!r} must be distinct and "
                             "non-empty (e.g. --frames S,A)")
        if len(frame_names) != frames.shape[0]:
            raise InputError(f"{path}: {len(frame_names)} frame names given "
                             f"({','.join(frame_names)}) for {frames.shape[0]} frames")
        meta["views"] = list(frame_names)
    if cfa:
        meta["cfa"] = _check_cfa(cfa)
    n = frames.shape[0]
    tiffio.check_real_dtype(path, frames.dtype)
    if black is not None:
        meta["black_level"] = [[float(black)] * 4 for _ in range(n)]
    if white is not None:
        meta["white_level"] = [float(white)] * n
    if meta.get("black_level") is None:
        meta["black_level"] = [[0.0] * 4 for _ in range(n)]
    if meta.get("white_level") is None and tops is not None:
        meta["white_level"] = [top for top, _ in tops]
    if meta.get("white_level") is None:
        meta["white_level"] = [float(np.iinfo(frames.dtype).max)
                               if frames.dtype.kind in "ui" else float("inf")] * n


def _check_levels(path, blacks: list, whites: list, dtype, *, given: tuple = (),
                  tops: list | None = None) -> None:
    """Black levels finite and >= 0, white levels above them (+inf: a float image's) and, for
    integer samples, within their range (``tops``: per frame, what a TIFF's header says they
    hold; a level they cannot reach makes every clipped pixel pass as light; the next stage
    refuses such a file). ``given``: the options the user gave, named in the message (the
    file's own levels otherwise)."""
    whole = float(np.iinfo(dtype).max) if np.dtype(dtype).kind in "ui" else np.inf
    tops = tops or [(whole, f"{np.dtype(dtype)} samples")] * len(whites)
    source = f" ({', '.join(given)})" if given else " (the file's)"
    for black, white, (top, label) in zip(blacks, whites, tops, strict=True):
        if white != white:  # NaN
            raise InputError(f"{path}: no white level for these floating-point samples; give it "
                             "with --white")
        low = np.asarray(black, np.float64)
        if not (np.all(np.isfinite(low)) and np.all(low >= 0)):
            raise InputError(f"{path}: black level {black} must be finite and >= 0 DN "
                             "(--black)")
        if white > top or low.max() >= top:  # a black at the top leaves no light above it
            level, value, where = (("white", white, "beyond") if white > top else
                                   ("black", low.max(), "not below"))
            raise InputError(f"{path}: {level} level {numbers([value])}{source} is {where} what "
                             f"its {label} can reach ({numbers([top])}); give a level "
                             "within the samples' range")
        if not white > low.max():  # also refuses NaN
            raise InputError(f"{path}: white level {numbers([white])} must be above the black "
                             f"level {numbers([low.max()])} DN{source}")


def _check_some_light(path, frames: np.ndarray, meta: dict, *, given: tuple = ()) -> None:
    """Some sample of each frame at or above its black level: light only adds to the black, and
    even a dark frame's noise puts about half its pixels above it, so a level above every
    sample is not this image's (every pixel would read as less than no light)."""
    source = " (--black)" if given else " (the file's)"
    for k, (frame, black) in enumerate(zip(frames, meta["black_level"], strict=True)):
        top = np.fmax.reduce(frame, axis=None)  # NaN skipped; NaN only when every sample is
        low = float(np.min(black))
        if top == top and top < low:  # an all-NaN frame is decode's 'no valid pixel' error
            name = (meta.get("views") or [f"frame{k}"] * len(frames))[k]
            raise InputError(f"{path}: black level {low:g} DN{source} is above every sample of "
                             f"frame {name} (the largest is {float(top):g}), so it would hold "
                             "less than no light; give the black level the image has")


def _check_cfa(cfa: str) -> str:
    try:
        return check_pattern(cfa)
    except ValueError as err:
        raise InputError(f"--cfa: {err}") from err


def _decode_canon(path, *, require_dual: bool) -> tuple[np.ndarray, dict]:
    import rawpy  # imported here: only raw files need LibRaw

    frames, blacks, meta = [], [], {}
    for shot in (0, 1):
        try:
            with rawpy.imread(str(path), shot_select=shot) as raw:
                frames.append(raw.raw_image.copy())  # only valid while the file is open
                blacks.append(_black_by_position(raw))
                if shot == 0:
                    meta = _rawpy_meta(raw, path)
        except (rawpy.LibRawError, OSError, ValueError) as err:
            if shot == 0:
                raise InputError(f"{path}: LibRaw cannot read this raw ({library_words(err)}); "
                                 "the file may be truncated or not a raw") from err
            break
    dual = len(frames) == 2 and not np.array_equal(frames[0], frames[1])
    if not dual:
        if require_dual:
            raise InputError(f"{path}: LibRaw returned the same frame for frame 0 and frame 1; "
                             "this is not a dual-pixel (DPRAW) file: use --camera auto")
        frames = frames[:1]
    meta["black_level"] = blacks[: len(frames)]
    meta["white_level"] = meta["white_level"] * len(frames)
    meta["views"] = ["S", "A"] if dual else ["S"]
    return np.stack(frames), meta


def _black_by_position(raw) -> list[float]:
    """LibRaw's black level for each 2 x 2 position (it is indexed by colour, not position)."""
    per_channel = raw.black_level_per_channel
    pattern = raw.raw_pattern
    return [float(per_channel[int(pattern[k // 2][k % 2])]) for k in range(4)]


def _rawpy_meta(raw, path) -> dict:
    sizes = raw.sizes
    desc = raw.color_desc.decode("ascii")
    pattern = raw.raw_pattern
    cfa = "".join(desc[int(pattern[k // 2][k % 2])] for k in range(4))
    top, left = int(sizes.top_margin), int(sizes.left_margin)
    bottom, right = top + int(sizes.height), left + int(sizes.width)
    masked = []
    if left - CANON_OB_FIRST >= 8:
        masked.append([top, CANON_OB_FIRST, bottom, left])
    if top - CANON_OB_FIRST >= 8:
        masked.append([CANON_OB_FIRST, left, top, right])
    return {
        "cfa": cfa if is_bayer(cfa) else None,
        "origin": [0, 0],
        "white_level": [float(raw.white_level)],
        "active_area": [top, left, bottom, right],
        "masked_areas": masked,
        "colour": rawmeta.rawpy_colour(raw, desc),
        "orientation": _libraw_orientation(raw, path),
    }


def _libraw_orientation(raw, path) -> int:
    """The raw's Orientation (1-8) from LibRaw's ``sizes.flip``."""
    flip = int(raw.sizes.flip)
    if flip not in turns.FROM_LIBRAW_FLIP:
        raise InputError(f"{path}: LibRaw reads an image flip {flip} (the raw's Orientation, tag "
                         f"{turns.TAG}), not one of 0-7; the raw is damaged")
    return turns.FROM_LIBRAW_FLIP[flip]


def _raw_pages(tif: tifffile.TiffFile):
    for page in tif.pages:
        yield page
        if page.subifds:
            yield from page.pages


def _tag(page, code, default=None):
    tag = page.tags.get(code)
    return default if tag is None else tag.value


def _decode_dng(path) -> tuple[np.ndarray, dict]:
    try:
        with tiffio.open_tiff(path) as tif:
            raws = dngtags.raw_pages(path, list(_raw_pages(tif)))
            frames, blacks, whites, names = [], [], [], []
            for k, page in enumerate(raws):
                data, black, white = _dng_frame(path, k, page)
                frames.append(data)
                blacks.append(black)
                whites.append(white)
                desc = page.description.strip() if page.description else ""
                names.append(desc if desc and len(desc) <= 16 and " " not in desc else f"frame{k}")
            shape = frames[0].shape
            if any(f.shape != shape for f in frames):
                raise InputError(f"{path}: raw IFDs of different sizes "
                                 f"{sorted({f.shape for f in frames})}; cannot stack them")
            layouts = [_dng_layout(path, k, page, shape) for k, page in enumerate(raws)]
            if any(layout != layouts[0] for layout in layouts):
                k = next(k for k, layout in enumerate(layouts) if layout != layouts[0])
                raise InputError(f"{path}: raw IFD {k} has another CFA pattern or active/masked "
                                 f"area than raw IFD 0 ({layouts[k]} vs {layouts[0]}); plenocli "
                                 "stacks frames of one sensor layout")
            cfa, (active, masked) = layouts[0]
            colour = rawmeta.dng_colour(raws[0], tif.pages[0])
            turned = dngtags.orientation(path, tif.pages[0], raws[0])
    except tiffio.READ_ERRORS as err:
        raise InputError(f"{path}: unreadable DNG ({library_words(err)}); the file may be "
                         "truncated") from err
    if len(set(names)) != len(names):
        names = [f"frame{k}" for k in range(len(names))]
    return np.stack(frames), {
        "cfa": cfa, "origin": [0, 0], "black_level": blacks, "white_level": whites,
        "active_area": active, "masked_areas": masked, "views": names, "colour": colour,
        "orientation": turned,
    }


def _dng_layout(path, k: int, page, shape: tuple[int, int]) -> tuple:
    """(CFA pattern at the stored image's pixel (0, 0), (active area, masked areas)) of a raw
    IFD. DNG gives CFAPattern at the ActiveArea's top-left, which need not be the stored
    image's (0, 0): an odd top or left swaps the pattern's rows or columns."""
    active, masked = dngtags.areas(path, k, page, shape)
    cfa = (shift_pattern(dngtags.cfa_pattern(path, k, page), -active[0], -active[1])
           if page.photometric == PHOTOMETRIC_CFA else None)
    return cfa, (active, masked)


def _dng_frame(path, k: int, page) -> tuple[np.ndarray, list[float], float]:
    """One raw IFD: its header checked before any pixel is read (io/dngtags), its samples
    decoded and linearised, its black levels per 2 x 2 position and its white level."""
    tiffio.check_page(Path(path), page)  # SubIFDs too, before any pixel is read
    if len(page.shape) != 2:  # from the header: refused before decoding
        raise InputError(f"{path}: raw image {k} holds {int(page.samplesperpixel)} samples "
                         "per pixel (a "
                         "demosaiced LinearRaw); plenocli reads raws of one sample per pixel "
                         "(CFA or mono): give the capture as the camera recorded it, or its "
                         "colours as a plain RGB TIFF")
    dngtags.check_layout(path, k, page, dng=dngtags.DNG_VERSION in page.parent.pages[0].tags)
    top, left = dngtags.areas(path, k, page, page.shape)[0][:2]
    black = dngtags.black_levels(path, k, page, (top, left))
    tiffio.check_segments(path, page)
    try:
        data = page.asarray()
    except tiffio.READ_ERRORS as err:  # the codecs' own errors too
        raise tiffio.read_error(path, err, f"{path}: raw IFD {k} is damaged "
                                f"({library_words(err)}); copy or export the DNG again") from err
    dngtags.check_samples(path, k, data)
    data, mapped = dngtags.linearized(path, k, page, data)
    return data, black, dngtags.white_level(path, k, page, data.dtype, mapped)


def _frame_pages(p: Path, tif, named: int = 0) -> tuple[np.ndarray, bool, list | None]:
    """The one full-resolution page of a TIFF (reduced-resolution previews and transparency
    masks beside it, NewSubfileType bits 0 and 2, are not the image), or (pages, rows, cols)
    when --frames names each of its grey pages (two images of a dual-pixel pair); and the
    largest level each frame's samples can hold (``tiffio.sample_tops``). Several pages
    otherwise are refused: keeping the first would drop the others silently, and a plain TIFF
    does not say which page is which frame."""
    images = [page for page in tif.pages if not page.subfiletype & TRANSPARENCY_MASK]
    pages = [page for page in images if not page.subfiletype & 1] or images
    if not pages:
        raise InputError(f"{p}: a TIFF of transparency masks only (NewSubfileType 4), no image")
    types = sorted({str(page.dtype) for page in pages})
    same = len({page.shape for page in pages}) == 1 and len(types) == 1
    if len(pages) > 1 and named == len(pages) and same and len(pages[0].shape) == 2:
        tops = [tiffio.sample_tops(p, page) for page in pages]
        return (np.stack([tiffio.page_levels(p, page) for page in pages]), True,
                None if None in tops else [top[0] for top in tops])
    if len(pages) > 1:
        shapes = [" x ".join(map(str, page.shape)) for page in pages]
        if len(set(shapes)) > 1:
            raise InputError(f"{p}: a TIFF of {len(pages)} pages of different sizes (page "
                             f"shapes {', '.join(shapes)}) not marked as reduced-resolution "
                             "previews; decode cannot tell which is the sensor image: save it "
                             "as a TIFF of its own")
        if named == len(pages) and len(types) > 1:
            raise InputError(f"{p}: its {len(pages)} pages hold samples of different types "
                             f"({' and '.join(types)}); frames named by --frames are pages of "
                             "one sensor, of one sample type: save them alike")
        raise InputError(f"{p}: a TIFF of {len(pages)} full-size pages (page shape {shapes[0]}); "
                         "decode reads a sensor image of one page, or grey pages each named by "
                         f"--frames ({len(pages)} names, e.g. --frames A,B for a dual-pixel "
                         "pair)")
    data = tiffio.page_levels(p, pages[0])
    if pages[0].axes[:1] == "S" and data.ndim == 3:  # planar samples: colour last
        data = np.moveaxis(data, 0, -1)
    return data, False, tiffio.sample_tops(p, pages[0])


def _check_tops(path, frames: np.ndarray, tops: list) -> None:
    """No sample above the level its header says it can hold (a 16-bit word of a 12-bit
    TIFF, a MaxSampleValue the samples exceed): the header or the samples are wrong."""
    for frame, (top, label) in zip(frames, tops, strict=True):
        largest = int(frame.max()) if frame.size else 0
        if largest > top:
            raise InputError(f"{path}: samples up to {largest} where its {label} reach "
                             f"{top:g} at most; the header or the image is damaged: write it "
                             "again")


def _decode_image(path, *, cfa: str | None, named: int = 0) -> tuple[np.ndarray, dict]:
    p = Path(path)
    data, stacked, tops = None, False, None
    if is_tiff(p):   # by its first bytes: a TIFF's kinds are judged by the TIFF rules
        try:
            with tiffio.open_tiff(p) as tif:
                for page in tif.pages:
                    tiffio.check_segments(p, page)
                    if not page.subfiletype & TRANSPARENCY_MASK:  # not read: see _frame_pages
                        tiffio.check_light_levels(p, page)
                data, stacked, tops = _frame_pages(p, tif, named)
        except tiffio.READ_ERRORS as err:
            raise tiffio.read_error(p, err, f"{p}: unreadable TIFF ({library_words(err)}); "
                                            "the file may be truncated") from err
    else:
        data, tops = read_plain_levels(p, tiffio.MAX_PAGE_PIXELS)
    if stacked:  # pages named by --frames (renamed by _apply_user_values)
        frames, views = data, [f"page{k}" for k in range(len(data))]
    elif data.ndim == 2:
        frames, views = data[np.newaxis], ["raw"]
    elif data.ndim == 3 and data.shape[-1] in (3, 4):
        frames, views = np.moveaxis(data[..., :3], -1, 0), ["R", "G", "B"]
        if cfa:
            raise InputError(f"{p}: an RGB image cannot carry a CFA pattern; drop --cfa")
    else:
        raise InputError(f"{p}: image of shape {data.shape}; decode reads grey or Bayer "
                         "(rows, cols) and RGB or RGBA (rows, cols, 3 or 4) sensor images")
    if tops is not None:
        tops = tops[:len(frames)] if not stacked else tops
        tops = tops if len(tops) == len(frames) else [tops[0]] * len(frames)
        _check_tops(p, frames, tops)
    rows, cols = frames.shape[1:]
    return np.ascontiguousarray(frames), {
        "sample_top": tops, "cfa": None, "origin": [0, 0], "black_level": None, "white_level": None,
        "active_area": [0, 0, rows, cols], "masked_areas": [], "views": views,
        "color": "rgb" if views == ["R", "G", "B"] else "mono",
    }
