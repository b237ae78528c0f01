"""Helpers of the bad-input tests: small files made by hand, and the run that checks that
nothing is left behind and no input changes."""

from __future__ import annotations

import hashlib
import json
import struct
import zlib
from pathlib import Path

import numpy as np
import tifffile
import yaml
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io import tiffio


def plain_tiff(path: Path, data: np.ndarray) -> None:
    tifffile.imwrite(path, data, photometric="minisblack", metadata=None)


def plenocli_tiff(path: Path, data: np.ndarray, **meta) -> None:
    data = np.asarray(data)
    rows, cols = data.shape[-2:]
    views = 1 if data.ndim == 2 else data.shape[0]
    base = {"views": [f"v{k}" for k in range(views)], "cfa": None, "origin": [0, 0],
            "active_area": [0, 0, rows, cols], "masked_areas": []}
    description = json.dumps({tiffio.FORMAT_KEY: tiffio.FORMAT_VERSION, **base, **meta})
    tifffile.imwrite(path, data, photometric="minisblack", metadata=None, description=description)


def huge_header_tiff(path: Path) -> None:
    """A tiny TIFF whose header claims 200000 x 200000 uint16 pixels in one strip."""
    entries = [(256, 4, 1, 200000), (257, 4, 1, 200000), (258, 3, 1, 16), (259, 3, 1, 1),
               (262, 3, 1, 1), (273, 4, 1, 8 + 2 + 12 * 9 + 4), (277, 3, 1, 1),
               (278, 4, 1, 200000), (279, 4, 1, 200000 * 200000 * 2 % 2 ** 32)]
    ifd = struct.pack("<H", len(entries))
    for tag, kind, count, value in entries:
        ifd += struct.pack("<HHI", tag, kind, count)
        ifd += struct.pack("<HH", value, 0) if kind == 3 else struct.pack("<I", value)
    body = b"II*\x00" + struct.pack("<I", 8) + ifd + struct.pack("<I", 0)
    path.write_bytes(body + bytes(831 - len(body)))


def png_chunk(kind: bytes, body: bytes) -> bytes:
    return (struct.pack(">I", len(body)) + kind + body
            + struct.pack(">I", zlib.crc32(kind + body)))


def write_grid_yaml(path: Path, base: dict, **changes) -> None:
    doc = {"lens_grid": {**base, **changes}}
    path.write_text(yaml.safe_dump(doc))


def hash_folder(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def run_bad(inputs: Path, out: Path, args: list[str]):
    out.mkdir(exist_ok=True)
    before = hash_folder(inputs)
    lens = Path(__file__).parents[2] / "configs" / "lenses" / "paper_table2.yaml"
    argv = [a.format(i=inputs, o=out, l=lens) for a in args]
    result = CliRunner().invoke(cli, argv)
    assert hash_folder(inputs) == before, "an input changed"
    left = [p.name for p in out.rglob("*")]
    assert not left, f"files left behind: {left}"
    return result


def assert_one_line(result, code: int, words: tuple[str, ...]) -> None:
    output = result.stderr if code == 1 else result.output
    assert "Traceback" not in result.output + result.stderr
    assert result.exit_code == code, result.output + result.stderr
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    if code == 1:
        assert len(lines) == 1, lines
        assert "internal error" not in lines[0], lines[0]
    assert lines[-1].startswith("Error:"), lines
    for word in words:
        assert word in output, (word, output)

