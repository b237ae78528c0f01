"""Raytrix ``RayCalibData`` XML: read, write, and conversion to / from ``LensGrid``.

A calibration is a plain dict (JSON-ready, so it also travels in TIFF metadata)::

    version        "1.0"
    offset         [x, y]  px, of the centre lens from the image centre, y pointing UP
    diameter       lens pitch, px
    rotation       rad, lattice orientation (y up, counter-clockwise)
    lens_border    px
    tcp            virtual depth of the total covering plane
    lens_base_x    [x, y]  first lattice vector, in units of ``diameter`` (y up)
    lens_base_y    [x, y]  second lattice vector
    sub_grid_base  [x, y]  base of the sub-grid of one lens type (= 2 (base_x + base_y))
    distortion     {"type", "function", "parameters": [..], "offset": [x, y]}
    lens_types     [{"id", "offset": [x, y] (lens units), "depth_range": [min, max]}, ...]
    k_matrix       3 x 3 list, or None when absent

Conventions (checked against the real origami frame, see tests/test_raytrix.py):

- Pixel (row r, col c) has its centre at (x, y) = (c, r) in plenocli. The centre lens of a
  W x H image sits at ``x = W/2 + offset.x``, ``y = H/2 - offset.y``.
- ``lens_base_x`` / ``lens_base_y`` are y-up vectors: in image coordinates (y down) they become
  ``diameter * (bx, -by)``. They give the lattice directions to float32 precision only (the files
  store e.g. ``(-1, -8.7e-8)`` with ``rotation = 2.5e-5``), so the lattice is turned by the small
  difference between ``rotation`` and the direction of ``lens_base_x`` (modulo 60 deg).
- ``LensGrid.angle_rad`` is measured from +x towards +y (down): it is minus the y-up angle.
- ``lens_type`` offsets (lens units, y up like the bases) point from a lens of that type to
  the type-0 centre lens: type t sits at minus its offset. Every file seen writes type 1 at
  the numbers of ``lens_base_x`` (type 1 at -base_x) and type 2 at minus them. Evidence: on
  Fujita2 and origami (base_x up) the coset so named type 2 (range 3.5-100) is the sharpest
  in the far third of the frame's g and gains most from near to far, type 0 (1-3.2) loses
  most; on the R42 crop (base_x right, every lens at g 5-7) the coset so named type 2
  (3.8-100) is sharper than type 1 (2.8-4), type 0 (1-3) least sharp; PlenopticToolbox 2.0
  reads its R42 and R29 files (rotation 0) alike. Read as vectors pointing to the type, types
  1 and 2 swap on both cameras (docs/calibrate.md).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np

from plenocli.errors import InputError, not_a_file
from plenocli.io.atomic import write_text
from plenocli.model.lensgrid import LensGrid

DEFAULT_LENS_TYPES = [
    {"id": 0, "offset": [0.0, 0.0], "depth_range": [1.0, 3.2]},
    {"id": 1, "offset": [1.0, 0.0], "depth_range": [2.6, 4.2]},
    {"id": 2, "offset": [-1.0, 0.0], "depth_range": [3.5, 100.0]},
]


# The unit each field is read in, and the spellings of a unit attribute that can be converted
# to it without knowing the camera (a length in mm would need the pixel size: refused).
FIELD_UNITS = {"offset": "pix", "diameter": "pix", "lens_border": "pix", "rotation": "rad",
               "distortion/offset": "pix", "tcp": "virtual_depth", "lens_base_x": "lens",
               "lens_base_y": "lens", "sub_grid_base": "lens", "lens_type/offset": "lens"}
UNIT_SCALES = {"pix": {"pix": 1.0, "px": 1.0, "pixel": 1.0, "pixels": 1.0},
               "rad": {"rad": 1.0, "radian": 1.0, "radians": 1.0, "deg": np.pi / 180,
                       "degree": np.pi / 180, "degrees": np.pi / 180},
               "lens": {"lens": 1.0}, "virtual_depth": {"virtual_depth": 1.0}}


def _scale(node: ET.Element, what: str) -> float:
    """The factor from the unit ``node`` states to the one plenocli reads ``what`` in (1 when
    it states none); a unit that cannot be converted is refused, never read as another."""
    units, field = node.get("units"), FIELD_UNITS.get(what)
    if units is None or field is None:
        return 1.0
    scale = UNIT_SCALES[field].get(units.strip().lower())
    if scale is None:
        raise ValueError(f'<{what} units="{units}">: plenocli reads {what} in {field} (the file '
                         f"gives nothing to convert {units} with); write it in {field}")
    return scale


def _xy(node: ET.Element | None, what: str) -> list[float]:
    if node is None:
        raise ValueError(f"missing <{what}>")
    scale = _scale(node, what)
    return [scale * _num(node.find("x"), f"{what}/x"), scale * _num(node.find("y"), f"{what}/y")]


def _num(node: ET.Element | None, what: str) -> float:
    if node is None or node.text is None or not node.text.strip():
        raise ValueError(f"missing <{what}>")
    return float(node.text.strip()) * _scale(node, what)


def _check_single(node: ET.Element, path: str = "") -> None:
    """Refuse an element given twice where the format has one (every element but the root's
    ``lens_type``s): a reader would keep one of them silently."""
    tags = [child.tag for child in node]
    for tag in dict.fromkeys(tags):
        if tags.count(tag) > 1 and not (path == "" and tag == "lens_type"):
            raise ValueError(f"<{path}{tag}> is given {tags.count(tag)} times; keep one")
    for child in node:
        _check_single(child, f"{path}{child.tag}/")


def _distortion(dist: ET.Element | None) -> dict | None:
    """The ``<distortion>`` element: its parameters must be as many as ``count`` says."""
    if dist is None:
        return None
    param = dist.find("parameter")
    count = int(param.get("count", "0")) if param is not None else 0
    values = _numbers(param.text) if param is not None else []
    if count == 0 and values in ([], [0.0]):  # "0": the placeholder of no parameters
        values = []
    if len(values) != count:
        raise ValueError(f"<distortion/parameter> has count {count} but holds {len(values)} "
                         "values")
    off = dist.find("offset")
    return {"type": dist.get("type", "radial"),
            "function": (dist.findtext("function") or "constant").strip(),
            "parameters": values,
            "offset": _xy(off, "distortion/offset") if off is not None else [0.0, 0.0]}


def _numbers(text: str | None) -> list[float]:
    parts = (text or "").replace(";", " ").replace(",", " ").split()
    return [float(p) for p in parts]


def parse_calib(text: str, *, source: str = "XML") -> dict:
    """Parse RayCalibData XML text into a calibration dict (see module doc)."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as err:
        raise InputError(f"{source}: malformed XML ({err}); pass a Raytrix RayCalibData file") \
            from err
    if root.tag != "RayCalibData":
        raise InputError(f"{source}: a <{root.tag}> file, not a Raytrix <RayCalibData> "
                         "calibration; plenocli reads RayCalibData XML only")
    try:
        _check_single(root)
        distortion = _distortion(root.find("distortion"))
        lens_types = []
        for lt in root.findall("lens_type"):
            rng = lt.find("depth_range")
            lens_types.append({"id": int(lt.get("id", len(lens_types))),
                               "offset": _xy(lt.find("offset"), "lens_type/offset"),
                               "depth_range": [_num(rng.find("min") if rng is not None else None,
                                                    "depth_range/min"),
                                               _num(rng.find("max") if rng is not None else None,
                                                    "depth_range/max")]})
        kmat = root.find("k_matrix")
        k_matrix = None
        if kmat is not None:
            k_matrix = [_numbers(kmat.findtext(f"row_{r}")) for r in (1, 2, 3)]
            if any(len(row) != 3 for row in k_matrix):
                raise ValueError("k_matrix rows must hold 3 numbers")
        calib = {
            "version": root.get("version", "1.0"),
            "offset": _xy(root.find("offset"), "offset"),
            "diameter": _num(root.find("diameter"), "diameter"),
            "rotation": _num(root.find("rotation"), "rotation"),
            "lens_border": _num(root.find("lens_border"), "lens_border")
            if root.find("lens_border") is not None else 1.0,
            "tcp": _num(root.find("tcp"), "tcp") if root.find("tcp") is not None else None,
            "lens_base_x": _xy(root.find("lens_base_x"), "lens_base_x"),
            "lens_base_y": _xy(root.find("lens_base_y"), "lens_base_y"),
            "sub_grid_base": _xy(root.find("sub_grid_base"), "sub_grid_base")
            if root.find("sub_grid_base") is not None else None,
            "distortion": distortion,
            "lens_types": lens_types,
            "k_matrix": k_matrix,
        }
    except ValueError as err:
        hint = "; the file may be truncated" if str(err).startswith("missing") else ""
        raise InputError(f"{source}: bad RayCalibData ({err}){hint}") from err
    try:
        check_calib(calib)
    except ValueError as err:
        raise InputError(f"{source}: {err}; the calibration is damaged, use the camera's "
                         "RayCalibData file") from err
    return calib


def check_calib(calib: dict) -> None:
    """Raise ValueError naming the first lattice field of ``calib`` that cannot describe a lens
    grid: non-finite numbers, a diameter below one pixel, a zero or degenerate lens basis."""
    if not 1.0 <= calib["diameter"] <= 1e6:   # false for NaN
        raise ValueError(f"diameter {calib['diameter']} must be a lens pitch from 1 to 1e6 px")
    for key in ("offset", "rotation", "lens_base_x", "lens_base_y"):
        values = np.asarray(calib[key], float)
        if not np.all(np.abs(values) <= 1e6):
            raise ValueError(f"{key} {calib[key]} must hold finite numbers")
    bx = np.asarray(calib["lens_base_x"], float)
    by = np.asarray(calib["lens_base_y"], float)
    nx, ny = float(np.hypot(*bx)), float(np.hypot(*by))
    if not (nx > 1e-6 and ny > 1e-6):
        raise ValueError(f"lens_base_x {list(bx)} and lens_base_y {list(by)} must be non-zero "
                         "vectors")
    if abs(float(bx[0] * by[1] - bx[1] * by[0])) < 0.1 * nx * ny:  # sin(angle) < 0.1
        raise ValueError(f"lens_base_x {list(bx)} and lens_base_y {list(by)} are (nearly) "
                         "parallel: they span no lattice")
    # a lens array is hexagonal (bases 60 or 120 deg apart) or square (90 deg), of one pitch
    between = float(np.degrees(np.arccos(np.clip(np.dot(bx, by) / (nx * ny), -1.0, 1.0))))
    if min(abs(between - a) for a in (60.0, 90.0, 120.0)) > 1.0 or abs(nx / ny - 1) > 0.01:
        raise ValueError(f"lens_base_x {list(bx)} and lens_base_y {list(by)} are {between:.1f} "
                         f"deg apart with lengths {nx:.4g} and {ny:.4g}: not a hexagonal "
                         "(60 or 120 deg) or square (90 deg) lens array of one pitch")
    _check_other_fields(calib)


def _check_other_fields(calib: dict) -> None:
    """The fields beside the lattice (kept in the metadata for later stages): finite, a
    non-negative border, a positive total covering plane, lens types of distinct ids 0..2 with
    depth ranges min < max."""
    distortion = calib.get("distortion") or {}
    fields = {"lens_border": calib.get("lens_border"), "tcp": calib.get("tcp"),
              "sub_grid_base": calib.get("sub_grid_base"),
              "distortion parameters": distortion.get("parameters"),
              "distortion offset": distortion.get("offset")}
    for k, lens_type in enumerate(calib.get("lens_types") or []):
        fields[f"lens_type {k} offset"] = lens_type["offset"]
        fields[f"lens_type {k} depth_range"] = lens_type["depth_range"]
    for name, value in fields.items():
        if value is not None and not np.all(np.isfinite(np.asarray(value, float))):
            raise ValueError(f"{name} {value} must hold finite numbers")
    if calib.get("lens_border", 0) < 0 or (calib.get("tcp") is not None and calib["tcp"] <= 0):
        raise ValueError(f"lens_border {calib.get('lens_border')} must be >= 0 px and tcp "
                         f"{calib.get('tcp')} > 0")
    ids = [t["id"] for t in calib.get("lens_types") or []]
    if len(set(ids)) != len(ids) or not set(ids) <= {0, 1, 2}:
        raise ValueError(f"lens_type ids {ids} must be distinct, from 0 to 2")
    for t in calib.get("lens_types") or []:
        low, high = t["depth_range"]
        if not low < high:
            raise ValueError(f"lens_type {t['id']} depth_range [{low}, {high}] must have min < max")


def read_calib(path: str | os.PathLike) -> dict:
    """Read a RayCalibData XML file."""
    p = Path(path)
    if not p.is_file():
        raise not_a_file(p)
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        raise InputError(f"{p}: not a text XML file ({err})") from err
    return parse_calib(text, source=str(p))


def _f(v: float) -> str:
    return repr(float(v))


def format_calib(calib: dict) -> str:
    """RayCalibData XML text of a calibration dict (floats written exactly)."""
    def xy(tag: str, v, units: str, indent: str = "  ") -> list[str]:
        return [f'{indent}<{tag} units="{units}">', f"{indent}  <x>{_f(v[0])}</x>",
                f"{indent}  <y>{_f(v[1])}</y>", f"{indent}</{tag}>"]

    out = [f'<RayCalibData version="{calib.get("version", "1.0")}">']
    out += xy("offset", calib["offset"], "pix")
    out.append(f'  <diameter units="pix">{_f(calib["diameter"])}</diameter>')
    out.append(f'  <rotation units="rad">{_f(calib["rotation"])}</rotation>')
    out.append(f'  <lens_border units="pix">{_f(calib.get("lens_border", 1.0))}</lens_border>')
    if calib.get("tcp") is not None:
        out.append(f'  <tcp units="virtual_depth">{_f(calib["tcp"])}</tcp>')
    out += xy("lens_base_x", calib["lens_base_x"], "lens")
    out += xy("lens_base_y", calib["lens_base_y"], "lens")
    if calib.get("sub_grid_base") is not None:
        out += xy("sub_grid_base", calib["sub_grid_base"], "lens")
    dist = calib.get("distortion")
    if dist is not None:
        params = dist.get("parameters", [])
        out.append(f'  <distortion type="{dist.get("type", "radial")}">')
        out.append(f'    <function>{dist.get("function", "constant")}</function>')
        text = ";".join(_f(v) for v in params) if params else "0"
        out.append(f'    <parameter count="{len(params)}">{text}</parameter>')
        out += xy("offset", dist.get("offset", [0.0, 0.0]), "pix", "    ")
        out.append("  </distortion>")
    for lt in calib.get("lens_types", []):
        out.append(f'  <lens_type id="{int(lt["id"])}">')
        out += xy("offset", lt["offset"], "lens", "    ")
        lo, hi = lt["depth_range"]
        out += ['    <depth_range units="virtual_depth">', f"      <min>{_f(lo)}</min>",
                f"      <max>{_f(hi)}</max>", "    </depth_range>", "  </lens_type>"]
    if calib.get("k_matrix") is not None:
        out.append('  <k_matrix count="9">')
        for r, row in enumerate(calib["k_matrix"], 1):
            out.append(f"    <row_{r}>{', '.join(_f(v) for v in row)}</row_{r}>")
        out.append("  </k_matrix>")
    out.append("</RayCalibData>")
    return "\n".join(out) + "\n"


def write_calib(path: str | os.PathLike, calib: dict, *, protect: tuple = ()) -> None:
    """Write a calibration dict as RayCalibData XML (atomically)."""
    write_text(path, format_calib(calib), protect=protect)


def _wrap(angle: float, period: float) -> float:
    return (angle + period / 2) % period - period / 2


def grid_from_calib(calib: dict, image_shape: tuple[int, int]) -> LensGrid:
    """The lattice of a Raytrix calibration as a ``LensGrid`` of an image of ``image_shape``
    (rows, cols). Lens (0, 0) is the centre lens; b1, b2 are the Raytrix base vectors (ordered
    so that b2 is b1 turned by +60 deg in image coordinates).

    A calibration with a lens distortion (a nonzero parameter) is refused: the lattice is
    placed undistorted, and the file does not state the radius its polynomial is normalised by,
    so the shift of the lens centres cannot be bounded (the real Cards2 file's k1 = -0.0015
    moves the corner lenses by ~6 px normalised to the half-diagonal, by far more in pixels);
    dropping it would put the lenses in the wrong place silently."""
    check_calib(calib)
    _refuse_distortion(calib.get("distortion"))
    rows, cols = image_shape
    d = float(calib["diameter"])
    bx = np.asarray(calib["lens_base_x"], float)
    by = np.asarray(calib["lens_base_y"], float)
    step = np.pi / 3 if abs(abs(float(np.dot(bx, by)) /
                                (np.linalg.norm(bx) * np.linalg.norm(by))) - 0.5) < 0.1 \
        else np.pi / 2
    lattice = "hex" if step == np.pi / 3 else "square"
    turn = _wrap(float(calib["rotation"]) - float(np.arctan2(bx[1], bx[0])), step)
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    u1 = rot @ bx * d / np.linalg.norm(bx)
    u2 = rot @ by * d / np.linalg.norm(by)
    img1, img2 = np.array([u1[0], -u1[1]]), np.array([u2[0], -u2[1]])
    a1, a2 = np.arctan2(img1[1], img1[0]), np.arctan2(img2[1], img2[0])
    first = img1 if _wrap(a2 - a1, 2 * np.pi) > 0 else img2
    centre = (cols / 2 + float(calib["offset"][0]), rows / 2 - float(calib["offset"][1]))
    grid = LensGrid(pitch_px=d, angle_rad=float(np.arctan2(first[1], first[0])),
                    offset_xy=centre, lattice=lattice, image_shape=(rows, cols))
    types = type_of_coset(calib, grid) if lattice == "hex" else None
    return grid if types is None else replace(grid, lens_type_of_coset=types)


def _coset_of(grid: LensGrid, vector_px: np.ndarray) -> int | None:
    """Coset (i - j) mod 3 of the lattice vector ``vector_px`` (image px, y down) of a hex
    grid, or None when it is not a lattice vector (within 0.1 lens)."""
    ij = np.linalg.solve(grid.basis().T, vector_px)
    if np.abs(ij - np.rint(ij)).max() > 0.1:
        return None
    return int((np.rint(ij[0]) - np.rint(ij[1])) % 3)


def type_of_coset(calib: dict, grid: LensGrid) -> tuple[int, int, int] | None:
    """The camera's lens type of each coset (i - j) mod 3 of ``grid`` (lens (0, 0) at the
    calibration's offset; type t at minus its offset, module doc), or None: no three lens
    types, or offsets that are not lattice vectors or do not make one type per coset."""
    types = calib.get("lens_types") or []
    if sorted(int(t["id"]) for t in types) != [0, 1, 2]:
        return None
    d = float(calib["diameter"])
    out = [-1, -1, -1]
    for t in types:
        ox, oy = (float(v) for v in t["offset"])
        coset = _coset_of(grid, d * np.array([-ox, oy]))   # minus the y-up offset, y down
        if coset is None:
            return None
        out[coset] = int(t["id"])
    return tuple(out) if sorted(out) == [0, 1, 2] else None


DISTORTION_FUNCTIONS = ("constant", "brown")  # the names RayCalibData files use


def _refuse_distortion(distortion: dict | None) -> None:
    function = str((distortion or {}).get("function", "constant"))
    if function.lower() not in DISTORTION_FUNCTIONS:
        raise ValueError(f"its distortion function {function!r} is not one plenocli knows "
                         f"({', '.join(DISTORTION_FUNCTIONS)}); use an XML without distortion")
    params = (distortion or {}).get("parameters") or []
    if any(float(v) != 0.0 for v in params):
        raise ValueError(f"its distortion ({distortion.get('function', 'constant')} "
                         f"{', '.join(f'{float(v):g}' for v in params)}) moves the lens centres, "
                         "and plenocli places the lattice undistorted (RayCalibData does not say "
                         "how its radius is normalised); use the grid of plenocli calibrate on "
                         "this camera's white image, or an XML without distortion")


def calib_from_grid(grid: LensGrid, *, template: dict | None = None) -> dict:
    """A RayCalibData dict for ``grid`` (which needs ``image_shape``). Fields the grid does not
    determine (lens_border, tcp, distortion, lens types' depth ranges, k_matrix) come from
    ``template`` or Raytrix-like defaults. The offset is the lens nearest the image centre."""
    if grid.image_shape is None:
        raise ValueError("grid.image_shape is needed to express the offset from the image centre")
    rows, cols = grid.image_shape
    i, j = grid.nearest_index((cols - 1) / 2, (rows - 1) / 2)
    x, y = grid.lattice_xy(i, j)
    b = grid.basis() / grid.pitch_px
    base_x = [float(b[0, 0]), float(-b[0, 1])]          # y up
    base_y = [float(b[1, 0]), float(-b[1, 1])]
    tpl = template or {}
    lens_types = _written_types(grid, tpl.get("lens_types", DEFAULT_LENS_TYPES), (i, j))
    return {
        "version": tpl.get("version", "1.0"),
        "offset": [float(x - cols / 2), float(rows / 2 - y)],
        "diameter": float(grid.pitch_px),
        "rotation": float(np.arctan2(base_x[1], base_x[0]) % (2 * np.pi)),
        "lens_border": tpl.get("lens_border", 1.0),
        "tcp": tpl.get("tcp", 2.2),
        "lens_base_x": base_x,
        "lens_base_y": base_y,
        "sub_grid_base": [2 * (base_x[0] + base_y[0]), 2 * (base_x[1] + base_y[1])],
        "distortion": tpl.get("distortion", {"type": "radial", "function": "constant",
                                             "parameters": [], "offset": [0.0, 0.0]}),
        "lens_types": lens_types,
        "k_matrix": tpl.get("k_matrix"),
    }


def _written_types(grid: LensGrid, template: list[dict], centre: tuple) -> list[dict]:
    """The lens types of a written file: the template's ids and depth ranges, each offset
    minus the y-up unit lattice vector (lens units) from the centre lens to a lens of its
    type (module doc; along base_x where it can be, as camera files have it). Without
    measured types the file carries none: a guessed type gives 2/3 of the lenses the wrong
    depth range."""
    cosets = grid.lens_type_of_coset
    if cosets is None:
        return []
    here = int((centre[0] - centre[1]) % 3)
    b = grid.basis() / grid.pitch_px
    units = [(di * b[0] + dj * b[1], (di - dj) % 3)   # image vectors (y down), coset shift
             for di, dj in ((-1, 0), (1, 0), (0, 1), (-1, 1), (0, -1), (1, -1))]
    out = []
    for lt in template:
        if int(lt["id"]) not in cosets:
            continue
        shift = (cosets.index(int(lt["id"])) - here) % 3
        u = next(u for u, k in units if k == shift) if shift else np.zeros(2)
        out.append({**lt, "offset": [float(-u[0]) + 0.0, float(u[1]) + 0.0]})
    return out
