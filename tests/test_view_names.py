"""One rule for page names (plenocli.model.views): colour pages, default names, sweeps; and every
command names the pages of one file without names the same way."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io import tiffio
from plenocli.model.views import (
    ViewNames,
    colour_page,
    default_names,
    split_colour_page,
    split_sweep,
    sweep_page,
    view_of,
)
from plenocli.pipeline.stages.simulate import simulate


def test_default_names_and_page_numbers():
    names = ViewNames.of({}, 3)
    assert names.pages == ("view0", "view1", "view2") and list(names.pages) == default_names(3)
    assert ViewNames.of({"views": ["A", "B"]}, 2).pages == ("A", "B")
    assert names.index("view2") == 2 and names.index("1") == 1  # a name, or a page number
    assert names.index("3") is None and names.index("A") is None


@pytest.mark.parametrize("name, split", [
    ("left.R", ("left", "R")), ("S01.B", ("S01", "B")), ("a.b.G", ("a.b", "G")),
    ("R", None), (".R", None), ("left.X", None), ("S00.view0", None), ("left.", None),
])
def test_colour_page_rule(name, split):
    assert split_colour_page(name) == split
    assert view_of(name) == (split[0] if split else name)
    if split:
        assert colour_page(*split) == name


def test_colour_layout_groups_and_rgb_views():
    two = ViewNames(("left.R", "left.G", "left.B", "right.R", "right.G", "right.B"))
    assert two.colour_layout() == (["left", "right"], ["R", "G", "B"])
    assert two.rgb_views() == ["left", "right"]
    assert two.groups("stem") == [("left", [0, 1, 2]), ("right", [3, 4, 5])]
    rgb = ViewNames(("R", "G", "B"))
    assert rgb.is_rgb and rgb.rgb_views() == [""] and rgb.groups("stem") == [("stem", [0, 1, 2])]
    assert rgb.colour_layout() is None  # one view: no views to compare
    mixed = ViewNames(("A", "B", "S"))
    assert mixed.colour_layout() is None and mixed.rgb_views() is None
    assert mixed.groups("stem") == [("A", [0]), ("B", [1]), ("S", [2])]
    assert ViewNames(("left.R", "left.G", "right.R")).colour_layout() is None  # uneven
    assert ViewNames(("left.G", "left.R", "left.B")).rgb_views() is None  # not in R, G, B order


def test_sweep_tags():
    assert sweep_page("left.R", 4.0) == "left.R@g4" and sweep_page("R", 2.5) == "R@g2.5"
    assert split_sweep("left.R@g4") == ("left.R", "@g4") and split_sweep("A") == ("A", "")


@pytest.fixture(scope="module")
def unnamed(tmp_path_factory):
    """Files whose pages have no names (foreign TIFFs): two views of a stereo rig, its two
    masked whites, and a lenslet frame twice with its grid."""
    d = tmp_path_factory.mktemp("unnamed")
    simulate("stereo-rig", d / "rig", view_shape=(96, 128), seed=1)
    simulate("raytrix-scene", d / "rs", rows=96, cols=128)
    for src, dst, copies in (("rig/views.tif", "views.tif", 1), ("rig/white_L.tif", "wl.tif", 1),
                             ("rig/white_R.tif", "wr.tif", 1), ("rs/frames.tif", "frames.tif", 2)):
        data = np.concatenate([tiffio.read_image(d / src)[0]] * copies).astype(np.float32)
        tifffile.imwrite(d / dst, data, photometric="minisblack", metadata=None)
    return d


def _run(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result


def test_every_command_names_unnamed_pages_alike(unnamed):
    d, expected = unnamed, default_names(2)
    _run("crosstalk", d / "views.tif", "-o", d / "c.json")
    assert json.loads((d / "c.json").read_text())["captures"][0]["views"] == expected
    _run("crosstalk", d / "wl.tif", d / "wr.tif", "--mixing-out", d / "m.tif", "-o", d / "cm.json")
    assert json.loads((d / "cm.json").read_text())["captures"][0]["views"] == expected
    _run("unmix", d / "views.tif", "--mixing", d / "m.tif", "-o", d / "u.tif")
    assert tiffio.read_meta(d / "u.tif")["views"] == expected
    _run("refocus", d / "frames.tif", "--grid", d / "rs" / "grid.yaml", "-o", d / "r.tif")
    assert tiffio.read_meta(d / "r.tif")["views"] == expected
    _run("sai", d / "views.tif", "-n", "2", "-o", d / "sai.tif")
    assert tiffio.read_meta(d / "sai.tif")["views"][:2] == [f"S00.{n}" for n in expected]
    result = CliRunner().invoke(cli, ["develop", str(d / "views.tif"), "-o", str(d / "x.jpg")])
    assert result.exit_code == 1 and ", ".join(expected) in result.stderr  # names the views
    # a view is picked by its default name, or by its page number
    _run("crosstalk", d / "views.tif", "--intended", "view0", "-o", d / "c0.json")
    _run("crosstalk", d / "views.tif", "--intended", "0", "-o", d / "c1.json")


def test_stitch_names_unnamed_pages_alike(unnamed):
    d = unnamed
    _run("stitch", d / "views.tif", "-o", d / "p.tif", "--report", d / "s.json")
    assert json.loads((d / "s.json").read_text())["input_views"] == default_names(2)
