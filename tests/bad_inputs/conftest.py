"""Bad inputs over every command: exit 1 (2 for usage), one line, no traceback, no file left,
inputs unchanged.

Each case runs a command in-process (click's CliRunner) on a folder of small inputs, good and
bad, made once for the package; the output goes to a fresh folder that must stay empty, and
the inputs are hashed before and after every case (files.run_bad)."""

from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
import tifffile
import yaml
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io import tiffio
from plenocli.io.dng import write_dng
from plenocli.io.raytrix import calib_from_grid, format_calib
from plenocli.pipeline.stages.simulate import simulate
from plenocli.synth.dualpixel import dng_options, dualpixel_capture
from tests.bad_inputs.files import (
    huge_header_tiff,
    plain_tiff,
    plenocli_tiff,
    png_chunk,
    write_grid_yaml,
)


def _write_misfits(d: Path) -> None:
    """Sound files of a kind a stage misreads: view B of the bias output negated (a sign lost
    in a subtraction; its masked pixels filled, so its demosaic clips it), and a report
    another stage writes (its record: the provenance), not a side file."""
    biased, meta = tiffio.read_image(d / "biased.tif")
    page = meta["views"].index("B")
    biased[page] = -np.nan_to_num(biased[page])
    tiffio.write_image(d / "biased_neg_b.tif", biased, meta)
    (d / "crosstalk.json").write_text(json.dumps({"r": 0.1,
                                                  "provenance": {"stage": "crosstalk"}}))


@pytest.fixture(scope="package")
def inputs(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("inputs")
    runner = CliRunner()
    # a dual-pixel raw, decoded and bias-corrected
    raw, truth = dualpixel_capture(seed=3, rows=48, cols=64, top=8, left=16)
    write_dng(d / "dp.dng", raw, **dng_options(truth))
    for args in (["decode", d / "dp.dng", "-o", d / "frames.tif"],
                 ["bias", d / "frames.tif", "-o", d / "biased.tif"],
                 ["develop", d / "biased.tif", "--view", "S", "--wb", "2,1,1.5", "--matrix",
                  "none", "-o", d / "photo.tif", "--linear", d / "linear.tif"],
                 ["develop", d / "biased.tif", "--view", "S", "--wb", "2,1,1.5", "--matrix",
                  "none", "-o", d / "photo.jpg"],
                 ["bias", d / "frames.tif", "--crop", "24x32", "-o", d / "biased_crop.tif"]):
        result = runner.invoke(cli, [str(a) for a in args])
        assert result.exit_code == 0, result.output
    rigs = Path(__file__).resolve().parents[2] / "configs" / "rigs"
    (d / "dualpixel_prism.yaml").write_text((rigs / "dualpixel_prism.yaml").read_text())
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
        write_grid_yaml(d / f"grid_{name}.yaml", base, **change)
    write_grid_yaml(d / "grid_noshape.yaml", {k: base[k] for k in base
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
    plenocli_tiff(d / "f512.tif", rng.random((512, 512), np.float32))
    plenocli_tiff(d / "f511x509.tif", rng.random((509, 511), np.float32))
    plenocli_tiff(d / "f3.tif", rng.random((3, 3), np.float32))
    plenocli_tiff(d / "nan.tif", np.full((64, 64), np.nan, np.float32))
    unmasked = 1 + 0.01 * rng.random((4, 64, 64), np.float32)
    for k in range(4):
        plenocli_tiff(d / f"unmasked{k}.tif", unmasked, views=["S00", "S01", "S10", "S11"])
    plenocli_tiff(d / "white_xy.tif", rng.random((2, 32, 32), np.float32), cfa="RGGB",
                   views=["X", "Y"])
    plain_tiff(d / "complex.tif", (rng.random((16, 16)) + 1j).astype(np.complex64))
    plain_tiff(d / "bool.tif", rng.random((16, 16)) > 0.5)
    plain_tiff(d / "int8.tif", rng.integers(-100, 100, (16, 16)).astype(np.int8))
    plain_tiff(d / "nan_plain.tif", np.full((16, 16), np.nan, np.float32))
    _write_misfits(d)
    good = (d / "biased.tif").read_bytes()
    (d / "biased_copy.tif").write_bytes(good)  # another file with the same views
    (d / "truncated.tif").write_bytes(good[: len(good) * 2 // 3])
    huge_header_tiff(d / "huge.tif")
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
    plain_tiff(d / "inf.tif", np.full((16, 16), np.inf, np.float32))
    (d / "huge.png").write_bytes(
        b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", struct.pack(">IIBBBBB", 200000, 200000,
                                                                16, 0, 0, 0, 0))
        + png_chunk(b"IDAT", zlib.compress(bytes(100))) + png_chunk(b"IEND", b""))
    plain_tiff(d / "volume.tif", rng.random((2, 3, 16, 16)).astype(np.float32))
    (d / "garbage.tif").write_bytes(b"II*\x00" + rng.integers(0, 255, 500, np.uint8).tobytes())
    (d / "empty.tif").write_bytes(b"")
    return d



@pytest.fixture(scope="package")
def infinite(tmp_path_factory, inputs) -> Path:
    from plenocli.io.mixingfile import write_mixing
    from plenocli.model.mixing import MixingField

    d = tmp_path_factory.mktemp("infinite")
    rng = np.random.default_rng(7)
    clean = (100 + 50 * rng.random((2, 64, 64))).astype(np.float32)
    bad = clean.copy()
    bad[1, 5, 7] = np.inf
    levels = {"black_level": [[0.0] * 4] * 2, "white_level": [1e4] * 2}
    plenocli_tiff(d / "clean.tif", clean, views=["A", "B"], cfa="RGGB", **levels)
    plenocli_tiff(d / "views.tif", bad, views=["A", "B"], cfa="RGGB", **levels)
    plenocli_tiff(d / "mono.tif", bad, views=["A", "B"], **levels)
    plenocli_tiff(d / "frame.tif", np.where(np.isinf(bad[1]), -np.inf, bad[0]))
    plain_tiff(d / "sensor.tif", bad[1])
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
