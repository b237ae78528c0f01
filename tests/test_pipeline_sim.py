"""The whole pipeline on simulated captures: simulate -> decode -> (sai | refocus) -> stitch."""

import json
from pathlib import Path

import numpy as np
import pytest

from plenocli.io.gridfile import read_grid
from plenocli.io.raw import decode
from plenocli.io.rigfile import read_rig
from plenocli.io.tiffio import read_image, read_meta
from plenocli.pipeline.config import load_config
from plenocli.pipeline.runner import run_pipeline
from plenocli.pipeline.stages.simulate import simulate
from plenocli.sai import demultiplex
from plenocli.stitch import stitch

ROOT = Path(__file__).resolve().parents[1]


def _views(frames, n=2):
    return np.stack([demultiplex(f, n) for f in frames])


def test_quadpixel_pyramid_stitches_to_twice_the_field(tmp_path):
    truth = simulate("quadpixel-pyramid", tmp_path, pixels=256, seed=0)
    frames, meta = decode(tmp_path / truth["files"]["capture"])
    views = _views(frames.astype(np.float32))  # (3 colours, 4 views, rows, cols)
    green = views[1]
    # placed by shifts alone, the prisms' distortion leaves the seams 0.8 px apart at their
    # ends: refused (as `plenocli stitch` refuses it); through the rig they line up
    with pytest.raises(ValueError, match="does not describe these views"):
        stitch(green, layout="2x2", model="translation")
    panorama, report = stitch(green, layout="2x2", rig=read_rig(ROOT / "configs" / "rigs"
                                                                / "quadpixel_pyramid.yaml"))
    rows, cols = green.shape[1:]
    # The four views overlap by a sliver only (64 deg stitched vs 2 x 32.6): the panorama is
    # close to twice a view in each direction.
    assert panorama.shape[-2] > 1.7 * rows and panorama.shape[-1] > 1.7 * cols
    assert truth["stitched_field_deg"]["x"] == pytest.approx(2 * truth["main_lens_field_deg"],
                                                             rel=0.05)
    assert report.layout == "2x2"


def test_dualpixel_prism_stitches_a_wider_image(tmp_path):
    truth = simulate("dualpixel-prism", tmp_path, pixels=384, seed=2, noise_dn=0.0)
    frames, meta = decode(tmp_path / truth["files"]["capture"])
    top, left, bottom, right = meta["active_area"]
    black = truth["black_level"]
    s = frames[0, top:bottom, left:right].astype(np.float32) - black
    a = frames[1, top:bottom, left:right].astype(np.float32) - black
    b = s - a
    # Green pixels of each 2 x 2 cell: a grey picture of each view. The raw image is inverted,
    # so A (deviated towards +x on the chart) is the left part of the panorama.
    views = np.stack([a[0::2, 1::2], b[0::2, 1::2]])
    panorama, report = stitch(views, layout="1x2", model="translation")
    cols = views.shape[-1]
    expected = cols + truth["overlap_shift_px"] / 2  # green sub-grid: half the pixels
    assert panorama.shape[-1] == pytest.approx(expected, abs=4)


def test_raytrix_prism_pipeline_from_the_config(tmp_path):
    """simulate -> decode -> calibrate -> flat -> refocus (sweep, left, right) -> stitch, run by
    the shipped config with its inputs and outputs redirected into a temp folder."""
    for kind in ("raytrix-prism", "raytrix-white", "raytrix-ghost"):
        simulate(kind, tmp_path / kind, pixels=1200)
    out = tmp_path / "out"
    overrides = [f"decode.input={tmp_path / 'raytrix-prism' / 'capture.tif'}",
                 f"decode_white.input={tmp_path / 'raytrix-white' / 'capture.tif'}",
                 *(f"decode_masked_{h}.input={tmp_path / 'raytrix-ghost' / f'masked_{h}.tif'}"
                   for h in ("left", "right"))]
    steps = load_config(ROOT / "configs" / "raytrix_r5.yaml", overrides)
    for step in steps:  # every path under out/demo goes to the temp folder instead
        for key in (*step.stage.inputs, *step.stage.outputs):
            value = step.params.get(key)
            if isinstance(value, (list, tuple)):
                step.params[key] = [_moved(v, out) for v in value]
            elif value:
                step.params[key] = _moved(value, out)
    run_pipeline(steps)

    truth = json.loads((tmp_path / "raytrix-prism" / "truth.json").read_text())
    grid = read_grid(out / "grid.yaml")
    assert grid.pitch_px == pytest.approx(truth["lattice"]["diameter"], abs=0.005)
    assert read_meta(out / "sweep.tif")["sharpness"]["best_g"] == pytest.approx(truth["g"])
    left, _ = read_image(out / "left.tif")
    panorama, _ = read_image(out / "panorama.tif")
    assert panorama.shape[-1] > 1.2 * left.shape[-1]  # wider than one view: the prism's field


def _moved(path: str, folder: Path) -> str:
    return str(folder / Path(path).name) if "out/demo" in path else path
