"""Bad inputs over every command: exit 1 (2 for usage), one line, no traceback, no file left,
inputs unchanged.

Each case runs a command in-process (click's CliRunner) on a folder of small inputs, good and
bad, shared by the module; the output goes to a fresh folder that must stay empty. The inputs are
hashed before and after every case.
"""

from __future__ import annotations

import hashlib
import json
import os
import struct
import zlib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import tifffile
import yaml
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.errors import ConfigError
from plenocli.io import tiffio
from plenocli.io.dng import write_dng
from plenocli.io.raytrix import calib_from_grid, format_calib
from plenocli.pipeline.config import load_config
from plenocli.pipeline.stages.simulate import simulate
from plenocli.synth.dualpixel import dng_options, dualpixel_capture


def _plain_tiff(path: Path, data: np.ndarray) -> None:
    tifffile.imwrite(path, data, photometric="minisblack", metadata=None)


def _plenocli_tiff(path: Path, data: np.ndarray, **meta) -> None:
    data = np.asarray(data)
    rows, cols = data.shape[-2:]
    views = 1 if data.ndim == 2 else data.shape[0]
    base = {"views": [f"v{k}" for k in range(views)], "cfa": None, "origin": [0, 0],
            "active_area": [0, 0, rows, cols], "masked_areas": []}
    description = json.dumps({tiffio.FORMAT_KEY: tiffio.FORMAT_VERSION, **base, **meta})
    tifffile.imwrite(path, data, photometric="minisblack", metadata=None, description=description)


def _huge_header_tiff(path: Path) -> None:
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


def _png_chunk(kind: bytes, body: bytes) -> bytes:
    return (struct.pack(">I", len(body)) + kind + body
            + struct.pack(">I", zlib.crc32(kind + body)))


def _write_grid_yaml(path: Path, base: dict, **changes) -> None:
    doc = {"lens_grid": {**base, **changes}}
    path.write_text(yaml.safe_dump(doc))


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("inputs")
    runner = CliRunner()
    # a dual-pixel raw, decoded and bias-corrected
    raw, truth = dualpixel_capture(seed=3, rows=48, cols=64, top=8, left=16)
    write_dng(d / "dp.dng", raw, **dng_options(truth))
    for args in (["decode", d / "dp.dng", "-o", d / "frames.tif"],
                 ["bias", d / "frames.tif", "-o", d / "biased.tif"]):
        result = runner.invoke(cli, [str(a) for a in args])
        assert result.exit_code == 0, result.output
    white = truth["params"]["white_level"]
    write_dng(d / "clipped.dng", np.full_like(raw, white), **dng_options(truth))
    # a focused (Raytrix-like) capture and its grid
    simulate("raytrix-scene", d / "rt", seed=5, rows=120, cols=160)
    grid = yaml.safe_load((d / "rt" / "grid.yaml").read_text())["lens_grid"]
    base = {k: grid[k] for k in ("lattice", "pitch_px", "angle_rad", "offset_xy",
                                 "image_shape", "sensor_origin")}
    nan = float("nan")
    for name, change in {
        "angle_nan": {"angle_rad": nan}, "offset_nan": {"offset_xy": [nan, 3.0]},
        "pitch_nan": {"pitch_px": nan}, "pitch_inf": {"pitch_px": float("inf")},
        "pitch_tiny": {"pitch_px": 1e-6}, "rotation_inf": {"angle_rad": float("inf")},
        "shape_negative": {"image_shape": [-120, 160]},
        "lenses_nan": {"lenses": {"rows": [[0, 0, nan, 1.0], [0, 1, 3.0, 4.0]]}},
        "far_away": {"offset_xy": [1e9, 1e9]},
        "pitch_beyond_frame": {"pitch_px": 5000.0},
        "lens_twice": {"lenses": {"rows": [[0, 0, 10.0, 10.0], [0, 0, 11.0, 11.0]]}},
    }.items():
        _write_grid_yaml(d / f"grid_{name}.yaml", base, **change)
    _write_grid_yaml(d / "grid_noshape.yaml", {k: base[k] for k in base
                                               if k not in ("image_shape", "sensor_origin")})
    from plenocli.model.lensgrid import LensGrid

    calib = calib_from_grid(LensGrid.from_dict(base))
    (d / "rt" / "calib.xml").write_text(format_calib(calib))
    for name, change in {"basis_zero": {"lens_base_x": [0.0, 0.0]},
                         "basis_parallel": {"lens_base_y": calib["lens_base_x"]},
                         "diameter_inf": {"diameter": float("inf")},
                         "offset_nan": {"offset": [nan, 0.0]}}.items():
        (d / f"calib_{name}.xml").write_text(format_calib({**calib, **change}))
    # images for sai, flat and decode
    rng = np.random.default_rng(0)
    _plenocli_tiff(d / "f512.tif", rng.random((512, 512), np.float32))
    _plenocli_tiff(d / "f511x509.tif", rng.random((509, 511), np.float32))
    _plenocli_tiff(d / "f3.tif", rng.random((3, 3), np.float32))
    _plenocli_tiff(d / "nan.tif", np.full((64, 64), np.nan, np.float32))
    unmasked = 1 + 0.01 * rng.random((4, 64, 64), np.float32)
    for k in range(4):
        _plenocli_tiff(d / f"unmasked{k}.tif", unmasked, views=["S00", "S01", "S10", "S11"])
    _plenocli_tiff(d / "white_xy.tif", rng.random((2, 32, 32), np.float32), cfa="RGGB",
                   views=["X", "Y"])
    _plain_tiff(d / "complex.tif", (rng.random((16, 16)) + 1j).astype(np.complex64))
    _plain_tiff(d / "bool.tif", rng.random((16, 16)) > 0.5)
    _plain_tiff(d / "int8.tif", rng.integers(-100, 100, (16, 16)).astype(np.int8))
    _plain_tiff(d / "nan_plain.tif", np.full((16, 16), np.nan, np.float32))
    good = (d / "biased.tif").read_bytes()
    (d / "biased_copy.tif").write_bytes(good)  # another file with the same views
    (d / "truncated.tif").write_bytes(good[: len(good) * 2 // 3])
    _huge_header_tiff(d / "huge.tif")
    meta = tiffio.read_meta(d / "frames.tif")
    frames, _ = tiffio.read_image(d / "frames.tif")
    for name, change in {"active_beyond": {"active_area": [0, 0, 480, 640]},
                         "active_empty": {"active_area": [8, 16, 8, 16]},
                         "left_only": {"masked_areas": meta["masked_areas"][:1]}}.items():
        bad = dict(meta, **change)
        tifffile.imwrite(d / f"{name}.tif", frames, photometric="minisblack", metadata=None,
                         description=json.dumps({tiffio.FORMAT_KEY: 1, **bad}))
    for name, description in {
            "meta_future": json.dumps({tiffio.FORMAT_KEY: 99, **meta}),
            "meta_not_json": f'{{"{tiffio.FORMAT_KEY}": 1, "views": ["S",'}.items():
        tifffile.imwrite(d / f"{name}.tif", frames, photometric="minisblack", metadata=None,
                         description=description)
    (d / "not_yaml.yaml").write_text("lens_grid: [unclosed\n")
    for name, change in {"meta_black": {"black_level": "abc"},
                         "meta_black_short": {"black_level": [[0] * 4]},
                         "meta_white": {"white_level": [None, None]},
                         "meta_cfa": {"cfa": "XYZW"}, "meta_cfa_int": {"cfa": 5},
                         "meta_masked": {"masked_areas": "x"},
                         "meta_provenance": {"provenance": "x"},
                         "meta_views_twice": {"views": ["S", "S"]},
                         "meta_black_negative": {"black_level": [[-100] * 4] * 2}}.items():
        tifffile.imwrite(d / f"{name}.tif", frames, photometric="minisblack", metadata=None,
                         description=json.dumps({tiffio.FORMAT_KEY: 1, **meta, **change}))
    for name, text in {
        "grid_int": "lens_grid: 5\n",
        "grid_pitch_text": "lens_grid: {pitch_px: abc, angle_rad: 0, offset_xy: [0, 0]}\n",
        "grid_offset_short": "lens_grid: {pitch_px: 20, angle_rad: 0, offset_xy: [0]}\n",
        "grid_lattice": "lens_grid: {pitch_px: 20, angle_rad: 0, offset_xy: [0, 0], "
                        "lattice: tri}\n",
        "grid_origin_nan": "lens_grid: {pitch_px: 20, angle_rad: 0, offset_xy: [0, 0], "
                           "sensor_origin: [.nan, 0]}\n",
        "grid_origin_negative": "lens_grid: {pitch_px: 20, angle_rad: 0, offset_xy: [0, 0], "
                                "sensor_origin: [-5, 0]}\n",
        "grid_lens_row_short": "lens_grid: {pitch_px: 20, angle_rad: 0, offset_xy: [0, 0], "
                               "lenses: {rows: [[0, 0, 1]]}}\n",
        "grid_shape_3d": "lens_grid: {pitch_px: 20, angle_rad: 0, offset_xy: [0, 0], "
                         "image_shape: [3, 4, 5]}\n",
        "grid_square_tiny": "lens_grid: {pitch_px: 1, angle_rad: 0, offset_xy: [0, 0], "
                            "lattice: square}\n",
    }.items():
        (d / f"{name}.yaml").write_text(text)
    import cv2

    sensor = (rng.random((64, 64)) * 60000).astype(np.uint16)
    for suffix in (".png", ".bmp"):
        ok, encoded = cv2.imencode(suffix, sensor if suffix == ".png" else sensor >> 8)
        assert ok
        (d / f"trunc{suffix}").write_bytes(encoded.tobytes()[: encoded.size // 2])
    tifffile.imwrite(d / "zlib.tif", sensor, compression="zlib")
    packed = (d / "zlib.tif").read_bytes()
    (d / "zlib_trunc.tif").write_bytes(packed[: len(packed) // 2])
    _plain_tiff(d / "inf.tif", np.full((16, 16), np.inf, np.float32))
    (d / "huge.png").write_bytes(
        b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", struct.pack(">IIBBBBB", 200000, 200000,
                                                                16, 0, 0, 0, 0))
        + _png_chunk(b"IDAT", zlib.compress(bytes(100))) + _png_chunk(b"IEND", b""))
    _plain_tiff(d / "volume.tif", rng.random((2, 3, 16, 16)).astype(np.float32))
    (d / "garbage.tif").write_bytes(b"II*\x00" + rng.integers(0, 255, 500, np.uint8).tobytes())
    (d / "empty.tif").write_bytes(b"")
    return d


def _hash_folder(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def run_bad(inputs: Path, out: Path, args: list[str]):
    out.mkdir(exist_ok=True)
    before = _hash_folder(inputs)
    lens = Path(__file__).parents[1] / "configs" / "lenses" / "paper_table2.yaml"
    argv = [a.format(i=inputs, o=out, l=lens) for a in args]
    result = CliRunner().invoke(cli, argv)
    assert _hash_folder(inputs) == before, "an input changed"
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


# (id, argv with {i} = inputs folder and {o} = output folder, exit code, words in the message);
# a value the option's own type refuses is a usage error (exit 2), like any bad flag
CASES = [
    # refocus: g, s and grids
    # depth: a g bound past the shift the grid can measure (pitch / 0.25 px) is a usage error
    ("depth-g-past-measurable", ["depth", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                                 "--g", "2:1e308", "-o", "{o}/d.tif"], 2, ("--g", "1 < g <=")),
    ("depth-g-galilean-past-measurable", ["depth", "{i}/rt/frames.tif", "--grid",
                                          "{i}/rt/grid.yaml", "--g", "-1e6:-2", "-o",
                                          "{o}/d.tif"], 2, ("--g", "<= g < -1")),
    ("refocus-g0", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--g", "0",
                    "-o", "{o}/r.tif"], 2, ("non-zero",)),
    ("refocus-g-neg", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--g=-1",
                       "-o", "{o}/r.tif"], 1, ("Keplerian", "--g 1")),
    ("refocus-g-list-neg", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                            "--g", "2,-3", "-o", "{o}/r.tif"], 2, ("one sign",)),
    ("refocus-g-sweep-huge", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                              "--g", "0:1e9:1", "-o", "{o}/r.tif"], 2, ("at most 1000",)),
    ("refocus-g-sweep-1001", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                              "--g", "1:1001:1", "-o", "{o}/r.tif"], 2, ("at most 1000",)),
    ("refocus-g-list-1001", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                             "--g", ",".join(["4"] * 1001), "-o", "{o}/r.tif"], 2, ("1000",)),
    ("refocus-g-nan-range", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                             "--g", "nan:5:1", "-o", "{o}/r.tif"], 2, ("--g",)),
    ("refocus-g-inf", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--g",
                       "inf", "-o", "{o}/r.tif"], 2, ("g",)),
    ("refocus-s1000", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--s",
                       "1000", "-o", "{o}/r.tif"], 2, ("'--s'", "x<=1")),
    ("refocus-g-empty-item", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                              "--g", "1,,2", "-o", "{o}/r.tif"], 2, ("'--g'",)),
    ("refocus-s-tiny", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--s",
                        "1e-9", "-o", "{o}/r.tif"], 1, ("at least 4 pixels",)),
    ("refocus-g-huge", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--g",
                        "1e9", "-o", "{o}/r.tif"], 1, ("g = 1e+09", "no valid pixel")),
    ("refocus-mask-covers-lens", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                                  "--view", "left", "--mask-width", "1e9", "-o", "{o}/r.tif"],
     2, ("--mask-width", "0 <= m < ")),
    ("refocus-s-nan", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml", "--s",
                       "nan", "-o", "{o}/r.tif"], 2, ("'--s'",)),
    *[(f"refocus-grid-{name}", ["refocus", "{i}/rt/frames.tif", "--grid",
                                f"{{i}}/grid_{name}.yaml", "-o", "{o}/r.tif"], 1, words)
      for name, words in [("angle_nan", ("angle_rad",)), ("offset_nan", ("offset_xy",)),
                          ("pitch_nan", ("pitch_px",)), ("pitch_inf", ("pitch_px",)),
                          ("pitch_tiny", ("pitch_px",)), ("rotation_inf", ("angle_rad",)),
                          ("shape_negative", ("image_shape",)), ("lenses_nan", ("centres",)),
                          ("far_away", ("offset_xy",)),
                          ("pitch_beyond_frame", ("micro-images across",)),
                          ("lens_twice", ("listed twice",))]],
    *[(f"refocus-xml-{name}", ["refocus", "{i}/rt/frames.tif", "--grid",
                               f"{{i}}/calib_{name}.xml", "-o", "{o}/r.tif"], 1, words)
      for name, words in [("basis_zero", ("lens_base",)), ("basis_parallel", ("parallel",)),
                          ("diameter_inf", ("diameter",)), ("offset_nan", ("offset",))]],
    ("refocus-grid-not-yaml", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/not_yaml.yaml",
                               "-o", "{o}/r.tif"], 1, ("YAML",)),
    ("refocus-grid-misses-frame", ["refocus", "{i}/nan.tif", "--grid", "{i}/rt/grid.yaml",
                                   "-o", "{o}/r.tif"], 1,
     ("calibrated on a 160 x 120 image", "is 64 x 64", "same camera and crop")),
    ("refocus-all-nan", ["refocus", "{i}/nan.tif", "--grid", "{i}/grid_noshape.yaml",
                         "-o", "{o}/r.tif"], 1, ("no valid pixel",)),
    # sai: whole micro-images, enough of them
    ("sai-n7-512", ["sai", "{i}/f512.tif", "-n", "7", "-o", "{o}/v.tif"], 1,
     ("not a whole number", "511 x 511")),
    ("sai-n2-511x509", ["sai", "{i}/f511x509.tif", "-n", "2", "-o", "{o}/v.tif"], 1,
     ("not a whole number",)),
    ("sai-n2-3x3", ["sai", "{i}/f3.tif", "-n", "2", "-o", "{o}/v.tif"], 1, ("at least",)),
    ("sai-n-huge", ["sai", "{i}/f512.tif", "-n", "1000000", "-o", "{o}/v.tif"], 1,
     ("at least",)),
    ("sai-n0", ["sai", "{i}/f512.tif", "-n", "0", "-o", "{o}/v.tif"], 2, ("'-n'", "x>=1")),
    ("sai-all-nan", ["sai", "{i}/nan.tif", "-n", "2", "-o", "{o}/v.tif"], 1, ("no valid",)),
    # bias: guard, smooth, over-scan
    ("bias-guard-huge", ["bias", "{i}/frames.tif", "--guard", "99999", "-o", "{o}/b.tif"], 1,
     ("guard",)),
    ("bias-smooth-huge", ["bias", "{i}/frames.tif", "--smooth", "100000", "-o", "{o}/b.tif"],
     1, ("smooth",)),
    ("bias-overscan-top-missing", ["bias", "{i}/left_only.tif", "--overscan", "top", "-o",
                                   "{o}/b.tif"], 1, ("over-scan",)),
    ("bias-active-beyond", ["bias", "{i}/active_beyond.tif", "-o", "{o}/b.tif"], 1,
     ("active_area",)),
    ("bias-active-empty", ["bias", "{i}/active_empty.tif", "-o", "{o}/b.tif"], 1,
     ("active_area",)),
    ("bias-all-clipped", ["bias", "{o}/../clipped_frames.tif", "-o", "{o}/b.tif"], 1,
     ("no valid pixel",)),
    ("bias-crop-huge", ["bias", "{i}/frames.tif", "--crop", "99999x99999", "-o", "{o}/b.tif"],
     1, ("crop",)),
    ("bias-guard-negative", ["bias", "{i}/frames.tif", "--guard=-5", "-o", "{o}/b.tif"], 2,
     ("'--guard'", "x>=0")),
    # decode: levels and sample types
    ("decode-black-nan", ["decode", "{i}/f512.tif", "--black", "nan", "-o", "{o}/d.tif"], 2,
     ("black",)),
    ("decode-black-inf", ["decode", "{i}/f512.tif", "--black", "inf", "-o", "{o}/d.tif"], 2,
     ("black",)),
    ("decode-white-neg", ["decode", "{i}/zlib.tif", "--white=-5", "-o", "{o}/d.tif"], 2,
     ("white",)),
    ("decode-white-nan", ["decode", "{i}/zlib.tif", "--white", "nan", "-o", "{o}/d.tif"], 2,
     ("white",)),
    ("decode-black-above-white", ["decode", "{i}/zlib.tif", "--black", "900", "--white", "800",
                                  "-o", "{o}/d.tif"], 1, ("white level",)),
    ("decode-black-negative", ["decode", "{i}/zlib.tif", "--black=-3", "-o", "{o}/d.tif"], 2,
     ("black",)),
    # a level the samples cannot reach: refused here, not written for bias to call damaged
    ("decode-white-beyond-samples", ["decode", "{i}/zlib.tif", "--white", "1e308", "-o",
                                     "{o}/d.tif"], 1, ("(--white)", "uint16", "65535")),
    ("decode-white-70000", ["decode", "{i}/zlib.tif", "--white", "70000", "-o", "{o}/d.tif"], 1,
     ("(--white)", "65535")),
    ("decode-black-huge", ["decode", "{i}/zlib.tif", "--black", "1e308", "-o", "{o}/d.tif"], 1,
     ("black level 1e+308 (--black)",)),
    # a raw records its own levels and pattern: one value over them is not taken (audit 7 W7)
    *[(f"decode-raw-{name}", ["decode", "{i}/dp.dng", f"--{name}", value, "-o", "{o}/d.tif"],
       2, (f"--{name}", "records its own black and white levels and CFA pattern"))
      for name, value in (("black", "100"), ("white", "9000"), ("cfa", "BGGR"))],
    *[(f"decode-{kind}", ["decode", f"{{i}}/{kind}.tif", "-o", "{o}/d.tif"], 1, ("real",))
      for kind in ("complex", "bool", "int8")],
    ("decode-all-nan", ["decode", "{i}/nan_plain.tif", "-o", "{o}/d.tif"], 1, ("no valid",)),
    # audit 7 E2: a frame name that reads as another page (colour page S.R of a view S, a sweep
    # page, a page number) or twice is a usage error, before the raw is read
    ("decode-frame-colour-page", ["decode", "{i}/dp.dng", "--frames", "S.R,A", "-o",
                                  "{o}/d.tif"], 2, ("colour page R of a view S",)),
    ("decode-frame-sweep-page", ["decode", "{i}/dp.dng", "--frames", "S@g3,A", "-o",
                                 "{o}/d.tif"], 2, ("'@g'",)),
    # audit 8 E9: a newline in a name split every later one-line message naming the view
    ("decode-frame-control", ["decode", "{i}/dp.dng", "--frames", "S\nError: x,A", "-o",
                              "{o}/d.tif"], 2, ("control character",)),
    ("decode-frame-number", ["decode", "{i}/dp.dng", "--frames", "S,1", "-o", "{o}/d.tif"], 2,
     ("page number",)),
    ("decode-frame-twice", ["decode", "{i}/dp.dng", "--frames", "S,S", "-o", "{o}/d.tif"], 2,
     ("given twice",)),
    ("decode-truncated", ["decode", "{i}/truncated.tif", "-o", "{o}/d.tif"], 1,
     ("truncated",)),
    # audit 9 E6: a raw DNG was "a monochrome capture" and "a plain (not plenocli) TIFF" to
    # develop, and stitch, crosstalk, depth, sai, calibrate each said something else
    ("develop-raw", ["develop", "{i}/dp.dng", "-o", "{o}/x.jpg"], 1,
     ("is a raw capture (DNG)", "develop takes as input", "decode it first")),
    ("bias-raw", ["bias", "{i}/dp.dng", "-o", "{o}/x.tif"], 1, ("raw capture (DNG)",)),
    ("flat-white-raw", ["flat", "{i}/biased.tif", "--white", "{i}/dp.dng", "-o", "{o}/x.tif"], 1,
     ("raw capture (DNG)", "flat takes as white")),
    ("stitch-raw", ["stitch", "{i}/dp.dng", "-o", "{o}/x.tif"], 1, ("raw capture (DNG)",)),
    ("crosstalk-raw", ["crosstalk", "{i}/dp.dng", "-o", "{o}/x.json"], 1,
     ("raw capture (DNG)",)),
    ("depth-raw", ["depth", "{i}/dp.dng", "-o", "{o}/x.tif"], 1, ("raw capture (DNG)",)),
    # audit 9 W9: past 12 px a half-pixel view's blur leaves side lobes matched at wrong
    # shifts with clear confidence (bands of 16-31 px read 7-15 px, signs flipped)
    ("depth-max-disparity-past-measured", ["depth", "{i}/biased.tif", "--max-disparity", "24",
                                           "-o", "{o}/x.tif"], 2, ("--max-disparity", "12")),
    ("simulate-disparity-past-measured", ["simulate", "dualpixel-depth", "-o", "{o}/s",
                                          "--param", "disparities=[-20,-2,-1,0,1,2,3,20]"], 2,
     ("disparities", "12")),
    ("sai-raw", ["sai", "{i}/dp.dng", "-n", "2", "-o", "{o}/x.tif"], 1, ("raw capture (DNG)",)),
    ("calibrate-raw", ["calibrate", "{i}/dp.dng", "-o", "{o}/g.yaml"], 1,
     ("raw capture (DNG)",)),
    # audit 9 E3: a view named twice in --views was exit 1, --frames S,S a usage error
    ("stitch-views-twice", ["stitch", "{i}/biased.tif", "--views", "A,A", "-o", "{o}/p.tif"], 2,
     ("'A' is named twice",)),
    ("decode-huge-header", ["decode", "{i}/huge.tif", "-o", "{o}/d.tif"], 1, ("200000",)),
    ("decode-empty-file", ["decode", "{i}/empty.tif", "-o", "{o}/d.tif"], 1,
     ("empty.tif", "not a raw capture")),
    *[(f"decode-{name}", ["decode", f"{{i}}/{name}", "-o", "{o}/d.tif"], 1, words)
      for name, words in [("trunc.png", ("unreadable",)), ("trunc.bmp", ("unreadable",)),
                          ("zlib_trunc.tif", ("truncated",)), ("inf.tif", ("infinite",)),
                          ("volume.tif", ("shape",)), ("garbage.tif", ("damaged",)),
                          ("huge.png", ("more than",))]],
    ("decode-frames-empty", ["decode", "{i}/dp.dng", "--frames=", "-o", "{o}/d.tif"], 2,
     ("'--frames'", "empty")),
    ("decode-frames-count", ["decode", "{i}/dp.dng", "--frames", "S,A,B", "-o", "{o}/d.tif"],
     1, ("3 frame names",)),
    ("decode-calib-without-raytrix", ["decode", "{i}/dp.dng", "--calib", "{i}/rt/calib.xml",
                                      "-o", "{o}/d.tif"], 1, ("--calib",)),
    ("decode-raytrix-bad-calib", ["decode", "{i}/f512.tif", "--camera", "raytrix", "--calib",
                                  "{i}/calib_basis_zero.xml", "-o", "{o}/d.tif"], 1,
     ("lens_base",)),
    ("decode-cfa-bad", ["decode", "{i}/f512.tif", "--cfa", "RRGB", "-o", "{o}/d.tif"], 2,
     ("'--cfa'",)),
    # flat
    # (a white flat-fielded by itself only with --save-gain: one file given twice otherwise)
    ("flat-median-huge", ["flat", "{i}/biased.tif", "--white", "{i}/biased.tif", "--median",
                          "100001", "-o", "{o}/f.tif", "--save-gain", "{o}/g.tif"], 1,
     ("median",)),
    ("flat-white-nan", ["flat", "{i}/nan.tif", "--white", "{i}/nan.tif", "-o", "{o}/f.tif",
                        "--save-gain", "{o}/g.tif"], 1, ("no valid pixel",)),
    ("flat-truncated-white", ["flat", "{i}/biased.tif", "--white", "{i}/truncated.tif", "-o",
                              "{o}/f.tif"], 1, ("truncated",)),
    ("flat-percentile-nan", ["flat", "{i}/biased.tif", "--white", "{i}/biased.tif",
                             "--reference", "percentile", "--percentile", "nan", "-o",
                             "{o}/f.tif"], 2, ("percentile",)),
    ("flat-floor-nan", ["flat", "{i}/biased.tif", "--white", "{i}/biased.tif", "--floor", "nan",
                        "-o", "{o}/f.tif"], 2, ("floor",)),
    # a value the option's own rule refuses, or an option with no effect: usage errors naming it
    ("flat-median-even", ["flat", "{i}/biased.tif", "--white", "{i}/biased.tif", "--median",
                          "10", "-o", "{o}/f.tif"], 2, ("'--median'", "10 is not odd")),
    # audit 8 W6: S = A + B named in --views beside A only passed (r = 68 %, exit 0)
    ("crosstalk-views-sum", ["crosstalk", "{i}/biased.tif", "--views", "A,S", "-o",
                             "{o}/c.json"], 1, ("S is the sum A + B",)),
    ("crosstalk-tile-odd", ["crosstalk", "{i}/biased.tif", "--tile", "3", "-o", "{o}/c.json"], 2,
     ("'--tile'", "3 is not even")),
    # audit 7 E17: one source of the gain is a usage error, as other option pairs are
    ("flat-white-and-gain", ["flat", "{i}/biased.tif", "--white", "{i}/biased_copy.tif", "--gain",
                             "{i}/biased.tif", "-o", "{o}/f.tif"], 2, ("exactly one of",)),
    ("flat-no-white-nor-gain", ["flat", "{i}/biased.tif", "-o", "{o}/f.tif"], 2,
     ("exactly one of",)),
    ("flat-gain-with-median", ["flat", "{i}/biased.tif", "--gain", "{i}/biased.tif", "--median",
                               "7", "-o", "{o}/f.tif"], 2, ("--median makes a gain",)),
    ("flat-gain-with-floor", ["flat", "{i}/biased.tif", "--gain", "{i}/biased.tif", "--floor",
                              "0.5", "-o", "{o}/f.tif"], 2, ("--floor makes a gain",)),
    ("flat-percentile-with-max", ["flat", "{i}/biased.tif", "--white", "{i}/biased.tif",
                                  "--percentile", "0", "-o", "{o}/f.tif"], 2,
     ("--percentile applies to --reference percentile",)),
    ("refocus-mask-width-full-view", ["refocus", "{i}/rt/frames.tif", "--grid",
                                      "{i}/rt/grid.yaml", "--mask-width", "5", "-o",
                                      "{o}/r.tif"], 2, ("--mask-width applies to half",)),
    ("flat-not-bias-corrected", ["flat", "{i}/frames.tif", "--white", "{i}/frames.tif", "-o",
                                 "{o}/f.tif", "--save-gain", "{o}/g.tif"], 1,
     ("run plenocli bias first",)),
    ("flat-white-not-bias-corrected", ["flat", "{i}/biased.tif", "--white", "{i}/frames.tif",
                                       "-o", "{o}/f.tif"], 1, ("run plenocli bias first",)),
    ("flat-gain-not-gain", ["flat", "{i}/biased.tif", "--gain", "{i}/biased_copy.tif", "-o",
                            "{o}/f.tif"], 1, ("not a gain",)),
    ("flat-white-other-size", ["flat", "{i}/biased.tif", "--white", "{i}/f512.tif", "-o",
                               "{o}/f.tif"], 1, ("white image",)),
    # refocus and sai: other options
    *[(f"refocus-{opt}-{value}", ["refocus", "{i}/rt/frames.tif", "--grid", "{i}/rt/grid.yaml",
                                  f"--{opt}", value, "-o", "{o}/r.tif"], 2, (f"'--{opt}'",))
      for opt, value in [("radius", "nan"), ("radius", "-1"), ("min-weight", "nan"),
                         ("mask-width", "inf"), ("mask-width", "-1")]],
    ("sai-grid-hex", ["sai", "{i}/rt/frames.tif", "-n", "2", "--grid", "{i}/rt/grid.yaml", "-o",
                      "{o}/v.tif"], 1, ("square",)),
    ("sai-of-views", ["sai", "{o}/../views.tif", "-o", "{o}/v.tif"], 1, ("`plenocli sai` output",)),
    ("sai-dualpixel-views", ["sai", "{i}/biased.tif", "-o", "{o}/v.tif"], 1, ("dual-pixel",)),
    ("sai-micro-image-mono", ["sai", "{i}/f512.tif", "--cfa-layout", "micro-image", "-o",
                              "{o}/v.tif"], 1, ("no CFA",)),
    ("sai-cfa-layout", ["sai", "{i}/f512.tif", "--cfa-layout", "diagonal", "-o", "{o}/v.tif"],
     2, ("cfa-layout",)),
    # metadata a stage reads, edited or damaged
    *[(f"bias-{name}", ["bias", f"{{i}}/{name}.tif", "-o", "{o}/b.tif"], 1, (word,))
      for name, word in [("meta_black", "black_level"), ("meta_black_short", "black_level"),
                         ("meta_white", "white_level"), ("meta_cfa", "cfa"),
                         ("meta_cfa_int", "cfa"), ("meta_masked", "masked area"),
                         ("meta_provenance", "provenance"), ("meta_views_twice", "twice"),
                         ("meta_black_negative", "black_level"), ("meta_future", "format 99"),
                         ("meta_not_json", "damaged")]],
    ("info-meta-not-json", ["info", "{i}/meta_not_json.tif"], 1, ("damaged",)),
    ("sai-meta-cfa", ["sai", "{i}/meta_cfa.tif", "-n", "2", "-o", "{o}/v.tif"], 1, ("cfa",)),
    *[(f"refocus-{name}", ["refocus", "{i}/rt/frames.tif", "--grid", f"{{i}}/{name}.yaml",
                           "-o", "{o}/r.tif"], 1, (word,))
      for name, word in [("grid_int", "lens grid"), ("grid_pitch_text", "abc"),
                         ("grid_offset_short", "offset_xy"), ("grid_lattice", "lattice"),
                         ("grid_origin_nan", "sensor_origin"),
                         ("grid_origin_negative", "sensor_origin"),
                         ("grid_lens_row_short", "lens grid"),
                         ("grid_shape_3d", "image_shape")]],
    ("sai-grid-pitch-below-n", ["sai", "{i}/rt/frames.tif", "--grid", "{i}/grid_square_tiny.yaml",
                                "-n", "3", "-o", "{o}/v.tif"], 1, ("sub-apertures",)),
    ("info-grid-origin-nan", ["info", "{i}/grid_origin_nan.yaml"], 1, ("sensor_origin",)),
    # crosstalk
    ("crosstalk-views-twice", ["crosstalk", "{i}/biased.tif", "--views", "B, B", "-o",
                               "{o}/c.json"], 2, ("'B' is named twice",)),  # audit 9 E3
    # audit 9 E12: one view named was "holds one view (A; pages R, G, B are its colours)"
    ("crosstalk-views-one", ["crosstalk", "{i}/biased.tif", "--views", "A", "-o", "{o}/c.json"],
     2, ("--views names one view (A): cross-talk compares two or more",)),
    ("crosstalk-views-twice-by-number", ["crosstalk", "{i}/biased.tif", "--views", "A,0", "-o",
                                         "{o}/c.json"], 1, ("twice",)),
    ("crosstalk-same-white-twice", ["crosstalk", "{i}/unmasked0.tif", "{i}/unmasked0.tif",
                                    "{i}/unmasked2.tif", "{i}/unmasked3.tif", "--intended",
                                    "S00,S01,S10,S11", "--mixing-out", "{o}/m.tif", "-o",
                                    "{o}/c.json"], 1, ("given twice",)),
    ("crosstalk-whites-not-masked", ["crosstalk", "{i}/unmasked0.tif", "{i}/unmasked1.tif",
                                     "{i}/unmasked2.tif", "{i}/unmasked3.tif", "--intended",
                                     "S00,S01,S10,S11", "--mixing-out", "{o}/m.tif", "-o",
                                     "{o}/c.json"], 1, ("not brighter",)),
    ("unmix-same-views-twice", ["unmix", "{i}/unmasked0.tif", "{i}/unmasked0.tif", "--mixing",
                                "{i}/unmasked1.tif", "-o", "{o}/u.tif"], 1, ("given twice",)),
    ("crosstalk-grid-without-sweep", ["crosstalk", "{i}/biased.tif", "--grid",
                                      "{i}/rt/grid.yaml", "-o", "{o}/c.json"], 2,
     ("--grid applies to the --mask-widths sweep only",)),
    # a mask as wide as the micro-images keeps none of them: the range it can take is named
    ("crosstalk-mask-widths-past-the-pitch", ["crosstalk", "{i}/rt/frames.tif", "--grid",
                                              "{i}/rt/grid.yaml", "--mask-widths", "0,1e308",
                                              "--tile", "8", "-o", "{o}/c.json"], 2,
     ("--mask-widths", "0 <= m < ")),
    ("crosstalk-mask-widths-infinite", ["crosstalk", "{i}/rt/frames.tif", "--grid",
                                        "{i}/rt/grid.yaml", "--mask-widths", "0,inf", "-o",
                                        "{o}/c.json"], 2, ("'--mask-widths'", ">= 0 px")),
    # audit 9 E8: the sweep wrote no preview and said nothing
    ("crosstalk-mask-widths-preview", ["crosstalk", "{i}/rt/frames.tif", "--grid",
                                       "{i}/rt/grid.yaml", "--mask-widths", "0,1", "-o",
                                       "{o}/c.json", "--preview", "{o}/c.png"], 2,
     ("--preview is not drawn for the --mask-widths sweep",)),
    ("crosstalk-mask-widths-twice", ["crosstalk", "{i}/rt/frames.tif", "--grid",
                                     "{i}/rt/grid.yaml", "--mask-widths", "0,1,1", "-o",
                                     "{o}/c.json"], 2, ("'--mask-widths'", "each once")),
    # optics
    ("optics-png", ["optics", "{i}/huge.png"], 1, ("not a YAML lens",)),
    ("optics-prism-n-1", ["optics", "{l}", "--prism-n", "1"], 2, ("'--prism-n'",)),
    ("optics-prism-n-huge", ["optics", "{l}", "--prism-n", "1e9"], 2, ("'--prism-n'",)),
    ("optics-prism-reflects", ["optics", "{l}", "--prism-apex-deg", "89.9"], 1,
     ("totally",)),
    ("optics-sensor-beyond-image-circle", ["optics", "{l}", "--sensor-mm", "20"], 1,
     ("image circle",)),
    ("optics-pixel-huge", ["optics", "{l}", "--crosstalk", "--pixel-um", "1e9"], 2,
     ("'--pixel-um'",)),
    ("optics-pixel-tiny", ["optics", "{l}", "--crosstalk", "--pixel-um", "1e-9"], 2,
     ("'--pixel-um'",)),
    # simulate
    # audit 7 E11: a value simulate does not take is a usage error (exit 2), as for a flag
    ("simulate-pixels-0", ["simulate", "dualpixel", "-o", "{o}/s", "--pixels", "0"], 2,
     ("'0' is not one positive whole number",)),
    ("simulate-pixels-huge", ["simulate", "dualpixel", "-o", "{o}/s", "--pixels", "1000000"], 2,
     ("smaller sensor",)),
    ("simulate-rays-huge", ["simulate", "quadpixel-white", "-o", "{o}/s", "--pixels", "64",
                            "--rays", "100000000"], 2, ("smaller sensor",)),
    ("simulate-rows-x-cols-for-one-number", ["simulate", "dualpixel-white", "-o", "{o}/s",
                                             "--pixels", "64x96"], 2, ("pixels = '64x96'",)),
    ("simulate-param-nan", ["simulate", "hexgrid-white", "-o", "{o}/s", "--param",
                            "pitch_px=.nan"], 2, ("pitch_px = nan",)),
    ("simulate-param-text", ["simulate", "hexgrid-white", "-o", "{o}/s", "--param", "size=abc"],
     2, ("size = 'abc'",)),
    ("simulate-pixels-tiny", ["simulate", "dualpixel", "-o", "{o}/s", "--pixels", "2"], 2,
     ("at least 16",)),
    ("simulate-pitch-negative", ["simulate", "hexgrid-white", "-o", "{o}/s", "--param",
                                 "pitch_px=-3"], 2, ("pitch_px must be",)),
    ("simulate-rig-empty-views", ["simulate", "stereo-rig", "-o", "{o}/s", "--param",
                                  "view_shape=[0, 0]"], 2, ("view_shape must be",)),
    ("simulate-raytrix-s-0", ["simulate", "raytrix-scene", "-o", "{o}/s", "--param", "s=0"], 2,
     ("s must be",)),
    ("simulate-raytrix-g-negative", ["simulate", "raytrix-scene", "-o", "{o}/s", "--param",
                                     "g_true=-1"], 2, ("g_true must be > 0",)),
    ("simulate-noise-negative", ["simulate", "dualpixel", "-o", "{o}/s", "--param", "noise=-5"],
     2, ("noise must be in [0, 65535]", "got -5")),
    ("simulate-crosstalk-one", ["simulate", "dualpixel-prism", "-o", "{o}/s", "--pixels", "48",
                                "--param", "crosstalk=1"], 2, ("crosstalk must be in [0, 1)",)),
    ("simulate-param-unknown", ["simulate", "dualpixel", "-o", "{o}/s", "--param", "nosie=1"],
     2, ("does not take 'nosie'", "noise")),
    ("bias-crop-below-cfa-cell", ["bias", "{i}/frames.tif", "--crop", "1x1", "-o", "{o}/b.tif"],
     1, ("CFA cell",)),
    ("develop-wb-huge", ["develop", "{i}/biased.tif", "--view", "S", "--wb", "1e308,1,1", "-o",
                         "{o}/d.jpg"], 2, ("100 times",)),
    ("develop-wb-from-other-views", ["develop", "{i}/biased.tif", "--view", "S", "--matrix",
                                     "none", "--wb-from", "{i}/white_xy.tif", "-o",
                                     "{o}/d.jpg"], 1, ("no view S",)),
    # batch
    ("batch-timeout-0", ["batch", "{i}/none.yaml", "--inputs", "{i}/dp.dng", "--timeout", "0"],
     2, ("'--timeout'", "x>0")),
    ("batch-timeout-nan", ["batch", "{i}/none.yaml", "--inputs", "{i}/dp.dng", "--timeout",
                           "nan"], 2, ("'--timeout'", "not a finite number")),
    ("batch-scheduler-malformed", ["batch", "{i}/none.yaml", "--inputs", "{i}/dp.dng",
                                   "--scheduler", "nonsense"], 1, ("tcp://HOST:PORT",)),
    ("batch-scheduler-not-there", ["batch", "{i}/none.yaml", "--inputs", "{i}/dp.dng",
                                   "--scheduler", "tcp://127.0.0.1:1"], 1, ("cannot reach",)),
    ("batch-inputs-none", ["batch", "{i}/none.yaml", "--inputs", "{i}/nothing/*.dng"], 1,
     ("matches no file",)),
    ("unmix-regularise-huge", ["unmix", "{i}/qg/views.tif", "--mixing", "{i}/qg/mixing.tif",
                               "--regularise", "1e308", "-o", "{o}/u.tif"], 2,
     ("'--regularise'",)),
    # info
    ("info-zlib-truncated", ["info", "{i}/zlib_trunc.tif"], 1, ("truncated",)),
    ("info-garbage", ["info", "{i}/garbage.tif"], 1, ("damaged",)),
    ("info-huge-png", ["info", "{i}/huge.png"], 1, ("more than",)),
    ("info-bad-xml", ["info", "{i}/calib_basis_zero.xml"], 1, ("lens_base",)),
    ("info-bad-yaml", ["info", "{i}/not_yaml.yaml"], 1, ("YAML",)),
    ("info-truncated", ["info", "{i}/truncated.tif"], 1, ("truncated",)),
    ("info-huge-header", ["info", "{i}/huge.tif"], 1, ("200000",)),
    ("info-empty", ["info", "{i}/empty.tif"], 1, ("empty.tif", "does not know this kind")),
    # every reader: a damaged TIFF is one line
    ("sai-truncated", ["sai", "{i}/truncated.tif", "-o", "{o}/v.tif"], 1, ("truncated",)),
    ("refocus-huge", ["refocus", "{i}/huge.tif", "--grid", "{i}/rt/grid.yaml", "-o",
                      "{o}/r.tif"], 1, ("200000",)),
    ("bias-device", ["bias", "/dev/null", "-o", "{o}/b.tif"], 1, ("not a regular file",)),
    ("info-device", ["info", "/dev/zero"], 1, ("not a regular file",)),
    ("decode-folder-as-calib", ["decode", "{i}/f512.tif", "--camera", "raytrix", "--calib",
                                "{i}/rt", "-o", "{o}/d.tif"], 2, ("directory",)),
    ("bias-complex", ["bias", "{i}/complex.tif", "-o", "{o}/b.tif"], 1, ("real",)),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_and_leaves_nothing(case, inputs, tmp_path):
    name, args, code, words = case
    if "views.tif" in " ".join(args):
        result = CliRunner().invoke(cli, ["sai", str(inputs / "f512.tif"), "-o",
                                          str(tmp_path / "views.tif")])
        assert result.exit_code == 0, result.output
    if "clipped_frames" in " ".join(args):
        result = CliRunner().invoke(cli, ["decode", str(inputs / "clipped.dng"), "-o",
                                          str(tmp_path / "clipped_frames.tif")])
        assert result.exit_code == 0, result.output
    result = run_bad(inputs, tmp_path / "out", args)
    assert_one_line(result, code, words)


@pytest.mark.parametrize("head", [b"II*\0", b"MM\0*", b"II*\0\x08\0\0", b"II+\0\x08\0\0\0"])
@pytest.mark.parametrize("command", [["info"], ["info", "--json"], ["decode", "-o", "{o}/d.tif"],
                                     ["decode", "--camera", "dng", "-o", "{o}/d.tif"],
                                     ["bias", "-o", "{o}/b.tif"], ["sai", "-o", "{o}/s.tif"],
                                     ["calibrate", "-o", "{o}/g.yaml"]])
def test_a_tiff_cut_inside_its_header_is_damaged_not_an_internal_error(head, command, tmp_path):
    # audit 7 I1: tifffile's struct.error ("unpack requires a buffer of 4 bytes") was an
    # internal error in every command
    cut = tmp_path / "in" / "cut.tif"
    cut.parent.mkdir()
    cut.write_bytes(head)
    result = run_bad(tmp_path / "in", tmp_path / "out", [command[0], str(cut), *command[1:]])
    assert_one_line(result, 1, ("damaged TIFF", "ends inside its header", "truncated"))


def test_truncated_tiff_gives_no_stray_tifffile_line(inputs, tmp_path, capfd):
    result = run_bad(inputs, tmp_path / "out", ["info", "{i}/truncated.tif"])
    captured = capfd.readouterr()
    assert "tifffile" not in captured.err + captured.out + result.stderr
    assert_one_line(result, 1, ("truncated",))


# ------------------- the parameter path and the stage edge (more in tests/cli/test_edge.py)

@pytest.mark.parametrize("step,words", [
    ({"stage": "bias", "smooth": -3}, ("smooth",)),
    ({"stage": "bias", "guard": -5}, ("guard",)),
    ({"stage": "bias", "smooth": 1.5}, ("smooth",)),
    ({"stage": "bias", "smooth": "abc"}, ("smooth",)),
])
def test_yaml_values_are_checked_like_flags(step, words, inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(yaml.safe_dump({"out": str(out), "steps": {"bias": {
        **step, "input": str(inputs / "frames.tif"), "output": "{out}/b.tif"}}}))
    result = run_bad(inputs, out, ["run", str(config)])
    assert_one_line(result, 1, words)


def test_a_view_named_twice_in_yaml_is_refused_like_the_flag(inputs, tmp_path):
    # audit 9 E3: --views is checked when read, as --frames is
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(yaml.safe_dump({"out": str(out), "steps": {"stitch": {
        "inputs": [str(inputs / "biased.tif")], "views": "A, A", "output": "{out}/p.tif"}}}))
    result = run_bad(inputs, out, ["run", str(config)])
    assert_one_line(result, 1, ("--views", "'A' is named twice"))


def test_simulate_params_from_yaml_are_checked_like_flags(inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(yaml.safe_dump({"out": str(out), "steps": {"sim": {
        "stage": "simulate", "kind": "dualpixel", "output": "{out}/s",
        "param": ["noise=-5"]}}}))
    result = run_bad(inputs, out, ["run", str(config)])
    assert_one_line(result, 1, ("noise must be in [0, 65535]", "got -5"))


@pytest.mark.parametrize("args,words", [
    (["flat", "{i}/biased.tif", "--white", "{i}/biased.tif", "--save-gain", "{o}/x.tif"],
     ("two outputs",)),
    (["flat", "{i}/biased.tif", "--white", "{i}/biased.tif", "--save-gain", "{i}/biased.tif"],
     ("also an input",)),
])
def test_outputs_that_collide_are_refused(args, words, inputs, tmp_path):
    result = run_bad(inputs, tmp_path / "out", [*args, "-o", "{o}/x.tif"])
    assert_one_line(result, 1, words)


@pytest.mark.parametrize("args", [
    ["decode", "{i}/dp.dng", "-o", "{o}/x.tif", "--preview", "{o}/x.jpg"],
    ["decode", "{i}/dp.dng", "-o", "{o}/x.tif", "--preview", "{o}/x"],
    ["decode", "{i}/dp.dng", "-o", "{o}/x.png"],
    ["flat", "{i}/biased.tif", "--white", "{i}/biased.tif", "-o", "{o}/x.tif", "--save-gain",
     "{o}/g.png"],
    ["develop", "{i}/biased.tif", "--view", "S", "-o", "{o}/x.jpg", "--linear", "{o}/l.png"],
    ["optics", "{i}/none.yaml", "--json", "{o}/x.yaml"],
])
def test_an_output_named_for_another_format_is_refused(args, inputs, tmp_path):
    result = run_bad(inputs, tmp_path / "out", args)
    assert_one_line(result, 2, ("ending in",))


@pytest.mark.parametrize("args,words", [
    (["decode", "{i}/dp.dng", "-o", "{o}/.tif"], "has no name before its suffix"),
    (["decode", "{i}/dp.dng", "-o", "{o}/x.tif", "--preview", "{o}/.PNG"],
     "has no name before its suffix"),
    (["decode", "{i}/dp.dng", "-o", "{o}/nl\nname.tif"], "holds a control character ('\\n')"),
    (["simulate", "dualpixel", "-o", "{o}/a\tb"], "holds a control character ('\\t')"),
])
def test_an_output_name_that_is_only_a_suffix_or_holds_a_newline_is_refused(args, words, inputs,
                                                                              tmp_path):
    # audit 7 E14: '-o .tif' was told to end in .tif; a newline split the one-line messages
    result = run_bad(inputs, tmp_path / "out", args)
    assert_one_line(result, 2, (words,))


def _config_text(inputs: Path, out: Path, extra_bias: str = "", extra_steps: str = "",
                 top: str = "") -> str:
    return (f"out: {out}\n{top}steps:\n"
            f"  decode:\n    input: {inputs}/dp.dng\n    output: \"{{out}}/f.tif\"\n"
            f"  bias:\n    input: \"{{out}}/f.tif\"\n    output: \"{{out}}/b.tif\"\n{extra_bias}"
            f"{extra_steps}")


@pytest.mark.parametrize("name,parts,words", [
    ("duplicate-parameter", {"extra_bias": "    smooth: 1\n    smooth: 2\n"}, ("twice",)),
    ("duplicate-step", {"extra_steps": "  decode:\n    input: x.dng\n    output: y.tif\n"},
     ("twice",)),
    ("step-scalar", {"extra_steps": "  sai: 5\n"}, ("mapping",)),
    ("stage-list", {"extra_steps": "  x:\n    stage: [bias]\n"}, ("stage",)),
    ("two-writers", {"extra_steps": "  decode2:\n    stage: decode\n    input: x.dng\n"
                                     "    output: \"{out}/f.tif\"\n"}, ("both write",)),
    ("own-input", {"extra_steps": "  bias2:\n    stage: bias\n    input: \"{out}/b2.tif\"\n"
                                   "    output: \"{out}/b2.tif\"\n"}, ("also an input",)),
    ("preview-not-png", {"extra_bias": "    preview: \"{out}/b.jpg\"\n"}, ("ending in .png",)),
    # audit 8 W4: a YAML set was taken as its Python repr, in hash order ("{'A'", "'S'}")
    ("frames-set", {"extra_steps": "  decode2:\n    stage: decode\n    input: x.dng\n"
                                    "    output: \"{out}/g.tif\"\n    frames: !!set {S, A}\n"},
     ("plain value",)),
    ("frames-twice", {"extra_steps": "  decode2:\n    stage: decode\n    input: x.dng\n"
                                      "    output: \"{out}/g.tif\"\n    frames: S,S\n"},
     ("given twice",)),
])
def test_config_structure_is_checked_before_any_step_runs(name, parts, words, inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(_config_text(inputs, out, **parts))
    result = run_bad(inputs, out, ["run", str(config)])
    assert_one_line(result, 1, words)


@pytest.mark.parametrize("value, words", [
    ("5", "'out:'"), ("[a, b]", "'out:'"), ("{a: 1}", "'out:'"),
    # audit 7 E15: out: "{out}" wrote into a folder literally named {out}
    ('"{out}"', "holds a placeholder"), ('"runs/{name}"', "holds a placeholder"),
    ('"{foo}/x"', "holds a placeholder")])
def test_config_out_must_be_one_folder_without_placeholders(value, words, inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(_config_text(inputs, out).replace(f"out: {out}", f"out: {value}"))
    result = run_bad(inputs, out, ["run", str(config)])
    assert_one_line(result, 1, (words,))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "pipeline.yaml"]


def test_a_short_write_on_a_full_device_says_no_space(tmp_path, monkeypatch):
    import errno
    from types import SimpleNamespace

    from plenocli.io import atomic

    monkeypatch.setattr(atomic.os, "statvfs", lambda p: SimpleNamespace(f_bavail=0,
                                                                        f_frsize=4096))
    with pytest.raises(OSError) as info, atomic.atomic_path(tmp_path / "x.tif") as tmp:
        tmp.write_bytes(b"half")
        raise OSError("6144 requested and 2992 written")  # numpy's short write: no errno
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(tmp_path / "x.tif")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["x.json", ".x.tif.plenocli.json", "p.png"])
def test_a_full_device_while_a_record_or_preview_is_written_names_it(tmp_path, name):
    # audit 7 E16: a write without a file name (a record, a preview) said "no space left"
    # without naming the file
    import errno

    from plenocli.errors import os_error_message
    from plenocli.io import atomic

    with pytest.raises(OSError) as info, atomic.atomic_path(tmp_path / name) as tmp:
        tmp.write_bytes(b"half")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(tmp_path / name)
    assert os_error_message(info.value).startswith(f"{tmp_path / name}: no space left")
    assert list(tmp_path.iterdir()) == []


def test_a_missing_codec_is_named_not_taken_for_damage(tmp_path):
    err = KeyError("<COMPRESSION.LZW: 5> requires the 'imagecodecs' package")
    message = str(tiffio.read_error(tmp_path / "x.tif", err, "fallback"))
    assert "compressed with LZW" in message and "imagecodecs" in message
    assert str(tiffio.read_error(tmp_path / "x.tif", ValueError("bad"), "fallback")) == "fallback"


def test_a_bigtiff_sensor_image_decodes(tmp_path):
    sensor = np.arange(64 * 96, dtype=np.uint16).reshape(64, 96)
    tifffile.imwrite(tmp_path / "big.tif", sensor, bigtiff=True)
    result = CliRunner().invoke(cli, ["decode", str(tmp_path / "big.tif"), "-o",
                                      str(tmp_path / "frames.tif")])
    assert result.exit_code == 0, result.output
    frames, _ = tiffio.read_image(tmp_path / "frames.tif")
    assert np.array_equal(frames[0], sensor)


def test_set_reaches_a_step_whose_name_has_a_dot(inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    text = _config_text(inputs, out).replace("  bias:\n", "  bias.v2:\n    stage: bias\n")
    config.write_text(text)
    result = run_bad(inputs, out, ["run", str(config), "--dry-run", "--set", "bias.v2.smooth=-3"])
    assert_one_line(result, 2, ("step 'bias.v2'", "--smooth"))  # the value alone: a usage error


@pytest.mark.parametrize("word, code, words", [
    # audit 9 E5: ' 2 : 8 ' read as the YAML mapping {2: 8}: "expected a value, got a mapping"
    (" 2 : 4 ", 0, ()),
    ("a: b", 2, ("--set 'depth.g=a: b': step 'depth'", "got 'a: b'")),
    ("abc", 2, ("--set 'depth.g=abc': step 'depth'", "Invalid value for '--g'")),
    ("[2", 2, ("--set 'depth.g=[2'", "not valid YAML")),
])
def test_a_set_value_is_the_word_and_its_refusal_a_usage_error(word, code, words, inputs,
                                                                tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "c.yaml"
    config.write_text(f"steps:\n  depth:\n    input: {inputs}/rt/frames.tif\n"
                      f"    grid: {inputs}/rt/grid.yaml\n    output: {out}/d.tif\n")
    result = run_bad(inputs, out, ["run", str(config), "--dry-run", "--set", f"depth.g={word}"])
    if code == 0:
        assert result.exit_code == 0, result.output
        step = load_config(config, [f"depth.g={word}"])[0]
        assert step.params["g"].replace(" ", "") == "2:4"
    else:
        assert_one_line(result, code, words)


# ---- issue 21, class 8: unreadable inputs, lists for one path, empty values, cycles, long names

def _deny_reading(monkeypatch, path: Path) -> None:
    """Make ``path`` unreadable, even for root (who ignores permission bits): os.access says so
    and opening it fails with EACCES, as for a file of another user."""
    import builtins
    import errno
    import io
    import os

    target = os.path.realpath(path)
    real_access, real_open = os.access, builtins.open

    def access(p, mode, *args, **kwargs):
        if os.path.realpath(p) == target and mode & os.R_OK:
            return False
        return real_access(p, mode, *args, **kwargs)

    def opener(file, *args, **kwargs):
        if isinstance(file, (str, bytes, os.PathLike)) and os.path.realpath(file) == target:
            raise PermissionError(errno.EACCES, "Permission denied", str(file))
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(os, "access", access)
    monkeypatch.setattr(builtins, "open", opener)
    monkeypatch.setattr(io, "open", opener)


@pytest.mark.parametrize("args", [
    ["bias", "{f}", "-o", "{o}/b.tif"],
    ["flat", "{i}/biased.tif", "--white", "{f}", "-o", "{o}/v.tif"],
    ["info", "{f}"],
    ["run", "{c}"],
], ids=["argument", "option", "info", "run-config"])
def test_an_unreadable_input_is_an_input_error_not_a_usage_error(args, inputs, tmp_path,
                                                                 monkeypatch):
    secret = tmp_path / "secret.tif"
    secret.write_bytes((inputs / "biased.tif").read_bytes())
    config = tmp_path / "secret.tif"  # run reads it as its config
    out = tmp_path / "out"
    out.mkdir()
    _deny_reading(monkeypatch, secret)
    argv = [a.format(i=inputs, o=out, f=secret, c=config) for a in args]
    result = CliRunner().invoke(cli, argv)
    assert_one_line(result, 1, ("secret.tif", "ermission denied"))
    assert not list(out.iterdir())


def test_every_input_path_is_left_to_its_reader_to_check(tmp_path, monkeypatch):
    from plenocli.pipeline.registry import get_stages
    from plenocli.pipeline.validators import InputFile

    secret = tmp_path / "secret.tif"
    secret.write_bytes(b"")
    _deny_reading(monkeypatch, secret)
    for stage in get_stages().values():
        for param in stage.params:
            if param.role == "input":
                assert isinstance(param.type, InputFile), f"{stage.name} {param.name}"
                assert param.type.convert(str(secret)) == str(secret)  # the reader says why


@pytest.mark.parametrize("value", ["[a.tif, b.tif]", "[]"])
def test_a_list_for_one_output_path_is_refused(value, inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(_config_text(inputs, out).replace('output: "{out}/b.tif"',
                                                        f"output: {value}"))
    result = run_bad(inputs, out, ["run", str(config)])
    assert_one_line(result, 1, ("--output", "one file path"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "pipeline.yaml"]


@pytest.mark.parametrize("how,words", [
    (["--set", "bias.smooth="], ("--smooth", "''")),
    (["--set", "bias.smooth=~"], ("smooth", "no value")),
    (["--set", "bias.smooth=null"], ("smooth", "no value")),
    (["--set", "bias.input="], ("INPUT", "empty")),
    ("smooth: null", ("smooth", "no value")),
    ("smooth:", ("smooth", "no value")),
], ids=["set-empty", "set-tilde", "set-null", "set-empty-path", "yaml-null", "yaml-empty"])
def test_an_empty_or_null_value_is_refused_not_taken_for_the_default(how, words, inputs,
                                                                     tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    extra = f"    {how}\n" if isinstance(how, str) else "    smooth: 3\n"
    config.write_text(_config_text(inputs, out, extra_bias=extra))
    flags = how if isinstance(how, list) else []
    for mode in (["--dry-run"], ["--print-make"], []):
        result = run_bad(inputs, out, ["run", str(config), *flags, *mode])
        assert_one_line(result, 2 if flags else 1, words)  # a --set value: a usage error


@pytest.mark.parametrize("steps", [
    "  a:\n    stage: bias\n    input: \"{out}/y.tif\"\n    output: \"{out}/x.tif\"\n"
    "  b:\n    stage: bias\n    input: \"{out}/x.tif\"\n    output: \"{out}/y.tif\"\n",
    "  a:\n    stage: bias\n    input: \"{out}/b.tif\"\n    output: \"{out}/x.tif\"\n",
], ids=["cycle", "out-of-order"])
def test_print_make_refuses_what_run_refuses(steps, inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    text = _config_text(inputs, out).replace("steps:\n", "steps:\n" + steps)
    config.write_text(text)
    for mode in ([], ["--print-make"], ["--dry-run"]):
        result = run_bad(inputs, out, ["run", str(config), *mode])
        assert_one_line(result, 1, ("writes after it",))
        assert not result.stdout


def test_print_make_refuses_an_input_that_nothing_makes(inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(_config_text(inputs, out).replace(f"{inputs}/dp.dng", "nowhere.dng"))
    for mode in ([], ["--print-make"]):
        result = run_bad(inputs, out, ["run", str(config), *mode])
        assert_one_line(result, 1, ("nowhere.dng does not exist",))


def test_an_output_name_of_255_bytes_is_written_with_its_record(inputs, tmp_path):
    from plenocli.pipeline.records import read_record, record_path
    from plenocli.pipeline.runner import plan

    name = "b" * 251 + ".tif"
    result = CliRunner().invoke(cli, ["bias", str(inputs / "frames.tif"), "-o",
                                      str(tmp_path / name), "-q"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / name).is_file() and read_record(tmp_path / name) is not None
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([name,
                                                                 record_path(name).name])
    config = tmp_path / "c.yaml"
    config.write_text(f"steps:\n  bias:\n    input: {inputs / 'frames.tif'}\n"
                      f"    output: {name}\n")
    assert [d.run for d in plan(load_config(config))] == [False]
    too_long = CliRunner().invoke(cli, ["bias", str(inputs / "frames.tif"), "-o",
                                        str(tmp_path / ("c" * 252 + ".tif"))])
    assert_one_line(too_long, 1, ("too long",))

# ------------------- non-finite pixels: NaN is a clipped or unknown pixel, +-Inf is refused
# wherever a stage reads views (tiffio.read_image), naming the view

@pytest.fixture(scope="module")
def infinite(tmp_path_factory, inputs) -> Path:
    from plenocli.io.mixingfile import write_mixing
    from plenocli.model.mixing import MixingField

    d = tmp_path_factory.mktemp("infinite")
    rng = np.random.default_rng(7)
    clean = (100 + 50 * rng.random((2, 64, 64))).astype(np.float32)
    bad = clean.copy()
    bad[1, 5, 7] = np.inf
    levels = {"black_level": [[0.0] * 4] * 2, "white_level": [1e4] * 2}
    _plenocli_tiff(d / "clean.tif", clean, views=["A", "B"], cfa="RGGB", **levels)
    _plenocli_tiff(d / "views.tif", bad, views=["A", "B"], cfa="RGGB", **levels)
    _plenocli_tiff(d / "mono.tif", bad, views=["A", "B"], **levels)
    _plenocli_tiff(d / "frame.tif", np.where(np.isinf(bad[1]), -np.inf, bad[0]))
    _plain_tiff(d / "sensor.tif", bad[1])
    nodes = np.array([[1.0, 0.2], [0.1, 1.0]])[None, :, :, None, None] * np.ones((1, 1, 1, 2, 2))
    field = MixingField(nodes, np.array([15.5, 47.5]), np.array([15.5, 47.5]), (64, 64),
                        ("A", "B"), ("L",))
    write_mixing(d / "mixing.tif", field, layout="mono", cfa=None, meta={})
    frames, meta = tiffio.read_image(inputs / "rt" / "frames.tif")
    frames = frames.astype(np.float32)
    frames[0, 10, 10] = np.inf
    tifffile.imwrite(d / "rt_frames.tif", frames, photometric="minisblack", metadata=None,
                     description=json.dumps({tiffio.FORMAT_KEY: 1, **meta}))
    return d


@pytest.mark.parametrize("args", [
    ["flat", "{d}/views.tif", "--white", "{d}/clean.tif", "-o", "{o}/x.tif"],
    ["flat", "{d}/clean.tif", "--white", "{d}/views.tif", "-o", "{o}/x.tif"],
    ["sai", "{d}/frame.tif", "-n", "2", "-o", "{o}/x.tif"],
    ["refocus", "{d}/rt_frames.tif", "--grid", "{i}/rt/grid.yaml", "-o", "{o}/x.tif"],
    ["crosstalk", "{d}/views.tif", "-o", "{o}/x.json"],
    ["unmix", "{d}/mono.tif", "--mixing", "{d}/mixing.tif", "-o", "{o}/x.tif"],
    ["stitch", "{d}/mono.tif", "-o", "{o}/x.tif"],
    ["develop", "{d}/views.tif", "--view", "B", "--wb", "1,1,1", "--matrix", "none", "-o",
     "{o}/x.jpg"],
    ["calibrate", "{d}/frame.tif", "-o", "{o}/x.yaml"],
    ["decode", "{d}/sensor.tif", "-o", "{o}/x.tif"],
], ids=lambda a: a[0] + ("-white" if "{d}/clean.tif" == a[1] else ""))
def test_infinite_pixels_are_refused_by_every_stage_that_reads_views(args, inputs, infinite,
                                                                      tmp_path):
    result = run_bad(inputs, tmp_path / "out", [a.replace("{d}", str(infinite)) for a in args])
    assert_one_line(result, 1, ("infinite",))


# ------------------- camera metadata that is not what its field must be: dropped with a warning
# where it is read (io/rawmeta via tiffio.read_image and decode), never an internal error

@pytest.mark.parametrize("change,code,words", [
    ({"colour": {"as_shot_wb": [0, 1, 1]}}, 1, ("as-shot white balance [0, 1, 1]", "--wb")),
    ({"colour": {"as_shot_wb": [float("nan"), 1, 1]}}, 1, ("as-shot white balance",)),
    ({"colour": {"as_shot_wb": [-1, 1, 1]}}, 1, ("as-shot white balance",)),
    ({"colour": {"as_shot_wb": [1, 1]}}, 1, ("as-shot white balance",)),
    ({"colour": {"as_shot_wb": "abc"}}, 1, ("as-shot white balance 'abc'",)),
    ({"colour": {"as_shot_wb": [1e30, 1, 1.5]}}, 1, ("more than 100 times another", "--wb")),
    ({"colour": {"as_shot_wb": [1e-30, 1, 1.5]}}, 1, ("more than 100 times another",)),
    ({"colour": [1, 2]}, 1, ("colour metadata [1, 2] is not a mapping",)),
    ({"exif": {"ISO": 10 ** 7}}, 0, ("EXIF ISO 10000000",)),
    ({"exif": {"ISO": -5}}, 0, ("EXIF ISO -5",)),
    ({"exif": {"DateTimeOriginal": "2024:01:01 12:00:0\u00e9"}}, 0, ("DateTimeOriginal",)),
    ({"exif": {"Make": "Canon\u00e9"}}, 0, ("EXIF Make",)),
    ({"exif": {"FNumber": float("inf")}}, 0, ("EXIF FNumber inf",)),
    ({"exif": {"ExposureTime": "1/100"}}, 0, ("EXIF ExposureTime",)),
    ({"exif": [1, 2]}, 0, ("EXIF metadata [1, 2] is not a mapping",)),
], ids=lambda v: json.dumps(v, ensure_ascii=True)[:40] if isinstance(v, dict) else str(v))
@pytest.mark.parametrize("suffix", [".jpg", ".tif"])
def test_bad_camera_metadata_is_dropped_with_a_warning(change, code, words, suffix, inputs,
                                                       tmp_path, caplog):
    frames, meta = tiffio.read_image(inputs / "biased.tif")
    good = {"colour": {"as_shot_wb": [2.0, 1.0, 1.5], "xyz_to_camera": np.eye(3).tolist()},
            "exif": {"Model": "Test", "ISO": 100}}
    edited = {**meta, **good, **change}
    path = tmp_path / "edited.tif"
    tifffile.imwrite(path, frames, photometric="minisblack", metadata=None,
                     description=json.dumps({tiffio.FORMAT_KEY: 1, **edited}))
    out = tmp_path / "out"
    out.mkdir()
    result = CliRunner().invoke(cli, ["develop", str(path), "--view", "S", "-o",
                                      str(out / f"x{suffix}")])
    assert "internal error" not in result.stderr and "Traceback" not in result.output
    assert result.exit_code == code, result.stderr
    said = result.stderr + caplog.text  # the log goes to the handler of the first configure()
    assert all(w in said for w in words), said
    written = sorted(p.name for p in out.iterdir())
    assert written == ([] if code else [f".x{suffix}.plenocli.json", f"x{suffix}"])


def test_a_dng_with_a_zero_as_shot_neutral_decodes_without_a_white_balance(tmp_path, caplog):
    from plenocli.io.dng import write_dng

    raw = np.full((1, 16, 16), 1000, np.uint16)
    write_dng(tmp_path / "x.dng", raw, cfa="RGGB", black_levels=[0], white_level=4095,
              active_area=[0, 0, 16, 16], as_shot_neutral=[0.5, 1.0, 0.0])
    result = CliRunner().invoke(cli, ["decode", str(tmp_path / "x.dng"), "-o",
                                      str(tmp_path / "f.tif")])
    assert result.exit_code == 0 and "as-shot white balance" in result.stderr + caplog.text
    assert tiffio.read_meta(tmp_path / "f.tif")["colour"]["as_shot_wb"] is None


# ------------------- side files checked against what they describe: lens rows of a grid

def _lying_grid(path: Path, source: Path, change) -> None:
    from plenocli.model.lensgrid import LensGrid

    doc = yaml.safe_load(source.read_text())
    grid = LensGrid.from_dict(doc["lens_grid"])
    indices, centres = grid.lens_centres()  # the lattice's lenses, listed as calibrate does
    rows = np.hstack([indices, centres])
    doc["lens_grid"]["lenses"] = {"rows": change(grid, rows).tolist()}
    path.write_text(yaml.safe_dump(doc))


def _measured(rows):
    scatter = np.random.default_rng(3).normal(0, 0.02, (len(rows), 2))
    return rows + np.hstack([np.zeros((len(rows), 2)), scatter])


def _outside(grid, rows):
    i, j = rows[:, 0].max() + 3, rows[:, 1].max() + 3   # three lenses beyond the image
    return np.vstack([rows, [i, j, *grid.lattice_xy(i, j)]])


@pytest.mark.parametrize("name,change,words", [
    ("shifted", lambda g, r: r + [0, 0, 0.6 * g.pitch_px, 0], ("from its lattice place",)),
    ("indices-off-by-one", lambda g, r: r + [1, 0, 0, 0], ("from its lattice place",)),
    ("outside", _outside, ("outside the",)),
    # measured centres (scattered 0.02 px about the lattice) all moved, or listed for a lattice
    # of another pitch: neither the file's lattice nor that lattice bent by a smooth field
    ("all-moved-1px", lambda g, r: _measured(r) + [0, 0, 1.0, 0], ("up to 1.0", "smooth")),
    ("pitch-0.5%-larger", lambda g, r: _measured(np.hstack([r[:, :2], replace(
        g, pitch_px=1.005 * g.pitch_px).lattice_xy(r[:, 0], r[:, 1])])), ("lattice it lists",)),
])
@pytest.mark.parametrize("stage", ["refocus", "sai"])
def test_grid_lens_rows_that_are_not_the_lattice_are_refused(name, change, words, stage, inputs,
                                                            tmp_path):
    grid = tmp_path / "grid.yaml"
    _lying_grid(grid, inputs / "rt" / "grid.yaml", change)
    args = [stage, str(inputs / "rt" / "frames.tif"), "--grid", str(grid), "-o", "{o}/x.tif"]
    result = run_bad(inputs, tmp_path / "out", args + (["-n", "2"] if stage == "sai" else []))
    assert_one_line(result, 1, words)


@pytest.mark.parametrize("key,value,words", [
    ("angle_deg", 30.0, ("angle_deg 30.0 disagrees",)), ("count", 5, ("lenses.count 5",)),
    ("columns", ["i", "j", "y", "x"], ("lenses.columns ['i', 'j', 'y', 'x']",)),
])
def test_grid_fields_that_disagree_are_refused(key, value, words, inputs, tmp_path):
    doc = yaml.safe_load((inputs / "rt" / "grid.yaml").read_text())
    if key in ("count", "columns"):
        doc["lens_grid"]["lenses"] = {key: value, "rows": [[0, 0, *doc["lens_grid"][
            "offset_xy"]]]}
    else:
        doc["lens_grid"][key] = value
    (tmp_path / "grid.yaml").write_text(yaml.safe_dump(doc))
    args = ["refocus", str(inputs / "rt" / "frames.tif"), "--grid", str(tmp_path / "grid.yaml"),
            "-o", "{o}/x.tif"]
    assert_one_line(run_bad(inputs, tmp_path / "out", args), 1, words)


# ------------------- side files checked against what they describe: mixing files

def _mixing_variant(path: Path, change: str) -> None:
    from plenocli.io.mixingfile import write_mixing
    from plenocli.model.mixing import MixingField

    m = np.array([[1.0, 0.2], [0.1, 1.0]])
    rows = cols = np.array([15.5, 47.5])
    views = ("A", "B")
    if change == "share-1.5":
        m = m + [[0, 1.3], [0, 0]]
    elif change == "nodes-not-tile-centres":
        cols = cols / 2
    elif change == "scaled-1e30":
        m = m * 1e30
    elif change == "diagonal-negative":
        m = m * [[-1, 1], [1, 1]]
    elif change == "diagonal-zero":
        m = m * [[0, 1], [1, 1]]
    elif change == "negative-share":
        m = m - [[0, 0.7], [0, 0]]
    elif change == "nodes-outside":
        rows = np.array([16.0, 4800.0])
    elif change == "names-not-text":
        views = (1, 2)
    nodes = m[None, :, :, None, None] * np.ones((1, 1, 1, 2, 2))
    field = MixingField(nodes, rows, cols, (64, 64), views, ("L",))
    write_mixing(path, field, layout="mono", cfa=None, meta={})
    if change == "share-edited":  # still a mixing crosstalk could measure, but not this one
        pages, meta = tiffio.read_image(path)
        pages[1] += 0.1
        tifffile.imwrite(path, pages, photometric="minisblack", metadata=None,
                         description=json.dumps({tiffio.FORMAT_KEY: 1, **meta}))


@pytest.mark.parametrize("change,words", [
    ("scaled-1e30", ("1e+30", "diagonal")), ("diagonal-negative", ("diagonal",)),
    ("diagonal-zero", ("diagonal",)), ("negative-share", ("negative light",)),
    ("nodes-outside", ("node_rows", "outside")), ("names-not-text", ("views [1, 2]",)),
    ("share-1.5", ("M[A<-B]", "1.5", ">= 1")),
    ("nodes-not-tile-centres", ("node_cols", "centres of 32 px tiles")),
    ("share-edited", ("no longer match their checksum",)),
])
def test_a_mixing_file_that_lies_is_refused(change, words, inputs, infinite, tmp_path):
    side = tmp_path / "side"
    side.mkdir()
    clean, _ = tiffio.read_image(infinite / "clean.tif")
    _plenocli_tiff(side / "views.tif", clean, views=["A", "B"])
    _mixing_variant(side / "mixing.tif", change)
    args = ["unmix", str(side / "views.tif"), "--mixing", str(side / "mixing.tif"), "-o",
            "{o}/x.tif"]
    assert_one_line(run_bad(inputs, tmp_path / "out", args), 1, words)


# ------------------- side files checked against what they describe: saved gain maps

@pytest.mark.parametrize("change,words", [
    (lambda g: g * 1e30, ("outside (0, 20]",)),
    (lambda g: g * 0.5, ("smallest gain is 0.5",)),
    (lambda g: -g, ("outside",)),
    (lambda g: g * 1.3, ("not 1 as reference max",)),
    # edits that keep every rule of a gain: the checksum flat sealed the file with
    (lambda g: g[:, :, ::-1], ("no longer match their checksum",)),
    (lambda g: np.roll(g, 1, axis=2), ("no longer match their checksum",)),
    (lambda g: g[[1, 0, 2]], ("no longer match their checksum",)),
])
def test_a_gain_map_that_lies_is_refused(change, words, inputs, tmp_path):
    side = tmp_path / "side"
    side.mkdir()
    made = CliRunner().invoke(cli, ["flat", str(inputs / "biased.tif"), "--white",
                                    str(inputs / "biased.tif"), "--save-gain",
                                    str(side / "gain.tif"), "-o", str(side / "flat.tif")])
    assert made.exit_code == 0, made.stderr
    gains, meta = tiffio.read_image(side / "gain.tif")
    tifffile.imwrite(side / "gain.tif", change(gains).astype(np.float32),
                     photometric="minisblack", metadata=None,
                     description=json.dumps({tiffio.FORMAT_KEY: 1, **meta}))
    args = ["flat", str(inputs / "biased.tif"), "--gain", str(side / "gain.tif"), "-o",
            "{o}/x.tif"]
    assert_one_line(run_bad(inputs, tmp_path / "out", args), 1, words)


@pytest.mark.parametrize("names", [[1, 2], ["", "B"], [None, "B"], [["A"], "B"]])
@pytest.mark.parametrize("stage", ["stitch", "crosstalk", "develop"])
def test_view_names_that_are_not_text_are_refused(names, stage, inputs, infinite, tmp_path):
    side = tmp_path / "side"
    side.mkdir()
    clean, _ = tiffio.read_image(infinite / "clean.tif")
    _plenocli_tiff(side / "views.tif", clean, views=names, cfa="RGGB")
    out = "{o}/x.json" if stage == "crosstalk" else "{o}/x.tif"
    result = run_bad(inputs, tmp_path / "out", [stage, str(side / "views.tif"), "-o", out])
    assert_one_line(result, 1, ("non-empty text",))


@pytest.mark.parametrize("change,words", [
    ({"origin": [-8, 0]}, ("origin",)), ({"white_level": [100, 100]}, ("not above its black",)),
    ({"white_level": [15000.0, 1e30]}, ("beyond what its uint16",)),
    ({"masked_areas": -1}, ("masked area list -1",)),
    ({"masked_areas": [None] * 4}, ("masked area None",)),
    ({"view_colours": float("nan")}, ("view_colours",)), ({"views": None}, ("names None",)),
])
def test_frames_metadata_that_cannot_be_true_is_refused(change, words, inputs, tmp_path):
    frames, meta = tiffio.read_image(inputs / "frames.tif")
    path = tmp_path / "edited.tif"
    tifffile.imwrite(path, frames, photometric="minisblack", metadata=None,
                     description=json.dumps({tiffio.FORMAT_KEY: 1, **meta, **change}))
    result = run_bad(inputs, tmp_path / "out", ["bias", str(path), "-o", "{o}/b.tif"])
    assert_one_line(result, 1, words)


@pytest.mark.parametrize("change,words", [
    ({"tcp": float("nan")}, ("tcp",)),
    ({"lens_border": -3.0}, ("lens_border",)),
    ({"lens_types": [{"id": 0, "offset": [0.0, 0.0], "depth_range": [4.0, 1.0]}]},
     ("depth_range",)),
    ({"lens_types": [{"id": 1, "offset": [0.0, 0.0], "depth_range": [1.0, 3.0]}] * 2},
     ("lens_type ids",)),
    ({"sub_grid_base": [float("inf"), 0.0]}, ("sub_grid_base",)),
])
def test_raytrix_fields_beside_the_lattice_are_checked(change, words, inputs, tmp_path):
    from plenocli.io.raytrix import read_calib

    calib = {**read_calib(inputs / "rt" / "calib.xml"), **change}
    (tmp_path / "calib.xml").write_text(format_calib(calib))
    args = ["refocus", str(inputs / "rt" / "frames.tif"), "--grid", str(tmp_path / "calib.xml"),
            "-o", "{o}/x.tif"]
    assert_one_line(run_bad(inputs, tmp_path / "out", args), 1, words)


def test_a_result_that_overflows_to_infinity_is_not_written(inputs, infinite, tmp_path):
    side = tmp_path / "side"
    side.mkdir()
    clean, meta = tiffio.read_image(infinite / "clean.tif")
    clean[1, 10, 10] = 3.4e38  # finite, but any gain > 1 overflows float32
    _plenocli_tiff(side / "views.tif", clean, **{k: meta[k] for k in
                                                ("views", "cfa", "black_level", "white_level")})
    args = ["flat", str(side / "views.tif"), "--white", str(infinite / "clean.tif"), "-o",
            "{o}/x.tif"]
    assert_one_line(run_bad(inputs, tmp_path / "out", args), 1, ("overflowed", "view B"))


@pytest.mark.parametrize("photometric", ["palette", "miniswhite", "separated", "cielab"])
@pytest.mark.parametrize("stage", ["decode", "sai"])
def test_tiffs_of_palette_indices_or_inverted_grey_are_not_light(photometric, stage, inputs,
                                                                  tmp_path):
    side = tmp_path / "side"
    side.mkdir()
    grey = np.random.default_rng(4).integers(0, 255, (32, 48)).astype(np.uint8)
    extra = {"palette": {"colormap": np.tile(np.arange(256, dtype=np.uint16) * 257, (3, 1))}}
    samples = {"separated": 4, "cielab": 3}.get(photometric)
    image = grey if samples is None else np.repeat(grey[..., None], samples, axis=2)
    tifffile.imwrite(side / "x.tif", image, photometric=photometric, metadata=None,
                     **extra.get(photometric, {}))
    args = [stage, str(side / "x.tif"), "-o", "{o}/x.tif"] + (["-n", "2"] if stage == "sai"
                                                              else [])
    assert_one_line(run_bad(inputs, tmp_path / "out", args), 1, ("holds no light levels",))


def test_a_file_of_the_wrong_kind_or_already_processed_is_refused(inputs, tmp_path):
    """W5: each stage takes for each input the outputs of the stages it lists (pipeline/kinds);
    a stage that corrects a capture refuses one it has already corrected."""
    made = tmp_path / "made"
    made.mkdir()
    (made / "white.tif").write_bytes((inputs / "biased.tif").read_bytes())
    result = CliRunner().invoke(cli, [str(a) for a in [
        "flat", inputs / "biased.tif", "--white", made / "white.tif", "--save-gain",
        made / "gain.tif", "-o", made / "flat.tif"]])
    assert result.exit_code == 0, result.output
    out = tmp_path / "out"
    cases = [
        (["flat", made / "flat.tif", "--gain", made / "gain.tif", "-o", "{o}/x.tif"],
         "already went through `plenocli flat`"),
        (["flat", inputs / "biased.tif", "--white", made / "gain.tif", "-o", "{o}/x.tif"],
         "`plenocli flat-gain` output"),
        (["bias", inputs / "biased.tif", "-o", "{o}/x.tif"], "`plenocli bias` output"),
    ]
    for args, words in cases:
        result = run_bad(inputs, out, [str(a) for a in args])
        assert_one_line(result, 1, ())
        assert words in result.stderr, (args, result.stderr)


def test_decode_refuses_what_plenocli_made(inputs, tmp_path):
    """audit 7 W2, E7: a plenocli TIFF (frames, views, of one page or several) or preview is not
    a raw: decoding it dropped its history (flat then ran twice) or advised splitting its
    pages; it is refused, naming its stage and the stages that take it."""
    made = tmp_path / "made"
    made.mkdir()
    result = CliRunner().invoke(cli, [str(a) for a in [
        "bias", inputs / "frames.tif", "-o", made / "views.tif", "--preview", made / "v.png"]])
    assert result.exit_code == 0, result.output
    out = tmp_path / "out"
    cases = [(inputs / "frames.tif", "`plenocli decode` output", "give it as it is to bias"),
             (made / "views.tif", "`plenocli bias` output", "to flat, unmix"),
             (made / "v.png", "plenocli preview", "decode the capture it shows")]
    for path, what, where in cases:
        result = run_bad(inputs, out, ["decode", str(path), "-o", "{o}/x.tif"])
        assert_one_line(result, 1, (what, where, "not a raw capture or sensor image"
                                    if path.suffix == ".tif" else "not a sensor image"))


def test_decode_names_only_the_stages_that_take_the_file(inputs, tmp_path):
    """audit 9 E9: decode sent a depth map to refocus (as INPUT), a focal sweep to unmix,
    crosstalk, develop and stitch, and SAIs back to sai: each refuses that very file."""
    made = tmp_path / "made"
    simulate("dualpixel-depth", made / "dd", pixels="96x128", seed=2)
    rt = inputs / "rt"
    for args in (["depth", rt / "frames.tif", "--grid", rt / "grid.yaml", "-o", made / "g.tif"],
                 ["depth", made / "dd" / "views.tif", "-o", made / "disp.tif"],
                 ["refocus", rt / "frames.tif", "--grid", rt / "grid.yaml", "--g", "3,4", "-o",
                  made / "sweep.tif"],
                 ["sai", rt / "frames.tif", "-n", "2", "-o", made / "sai.tif"]):
        result = CliRunner().invoke(cli, [str(a) for a in args])
        assert result.exit_code == 0, result.output
    names = [f"S{i}{j}.{c}" for i in "01" for j in "01" for c in "RGB"]
    _plenocli_tiff(made / "colour_sai.tif", np.ones((12, 16, 16), np.float32), views=names,
                   provenance={"stage": "sai"})
    out = tmp_path / "out"
    cases = [("colour_sai.tif", "give it as it is to unmix, crosstalk, develop, stitch"),
             ("g.tif", "give it as it is to refocus --depth"),
             ("disp.tif", "no stage reads it as an image"),
             ("sweep.tif", "no stage reads it as an image"),
             ("sai.tif", "give it as it is to unmix, crosstalk, depth, develop, stitch")]
    for name, where in cases:
        result = run_bad(inputs, out, ["decode", str(made / name), "-o", "{o}/x.tif"])
        assert_one_line(result, 1, (where,))
        assert result.output.rstrip().endswith(where) or "decode the capture" in result.output


@pytest.mark.parametrize("args", [
    ["crosstalk", "{i}/frames.tif", "-o", "{o}/r.json"],
    ["crosstalk", "{b}/views.tif", "--views", "A,B", "-o", "{o}/r.json"],
    ["crosstalk", "{b}/views.tif", "{b}/views2.tif", "--mixing-out", "{o}/m.tif", "-o",
     "{o}/r.json"],
    ["unmix", "{b}/views.tif", "--mixing", "{d}/mixing.tif", "-o", "{o}/u.tif"],
    ["sai", "{b}/frames.tif", "-n", "2", "-o", "{o}/s.tif"],
    ["refocus", "{b}/frames.tif", "--grid", "{i}/rt/grid.yaml", "-o", "{o}/r.tif"],
])
def test_light_ratios_refuse_frames_whose_black_level_is_not_subtracted(args, inputs, infinite,
                                                                        tmp_path):
    """audit 7 W3: crosstalk measured r on decoded frames with their black level in the flux
    (exit 0, r = 67 %); like flat, every stage that takes ratios of light (crosstalk, unmix)
    or drops the level from its output (sai, refocus) refuses them."""
    assert np.max(tiffio.read_meta(inputs / "frames.tif")["black_level"]) > 0
    side = tmp_path / "black"
    side.mkdir()
    clean, _ = tiffio.read_image(infinite / "clean.tif")
    levels = {"black_level": [[64.0] * 4] * 2, "white_level": [1e4] * 2}
    _plenocli_tiff(side / "views.tif", clean + 64, views=["A", "B"], **levels)
    _plenocli_tiff(side / "views2.tif", clean[::-1] + 64, views=["A", "B"], **levels)
    frames, meta = tiffio.read_image(inputs / "rt" / "frames.tif")
    tifffile.imwrite(side / "frames.tif", frames.astype(np.float32) + 64, metadata=None,
                     photometric="minisblack", description=json.dumps(
                         {tiffio.FORMAT_KEY: 1, **meta, "black_level": [[64.0] * 4],
                          "white_level": [100.0]}))
    argv = [a.replace("{b}", str(side)).replace("{d}", str(infinite)) for a in args]
    result = run_bad(inputs, tmp_path / "out", argv)
    assert_one_line(result, 1, ("tif: black level", "not subtracted yet",
                                "run plenocli bias first"))


def test_a_noise_gain_map_is_a_map_of_its_own_refused_as_views(inputs, infinite, tmp_path):
    """audit 7 P1: unmix --noise-map of views A, B, S wrote 2 pages with 3 views' levels (every
    stage then called the untouched file "edited or damaged") under the record `unmix`, so
    flat took it for an unmixed capture; it is now consistent and of a kind of its own."""
    made = tmp_path / "made"
    made.mkdir()
    clean, meta = tiffio.read_image(infinite / "clean.tif")
    levels = {"black_level": [[0.0] * 4] * 3, "white_level": [1e4] * 3}
    _plenocli_tiff(made / "views.tif", np.concatenate([clean, clean.sum(0, keepdims=True)]),
                   views=["A", "B", "S"], **levels)
    result = CliRunner().invoke(cli, [str(a) for a in [
        "unmix", made / "views.tif", "--mixing", infinite / "mixing.tif", "--noise-map",
        made / "noise.tif", "-o", made / "clean.tif"]])
    assert result.exit_code == 0, result.output
    gains, meta = tiffio.read_image(made / "noise.tif")
    assert gains.shape[0] == 2 and meta["views"] == ["A", "B"]
    assert meta["provenance"]["stage"] == "unmix-noise-gain"
    assert meta["black_level"] is None and meta["white_level"] is None
    assert tiffio.read_meta(made / "clean.tif")["views"] == ["A", "B", "S"]
    out = tmp_path / "out"
    for args in (["stitch", made / "noise.tif", "-o", "{o}/p.tif"],
                 ["flat", made / "noise.tif", "--white", inputs / "biased.tif", "-o",
                  "{o}/f.tif"],
                 ["develop", made / "noise.tif", "-o", "{o}/d.tif"],
                 ["crosstalk", made / "noise.tif", "-o", "{o}/c.json"],
                 ["decode", made / "noise.tif", "-o", "{o}/x.tif"]):
        result = run_bad(inputs, out, [str(a) for a in args])
        assert_one_line(result, 1, ("`plenocli unmix-noise-gain` output",))


def test_sais_of_a_per_pixel_bayer_frame_are_read_by_every_stage(inputs, tmp_path):
    """audit 7 P3: sai -n 2 of a Bayer frame records one colour per view (R, G, G, B); the
    reader took that for damage, so develop, stitch, depth and crosstalk all refused sai's own
    untouched output as "edited or damaged"."""
    made = tmp_path / "made"
    made.mkdir()
    runner = CliRunner()
    for args in (["decode", inputs / "zlib.tif", "--cfa", "RGGB", "-o", made / "frames.tif"],
                 ["sai", made / "frames.tif", "-n", "2", "-o", made / "sai.tif"]):
        result = runner.invoke(cli, [str(a) for a in args])
        assert result.exit_code == 0, (args, result.output)
    # depth and stitch read the file (on these noise views they may refuse what they find)
    for args in (["depth", made / "sai.tif", "-o", made / "d.tif"],
                 ["stitch", made / "sai.tif", "--layout", "2x2", "-o", made / "p.tif"]):
        result = runner.invoke(cli, [str(a) for a in args])
        assert "edited or damaged" not in result.output + result.stderr, args
    _, meta = tiffio.read_image(made / "sai.tif")
    assert meta["view_colours"] == ["R", "G", "G", "B"]
    # audit 7 W8: each SAI keeps its frame's white level (it was null: clipped pixels passed
    # as light in develop); the black level is 0, as sai takes only frames without one
    assert meta["white_level"] == [65535.0] * 4 and meta["black_level"] == [[0.0] * 4] * 4
    result = run_bad(inputs, tmp_path / "out", ["develop", str(made / "sai.tif"), "--wb",
                                                "1,1,1", "--matrix", "none", "-o", "{o}/d.png"])
    assert_one_line(result, 1, ("each view holds a single colour",))


def test_colour_channels_and_lenslet_pixels_are_not_taken_as_views(inputs, tmp_path):
    """audit 7 W12: crosstalk took the pages R, G, B of one colour view as three views (r =
    96 % "between" colours), and sai cut 2 x 2 pixel "SAIs" out of Raytrix (lenslet) frames."""
    made = tmp_path / "made"
    made.mkdir()
    rng = np.random.default_rng(3)
    tifffile.imwrite(made / "rgb.tif", rng.integers(100, 4000, (48, 64, 3)).astype(np.uint16),
                     photometric="rgb")
    frames, _ = tiffio.read_image(inputs / "rt" / "frames.tif")
    _plain_tiff(made / "rt.tif", frames[0].astype(np.float32))
    runner = CliRunner()
    for args in (["decode", made / "rgb.tif", "-o", made / "rgb_frames.tif"],
                 ["decode", made / "rt.tif", "--camera", "raytrix", "--calib",
                  inputs / "rt" / "calib.xml", "--white", "1e4", "-o", made / "rt_frames.tif"]):
        result = runner.invoke(cli, [str(a) for a in args])
        assert result.exit_code == 0, result.output
    out = tmp_path / "out"
    result = run_bad(inputs, out, ["crosstalk", str(made / "rgb_frames.tif"), "-o", "{o}/c.json"])
    assert_one_line(result, 1, ("holds one view", "pages R, G, B are its colours"))
    result = run_bad(inputs, out, ["sai", str(made / "rt_frames.tif"), "-n", "2", "-o",
                                   "{o}/s.tif"])
    assert_one_line(result, 1, ("focused plenoptic (Raytrix) camera", "plenocli refocus"))


# ------------------- JSON nested past any plenocli document: one line, never a RecursionError

def test_json_nested_too_deep_is_one_line_everywhere(inputs, tmp_path):
    side = tmp_path / "side"
    side.mkdir()
    deep = "[" * 100_000 + "]" * 100_000
    (side / "deep.json").write_text(deep)
    tifffile.imwrite(side / "deep.tif", np.ones((8, 8), np.float32), metadata=None,
                     description=f'{{"{tiffio.FORMAT_KEY}": 1, "x": {deep}}}')
    for args in (["info", str(side / "deep.json")], ["info", str(side / "deep.tif")],
                 ["develop", str(side / "deep.tif"), "--wb", "1,1,1", "--matrix", "none", "-o",
                  "{o}/x.jpg"],
                 ["stitch", str(inputs / "biased.tif"), "--views", "A,B", "--transform-in",
                  str(side / "deep.json"), "-o", "{o}/x.tif"]):
        assert_one_line(run_bad(inputs, tmp_path / "out", args), 1, ("nested more than 100",))
    # a record that deep is unreadable: the step runs again, as for no record
    made = tmp_path / "made"
    made.mkdir()
    config = made / "c.yaml"
    config.write_text(f"steps:\n  bias:\n    input: {inputs / 'frames.tif'}\n"
                      f"    output: {made / 'b.tif'}\n")
    assert CliRunner().invoke(cli, ["run", str(config)]).exit_code == 0
    (made / ".b.tif.plenocli.json").write_text(deep)
    again = CliRunner().invoke(cli, ["run", str(config)])
    assert again.exit_code == 0 and "internal error" not in again.output + again.stderr
    assert "skip" not in again.stderr + again.output


def test_an_output_record_that_cannot_be_written_is_refused_before_any_work(inputs, tmp_path):
    """The record beside an output (.NAME.plenocli.json) is checked with the outputs: a folder
    in its place, or another output given its name, is one line before the stage runs."""
    (tmp_path / ".b.tif.plenocli.json").mkdir()
    result = CliRunner().invoke(cli, ["bias", str(inputs / "frames.tif"), "-o",
                                      str(tmp_path / "b.tif")])
    assert_one_line(result, 1, ("records how", "is a folder"))
    assert "bias:" not in result.stderr and not (tmp_path / "b.tif").exists()
    result = CliRunner().invoke(cli, ["crosstalk", str(inputs / "unmasked0.tif"),
                                      str(inputs / "unmasked1.tif"), "--mixing-out",
                                      str(tmp_path / "m.tif"), "-o",
                                      str(tmp_path / ".m.tif.plenocli.json")])
    assert_one_line(result, 2, ("is named as a plenocli record",))
    assert sorted(p.name for p in tmp_path.iterdir()) == [".b.tif.plenocli.json"]


def test_no_output_may_take_a_records_name(inputs, tmp_path):
    # audit 7 W6: crosstalk -o .f.tif.plenocli.json replaced f.tif's record (and in a config
    # the pipeline never settled: every run remade both steps)
    made = CliRunner().invoke(cli, ["bias", str(inputs / "frames.tif"), "-o",
                                    str(tmp_path / "b.tif")])
    assert made.exit_code == 0, made.output
    record = (tmp_path / ".b.tif.plenocli.json").read_bytes()
    result = CliRunner().invoke(cli, ["crosstalk", str(tmp_path / "b.tif"), "-o",
                                      str(tmp_path / ".b.tif.plenocli.json")])
    assert_one_line(result, 2, ("is named as a plenocli record",))
    assert (tmp_path / ".b.tif.plenocli.json").read_bytes() == record
    config = tmp_path / "c.yaml"
    config.write_text(f"steps:\n  crosstalk: {{inputs: [{tmp_path / 'b.tif'}], "
                      f"output: {tmp_path / 'o' / '.b.tif.plenocli.json'}}}\n")
    with pytest.raises(ConfigError, match="is named as a plenocli record"):
        load_config(config)


# an option with no effect is refused when given, whatever its value (its default's included)
NO_EFFECT = [  # stage, its other values (as a YAML step), the options that then do nothing
    ("depth", {"input": "v.tif", "output": "o.tif"}, ["g", "s", "min_confidence", "camera"]),
    ("depth", {"input": "f.tif", "grid": "g.yaml", "output": "o.tif"}, ["max_disparity"]),
    ("refocus", {"input": "f.tif", "grid": "g.yaml", "output": "o.tif"}, ["mask_width"]),
    ("refocus", {"input": "f.tif", "grid": "g.yaml", "depth": "d.tif", "output": "o.tif"},
     ["g"]),
    ("stitch", {"inputs": ["v.tif"], "transform_in": "t.json", "output": "o.tif"},
     ["overlap", "overlap_tolerance"]),
    ("stitch", {"inputs": ["v.tif"], "rig": "r.yaml", "output": "o.tif"},
     ["overlap", "overlap_tolerance"]),
    ("stitch", {"inputs": ["v.tif"], "output": "o.tif"}, ["overlap_tolerance"]),
    ("crosstalk", {"inputs": ["v.tif"], "output": "o.json"}, ["s", "g", "grid"]),
    ("crosstalk", {"inputs": ["f.tif"], "mask_widths": "0,1", "grid": "g.yaml",
                   "output": "o.json"}, ["views", "mixing_out"]),
    ("bias", {"input": "f.tif", "overscan": "none", "output": "o.tif"}, ["smooth", "guard"]),
    ("develop", {"input": "v.tif", "wb_from": "w.tif", "output": "o.jpg"}, ["wb"]),
    ("develop", {"input": "v.tif", "output": "o.png"}, ["quality"]),
    ("optics", {"input": "l.yaml"}, ["mask_width"]),
]
NO_DEFAULT = {"camera": "c.yaml", "overlap": 0.2, "grid": "g.yaml", "views": "A,B",
              "mixing_out": "m.tif"}  # a value for options without a default


@pytest.mark.parametrize("stage,step,name", [(s, a, n) for s, a, names in NO_EFFECT
                                              for n in names])
def test_an_option_with_no_effect_is_refused_at_its_default_value_too(stage, step, name,
                                                                      tmp_path, monkeypatch):
    """From the shell (a usage error) and from a YAML step alike, before any file is read."""
    from plenocli.pipeline.config import load_config
    from plenocli.pipeline.params import shell_words
    from plenocli.pipeline.registry import get_stage

    monkeypatch.chdir(tmp_path)
    params = get_stage(stage).params
    param = next(p for p in params if p.name == name)
    step = {**step, name: NO_DEFAULT[name] if param.default is None else param.default}
    result = CliRunner().invoke(cli, [stage, *shell_words(params, step)])
    assert result.exit_code == 2, result.output
    assert f"{param.label} " in result.output and not list(tmp_path.iterdir())
    (tmp_path / "c.yaml").write_text(yaml.safe_dump({"steps": {"s": {"stage": stage, **step}}}))
    with pytest.raises(ConfigError, match=param.label):
        load_config(tmp_path / "c.yaml")
@pytest.mark.parametrize("how", ["yaml", "set"])
def test_a_g_bound_past_what_the_grid_measures_is_refused_from_a_config(how, inputs, tmp_path):
    """`depth --g 2:1e308` searched shifts of 1e-307 px and wrote a map with exit 0: refused
    as from the shell (exit 2, naming the range the grid measures), from YAML and --set."""
    out = tmp_path / "out"
    config = tmp_path / "c.yaml"
    g = "2:1e308" if how == "yaml" else "2:8"
    config.write_text(f"steps:\n  depth:\n    input: {inputs}/rt/frames.tif\n"
                      f"    grid: {inputs}/rt/grid.yaml\n    g: \"{g}\"\n"
                      f"    output: {out}/d.tif\n")
    extra = ["--set", "depth.g=2:1e308"] if how == "set" else []
    result = run_bad(inputs, out, ["run", str(config), *extra])
    assert_one_line(result, 2, ("step 'depth'", "--g", "1 < g <="))


def _png_chunk(kind: bytes, body: bytes) -> bytes:
    return (struct.pack(">I", len(body)) + kind + body
            + struct.pack(">I", zlib.crc32(kind + body) & 0xffffffff))


def _damaged_pngs(folder: Path) -> dict[str, Path]:
    """A PNG whose pixel data fails its check, one whose header claims 2^31 - 1 columns, and
    one with a truncated zTXt chunk (its pixels whole)."""
    import cv2

    image = (np.random.default_rng(0).random((64, 96, 3)) * 255).astype(np.uint8)
    raw = cv2.imencode(".png", image)[1].tobytes()
    bad = bytearray(raw)
    bad[-20] ^= 0xFF
    header = raw.find(b"IHDR")
    wide = bytearray(raw)
    wide[header + 4:header + 12] = struct.pack(">II", 2 ** 31 - 1, 1)
    wide[header + 17:header + 21] = struct.pack(">I", zlib.crc32(bytes(wide[header:header + 17]))
                                                & 0xffffffff)
    data = raw.find(b"IDAT") - 4
    cut = zlib.compress(b"A" * 100_000)[:-9]   # a compressed comment that stops short
    ztxt = raw[:data] + _png_chunk(b"zTXt", b"Comment\x00\x00" + cut) + raw[data:]
    files = {"badcrc": bytes(bad), "wide": bytes(wide), "ztxt": ztxt}
    for name, content in files.items():
        (folder / f"{name}.png").write_bytes(content)
    return {name: folder / f"{name}.png" for name in files}


def test_a_damaged_png_is_one_line_without_the_codecs_own(tmp_path, capfd):
    """E1 (audit 6): libpng printed its warnings and errors on stderr (2-3 lines, also on
    success); they are the reason in plenocli's one line, or logged with -v."""
    pngs = _damaged_pngs(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    for args, words in (
            (["decode", str(pngs["badcrc"]), "-o", str(out / "a.tif")], ("incorrect data check",)),
            (["calibrate", str(pngs["badcrc"]), "-o", str(out / "g.yaml")],
             ("incorrect data check",)),
            (["decode", str(pngs["wide"]), "-o", str(out / "b.tif")], ("IHDR",)),
            (["calibrate", str(pngs["wide"]), "-o", str(out / "g.yaml")], ("IHDR",))):
        result = CliRunner().invoke(cli, args)
        assert_one_line(result, 1, words)
        assert "libpng" not in capfd.readouterr().err
    assert not list(out.iterdir())
    result = CliRunner().invoke(cli, ["decode", str(pngs["ztxt"]), "-o", str(out / "z.tif")])
    assert result.exit_code == 0, result.output
    assert "libpng" not in capfd.readouterr().err + result.stderr
    # a truncated JPEG: libjpeg fills the rest grey with a warning; refused, not calibrated
    import cv2

    image = (np.random.default_rng(1).random((64, 96)) * 255).astype(np.uint8)
    jpeg = cv2.imencode(".jpg", image)[1].tobytes()
    (tmp_path / "cut.jpg").write_bytes(jpeg[:len(jpeg) * 2 // 3])
    result = CliRunner().invoke(cli, ["calibrate", str(tmp_path / "cut.jpg"), "-o",
                                      str(out / "g.yaml")])
    assert_one_line(result, 1, ("Premature end of JPEG file", "pixels is missing"))
    assert "JPEG" not in capfd.readouterr().err


def test_a_list_or_camera_file_that_is_no_text_file_is_one_line(inputs, tmp_path, monkeypatch):
    """M1 (audit 6): `depth --camera /dev/zero` read the device whole (RSS 6 GB in 8 s), a
    FIFO blocked; `batch --inputs @LIST` of a binary file was an internal error
    (UnicodeDecodeError), of a device "no such list file". Every text side file is read as a
    regular file of bounded size."""
    binary = tmp_path / "bin.lst"
    binary.write_bytes(bytes(range(128, 256)))
    config = Path(__file__).parents[1] / "configs" / "batch_dualpixel.yaml"
    for listing, words in ((binary, "not UTF-8"), (Path(os.devnull), "not a regular file")):
        result = run_bad(inputs, tmp_path / "out", ["batch", str(config), "--inputs",
                                                    f"@{listing}", "--out", "{o}/b"])
        assert_one_line(result, 1, ("--inputs", words))
    result = run_bad(inputs, tmp_path / "out", ["depth", "{i}/rt/frames.tif", "--grid",
                                                "{i}/rt/grid.yaml", "--camera", os.devnull,
                                                "-o", "{o}/d.tif"])
    assert_one_line(result, 1, ("not a regular file",))
    from plenocli.io import yamlfile

    monkeypatch.setattr(yamlfile, "MAX_TEXT_BYTES", 1 << 20)
    camera = tmp_path / "camera.yaml"
    camera.write_text("focal_length_mm: 50\n" + "# padding\n" * 120_000)
    result = run_bad(inputs, tmp_path / "out", ["depth", "{i}/rt/frames.tif", "--grid",
                                                "{i}/rt/grid.yaml", "--camera", str(camera),
                                                "-o", "{o}/d.tif"])
    assert_one_line(result, 1, ("more than 1 MiB of text",))


def test_messages_name_what_is_wrong(inputs, tmp_path):
    """E3 (audit 6): bias said it takes simulate outputs (it refuses them) "or a foreign file";
    `camera: false` in a config was "input .../False"; a 1-bit image "looks like a Bayer
    mosaic" with its four phases alike."""
    import cv2

    result = run_bad(inputs, tmp_path / "out", ["bias", "{i}/rt/frames.tif", "-o", "{o}/b.tif"])
    assert_one_line(result, 1, ("takes as input the output of decode",))
    assert "simulate" not in result.stderr.split("output of")[-1]
    assert "foreign" not in result.stderr
    config = tmp_path / "c.yaml"
    config.write_text(f"steps:\n  depth:\n    input: {inputs}/rt/frames.tif\n    grid: "
                      f"{inputs}/rt/grid.yaml\n    camera: false\n    output: {tmp_path}/d.tif\n")
    result = run_bad(inputs, tmp_path / "out", ["run", str(config)])
    assert_one_line(result, 1, (f"{tmp_path}/false does not exist",))
    binary = tmp_path / "binary.png"
    rng = np.random.default_rng(0)
    cv2.imwrite(str(binary), np.where(rng.random((96, 128)) > 0.5, 255, 0).astype(np.uint8))
    result = run_bad(inputs, tmp_path / "out", ["calibrate", str(binary), "-o", "{o}/g.yaml"])
    assert result.exit_code == 1 and "Bayer" not in result.stderr


def test_a_palette_png_is_refused_and_grey_with_alpha_is_one_grey_frame(inputs, tmp_path):
    """audit 8 E1: OpenCV expands a palette PNG, and a grey PNG with alpha, into three colour
    channels: the palette's indices were decoded as R, G, B light levels, and a grey image
    became three identical frames, exit 0."""
    from PIL import Image

    side = tmp_path / "side"
    side.mkdir()
    grey = np.random.default_rng(5).integers(0, 255, (24, 32), dtype=np.uint8)
    Image.fromarray(grey).convert("P", palette=Image.Palette.ADAPTIVE).save(side / "pal.png")
    Image.fromarray(grey).convert("LA").save(side / "la.png")
    result = run_bad(inputs, tmp_path / "out", ["decode", str(side / "pal.png"), "-o",
                                                "{o}/p.tif"])
    assert_one_line(result, 1, ("palette", "not light levels"))
    result = CliRunner().invoke(cli, ["decode", str(side / "la.png"), "-o",
                                      str(tmp_path / "l.tif")])
    assert result.exit_code == 0, result.output
    frames, _ = tiffio.read_image(tmp_path / "l.tif")
    assert frames.shape == (1, 24, 32) and np.array_equal(frames[0], grey)


def test_a_focal_sweep_is_not_taken_for_pupil_views(inputs, tmp_path):
    """audit 8 W2: crosstalk took a refocus sweep's planes (raw@g2 .. raw@g6: one view at nine
    g) for views and reported r = 99.97 %, exit 0."""
    side = tmp_path / "side"
    side.mkdir()
    planes = np.random.default_rng(6).uniform(100, 200, (3, 32, 48)).astype(np.float32)
    _plenocli_tiff(side / "sweep.tif", planes, views=["raw@g3", "raw@g4", "raw@g5"])
    result = run_bad(inputs, tmp_path / "out", ["crosstalk", str(side / "sweep.tif"), "-o",
                                                "{o}/c.json"])
    assert_one_line(result, 1, ("focal sweep", "@g3"))


@pytest.mark.parametrize("shape", [(4, 20000), (20000, 4)])
def test_the_preview_of_a_very_elongated_frame_keeps_a_pixel_across(shape, tmp_path):
    """audit 8 I1: shrunk to 2048 px, a 4 x 20000 frame's short side rounded to 0 and OpenCV's
    resize failed: an "internal error" after the success line."""
    tifffile.imwrite(tmp_path / "long.tif", np.arange(np.prod(shape), dtype=np.uint16)
                     .reshape(shape))
    result = CliRunner().invoke(cli, ["decode", str(tmp_path / "long.tif"), "-o",
                                      str(tmp_path / "f.tif"), "--preview",
                                      str(tmp_path / "f.png")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "f.png").stat().st_size > 0


def test_no_command_writes_a_page_name_twice():
    """audit 8 P2: refocus --g 4,4 wrote two pages raw@g4 and sai -n 12 named views S111 for
    (1, 11) and (11, 1): every later command called the file edited or damaged."""
    from plenocli.model.focus import parse_g
    from plenocli.model.views import sweep_page
    from plenocli.sai import view_names

    with pytest.raises(ValueError, match="g 4 is given twice"):
        parse_g("4,4")
    # audit 9 P2: values that differ beyond the page name's 6 digits named one page too
    for text in ("4,4.0000001", "4:4.00001:0.000001"):
        with pytest.raises(ValueError, match="would name one sweep page"):
            parse_g(text)
    assert len({sweep_page("raw", g) for g in parse_g("4,4.00001")}) == 2
    assert len({sweep_page("raw", g) for g in parse_g("2:3:0.1")}) == 11
    for n in (2, 9, 10, 12):
        names = view_names(n)
        assert len(set(names)) == n * n
    assert view_names(2) == ["S00", "S01", "S10", "S11"]


def test_crosstalk_refuses_a_capture_whose_open_part_is_outshone_in_some_tiles(inputs,
                                                                               tmp_path):
    """audit 8 W6: an unmasked scene passed as a masked white gave r = 95 % with tiles up to
    176 %, exit 0: somewhere the 'open' part was the darker view, which no masked white is."""
    side = tmp_path / "side"
    side.mkdir()
    a = np.full((64, 64), 1000.0, np.float32)
    b = np.full((64, 64), 300.0, np.float32)
    b[:, 48:] = 1500.0  # brighter than A in the right quarter only: A is brightest overall
    _plenocli_tiff(side / "scene.tif", np.stack([a, b]), views=["A", "B"])
    result = run_bad(inputs, tmp_path / "out", ["crosstalk", str(side / "scene.tif"),
                                                "--tile", "16", "-o", "{o}/c.json"])
    assert_one_line(result, 1, ("not brighter than the others everywhere", "r up to 150 %"))


def test_an_unwritable_output_folder_is_named_not_a_file_x_in_it(inputs, tmp_path):
    """audit 8 E7: a folder a stage fills was checked through a file 'x' in it, and the
    message named that file ('cannot write link/x'), which the user never gave."""
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "link").symlink_to(tmp_path / "nowhere")
    result = CliRunner().invoke(cli, ["simulate", "dualpixel", "-o", str(tmp_path / "out" / "link"),
                                      "--pixels", "64"])
    assert result.exit_code == 1
    assert "cannot write into" in result.output and "/x" not in result.output
