"""Side files (grids, mixing files, gain maps) checked against what they describe, and view
names and frame metadata that cannot be true."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import tifffile
import yaml
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io import tiffio
from plenocli.io.raytrix import format_calib
from tests.bad_inputs.files import (
    assert_one_line,
    plenocli_tiff,
    run_bad,
)

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
    plenocli_tiff(side / "views.tif", clean, views=["A", "B"])
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
    plenocli_tiff(side / "views.tif", clean, views=names, cfa="RGGB")
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
    plenocli_tiff(side / "views.tif", clean, **{k: meta[k] for k in
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
    # a table of colours (a grey table is read through: tests/test_samplekind.py)
    ramp = np.arange(256, dtype=np.uint16) * 257
    extra = {"palette": {"colormap": np.stack([ramp, ramp[::-1], ramp])}}
    samples = {"separated": 4, "cielab": 3}.get(photometric)
    image = grey if samples is None else np.repeat(grey[..., None], samples, axis=2)
    tifffile.imwrite(side / "x.tif", image, photometric=photometric, metadata=None,
                     **extra.get(photometric, {}))
    args = [stage, str(side / "x.tif"), "-o", "{o}/x.tif"] + (["-n", "2"] if stage == "sai"
                                                              else [])
    assert_one_line(run_bad(inputs, tmp_path / "out", args), 1, ("holds no light levels",))
