"""ICC profiles of the output spaces, embedded in exported images.

sRGB comes from LittleCMS through Pillow (``ImageCms.createProfile("sRGB")``). LittleCMS can build
any matrix/TRC RGB profile, but Pillow does not expose that call and no maintained package on
PyPI ships Display P3 or linear Rec.2020 profiles for this Python; so those two are encoded
here as ICC.1:2001 (v2.1) display profiles of the simplest kind: ``desc``, ``cprt``, ``wtpt``,
colorants (``rXYZ``, ``gXYZ``, ``bXYZ``, Bradford-adapted to the D50 connection space) and one
tone curve per channel. The test suite opens them with LittleCMS and checks colour conversions
against colour-science.
"""

from __future__ import annotations

import io
import struct
import warnings

import numpy as np

from plenocli.model.colour import OUTPUT_SPACES, rgb_to_xyz

D50 = (0.9642, 1.0, 0.8249)  # the ICC profile connection space white
DESCRIPTIONS = {"display-p3": "Display P3 (plenocli)",
                "rec2020-linear": "Rec. ITU-R BT.2020 linear (plenocli)"}
TONE_CURVES = {"display-p3": "srgb", "rec2020-linear": "linear"}


def profile_bytes(space: str) -> bytes:
    """The ICC profile of an output space (a key of ``matrix.OUTPUT_SPACES``)."""
    if space not in OUTPUT_SPACES:
        raise ValueError(f"colour space {space!r} unknown; choose one of "
                         f"{', '.join(OUTPUT_SPACES)}")
    if space == "srgb":
        from PIL import ImageCms

        return ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    return _matrix_trc_profile(rgb_to_xyz(space), DESCRIPTIONS[space], TONE_CURVES[space])


def _s15(value: float) -> bytes:
    return struct.pack(">i", int(round(value * 65536)))


def _xyz_tag(xyz) -> bytes:
    return b"XYZ " + bytes(4) + b"".join(_s15(v) for v in xyz)


def _text_description(text: str) -> bytes:
    ascii_ = text.encode("ascii") + b"\0"
    return (b"desc" + bytes(4) + struct.pack(">I", len(ascii_)) + ascii_
            + struct.pack(">II", 0, 0) + struct.pack(">HB", 0, 0) + bytes(67))


def _curve(kind: str) -> bytes:
    if kind == "linear":  # count 0: the identity
        return b"curv" + bytes(4) + struct.pack(">I", 0)
    x = np.linspace(0.0, 1.0, 4096)
    y = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)  # IEC 61966-2-1 decoding
    return (b"curv" + bytes(4) + struct.pack(">I", x.size)
            + np.round(y * 65535).astype(">u2").tobytes())


def _bradford_to_d50(white_xyz) -> np.ndarray:
    with warnings.catch_warnings():  # colour-science warns about optional plotting packages
        warnings.simplefilter("ignore")
        from colour.adaptation import matrix_chromatic_adaptation_VonKries

        return np.asarray(matrix_chromatic_adaptation_VonKries(
            np.asarray(white_xyz), np.asarray(D50), transform="Bradford"))


def _matrix_trc_profile(to_xyz: np.ndarray, description: str, curve: str) -> bytes:
    white = to_xyz.sum(axis=1)  # XYZ of RGB = (1, 1, 1)
    adapted = _bradford_to_d50(white) @ to_xyz
    trc = _curve(curve)
    tags = [(b"desc", _text_description(description)),
            (b"cprt", b"text" + bytes(4) + b"No copyright, use freely\0"),
            (b"wtpt", _xyz_tag(white / white[1])),
            (b"rXYZ", _xyz_tag(adapted[:, 0])), (b"gXYZ", _xyz_tag(adapted[:, 1])),
            (b"bXYZ", _xyz_tag(adapted[:, 2])),
            (b"rTRC", trc), (b"gTRC", trc), (b"bTRC", trc)]
    table_size = 4 + 12 * len(tags)
    offset = 128 + table_size
    table, data, placed = io.BytesIO(), io.BytesIO(), {}
    table.write(struct.pack(">I", len(tags)))
    for signature, body in tags:
        if body not in placed:  # the three tone curves share one body
            placed[body] = offset + data.tell()
            data.write(body + bytes(-len(body) % 4))
        table.write(signature + struct.pack(">II", placed[body], len(body)))
    size = 128 + table_size + len(data.getvalue())
    header = (struct.pack(">I", size) + bytes(4) + struct.pack(">I", 0x02100000)
              + b"mntr" + b"RGB " + b"XYZ " + struct.pack(">6H", 2026, 1, 1, 0, 0, 0)
              + b"acsp" + bytes(24) + struct.pack(">I", 0)
              + b"".join(_s15(v) for v in D50) + bytes(48))
    return header + table.getvalue() + data.getvalue()
