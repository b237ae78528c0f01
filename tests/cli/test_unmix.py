"""End-to-end: plenocli crosstalk --mixing-out and plenocli unmix on synthetic views files."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io import tiffio
from plenocli.io.mixingfile import read_mixing, write_mixing
from plenocli.synth import mixing as sim_mixing
from plenocli.unmix import MixingField

SHAPE = (64, 96)


def _invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture()
def rig(tmp_path):
    """Dual-pixel views (A, B, S; RGGB) with r = 50 % ghosts, their masked whites, the truth."""
    rng = np.random.default_rng(0)
    colours = sim_mixing.colour_index(SHAPE, "RGGB")
    field = sim_mixing.mixing_field(SHAPE, n_views=2, r=0.5, colours=("R", "G", "B"), seed=1)
    clean = rng.uniform(0.2, 1.0, (2, *SHAPE))
    ghosted = sim_mixing.apply_mixing(clean, field, colours)
    whites = np.ones((2, *SHAPE))
    meta = {"views": ["A", "B", "S"], "cfa": "RGGB", "active_area": [0, 0, *SHAPE]}
    paths = {}
    for name, views in (("views", ghosted), *(
            (f"masked_{n}", sim_mixing.masked_white(whites, field, j, colours))
            for j, n in enumerate("AB"))):
        paths[name] = tmp_path / f"{name}.tif"
        stack = np.concatenate([views, views.sum(axis=0, keepdims=True)]).astype(np.float32)
        tiffio.write_image(paths[name], stack, meta)
    paths["mixing"] = tmp_path / "mixing.tif"
    res = _invoke("crosstalk", paths["masked_A"], paths["masked_B"], "--views", "A,B",
                  "--intended", "A,B", "--tile", 8, "-o", tmp_path / "ct.json",
                  "--mixing-out", paths["mixing"], "--preview", tmp_path / "ct.png")
    assert res.exit_code == 0, res.output
    return paths, clean, ghosted, tmp_path


def test_crosstalk_writes_mixing_and_r(rig):
    paths, _, _, tmp = rig
    field, meta = read_mixing(paths["mixing"])
    assert field.views == ("A", "B") and field.colours == ("R", "G", "B")
    assert meta["mixing"]["layout"] == "cfa" and meta["mixing"]["cfa"] == "RGGB"
    assert meta["provenance"]["stage"] == "crosstalk"
    report = json.loads((tmp / "ct.json").read_text())
    assert [c["intended"] for c in report["captures"]] == ["A", "B"]
    # r (the paper's number, flux over the frame) agrees with the mean of M's off-diagonal
    assert report["r"] == pytest.approx(report["mixing"]["r_mean"], abs=0.01)
    assert report["mixing"]["r_max"] >= report["r"]
    assert (tmp / "ct.png").stat().st_size > 0


def test_unmix_recovers_views_and_keeps_pages(rig):
    paths, clean, ghosted, tmp = rig
    out = tmp / "clean.tif"
    res = _invoke("unmix", paths["views"], "--mixing", paths["mixing"], "-o", out,
                  "--noise-map", tmp / "gain.tif", "--preview", tmp / "clean.png")
    assert res.exit_code == 0, res.output
    data, meta = tiffio.read_image(out)
    assert meta["views"] == ["A", "B", "S"] and meta["cfa"] == "RGGB"
    np.testing.assert_allclose(data[:2], clean, rtol=2e-3)
    # S = A + B (bias's views) is made again from the unmixed A and B, not copied with its
    # ghosts (audit 6 W6)
    np.testing.assert_array_equal(data[2], data[0] + data[1])
    np.testing.assert_allclose(data[2], clean.sum(axis=0), rtol=2e-3)
    assert meta["provenance"]["stage"] == "unmix" and meta["unmix"]["noise_gain_max"] > 1.3
    gain, gain_meta = tiffio.read_image(tmp / "gain.tif")
    assert gain_meta["views"] == ["A", "B"] and gain.shape == (2, *SHAPE)
    assert (tmp / "clean.png").stat().st_size > 0


def test_regularise_and_nan(rig):
    paths, clean, ghosted, tmp = rig
    views, meta = tiffio.read_image(paths["views"])
    views[0, 10, 20] = np.nan
    path = tmp / "nan.tif"
    tiffio.write_image(path, views, meta)
    res = _invoke("unmix", path, "--mixing", paths["mixing"], "-o", tmp / "o.tif",
                  "--regularise", 0.05)
    assert res.exit_code == 0, res.output
    data, meta = tiffio.read_image(tmp / "o.tif")
    assert np.isnan(data[:2, 10, 20]).all() and np.isfinite(data[:2, 11, 20]).all()
    assert meta["unmix"]["regularise"] == 0.05
    res = _invoke("unmix", path, "--mixing", paths["mixing"], "-o", tmp / "o2.tif",
                  "--regularise", "nan")
    assert res.exit_code == 2 and not (tmp / "o2.tif").exists()


def _bad_views(tmp, shape=SHAPE, names=("A", "B", "S"), cfa="RGGB"):
    path = tmp / "bad_views.tif"
    tiffio.write_image(path, np.ones((len(names), *shape), np.float32),
                       {"views": list(names), "cfa": cfa})
    return path


def _mixing_file(tmp, nodes, views=("A", "B")):
    path = tmp / "bad_mixing.tif"
    # the centres of 48 px tiles on the 96 x 64 frame, as crosstalk --tile 48 writes them
    field = MixingField(nodes, np.array([23.5, 55.5]), np.array([23.5, 71.5]), SHAPE, views,
                        ("L",))
    write_mixing(path, field, layout="mono", cfa=None, meta={})
    return path


@pytest.mark.parametrize("case,message", [
    ("size", "measured on 96 x 64"),
    ("cfa", "CFA GRBG"),
    ("names", "has no view 'A'"),
    ("view_count", "has no view 'c'"),
    ("singular", "singular"),
    ("not_mixing", "not a mixing file"),
    ("parts_left_out", "mixes views S00,S01 only, but"),   # W5 (audit 6): half unmixed, exit 0
])
def test_bad_input_one_line_exit_1_nothing_written(rig, case, message):
    paths, _, _, tmp = rig
    views, mixing = paths["views"], paths["mixing"]
    if case == "size":
        views = _bad_views(tmp, shape=(64, 100))
    elif case == "cfa":
        views = _bad_views(tmp, cfa="GRBG")
    elif case == "names":
        views = _bad_views(tmp, names=("L", "R"))
    elif case == "view_count":
        m = np.eye(4) + 0.1 * (1 - np.eye(4))  # M_jj = 1, as measured
        nodes = np.tile(m[None, :, :, None, None], (1, 1, 1, 2, 2))
        mixing = _mixing_file(tmp, nodes, views=("A", "B", "c", "d"))
    elif case == "singular":
        views = _bad_views(tmp, cfa=None, names=("A", "B", "C"))
        m = np.array([[1, 0, 5 / 6], [0, 1, 5 / 6], [0.6, 0.6, 1]])  # row C = 0.6 (A + B)
        mixing = _mixing_file(tmp, np.tile(m[None, :, :, None, None], (1, 1, 1, 2, 2)),
                              views=("A", "B", "C"))
    elif case == "not_mixing":
        mixing = paths["masked_A"]
    elif case == "parts_left_out":
        views = _bad_views(tmp, cfa=None, names=("S00", "S01", "S10", "S11"))
        m = np.eye(2) + 0.1 * (1 - np.eye(2))
        mixing = _mixing_file(tmp, np.tile(m[None, :, :, None, None], (1, 1, 1, 2, 2)),
                              views=("S00", "S01"))
    out = tmp / "out.tif"
    res = _invoke("unmix", views, "--mixing", mixing, "-o", out, "--noise-map",
                  tmp / "gain.tif", "--preview", tmp / "p.png")
    assert res.exit_code == 1, res.output
    assert message in res.output and len(res.output.strip().splitlines()) == 1
    assert "Traceback" not in res.output
    assert not out.exists() and not (tmp / "gain.tif").exists() and not (tmp / "p.png").exists()


def test_crosstalk_mixing_covers_every_pupil_part(tmp_path):
    """W5 (audit 6): --views S00,S01 on a quad-pixel rig's masked whites wrote a 2 x 2 mixing
    that unmix applied to the four views (S00, S01 18 % off, S10, S11 left ghosted)."""
    names = ["S00", "S01", "S10", "S11"]
    whites = []
    for j in range(2):
        path = tmp_path / f"w{j}.tif"
        views = np.full((4, *SHAPE), 0.1, np.float32)
        views[j] = 1.0
        tiffio.write_image(path, views, {"views": names})
        whites.append(path)
    res = _invoke("crosstalk", *whites, "--views", "S00,S01", "--intended", "S00,S01",
                  "--tile", 16, "-o", tmp_path / "c.json", "--mixing-out", tmp_path / "m.tif")
    assert res.exit_code == 1 and "holds pupil parts S00,S01,S10,S11" in res.output
    assert not (tmp_path / "m.tif").exists() and not (tmp_path / "c.json").exists()
    res = _invoke("crosstalk", *whites, "--views", "S00,S01", "--intended", "S00,S01",
                  "--tile", 16, "-o", tmp_path / "c.json")   # r alone of two parts: fine
    assert res.exit_code == 0, res.output


def test_crosstalk_mixing_needs_one_white_per_part(rig):
    paths, _, _, tmp = rig
    res = _invoke("crosstalk", paths["masked_A"], "--views", "A,B", "-o", tmp / "c.json",
                  "--mixing-out", tmp / "m.tif")
    assert res.exit_code == 1 and "one masked white per pupil part" in res.output
    res = _invoke("crosstalk", paths["masked_A"], paths["masked_A"], "--views", "A,B",
                  "-o", tmp / "c.json", "--mixing-out", tmp / "m.tif")
    assert res.exit_code == 1 and "given twice" in res.output
    again = tmp / "masked_A_again.tif"  # the same white under two names
    again.write_bytes(paths["masked_A"].read_bytes())
    res = _invoke("crosstalk", paths["masked_A"], again, "--views", "A,B",
                  "-o", tmp / "c.json", "--mixing-out", tmp / "m.tif")
    assert res.exit_code == 1 and "open each pupil part once" in res.output
    assert not (tmp / "m.tif").exists() and not (tmp / "c.json").exists()


def test_one_file_per_view_like_raytrix_left_right(tmp_path):
    """Refocused left/right images are one file each: crosstalk takes two per masked white (in
    the order of --views), unmix takes both and names the views after the files."""
    field = sim_mixing.mixing_field(SHAPE, n_views=2, r=0.1, seed=4)
    whites = np.ones((2, *SHAPE))
    clean = np.random.default_rng(3).uniform(0.2, 1.0, (2, *SHAPE))
    ghosted = sim_mixing.apply_mixing(clean, field)
    files = []
    for j, half in enumerate(("left", "right")):
        masked = sim_mixing.masked_white(whites, field, j)
        for k, view in enumerate(("left", "right")):
            path = tmp_path / f"masked_{half}_{view}.tif"
            tiffio.write_image(path, masked[k:k + 1].astype(np.float32), {"views": ["L"]})
            files.append(path)
    for k, view in enumerate(("left", "right")):
        tiffio.write_image(tmp_path / f"{view}.tif", ghosted[k:k + 1].astype(np.float32),
                           {"views": ["L"]})
    res = _invoke("crosstalk", *files, "--views", "left,right", "--intended", "left,right",
                  "--tile", 8, "-o", tmp_path / "ct.json", "--mixing-out", tmp_path / "m.tif")
    assert res.exit_code == 0, res.output
    res = _invoke("unmix", tmp_path / "left.tif", tmp_path / "right.tif", "--mixing",
                  tmp_path / "m.tif", "-o", tmp_path / "clean.tif")
    assert res.exit_code == 0, res.output
    data, meta = tiffio.read_image(tmp_path / "clean.tif")
    assert meta["views"] == ["left", "right"]
    np.testing.assert_allclose(data, clean, rtol=1e-3)
    res = _invoke("crosstalk", *files[:3], "--views", "left,right", "-o", tmp_path / "c2.json",
                  "--mixing-out", tmp_path / "m2.tif")
    assert res.exit_code == 1 and "give that many files per masked white" in res.output
    # audit 23 F2: files named otherwise (capture_left.tif) are named by --views, as crosstalk's
    for view in ("left", "right"):
        (tmp_path / f"{view}.tif").rename(tmp_path / f"capture_{view}.tif")
    named = [tmp_path / f"capture_{view}.tif" for view in ("right", "left")]
    res = _invoke("unmix", *named, "--mixing", tmp_path / "m.tif", "-o", tmp_path / "c3.tif")
    assert res.exit_code == 1 and "or by --views (e.g. --views left,right)" in res.output
    res = _invoke("unmix", *named, "--views", "right,left", "--mixing", tmp_path / "m.tif",
                  "-o", tmp_path / "c3.tif")
    assert res.exit_code == 0, res.output
    data, meta = tiffio.read_image(tmp_path / "c3.tif")
    assert meta["views"] == ["right", "left"]
    assert meta["provenance"]["parameters"]["views"] == "right,left"
    np.testing.assert_allclose(data, clean[::-1], rtol=1e-3)
    # audit 24c W2: a file's refocus record says which part it holds, whatever its name
    for k, view in enumerate(("left", "right")):
        tiffio.write_image(tmp_path / f"{('right', 'left')[k]}.tif",
                           ghosted[k:k + 1].astype(np.float32),
                           {"views": ["raw"], "refocus": {"view": view}})
    swapped = [tmp_path / "right.tif", tmp_path / "left.tif"]
    res = _invoke("unmix", *swapped, "--mixing", tmp_path / "m.tif", "-o", tmp_path / "c5.tif")
    assert res.exit_code == 0, res.output
    data, meta = tiffio.read_image(tmp_path / "c5.tif")
    assert meta["views"] == ["left", "right"]
    np.testing.assert_allclose(data, clean, rtol=1e-3)
    res = _invoke("unmix", *swapped, "--views", "right,left", "--mixing", tmp_path / "m.tif",
                  "-o", tmp_path / "c6.tif")
    assert res.exit_code == 1 and "refocus made it of the left part" in res.output
    for views in ("left", "left,left", "left,right,x"):
        res = _invoke("unmix", *named, "--views", views, "--mixing", tmp_path / "m.tif",
                      "-o", tmp_path / "c4.tif")
        assert res.exit_code == 2 and "--views" in res.output and not (tmp_path / "c4.tif").exists()


def test_non_finite_mixing_is_refused(rig):
    paths, _, _, tmp = rig
    nodes = np.tile(np.eye(2)[None, :, :, None, None], (1, 1, 1, 2, 2))
    nodes[0, 0, 1, 1, 1] = np.nan
    mixing = _mixing_file(tmp, nodes)
    res = _invoke("unmix", _bad_views(tmp, cfa=None), "--mixing", mixing, "-o", tmp / "o.tif",
                  "--regularise", 0.1)
    assert res.exit_code == 1 and "non-finite" in res.output and not (tmp / "o.tif").exists()


def _made_by(path, stages):
    """Rewrite ``path`` as if the stages listed (oldest first) had made it."""
    data, meta = tiffio.read_image(path)
    records = [{"software": "plenocli", "stage": s, "parameters": {}, "inputs": []}
               for s in stages]
    tiffio.write_image(path, data, {**meta, "history": records[:-1], "provenance": records[-1]})


def test_a_mixing_of_views_processed_otherwise_is_refused(rig):
    """W3 (audit 6): a mixing measured on bias-only whites unmixed flat-fielded views (ghosts
    of 2 % median, 7 % p99 left, exit 0). The mixing records the stages that made its whites;
    unmix refuses views made by others, and crosstalk whites processed unalike."""
    paths, _, _, tmp = rig
    for name in ("masked_A", "masked_B"):
        _made_by(paths[name], ["decode", "bias"])
    _made_by(paths["views"], ["decode", "bias", "flat"])
    mixing = tmp / "m_bias.tif"
    res = _invoke("crosstalk", paths["masked_A"], paths["masked_B"], "--views", "A,B",
                  "--intended", "A,B", "--tile", 8, "-o", tmp / "c.json", "--mixing-out", mixing)
    assert res.exit_code == 0, res.output
    assert read_mixing(mixing)[1]["mixing"]["views_made_by"] == ["decode", "bias"]
    out = tmp / "u.tif"
    res = _invoke("unmix", paths["views"], "--mixing", mixing, "-o", out)
    assert res.exit_code == 1 and not out.exists()
    assert "measured on views made by decode > bias, but" in res.output
    assert "made by decode > bias > flat" in res.output
    _made_by(paths["views"], ["decode", "bias"])
    assert _invoke("unmix", paths["views"], "--mixing", mixing, "-o", out).exit_code == 0
    # a mixing file written before the record: the last stage of its whites (its history)
    field, _ = read_mixing(mixing)
    older = tmp / "older.tif"
    write_mixing(older, field, layout="cfa", cfa="RGGB",
                 meta={"history": [{"stage": "bias", "parameters": {}}] * 2})
    _made_by(paths["views"], ["decode", "bias", "flat"])
    res = _invoke("unmix", paths["views"], "--mixing", older, "-o", out)
    assert res.exit_code == 1 and "measured on views made by bias" in res.output
    _made_by(paths["masked_B"], ["decode", "bias", "flat"])
    res = _invoke("crosstalk", paths["masked_A"], paths["masked_B"], "--views", "A,B",
                  "--intended", "A,B", "--tile", 8, "-o", tmp / "d.json", "--mixing-out",
                  tmp / "m2.tif")
    assert res.exit_code == 1 and "process the masked whites alike" in res.output


def test_colour_views_given_one_file_each_are_unmixed(tmp_path):
    """audit 7 E22: left.tif and right.tif of pages R, G, B each (refocus --view left/right of
    colour frames) were refused as "repeated view names (R,G,B,R,G,B)"; each file is one view
    named after it, its pages that view's colours."""
    import tifffile

    rng = np.random.default_rng(5)
    clean = (100 + 50 * rng.random((2, 3, 32, 32))).astype(np.float32)
    m = np.array([[1.0, 0.2], [0.1, 1.0]])
    mixed = np.einsum("kj,jcyx->kcyx", m, clean).astype(np.float32)
    for name, views in zip(("left", "right"), mixed, strict=True):
        tifffile.imwrite(tmp_path / f"{name}.tif", views, photometric="minisblack",
                         metadata=None, description=json.dumps(
                             {tiffio.FORMAT_KEY: 1, "views": ["R", "G", "B"], "cfa": None}))
    nodes = m[None, :, :, None, None] * np.ones((3, 1, 1, 2, 2))
    field = MixingField(nodes, np.array([7.5, 23.5]), np.array([7.5, 23.5]), (32, 32),
                        ("left", "right"), ("R", "G", "B"))
    write_mixing(tmp_path / "mixing.tif", field, layout="channels", cfa=None, meta={})
    result = CliRunner().invoke(cli, ["unmix"] + [str(tmp_path / a) for a in (
        "left.tif", "right.tif")] + ["--mixing", str(tmp_path / "mixing.tif"), "-o",
                                     str(tmp_path / "clean.tif")])
    assert result.exit_code == 0, result.output
    out, meta = tiffio.read_image(tmp_path / "clean.tif")
    assert meta["views"] == ["left.R", "left.G", "left.B", "right.R", "right.G", "right.B"]
    np.testing.assert_allclose(out.reshape(2, 3, 32, 32), clean, rtol=1e-4)


def test_a_mixing_that_removes_more_light_than_there_is_is_refused(rig):
    """audit 21b W1: a mixing measured on a rig of r 65 % applied to a capture of r 50 % gave
    clean views 14-19 % RMS wrong, down to -2954 DN on ~4000 DN, exit 0. Here the rig's mixing
    (r 50 %) is applied to views ghosted at r 30 % with dark patches: refused in one line."""
    paths, _, _, tmp = rig
    yy, xx = np.mgrid[:SHAPE[0], :SHAPE[1]]
    clean = np.stack([0.5 + 0.4 * np.sin(xx / 5.0), 0.6 + 0.3 * np.cos(yy / 4.0)])
    clean[0, 10:40, 20:60] = 0.005
    colours = sim_mixing.colour_index(SHAPE, "RGGB")
    field = sim_mixing.mixing_field(SHAPE, n_views=2, r=0.3, colours=("R", "G", "B"), seed=1)
    views = sim_mixing.apply_mixing(clean, field, colours)
    path = tmp / "r30.tif"
    tiffio.write_image(path, np.concatenate([views, views.sum(axis=0, keepdims=True)]).astype(
        np.float32), {"views": ["A", "B", "S"], "cfa": "RGGB", "active_area": [0, 0, *SHAPE]})
    out = tmp / "out.tif"
    res = _invoke("unmix", path, "--mixing", paths["mixing"], "-o", out)
    assert res.exit_code == 1, res.output
    assert "removes more light than" in res.output and "view A's pixels" in res.output
    assert "content out of focus" in res.output
    assert len(res.output.strip().splitlines()) == 1 and not out.exists()
    res = _invoke("unmix", paths["views"], "--mixing", paths["mixing"], "-o", out)
    assert res.exit_code == 0, res.output  # its own capture (pixel-scale texture) passes


def test_a_mixing_too_strong_in_one_bayer_colour_is_refused_wherever_the_object_falls():
    """Audit 23 W1/W4: one colour over-corrected in a dark patch darkens exactly a quarter of
    each 32 px block (never more than the block rule's quarter), and an object across four
    blocks had a fifth of each: both passed with exit 0. Mosaics are judged colour by colour,
    blocks on two grids half a block apart."""
    from types import SimpleNamespace

    from plenocli.errors import CalibrationError
    from plenocli.pipeline.stages.unmix import _check_light

    observed = np.full((2, 512, 512), 4000.0, np.float32)
    views = observed.copy()
    views[0, 150:206:2, 200:256:2] = -1400.0  # the red sites of a 56 x 56 patch
    observed[0, 150:206, 200:256] = 0.0
    res = SimpleNamespace(views=views, noise_gain=np.ones_like(views))
    _check_light(res, observed, ["A", "B"], "m.tif", ["v.tif"], mosaic=False)  # 0.3 %: passes
    with pytest.raises(CalibrationError, match="below zero"):
        _check_light(res, observed, ["A", "B"], "m.tif", ["v.tif"], mosaic=True)
    views = observed.copy()
    views[0, 146:174, 146:174] = -1330.0  # across the corner of four blocks, a fifth of each
    res = SimpleNamespace(views=views, noise_gain=np.ones_like(views))
    with pytest.raises(CalibrationError, match="below zero"):
        _check_light(res, observed, ["A", "B"], "m.tif", ["v.tif"], mosaic=False)
