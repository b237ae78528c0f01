"""The refocus parameters' vocabulary: splatting kernels, pupil views and g values.

Kept apart from :mod:`plenocli.refocus` (numba kernels) so that declaring and checking the
parameters (the stage schema, ``--help``) does not compile or load the kernels.
"""

from __future__ import annotations

import math

from plenocli.model.numbers import decimal, number_word
from plenocli.model.views import g_label

KERNELS = {"bilinear": 1, "lanczos2": 2, "lanczos3": 3, "lanczos4": 4}
# (x sign, y sign) of the kept half-planes: -1 keeps d < -m/2, +1 keeps d > m/2, 0 keeps all.
VIEWS = {
    "full": (0, 0), "left": (-1, 0), "right": (1, 0), "top": (0, -1), "bottom": (0, 1),
    "q00": (-1, -1), "q01": (1, -1), "q10": (-1, 1), "q11": (1, 1),
}
MAX_G_VALUES = 1000  # a focal sweep longer than this is a typo, not a plan
# s is the output size relative to the sensor image: above 1 an output pixel gets fewer than one
# sensor sample on average (holes). refocus, depth's lenslet map and the Raytrix sweep alike.
MAX_S = 1.0


def parse_g(text: str | float) -> list[float]:
    """g values from "4", "2,3,4" or a range "start:stop:step" (stop included when on a step).

    Every value must be finite and non-zero, all of one sign (positive for a Keplerian camera,
    negative for a Galilean one, whose micro-images are inverted), and a sweep holds at most
    MAX_G_VALUES values (checked before the list is built: ``0:1e9:1`` is refused at once)."""
    if isinstance(text, (int, float)):
        values = [float(text)]
    else:
        values = _g_values(str(text).strip(), text)
    if not values or not (all(math.isfinite(v) and v > 0 for v in values)
                          or all(math.isfinite(v) and v < 0 for v in values)):
        raise ValueError(f"g must hold finite non-zero numbers of one sign (paper: 4; "
                         f"negative, e.g. -4, for a Galilean camera), got {text!r}")
    values = [round(v, 10) for v in values]
    # one page each, named by its g: two values a page name cannot tell apart would be two
    # pages of one name
    labels = [g_label(v) for v in values]
    twice = next((label for label in labels if labels.count(label) > 1), None)
    if twice is not None:
        same = sorted({v for v, label in zip(values, labels, strict=True) if label == twice})
        if len(same) == 1:
            raise ValueError(f"g {twice} is given twice in {text!r}; give each g once")
        raise ValueError(f"g {same[0]!r} and {same[1]!r} in {text!r} would name one sweep page "
                         f"(@g{twice}: a page names its g to 6 significant digits); give g "
                         "values that differ within their first 6 digits")
    return values


def g_words(text: str | float) -> str:
    """The resolved spelling of a valid g (:func:`parse_g`): each number as the shortest word
    that reads back as itself, no spaces; a range stays a range (``' 2 : 6 : 0.5 '`` is
    ``2:6:0.5``, ``'2, 3.0'`` is ``2,3``), so one g gives one record however it was typed."""
    parse_g(text)
    spec = str(text).strip()
    sep = ":" if ":" in spec else ","
    return sep.join(number_word(decimal(p)) for p in spec.split(sep))


def _g_values(spec: str, text) -> list[float]:
    usage = (f"g must be a number, a list like 2,3,4 or a range like 2:6:0.5 "
             f"(start:stop:step, step > 0), got {text!r}")
    try:
        parts = [decimal(p) for p in (spec.split(":") if ":" in spec else spec.split(","))]
    except ValueError as err:
        raise ValueError(usage) from err
    if ":" in spec:
        if (len(parts) != 3 or not all(math.isfinite(p) for p in parts) or parts[2] <= 0
                or parts[1] < parts[0]):
            raise ValueError(usage)
        count = int(math.floor((parts[1] - parts[0]) / parts[2] + 1e-9)) + 1
    else:
        count = len(parts)
    if count > MAX_G_VALUES:
        raise ValueError(f"g {text!r} asks for {count} refocus planes; a sweep holds at most "
                         f"{MAX_G_VALUES} (use a larger step)")
    if ":" in spec:
        return [parts[0] + k * parts[2] for k in range(count)]
    return parts


def check_mask_width(mask_width: float, pitch_px: float) -> None:
    """ValueError naming the widths that keep pixels: a central mask as wide as the
    micro-images (one pitch) or wider keeps none of them."""
    if not mask_width < pitch_px:
        raise ValueError(f"a mask width of {mask_width:g} px covers the whole {pitch_px:.4g} px "
                         f"micro-images; use 0 <= m < {pitch_px:.4g}")
