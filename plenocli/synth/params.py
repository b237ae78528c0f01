"""The parameters of the simulated kinds, declared once: what each name means and the values it
may take. ``check_params`` refuses, before any generator runs, a name the kind does not take, a
value not of its default's type and a value out of its range, whatever the values came from
(``simulate --param``, a YAML step, a test), and one given that the kind's other values leave
unused (g of a scene that is not the plane: recorded, yet changing nothing). A generator still
checks what depends on its other parameters (e.g. a pitch of at most a quarter of the sensor).
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable
from dataclasses import dataclass

from plenocli.depth import MAX_DISPARITY
from plenocli.errors import value_words

MAX_PIXELS = 2 ** 27  # a 134 Mpx sensor: beyond every camera simulated here
MAX_RAYS = 2 ** 31    # rays traced in all: hours of work, gigabytes of arrays
INF = math.inf


@dataclass(frozen=True)
class Param:
    """A parameter's meaning and range: ``low``..``high``, each end closed unless ``open_*``;
    no bounds for a text or a flag (the generator checks the choices)."""

    meaning: str
    low: float = -INF
    high: float = INF
    open_low: bool = False
    open_high: bool = False
    text: bool = False  # names, kept as written: 00 is the quarter "00", not the number 0

    def contains(self, value: float) -> bool:
        above = value > self.low if self.open_low else value >= self.low
        below = value < self.high if self.open_high else value <= self.high
        return above and below

    def describe(self) -> str:
        low, high = _exact(self.low), _exact(self.high)
        if self.high == INF:
            return f"{'>' if self.open_low else '>='} {low}"
        return (f"in {'(' if self.open_low else '['}{low}, {high}"
                f"{')' if self.open_high else ']'}")


def _exact(bound: float) -> str:
    """A bound as written, whole numbers in all their digits: %g's 4.29497e+09 for 2^32 read as
    a bound below the value it refused."""
    return str(int(bound)) if float(bound).is_integer() else f"{bound:g}"


_FRACTION = {"low": 0.0, "high": 1.0, "open_high": True}
PARAMS: dict[str, Param] = {
    "seed": Param("random seed", 0, 2 ** 32, open_high=True),
    # checked by the generator (and _check_pixels: one number for a square-only kind)
    "pixels": Param("sensor size, one number (square) or ROWSxCOLS where the kind takes it"),
    "rays": Param("rays per pixel", 1),
    "rows": Param("sensor rows, pixels", 16),
    "cols": Param("sensor columns, pixels", 16),
    "size": Param("sensor side, pixels", 16),
    "view_shape": Param("[ROWS, COLS] of each view, pixels", 32),
    # a read noise of more than the 16-bit range leaves nothing but noise in any capture
    "noise": Param("read noise, DN, or relative to the mean level", 0, 65535),
    "noise_dn": Param("read noise, DN", 0, 65535),
    "jitter_px": Param("random displacement of the lenses, pixels", 0),
    "edge_blur_px": Param("blur of the micro-image edges, pixels", 0),
    "crosstalk": Param("cross-talk ratio r", **_FRACTION),
    "r": Param("cross-talk ratio r", **_FRACTION),
    "ghost_r": Param("ghost ratio", **_FRACTION),
    "slope": Param("change of the mixing across the frame", **_FRACTION),
    "vignetting": Param("vignetting at the corners, fraction", **_FRACTION),
    "overlap": Param("overlap of neighbouring views, fraction", **_FRACTION),
    "pitch_px": Param("micro-lens pitch, pixels", 2),
    "s": Param("refocus scale s", 0, 1, open_low=True),
    "g_true": Param("true refocus parameter g", 0, open_low=True),
    "prism_apex_deg": Param("prism apex angle, degrees", 0, 90, open_high=True),
    "angle_deg": Param("lattice rotation, degrees", -180, 180),
    "no_prisms": Param("leave the prisms out"),
    "cross_mask": Param("cross mask in the stop"),
    "cfa": Param("Bayer pattern", text=True),
    "lattice": Param("micro-lens lattice", text=True),
    "model": Param("view transform model", text=True),
    "open_halves": Param("open pupil halves", text=True),
    "open_quarters": Param("open pupil quarters", text=True),
    "scene": Param("scene", text=True),
    "g": Param("refocus parameter g of the scene (negative: Galilean)", -100, 100),
    "distance_m": Param("distance of the plane, metres (0: placed by g)", 0),
    "disparities": Param("disparity of each band, pixels", -MAX_DISPARITY, MAX_DISPARITY),
    "quad": Param("2 x 2 sub-aperture views instead of A, B"),
}


def check_params(kind: str, generate: Callable[..., object], params: dict) -> dict:
    """``params`` as ``generate`` takes them (a whole number given where the default is a
    fraction made a float, as the shell's ``0`` means ``0.0``); ValueError (one line naming the
    parameter) unless every value is one ``generate`` takes, of its default's type, in its
    declared range, and the sensor and rays fit a machine."""
    accepted = inspect.signature(generate).parameters
    for key, value in params.items():
        if key not in accepted:
            raise ValueError(f"simulate {kind} does not take {key!r}; it takes: "
                             f"{', '.join(accepted)}")
        if key == "pixels":
            _check_pixels(kind, value, accepted[key].default)
        _check_type(kind, key, value, accepted[key].default)
        _check_range(kind, key, value)
        if key in RULES and value is not None:
            problem = RULES[key](value)
            if problem:
                raise ValueError(f"simulate {kind}: {key} = {value_words(value)}: {problem}")
    # the size asked for, the generator's defaults filling what is not given (a default 256 px
    # sensor times --rays 100000 is 6.6e9 rays)
    defaults = {k: v.default for k, v in accepted.items()
                if v.default is not inspect.Parameter.empty}
    _check_size(kind, {**defaults, **params})
    _check_used(kind, params, {**defaults, **params})
    return {key: _as_default(value, accepted[key].default) for key, value in params.items()}


def resolved_params(generate: Callable[..., object], params: dict) -> dict:
    """Every keyword of ``generate``: ``params`` (as :func:`check_params` returns them) over
    the generator's defaults."""
    accepted = inspect.signature(generate).parameters
    defaults = {k: v.default for k, v in accepted.items()
                if v.default is not inspect.Parameter.empty}
    return {**defaults, **{key: _as_default(value, accepted[key].default)
                           for key, value in params.items() if key in accepted}}


def _as_default(value, default):
    if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if isinstance(default, (tuple, list)) and isinstance(value, (tuple, list)):
        return type(value)(_as_default(v, d) for v, d in zip(value, default, strict=True))
    return value


def _cfa(value) -> str | None:
    from plenocli.model.cfa import check_pattern

    try:
        check_pattern(value)
    except ValueError as err:
        return str(err).removeprefix(f"cfa {value!r} ")
    return None


def _names(allowed: tuple[str, ...]):
    def problem(value) -> str | None:
        names = [n.strip() for n in str(value).split(",")]
        if set(names) - set(allowed) or len(set(names)) != len(names):
            return f"give distinct names from {', '.join(allowed)} separated by commas"
        return None
    return problem


def _g(value) -> str | None:
    # |g| <= 1 images no plane through the lenses (g = 1 is the lens plane itself); depth and
    # refocus refuse it, so a truth there could never be measured
    return "|g| must be > 1 (g = 1 is the micro-lens plane)" if abs(value) <= 1 else None


# what a range cannot say: the choices of a text, the planes no camera images
RULES: dict[str, Callable[[object], str | None]] = {
    "cfa": _cfa,
    "open_quarters": _names(("00", "01", "10", "11")),
    "open_halves": _names(("A", "B")),
    "g": _g,
    "g_true": _g,
}


def _g_unused(values: dict) -> str | None:
    if values.get("distance_m"):
        return (f"distance_m = {values['distance_m']!r} places the plane (its g from the "
                "simulated camera); give g or distance_m, not both")
    if values.get("scene") != "plane":
        return f"only the plane scene is placed by g (scene is {values.get('scene')!r}); give " \
               "scene=plane"
    return None


def _distance_unused(values: dict) -> str | None:
    if values.get("scene") != "plane":
        return (f"distance_m places the plane scene (scene is {values.get('scene')!r}); give "
                "scene=plane")
    return None


def _apex_unused(values: dict) -> str | None:
    if values.get("no_prisms"):
        return ("the prisms are left out (no_prisms, or a kind without prisms); leave "
                "prism_apex_deg out, or simulate a kind with prisms")
    return None


# a value the kind's other values leave unused: it would change nothing, yet be recorded
UNUSED_WHEN: dict[str, Callable[[dict], str | None]] = {
    "g": _g_unused,
    "distance_m": _distance_unused,
    "prism_apex_deg": _apex_unused,
}


def _check_used(kind: str, given: dict, values: dict) -> None:
    """Refuse a parameter given that the other values (given or default) leave unused."""
    for key, unused in UNUSED_WHEN.items():
        problem = unused(values) if key in given else None
        if problem:
            raise ValueError(f"simulate {kind}: {key} = {value_words(given[key])} is not used: "
                             f"{problem}")


def _check_range(kind: str, key: str, value) -> None:
    param = PARAMS[key]
    numbers = value if isinstance(value, (list, tuple)) else [value]
    if param.low == -INF and param.high == INF:
        return
    for number in numbers:
        if isinstance(number, (int, float)) and not isinstance(number, bool) \
                and not param.contains(number):
            raise ValueError(f"simulate {kind}: {key} must be {param.describe()} "
                             f"({param.meaning}), got {value_words(value)}")


def _check_pixels(kind: str, value, default) -> None:
    """A kind whose default sensor size is one number makes square sensors only."""
    if isinstance(default, int) and isinstance(value, str):
        raise ValueError(f"simulate {kind}: pixels = {value!r}: this kind's sensor is square; "
                         f"give one number, e.g. {default}")


def _check_type(kind: str, key: str, value, default) -> None:
    """A value of the type the kind's default has (a whole number where the default is one,
    a list of as many numbers as the default's), every number finite."""
    def number(v, whole: bool) -> bool:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            return False
        return math.isfinite(v) and (isinstance(v, int) or not whole)

    if default is None or default is inspect.Parameter.empty:
        ok = not isinstance(value, float) or math.isfinite(value)
    elif isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, (int, float)):
        ok = number(value, whole=isinstance(default, int))
    elif isinstance(default, (tuple, list)):
        ok = (isinstance(value, (tuple, list)) and len(value) == len(default)
              and all(number(v, whole=isinstance(d, int))
                      for v, d in zip(value, default, strict=True)))
    else:
        ok = isinstance(value, type(default))
    if not ok:
        shown_default = list(default) if isinstance(default, tuple) else default
        digits = ("; a whole number is written in digits, as YAML reads one: "
                  f"{key}={int(value)}" if isinstance(value, float) and math.isfinite(value)
                  and value.is_integer() and _expected(default) == "a whole number" else "")
        raise ValueError(f"simulate {kind}: {key} = {value_words(value)} is not "
                         f"{_expected(default)} "
                         f"(its default is {shown_default!r}){digits}")


def _expected(default) -> str:
    """What a value of ``default``'s type is, in words."""
    if isinstance(default, bool):
        return "true or false"
    if isinstance(default, int):
        return "a whole number"
    if isinstance(default, float):
        return "a finite number"
    if isinstance(default, (tuple, list)):
        whole = all(isinstance(d, int) for d in default)
        return f"a list of {len(default)} {'whole' if whole else 'finite'} numbers"
    return f"a {type(default).__name__}" if default is not None else "a finite value"


def _check_size(kind: str, params: dict) -> None:
    """Refuse, before any allocation, a sensor or a ray count no machine simulates."""
    rows, cols = _sensor_shape(params)
    rays = params["rays"] if isinstance(params.get("rays"), int) else 1
    if rows * cols > MAX_PIXELS or rows * cols * rays > MAX_RAYS:
        raise ValueError(f"simulate {kind}: {rows} x {cols} pixels x {rays} rays is beyond what "
                         f"a simulation holds ({MAX_PIXELS:.3g} pixels, {MAX_RAYS:.3g} rays); "
                         "simulate a smaller sensor or fewer rays")


def _sensor_shape(params: dict) -> tuple[int, int]:
    """(rows, cols) the parameters ask for, as far as they say (1 for what they leave out)."""
    pixels = params.get("pixels")
    if isinstance(pixels, int):
        return pixels, pixels
    parts = str(pixels).lower().split("x")
    if len(parts) == 2 and all(p.strip().isdigit() for p in parts):
        return int(parts[0]), int(parts[1])
    if isinstance(params.get("size"), int):
        return params["size"], params["size"]
    shape = params.get("view_shape")
    if isinstance(shape, (list, tuple)) and len(shape) == 2 and all(
            isinstance(v, int) for v in shape):
        return shape[0], shape[1]
    rows, cols = params.get("rows"), params.get("cols")
    return rows if isinstance(rows, int) else 1, cols if isinstance(cols, int) else 1
