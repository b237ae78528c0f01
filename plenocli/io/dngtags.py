"""The tags of a DNG raw IFD, each checked against the file and the DNG 1.7 rules before use.

A damaged or hand-made header can claim anything; every value plenocli takes from one is read
here, and one that breaks the specification (or describes a sensor plenocli cannot process, such
as a non-Bayer CFA) is an InputError naming the raw IFD, the tag and its value. Nothing is
guessed: a tag that is missing takes the default the specification gives it.
"""

from __future__ import annotations

import numpy as np

from plenocli.errors import InputError
from plenocli.io.tiffio import inside, rects_overlap
from plenocli.model import orientation as turns
from plenocli.model.cfa import is_bayer

CFA_REPEAT_DIM, CFA_PATTERN, CFA_PLANE_COLOR, CFA_LAYOUT = 33421, 33422, 50710, 50711
LINEARIZATION_TABLE, BLACK_REPEAT_DIM, BLACK_LEVEL = 50712, 50713, 50714
BLACK_DELTA_H, BLACK_DELTA_V, WHITE_LEVEL, DEFAULT_SCALE = 50715, 50716, 50717, 50718
ACTIVE_AREA, MASKED_AREAS = 50829, 50830
PLANE_COLOURS = {0: "R", 1: "G", 2: "B"}  # CFAPlaneColor / CFAPattern codes (3.. are C, M, Y..)
RATIONAL_TYPES = (5, 10)  # RATIONAL, SRATIONAL: numerator, denominator pairs
SHORT = 3
PHOTOMETRIC_CFA, PHOTOMETRIC_LINEAR_RAW = 32803, 34892
MAIN_IMAGE, REDUCED = 0, 1  # NewSubFileType: the full-resolution image, a preview
ENHANCED = 16  # DNG 1.5: an enhanced (demosaiced) image beside the raw, not the raw itself
# Tiles are a few hundred pixels (DNG converters write 256); a side larger than the image
# (rounded up to the 16 TIFF asks for) is allowed up to this, beyond it the decoder would
# allocate for pixels that do not exist.
MAX_TILE_SIDE = 1024


def _tag(page, code):
    return page.tags.get(code)


def numbers(path, k: int, page, code: int, name: str) -> np.ndarray | None:
    """A numeric tag as float64 values (rationals divided out), or None when absent."""
    tag = _tag(page, code)
    if tag is None:
        return None
    value = list(tag.value) if isinstance(tag.value, bytes) else tag.value  # BYTE tags
    try:
        values = np.atleast_1d(np.asarray(value, dtype=np.float64)).ravel()
    except (TypeError, ValueError) as err:
        raise InputError(f"{path}: raw IFD {k}: {name} {tag.value!r} is not numeric; the DNG "
                         "is damaged: copy or convert it again") from err
    if int(tag.dtype) in RATIONAL_TYPES:
        num, den = values[::2], values[1::2]
        if np.any(den == 0):
            bad = int(np.argmax(den == 0))
            raise InputError(f"{path}: raw IFD {k}: {name} holds {num[bad]:g}/0 (a zero "
                             "denominator); the DNG is damaged: copy or convert it again")
        values = num / den
    if not np.all(np.isfinite(values)):
        raise InputError(f"{path}: raw IFD {k}: {name} {values.tolist()} is not finite; the DNG "
                         "is damaged: copy or convert it again")
    return values


def raw_pages(path, pages: list) -> list:
    """The raw IFDs (NewSubFileType 0, CFA or LinearRaw) of a DNG's IFDs and SubIFDs (an
    enhanced image, NewSubFileType 16, is not read, as previews are not). A main image that is
    not raw, a raw IFD flagged with NewSubFileType bits DNG does not define for
    it, or raw IFDs that share bytes (a wrong offset reads another frame) are damage."""
    raws = []
    for k, page in enumerate(pages):
        kind, raw = int(page.subfiletype), int(page.photometric) in (PHOTOMETRIC_CFA,
                                                                     PHOTOMETRIC_LINEAR_RAW)
        if (kind == MAIN_IMAGE and not raw) or (raw and kind not in (MAIN_IMAGE, REDUCED,
                                                                      ENHANCED)):
            raise InputError(f"{path}: IFD {k} has NewSubFileType {kind} and Photometric "
                             f"{int(page.photometric)}; a DNG's full-resolution images are CFA "
                             "or LinearRaw raws: the DNG is damaged")
        if raw and kind == MAIN_IMAGE:
            raws.append(page)
    if not raws:
        raise InputError(f"{path}: a DNG without a raw image (no CFA or LinearRaw IFD)")
    full = {tuple(page.shape) for page in raws}
    for k, page in enumerate(pages):
        if int(page.subfiletype) == REDUCED and tuple(page.shape) in full and int(
                page.photometric) in (PHOTOMETRIC_CFA, PHOTOMETRIC_LINEAR_RAW):
            raise InputError(f"{path}: IFD {k} is a raw of full size flagged as a reduced "
                             "preview (NewSubFileType 1); the DNG is damaged")
    spans = sorted((int(o), int(o) + int(c), k) for k, page in enumerate(raws)
                   for o, c in zip(page.dataoffsets, page.databytecounts, strict=True))
    spans += [(page.offset, page.offset + 2 + 12 * len(page.tags), k)
              for k, page in enumerate(raws)]  # each IFD's entries (classic TIFF sizes)
    spans.sort()
    for (_, end, k), (start, _, m) in zip(spans, spans[1:], strict=False):
        if end > start and k != m:
            raise InputError(f"{path}: raw IFDs {min(k, m)} and {max(k, m)} share the bytes at "
                             f"{start} (a wrong offset or byte count); the DNG is damaged: "
                             "copy or convert it again")
    return raws


def orientation(path, main_page, raw_page) -> int:
    """The DNG's Orientation (tag 274): IFD 0's, where DNG puts it (the raw IFD's when IFD 0
    has none); 1 (as stored) when neither has one. A value outside 1-8 is damage: guessed, the
    photograph would be turned or mirrored wrongly."""
    tag = _tag(main_page, turns.TAG)
    tag = _tag(raw_page, turns.TAG) if tag is None else tag
    if tag is None:
        return 1
    value = tag.value[0] if isinstance(tag.value, tuple) and len(tag.value) == 1 else tag.value
    try:
        return turns.check(value)
    except ValueError as err:
        raise InputError(f"{path}: {err} (1 to 8 say how the image stands); the DNG is "
                         "damaged: copy or convert it again") from err


# Compression values DNG 1.7 allows for raw data: none, lossless JPEG, Deflate, lossy JPEG,
# JPEG XL. Another (LZW, PackBits, ...) is no DNG's: a damaged tag, or a file no DNG reader reads.
DNG_COMPRESSIONS = {1: "none", 7: "JPEG", 8: "Deflate", 34892: "lossy JPEG", 52546: "JPEG XL"}
DNG_VERSION = 50706


def check_layout(path, k: int, page, dng: bool = True) -> None:
    """What must hold before a pixel is decoded: a Compression DNG allows (``dng``: the file
    says it is one; a TIFF/EP raw follows the TIFF rules), tile sizes that fit the image."""
    compression = int(page.compression)
    if dng and compression not in DNG_COMPRESSIONS:
        allowed = ", ".join(f"{code} {name}" for code, name in DNG_COMPRESSIONS.items())
        raise InputError(f"{path}: raw IFD {k}: Compression {compression}, which DNG does not "
                         f"allow for raw data ({allowed}); the DNG is damaged: copy or convert "
                         "it again")
    _check_square_pixels(path, k, page)
    if not page.is_tiled:
        return
    rows, cols = page.imagelength, page.imagewidth
    for name, side, size in (("TileWidth", page.tilewidth, cols),
                             ("TileLength", page.tilelength, rows)):
        if side > max(-(-size // 16) * 16, MAX_TILE_SIDE):
            raise InputError(f"{path}: raw IFD {k}: {name} {side} for an image of {cols} x "
                             f"{rows} pixels; the header is damaged: copy or convert the DNG "
                             "again")


def _check_square_pixels(path, k: int, page) -> None:
    """DefaultScale of two different values says the pixels are not square (the picture is
    that many times wider or taller than stored, as LibRaw's pixel aspect stretches it): every
    stage measures in pixels (lens pitch, shifts, depth), so such a raw is refused, not
    squashed. Equal values only scale the picture shown."""
    scale = numbers(path, k, page, DEFAULT_SCALE, "DefaultScale")
    if scale is None:
        return
    if scale.size != 2 or not np.all(scale > 0):
        raise InputError(f"{path}: raw IFD {k}: DefaultScale {scale.tolist()} is not two "
                         "positive numbers; the DNG is damaged: copy or convert it again")
    if scale[0] == scale[1]:
        return   # square pixels, shown larger or smaller: nothing a measure in pixels sees
    raise InputError(f"{path}: raw IFD {k}: DefaultScale {scale[0]:g} x {scale[1]:g}: its "
                     "pixels are not square, and plenocli measures in pixels (lens pitch, "
                     "shifts, depth); convert the raw to square pixels first")


def cfa_pattern(path, k: int, page) -> str:
    """The 2 x 2 Bayer pattern of a CFA IFD (CFARepeatPatternDim, CFAPattern, CFAPlaneColor,
    CFALayout) as the file gives it: at the ActiveArea's top-left pixel, as DNG readers
    (the DNG SDK, LibRaw, rawspeed) take it; or an InputError naming the tag that is missing
    or wrong."""
    dims = numbers(path, k, page, CFA_REPEAT_DIM, "CFARepeatPatternDim")
    dims = (2, 2) if dims is None else tuple(int(v) for v in dims)
    if dims != (2, 2):
        raise InputError(f"{path}: raw IFD {k}: CFARepeatPatternDim {' x '.join(map(str, dims))}"
                         "; plenocli reads 2 x 2 Bayer mosaics (an X-Trans or other CFA must be "
                         "converted to a linear DNG first)")
    layout = numbers(path, k, page, CFA_LAYOUT, "CFALayout")
    if layout is not None and layout.tolist() != [1]:
        raise InputError(f"{path}: raw IFD {k}: CFALayout {layout.tolist()} (staggered pixels); "
                         "plenocli reads rectangular Bayer mosaics (CFALayout 1)")
    codes = numbers(path, k, page, CFA_PATTERN, "CFAPattern")
    if codes is None or codes.size != 4:
        raise InputError(f"{path}: raw IFD {k}: a CFA image whose CFAPattern is "
                         f"{'missing' if codes is None else f'{codes.size} entries'}, not the 4 "
                         "of its 2 x 2 repeat; the DNG is damaged")
    planes = numbers(path, k, page, CFA_PLANE_COLOR, "CFAPlaneColor")
    planes = [0, 1, 2] if planes is None else [int(v) for v in planes]
    letters = []
    for code in codes.astype(int):
        colour = PLANE_COLOURS.get(planes[code]) if 0 <= code < len(planes) else None
        if colour is None:
            raise InputError(f"{path}: raw IFD {k}: CFAPattern {codes.astype(int).tolist()} "
                             f"(planes {planes}) holds a colour other than red, green or blue "
                             "(0, 1, 2); plenocli reads RGB Bayer mosaics")
        letters.append(colour)
    pattern = "".join(letters)
    if not is_bayer(pattern):
        raise InputError(f"{path}: raw IFD {k}: CFAPattern {pattern} is not a Bayer pattern "
                         "(RGGB, BGGR, GRBG, GBRG)")
    return pattern


def black_levels(path, k: int, page, corner: tuple[int, int] = (0, 0)) -> list[float]:
    """BlackLevel per 2 x 2 position of the stored image from its pixel (0, 0) (DN), repeated
    over BlackLevelRepeatDim (default 1 x 1, level 0) from ``corner``, the ActiveArea's top-left
    (where DNG puts the repeat's origin); per-row or per-column deltas are refused: plenocli
    would not apply them."""
    dims = numbers(path, k, page, BLACK_REPEAT_DIM, "BlackLevelRepeatDim")
    dims = (1, 1) if dims is None else tuple(int(v) for v in dims)
    if len(dims) != 2 or not all(d in (1, 2) for d in dims):
        raise InputError(f"{path}: raw IFD {k}: BlackLevelRepeatDim {list(dims)}; plenocli "
                         "reads black levels repeating over 1 or 2 rows and columns")
    values = numbers(path, k, page, BLACK_LEVEL, "BlackLevel")
    values = np.zeros(1) if values is None else values
    if values.size != dims[0] * dims[1]:
        raise InputError(f"{path}: raw IFD {k}: BlackLevel has {values.size} values for a "
                         f"{dims[0]} x {dims[1]} repeat; the DNG is damaged")
    if np.any(values < 0):
        raise InputError(f"{path}: raw IFD {k}: BlackLevel {values.tolist()} is negative; the "
                         "DNG is damaged")
    for code, name in ((BLACK_DELTA_H, "BlackLevelDeltaH"), (BLACK_DELTA_V, "BlackLevelDeltaV")):
        delta = numbers(path, k, page, code, name)
        if delta is not None and np.any(delta != 0):
            raise InputError(f"{path}: raw IFD {k}: {name} holds per-column or per-row black "
                             "offsets, which plenocli does not apply; convert the DNG without "
                             "them (plenocli bias measures the black from the over-scan)")
    grid = values.reshape(dims)
    return [float(grid[(r - corner[0]) % dims[0], (c - corner[1]) % dims[1]])
            for r in (0, 1) for c in (0, 1)]


def white_level(path, k: int, page, dtype: np.dtype, linearized: bool) -> float:
    """WhiteLevel, within what the decoded samples (or the LinearizationTable's levels) can
    reach. Missing, it is the DNG default: 2^BitsPerSample - 1 for integers, 1.0 for
    floating-point samples."""
    bits = int(page.bitspersample)
    values = numbers(path, k, page, WHITE_LEVEL, "WhiteLevel")
    if values is None:
        if linearized:
            return 65535.0
        return float(2 ** bits - 1) if dtype.kind in "ui" else 1.0
    # BitsPerSample is no bound here: writers label lossless-JPEG raws of 14-bit data 12 bits
    top = 65535 if linearized else (np.iinfo(dtype).max if dtype.kind in "ui" else np.inf)
    if values.size != 1 or not 0 < values[0] <= top:
        raise InputError(f"{path}: raw IFD {k}: WhiteLevel {values.tolist()} is not one level "
                         f"in (0, {top:g}] for these {dtype} samples; the DNG is damaged (or "
                         "give the level with --white after converting it)")
    return float(values[0])


def linearized(path, k: int, page, data: np.ndarray) -> tuple[np.ndarray, bool]:
    """Stored values mapped through the LinearizationTable, as the DNG spec says before
    anything else (lossy DNGs store 8-bit codes; some cameras compress their raws this way),
    and whether there was one. Stored values beyond the table take its last entry (the DNG
    SDK's rule)."""
    tag = _tag(page, LINEARIZATION_TABLE)
    if tag is None:
        return data, False
    table = np.atleast_1d(np.asarray(tag.value)).ravel()
    if int(tag.dtype) != SHORT or not 0 < table.size <= 65536 or data.dtype.kind != "u":
        raise InputError(f"{path}: raw IFD {k}: LinearizationTable of {table.size} entries "
                         f"(TIFF type {int(tag.dtype)}) for {data.dtype} samples; the DNG spec "
                         "asks for 1 to 65536 SHORT levels mapping unsigned codes: the DNG is "
                         "damaged, or convert it without the table")
    last = min(table.size - 1, int(np.iinfo(data.dtype).max))  # a table past the samples' range
    return table.astype(np.uint16)[np.minimum(data, data.dtype.type(last))], True


def check_samples(path, k: int, data: np.ndarray) -> None:
    """Floating-point raw samples are light levels: NaN or +-Inf is damage."""
    if data.dtype.kind != "f":
        return
    bad = int(np.count_nonzero(~np.isfinite(data)))
    if bad:
        raise InputError(f"{path}: raw IFD {k} holds {bad} NaN or infinite samples; a raw "
                         "holds finite light levels: the DNG is damaged, copy or convert it "
                         "again")


def areas(path, k: int, page, shape: tuple[int, int]) -> tuple[list[int], list[list[int]]]:
    """ActiveArea (default the whole image) and MaskedAreas, as [top, left, bottom, right]."""
    active = numbers(path, k, page, ACTIVE_AREA, "ActiveArea")
    if active is not None and active.size != 4:
        raise InputError(f"{path}: raw IFD {k}: ActiveArea has {active.size} values, not 4 "
                         "(top, left, bottom, right); the DNG is damaged")
    masked = numbers(path, k, page, MASKED_AREAS, "MaskedAreas")
    if masked is not None and masked.size % 4:
        raise InputError(f"{path}: raw IFD {k}: MaskedAreas has {masked.size} values, not 4 "
                         "per rectangle; the DNG is damaged")
    active_list = [0, 0, *shape] if active is None else [int(v) for v in active]
    flat = [] if masked is None else [int(v) for v in masked]
    rects = [flat[i:i + 4] for i in range(0, len(flat), 4)]
    # named by their tags here: the metadata's own check speaks of a damaged plenocli TIFF
    for name, rect in [("ActiveArea", active_list)] + [("MaskedAreas", r) for r in rects]:
        if not inside(rect, shape):
            raise InputError(f"{path}: raw IFD {k}: {name} {rect} is not a [top, left, bottom, "
                             f"right] rectangle inside the {shape[1]} x {shape[0]} raw image; "
                             "the DNG is damaged")
    for rect in rects:
        if rects_overlap(rect, active_list):
            raise InputError(f"{path}: raw IFD {k}: MaskedAreas {rect} overlaps ActiveArea "
                             f"{active_list} (masked areas lie outside the active area); the "
                             "DNG is damaged")
    return active_list, rects
