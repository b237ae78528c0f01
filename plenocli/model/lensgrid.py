"""The micro-lens grid: a hexagonal (or square) lattice of micro-image centres.

Coordinates are pixel coordinates of the image the grid belongs to: ``x`` is the column, ``y``
the row (pointing down), and the centre of pixel (row r, col c) is at (x, y) = (c, r).
Lens (i, j) of the lattice sits at::

    centre(i, j) = offset_xy + i * b1 + j * b2
    b1 = pitch_px * (cos a, sin a)
    b2 = pitch_px * (cos(a + 60 deg), sin(a + 60 deg))   hexagonal lattice
    b2 = pitch_px * (cos(a + 90 deg), sin(a + 90 deg))   square lattice

with ``a = angle_rad`` measured from +x towards +y. ``centres_xy`` optionally holds the refined
centre of each lens (the real array is not a perfect lattice), with its ``indices`` (i, j).
``lens_type_of_coset`` (multi-focus arrays) gives the type of lens (i, j) as
``lens_type_of_coset[(i - j) % 3]``: the three lens types of a hex array each fill one coset of
the index-3 sub-lattice. ``sensor_origin`` is the (row, col) of pixel (0, 0) in full-sensor
coordinates, so a grid calibrated on one crop can be used on another.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

LATTICES = {"hex": np.pi / 3, "square": np.pi / 2}
# A lens narrower than a pixel, or a lattice (or its image) beyond this many pixels, is not a
# plenoptic sensor: refusing such grids keeps lens tables and loops from exploding.
MIN_PITCH_PX = 1.0
MAX_COORD_PX = 1e6
# What a listed lens centre may be besides its measured symmetry centre: the lattice place moved
# by a smooth field, a polynomial of this degree in the place, of at most FIELD_MAX pitch
# (calibration.fit.smooth_field; the grid reader holds a file's rows to the same rule).
FIELD_DEGREE = 2
FIELD_MAX = 0.05
LENS_COLUMNS = ["i", "j", "x", "y"]  # a grid file's lens rows


@dataclass(frozen=True)
class LensGrid:
    pitch_px: float
    angle_rad: float
    offset_xy: tuple[float, float]
    lattice: str = "hex"
    image_shape: tuple[int, int] | None = None
    sensor_origin: tuple[int, int] = (0, 0)
    centres_xy: np.ndarray | None = field(default=None, compare=False, repr=False)
    indices: np.ndarray | None = field(default=None, compare=False, repr=False)
    lens_type_of_coset: tuple[int, int, int] | None = None

    def __post_init__(self):
        if self.lattice not in LATTICES:
            raise ValueError(f"lattice must be one of {sorted(LATTICES)}, got {self.lattice!r}")
        if not MIN_PITCH_PX <= self.pitch_px <= MAX_COORD_PX:  # also false for NaN
            raise ValueError(f"pitch_px must be a number of pixels from {MIN_PITCH_PX:g} to "
                             f"{MAX_COORD_PX:g}, got {self.pitch_px}")
        if not np.isfinite(self.angle_rad):
            raise ValueError(f"angle_rad must be a finite angle, got {self.angle_rad}")
        _check_point("offset_xy", self.offset_xy)
        if self.image_shape is not None:
            _check_shape(self.image_shape)
        if not (len(self.sensor_origin) == 2
                and all(float(v).is_integer() and 0 <= v <= MAX_COORD_PX
                        for v in self.sensor_origin)):
            raise ValueError(f"sensor_origin must be two whole numbers >= 0 (row, col), got "
                             f"{self.sensor_origin}")
        if (self.centres_xy is None) != (self.indices is None):
            raise ValueError("centres_xy and indices go together")
        if self.centres_xy is not None:
            _check_centres(self.centres_xy, self.indices)
        if self.lens_type_of_coset is not None and (
                self.lattice != "hex" or sorted(self.lens_type_of_coset) != [0, 1, 2]):
            raise ValueError("lens_type_of_coset needs a hex lattice and holds types 0, 1, 2, "
                             f"got {self.lens_type_of_coset!r}")

    def lens_types(self, i, j) -> np.ndarray | None:
        """Type (0, 1, 2) of lenses (i, j) of a multi-focus array, or None."""
        if self.lens_type_of_coset is None:
            return None
        coset = (np.asarray(i, np.int64) - np.asarray(j, np.int64)) % 3
        return np.asarray(self.lens_type_of_coset, np.int64)[coset]

    def basis(self) -> np.ndarray:
        """(2, 2) array whose rows are the lattice vectors b1, b2 in pixels (x, y)."""
        a, step = self.angle_rad, LATTICES[self.lattice]
        return self.pitch_px * np.array([[np.cos(a), np.sin(a)],
                                         [np.cos(a + step), np.sin(a + step)]])

    def lattice_xy(self, i, j) -> np.ndarray:
        """Ideal lattice centres of lenses (i, j) (broadcast), shape (..., 2)."""
        i, j = np.asarray(i, float), np.asarray(j, float)
        b = self.basis()
        return (np.asarray(self.offset_xy)
                + i[..., None] * b[0] + j[..., None] * b[1])

    def nearest_index(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Lattice index (i, j) of the ideal centre nearest to each point (x, y)."""
        x, y = np.asarray(x, float), np.asarray(y, float)
        b = self.basis()
        inv = np.linalg.inv(b.T)
        dx, dy = x - self.offset_xy[0], y - self.offset_xy[1]
        u = inv[0, 0] * dx + inv[0, 1] * dy
        v = inv[1, 0] * dx + inv[1, 1] * dy
        i0, j0 = np.floor(u), np.floor(v)
        best_i, best_j = i0, j0
        best_d = np.full(np.broadcast(x, y).shape, np.inf)
        for di in (0, 1):  # the nearest lattice point is a corner of the enclosing cell
            for dj in (0, 1):
                ci, cj = i0 + di, j0 + dj
                px = self.offset_xy[0] + ci * b[0, 0] + cj * b[1, 0]
                py = self.offset_xy[1] + ci * b[0, 1] + cj * b[1, 1]
                d = (x - px) ** 2 + (y - py) ** 2
                closer = d < best_d
                best_d = np.where(closer, d, best_d)
                best_i = np.where(closer, ci, best_i)
                best_j = np.where(closer, cj, best_j)
        return best_i.astype(np.int64), best_j.astype(np.int64)

    def lens_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(indices (K, 2), centres (K, 2)): the refined centres, or the ideal lattice centres
        of every lens whose centre falls inside ``image_shape``."""
        if self.centres_xy is not None:
            return np.asarray(self.indices), np.asarray(self.centres_xy)
        if self.image_shape is None:
            raise ValueError("a grid without centres needs image_shape to list its lenses")
        rows, cols = self.image_shape
        corners_x = np.array([0, cols - 1, 0, cols - 1], float)
        corners_y = np.array([0, 0, rows - 1, rows - 1], float)
        inv = np.linalg.inv(self.basis().T)
        uv = inv @ np.vstack([corners_x - self.offset_xy[0], corners_y - self.offset_xy[1]])
        lo, hi = np.floor(uv.min(axis=1)) - 1, np.ceil(uv.max(axis=1)) + 1
        ii, jj = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1),
                             indexing="ij")
        xy = self.lattice_xy(ii.ravel(), jj.ravel())
        inside = ((xy[:, 0] >= 0) & (xy[:, 0] <= cols - 1)
                  & (xy[:, 1] >= 0) & (xy[:, 1] <= rows - 1))
        idx = np.stack([ii.ravel(), jj.ravel()], axis=1).astype(np.int64)[inside]
        return idx, xy[inside]

    def shifted(self, dx: float, dy: float) -> LensGrid:
        """The same grid in coordinates shifted by (dx, dy) pixels: centre -> centre - (dx, dy).

        For a crop whose pixel (0, 0) is this grid's pixel (dx, dy); the result has no
        ``image_shape`` (the crop's size is the caller's) and the crop's ``sensor_origin``.
        """
        centres = None if self.centres_xy is None else np.asarray(self.centres_xy) - (dx, dy)
        return replace(self, offset_xy=(self.offset_xy[0] - dx, self.offset_xy[1] - dy),
                       centres_xy=centres, image_shape=None,
                       sensor_origin=(self.sensor_origin[0] + int(round(dy)),
                                      self.sensor_origin[1] + int(round(dx))))

    def to_dict(self, *, lens_rows: bool = True) -> dict:
        """Human-readable, YAML-ready description (centres as lists). With ``lens_rows=False``
        the ``lenses`` entry holds only its count and columns (a writer adds the rows)."""
        out = {
            "lattice": self.lattice,
            "pitch_px": float(self.pitch_px),
            "angle_rad": float(self.angle_rad),
            "angle_deg": float(np.degrees(self.angle_rad)),
            "offset_xy": [float(v) for v in self.offset_xy],
            "image_shape": list(self.image_shape) if self.image_shape else None,
            "sensor_origin": [int(v) for v in self.sensor_origin],
        }
        if self.lens_type_of_coset is not None:
            out["lens_type_of_coset"] = [int(v) for v in self.lens_type_of_coset]
        if self.centres_xy is not None:
            out["lenses"] = {
                "count": int(len(self.centres_xy)),
                "columns": list(LENS_COLUMNS),
            }
            if lens_rows:
                out["lenses"]["rows"] = [
                    [int(i), int(j), round(float(x), 5), round(float(y), 5)]
                    for (i, j), (x, y) in zip(np.asarray(self.indices).tolist(),
                                              np.asarray(self.centres_xy).tolist(), strict=True)]
        return out

    @classmethod
    def from_dict(cls, data: dict) -> LensGrid:
        """The grid of a lens-grid mapping (YAML); ValueError naming the field that is missing
        or not of its kind. Numbers are YAML numbers: text such as '20.2' is refused, as in
        every other side file (a number means the same wherever it is written)."""
        if not isinstance(data, dict):
            raise ValueError(f"lens_grid must be a mapping of fields, got {data!r}")
        missing = [k for k in ("pitch_px", "angle_rad", "offset_xy") if k not in data]
        if missing:
            raise ValueError(f"no {missing[0]}")
        lenses = data.get("lenses")
        centres = indices = None
        if lenses:
            if not isinstance(lenses, dict) or "rows" not in lenses:
                raise ValueError("lenses must be a mapping with rows [i, j, x, y]")
            table = _lens_table(lenses["rows"])
            indices, centres = table[:, :2].astype(np.int64), table[:, 2:]
            if "count" in lenses and lenses["count"] != len(table):
                raise ValueError(f"lenses.count {lenses['count']!r} for {len(table)} rows")
            if lenses.get("columns", LENS_COLUMNS) != LENS_COLUMNS:
                raise ValueError(f"lenses.columns {lenses['columns']!r}: the rows are read as "
                                 f"{LENS_COLUMNS}")
        angle_rad = _number("angle_rad", data["angle_rad"])
        if "angle_deg" in data and not abs(_number("angle_deg", data["angle_deg"])
                                           - np.degrees(angle_rad)) <= 1e-6:
            raise ValueError(f"angle_deg {data['angle_deg']!r} disagrees with angle_rad "
                             f"{data['angle_rad']!r}")
        offset = data["offset_xy"]
        if not isinstance(offset, (list, tuple)):
            raise ValueError(f"offset_xy must be two numbers (x, y), got {offset!r}")
        shape = data.get("image_shape")
        types = data.get("lens_type_of_coset")
        return cls(pitch_px=_number("pitch_px", data["pitch_px"]), angle_rad=angle_rad,
                   offset_xy=tuple(_number("offset_xy", v) for v in offset),
                   lattice=data.get("lattice", "hex"),
                   image_shape=_whole("image_shape", shape) if shape else None,
                   sensor_origin=_whole("sensor_origin", data.get("sensor_origin", (0, 0))),
                   centres_xy=centres, indices=indices,
                   lens_type_of_coset=_whole("lens_type_of_coset", types)
                   if types is not None else None)


def _number(name: str, value) -> float:
    """A YAML number (not text, not true/false) as a float; ValueError naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    return float(value)


def _lens_table(rows) -> np.ndarray:
    """(K, 4) float rows [i, j, x, y] of numbers (text, true/false or ragged rows refused)."""
    try:
        table = np.asarray(rows)
    except ValueError:
        table = None   # ragged rows
    if table is None or table.dtype.kind not in "iuf" or table.size % 4:
        raise ValueError("lenses.rows must be rows [i, j, x, y] of four numbers")
    return table.astype(float).reshape(-1, 4)


def fit_lattice(indices: np.ndarray, centres: np.ndarray, *, lattice: str = "hex",
                weights: np.ndarray | None = None, return_se: bool = False) -> tuple:
    """Least-squares similarity lattice through lens centres.

    ``x_ij = o + i b1 + j R(step) b1`` is linear in (o, b1), so this is one linear solve.

    Parameters
    ----------
    indices : (K, 2) lattice indices (i, j)
    centres : (K, 2) centres (x, y) in px
    weights : (K,) optional weights (0 drops a lens)

    Returns
    -------
    pitch_px, angle_rad (unreduced), offset_xy (the centre of lens (0, 0)), and with
    ``return_se`` the standard errors (pitch px, angle rad) from the residuals
    """
    if lattice not in LATTICES:
        raise ValueError(f"lattice must be one of {sorted(LATTICES)}, got {lattice!r}")
    i = np.asarray(indices[:, 0], float)
    j = np.asarray(indices[:, 1], float)
    cs, sn = np.cos(LATTICES[lattice]), np.sin(LATTICES[lattice])
    ones, zeros = np.ones_like(i), np.zeros_like(i)
    # unknowns (ox, oy, u, v); b1 = (u, v), b2 = (cs u - sn v, sn u + cs v)
    ax = np.stack([ones, zeros, i + j * cs, -j * sn], axis=1)
    ay = np.stack([zeros, ones, j * sn, i + j * cs], axis=1)
    a = np.concatenate([ax, ay])
    b = np.concatenate([centres[:, 0], centres[:, 1]])
    if weights is not None:
        w = np.sqrt(np.concatenate([weights, weights]))
        a, b = a * w[:, None], b * w
    # the 4 x 4 normal equations, not the 2K x 4 design: well conditioned, as lens indices
    # count from the middle of the frame
    inverse = np.linalg.pinv(a.T @ a)
    sol = inverse @ (a.T @ b)
    ox, oy, u, v = sol
    pitch, angle = float(np.hypot(u, v)), float(np.arctan2(v, u))
    if not return_se:
        return pitch, angle, (float(ox), float(oy))
    if not pitch > 0:
        return pitch, angle, (float(ox), float(oy)), (np.inf, np.inf)
    # standard errors from the normal equations: pitch along (u, v), angle across it
    dof = max(len(b) - 4, 1)
    cov = inverse * float(np.sum((a @ sol - b) ** 2)) / dof
    radial = np.array([u, v]) / pitch
    across = np.array([-v, u]) / pitch
    se_pitch = float(np.sqrt(radial @ cov[2:, 2:] @ radial))
    se_angle = float(np.sqrt(across @ cov[2:, 2:] @ across)) / pitch
    return pitch, angle, (float(ox), float(oy)), (se_pitch, se_angle)


def _check_point(name: str, xy) -> None:
    values = np.asarray(xy, float)
    if values.shape != (2,) or not np.all(np.abs(values) <= MAX_COORD_PX):  # false for NaN
        raise ValueError(f"{name} must be two finite pixel coordinates (|v| <= {MAX_COORD_PX:g}),"
                         f" got {xy}")


def _check_shape(shape) -> None:
    if (len(shape) != 2 or not all(float(v).is_integer() and 0 < v <= MAX_COORD_PX
                                   for v in shape)):
        raise ValueError(f"image_shape must be two positive whole numbers of pixels, got {shape}")


def _check_centres(centres, indices) -> None:
    xy, ij = np.asarray(centres), np.asarray(indices)
    if xy.ndim != 2 or xy.shape[1:] != (2,) or ij.shape != xy.shape:
        raise ValueError(f"centres_xy and indices must both be (lenses, 2) arrays, got shapes "
                         f"{xy.shape} and {ij.shape}")
    if not np.all(np.abs(xy) <= MAX_COORD_PX):
        raise ValueError("centres_xy must hold finite pixel coordinates; "
                         f"{int(np.sum(~(np.abs(xy) <= MAX_COORD_PX)))} values are not")
    if not ij.size:
        return
    span = np.ptp(ij, axis=0).astype(np.float64) + 1
    # tables indexed by (i, j) are allocated from this span: keep it compact
    compact = span[0] * span[1] <= 16 * len(ij) + 1024
    if compact and np.issubdtype(ij.dtype, np.integer):   # one count per lattice place
        place = (ij[:, 0] - ij[:, 0].min()) * int(span[1]) + (ij[:, 1] - ij[:, 1].min())
        repeated = bool(np.bincount(place).max() > 1)
    else:
        repeated = len(np.unique(ij, axis=0)) != len(ij)
    if repeated:
        raise ValueError("lens indices must be distinct; a lens (i, j) is listed twice")
    if not compact:
        raise ValueError(f"lens indices span {int(span[0])} x {int(span[1])} lattice places "
                         f"for {len(ij)} lenses; they must be a compact block of the lattice")


def _whole(name: str, values) -> tuple[int, ...]:
    """``values`` as whole numbers; a ValueError naming ``name`` for NaN, 1.5 or text."""
    if not isinstance(values, (list, tuple)) or any(
            isinstance(v, bool) or not isinstance(v, (int, float)) for v in values):
        raise ValueError(f"{name} must hold whole numbers, got {values!r}")
    numbers = [float(v) for v in values]
    if not all(v.is_integer() and abs(v) <= MAX_COORD_PX for v in numbers):
        raise ValueError(f"{name} must hold whole numbers, got {values!r}")
    return tuple(int(v) for v in numbers)
