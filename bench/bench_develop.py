"""Development of natural photographs and charts against LibRaw, and of a full-size view.

Photographs. scikit-image's bundled photographs recorded as a Canon 5D Mark IV records them
(``plenocli.synth.natural``: its ColorMatrix, as-shot neutral, RGGB, black 512, white 16383, shot
and read noise) into a DNG; ``decode -> bias -> develop --linear`` with every ``--method``, and
LibRaw (``rawpy.postprocess``, camera white balance, linear sRGB) with each of its demosaics on
the same DNG, in the same run: PSNR and CIE dE2000 (mean, 95th percentile) against the scene,
8 pixels from the edges left out. LibRaw's output is scaled to the scene by least squares (its
best exposure); plenocli's is compared in its own units (no fit).

Charts. The simulator's ColorChecker and letters charts as a camera samples them (pixel area +
4-spot optical low-pass filter), mosaicked (RGGB), demosaiced by every method.

Speed. Baseline, measured in the same run: ``rawpy.postprocess()`` (LibRaw's whole development:
its AHD demosaic, white balance, colour matrix, 8-bit sRGB) of the same raw, written as a DNG with
plenocli's own writer. Timed against it: plenocli's default demosaic of the view, as-shot white
balance, camera matrix, exposure and sRGB encoding (``colour.develop``), file I/O excluded on
both sides as far as LibRaw allows (its time includes reading the DNG). Targets: ratio <= 1.0;
peak memory (numpy allocations, tracemalloc) <= 3 x the float32 RGB output.

    python bench/bench_develop.py [--rows 4544 --cols 6880] [--skip-speed] [--skip-charts]
"""

from __future__ import annotations

import argparse
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np
import rawpy
import skimage.data
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.colour import demosaic as dm
from plenocli.colour import develop as dev
from plenocli.colour.metrics import colour_error
from plenocli.io.dng import write_dng
from plenocli.io.tiffio import read_image
from plenocli.model.colour import camera_to_srgb, rgb_to_xyz
from plenocli.synth.chart import camera_sampled, colour_chart, test_chart
from plenocli.synth.natural import natural_capture

PHOTOGRAPHS = {"astronaut": skimage.data.astronaut, "coffee": skimage.data.coffee,
               "chelsea": skimage.data.chelsea, "rocket": skimage.data.rocket,
               "motorcycle": lambda: skimage.data.stereo_motorcycle()[0]}
LIBRAW = ("AHD", "AAHD", "DCB", "DHT", "VNG", "PPG")

CAMERA = np.array([[0.80, 0.15, 0.05], [0.10, 0.80, 0.10], [0.05, 0.20, 0.75]]) \
    * np.array([[0.55], [1.0], [0.7]])


def accuracy(rows: int, cols: int) -> None:
    charts = {"ColorChecker": camera_sampled(colour_chart(rows * 4, cols * 4)[0], 4),
              "letters": camera_sampled(test_chart(rows * 4, cols * 4) ** 2.2, 4)}
    print(f"accuracy, {cols} x {rows} px charts, RGGB mosaic -> RGB "
          "(PSNR dB | dE2000 mean | dE2000 p95 | s):")
    for name, truth in charts.items():
        mosaic = dm.mosaic(truth, "RGGB")
        for method in dm.METHODS:
            start = time.perf_counter()
            rgb = dm.demosaic(mosaic, "RGGB", method=method)
            took = time.perf_counter() - start
            e = colour_error(rgb, truth)
            mark = " (default)" if method == dm.DEFAULT_METHOD else ""
            print(f"  {name:12s} {method:11s} {e.psnr_db:6.2f} | {e.delta_e_mean:5.2f} | "
                  f"{e.delta_e_p95:5.2f} | {took:5.2f}{mark}")


def photographs(tmp: Path) -> None:
    print("photographs, Canon 5D Mark IV DNG -> decode -> bias -> develop --linear vs scene "
          "(PSNR dB | dE2000 mean | dE2000 p95):")
    for seed, (name, load) in enumerate(PHOTOGRAPHS.items()):
        cap = natural_capture(load(), seed=seed)
        dng = tmp / f"{name}.dng"
        write_dng(dng, cap.raw, cfa=cap.cfa, black_levels=[cap.black], white_level=cap.white,
                  active_area=[0, 0, *cap.raw.shape], frame_names=["S"],
                  as_shot_neutral=cap.as_shot_neutral, color_matrix=cap.xyz_to_camera.ravel())
        _cli("decode", dng, "-o", tmp / "frames.tif")
        _cli("bias", tmp / "frames.tif", "-o", tmp / "biased.tif")
        rows = {"before": _before(cap)}
        for method in dm.METHODS:
            _cli("develop", tmp / "biased.tif", "-o", tmp / "photo.tif", "--linear",
                 tmp / "linear.tif", "--method", method)
            linear = np.moveaxis(read_image(tmp / "linear.tif")[0], 0, -1)
            rows[method] = linear / (cap.dn_per_unit * cap.as_shot_neutral[1])
        for algorithm in LIBRAW:
            with rawpy.imread(str(dng)) as raw:
                rgb = raw.postprocess(
                    demosaic_algorithm=getattr(rawpy.DemosaicAlgorithm, algorithm),
                    use_camera_wb=True, output_color=rawpy.ColorSpace.sRGB, gamma=(1, 1),
                    no_auto_bright=True, output_bps=16, user_flip=0).astype(np.float32)
            rows[f"LibRaw {algorithm}"] = rgb * float((rgb * cap.truth).sum() / (rgb**2).sum())
        print(f"  {name} ({cap.raw.shape[1]} x {cap.raw.shape[0]}):")
        for label, rgb in rows.items():
            e = colour_error(rgb, cap.truth)
            mark = " (default)" if label == dm.DEFAULT_METHOD else ""
            print(f"    {label:11s} {e.psnr_db:6.2f} | {e.delta_e_mean:5.2f} | "
                  f"{e.delta_e_p95:5.2f}{mark}")


def _before(cap) -> np.ndarray:
    """What develop made before white balance moved ahead of demosaicing: menon2007 on camera
    RGB, then the gains and the matrix (in-process; decode and bias only subtract the black)."""
    mosaic = cap.raw.astype(np.float32) - cap.black
    gains = cap.as_shot_neutral[1] / cap.as_shot_neutral
    camera = dm.demosaic(mosaic, cap.cfa, method="menon2007", gains=(1, 1, 1))
    to_srgb = camera_to_srgb(cap.xyz_to_camera).astype(np.float32).T
    return camera * gains.astype(np.float32) @ to_srgb / (cap.dn_per_unit * cap.as_shot_neutral[1])


def edge_crop(path: Path, *, side: int = 40, zoom: int = 6) -> None:
    """A PNG of one crop of the coffee photograph, side by side: the scene, plenocli before
    (menon2007 demosaicing camera RGB, white balance after), plenocli now (the default, balanced
    first), LibRaw AHD. The crop is the window where "before" errs most (the cup's rim)."""
    from PIL import Image

    from plenocli.io.photo import encode

    cap = natural_capture(skimage.data.coffee(), seed=1)
    mosaic = cap.raw.astype(np.float32) - cap.black
    gains = cap.as_shot_neutral[1] / cap.as_shot_neutral
    to_srgb = camera_to_srgb(cap.xyz_to_camera).astype(np.float32).T
    scale = cap.dn_per_unit * cap.as_shot_neutral[1]

    before = _before(cap)
    after = dm.demosaic(mosaic, cap.cfa, gains=gains) * gains.astype(np.float32) @ to_srgb / scale
    with tempfile.TemporaryDirectory() as tmp:
        dng = Path(tmp) / "coffee.dng"
        write_dng(dng, cap.raw, cfa=cap.cfa, black_levels=[cap.black], white_level=cap.white,
                  active_area=[0, 0, *cap.raw.shape], as_shot_neutral=cap.as_shot_neutral,
                  color_matrix=cap.xyz_to_camera.ravel())
        with rawpy.imread(str(dng)) as raw:
            rgb = raw.postprocess(use_camera_wb=True, output_color=rawpy.ColorSpace.sRGB,
                                  gamma=(1, 1), no_auto_bright=True, output_bps=16,
                                  user_flip=0).astype(np.float32)
    libraw = rgb * float((rgb * cap.truth).sum() / (rgb**2).sum())
    err = np.abs(before - cap.truth).sum(axis=-1)
    windows = err[:err.shape[0] // side * side, :err.shape[1] // side * side]
    windows = windows.reshape(err.shape[0] // side, side, -1, side).sum(axis=(1, 3))
    r, c = (side * v for v in np.unravel_index(np.argmax(windows), windows.shape))
    panels = [encode(x[r:r + side, c:c + side], "srgb") for x in
              (cap.truth, before, after, libraw)]
    gap = np.ones((side, 2, 3), np.float32)
    strip = np.concatenate([p for panel in panels for p in (panel, gap)][:-1], axis=1)
    big = np.repeat(np.repeat(strip, zoom, axis=0), zoom, axis=1)
    Image.fromarray(np.round(big * 255).astype(np.uint8)).save(path)
    for label, x in (("before", before), ("now", after), ("LibRaw AHD", libraw)):
        e = colour_error(x[r:r + side, c:c + side], cap.truth[r:r + side, c:c + side], border=0)
        print(f"  crop rows {r}-{r + side}, cols {c}-{c + side}: {label:10s} "
              f"{e.psnr_db:6.2f} dB | dE2000 {e.delta_e_mean:5.2f}")


def _cli(*args) -> None:
    result = CliRunner().invoke(cli, [str(a) for a in args] + ["-q"])
    if result.exit_code != 0:
        raise RuntimeError(result.output)


def develop_view(mosaic: np.ndarray, gains, to_srgb, *, method: str = dm.DEFAULT_METHOD,
                 demosaic_gains="as-shot") -> np.ndarray:
    view = dev.ColourView("S", (0,), "RGGB")
    camera = dev.camera_rgb(mosaic[np.newaxis], view, method=method,
                            gains=gains if demosaic_gains == "as-shot" else demosaic_gains)
    scene = dev.scene_rgb(camera, gains=gains, camera_to_srgb=to_srgb, in_place=True)
    scale = dev.exposure_scale(scene)
    return dev.output_encoded(scene, "srgb", scale, in_place=True)


def speed(rows: int, cols: int, repeat: int) -> None:
    rng = np.random.default_rng(0)
    chart = colour_chart(rows, cols)[0]
    camera = chart @ CAMERA.T
    camera *= 0.9 + 0.2 * rng.random((rows, 1, 1), dtype=np.float32)  # some texture
    raw = np.round(512 + 12000 * dm.mosaic(camera, "RGGB")).astype(np.uint16)
    del chart, camera
    xyz_to_camera = CAMERA @ np.linalg.inv(rgb_to_xyz("srgb"))
    neutral = CAMERA.sum(axis=1)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "view.dng"
        write_dng(path, raw, cfa="RGGB", black_levels=[512], white_level=16383,
                  active_area=[0, 0, rows, cols], as_shot_neutral=neutral,
                  color_matrix=xyz_to_camera.ravel())

        def libraw():
            with rawpy.imread(str(path)) as r:
                return r.postprocess()

        base = min(_timed(libraw) for _ in range(repeat))
    mosaic = (raw.astype(np.float32) - 512)
    del raw
    gains, to_srgb = neutral[1] / neutral, camera_to_srgb(xyz_to_camera)
    ours = min(_timed(lambda: develop_view(mosaic, gains, to_srgb)) for _ in range(repeat))
    before = min(_timed(lambda: develop_view(mosaic, gains, to_srgb, method="menon2007",
                                             demosaic_gains=(1, 1, 1))) for _ in range(repeat))
    tracemalloc.start()
    out = develop_view(mosaic, gains, to_srgb)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rgb_bytes = rows * cols * 3 * 4
    print(f"speed, {cols} x {rows} view:")
    print(f"  rawpy.postprocess (baseline)     {base:6.2f} s")
    print(f"  plenocli demosaic + colour       {ours:6.2f} s   ratio {ours / base:.2f} "
          "(target <= 1.0)")
    print(f"  before (menon2007 on camera RGB) {before:6.2f} s   ratio {before / base:.2f}")
    print(f"  peak memory {peak / 2**20:7.0f} MiB = {peak / rgb_bytes:.2f} x the float32 RGB "
          f"output ({rgb_bytes / 2**20:.0f} MiB; target <= 3)")
    del out


def _timed(func) -> float:
    start = time.perf_counter()
    func()
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=4544)
    parser.add_argument("--cols", type=int, default=6880)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--chart-rows", type=int, default=768)
    parser.add_argument("--skip-speed", action="store_true")
    parser.add_argument("--skip-charts", action="store_true")
    parser.add_argument("--crop", type=Path, default=None,
                        help="write the edge crop (scene | before | now | LibRaw AHD) as PNG")
    args = parser.parse_args()
    if args.crop:
        edge_crop(args.crop)
    with tempfile.TemporaryDirectory() as tmp:
        photographs(Path(tmp))
    if not args.skip_charts:
        accuracy(args.chart_rows, args.chart_rows * 3 // 2)
    if not args.skip_speed:
        speed(args.rows, args.cols, args.repeat)


if __name__ == "__main__":
    main()
