"""Files of the wrong kind or already processed, JSON nested too deep, and record names."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.errors import ConfigError, InputError
from plenocli.io import tiffio
from plenocli.pipeline.config import load_config
from plenocli.pipeline.stages.simulate import simulate
from tests.bad_inputs.files import (
    assert_one_line,
    plenocli_tiff,
    run_bad,
)


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
         "`plenocli flat --save-gain` output"),
        (["bias", inputs / "biased.tif", "-o", "{o}/x.tif"], "`plenocli bias` output"),
        # audit 14 M1: each producer named by the command and option that writes it
        (["unmix", inputs / "biased.tif", "--mixing", made / "gain.tif", "-o", "{o}/x.tif"],
         # audit 18 M3: a mixing file needs its record: no "(or a foreign file)"
         "unmix takes as mixing the output of crosstalk --mixing-out, simulate\n"),
        # audit 18 M3: unmix's own output is refused as an input: not in the list
        (["unmix", made / "gain.tif", "--mixing", made / "mixing.tif", "-o", "{o}/x.tif"],
         "unmix takes as inputs the output of decode, bias, flat, simulate, sai, refocus (or"),
        (["develop", made / "gain.tif", "-o", "{o}/x.tif"], "stitch, develop --linear (or"),
        (["bias", made / "mixing.tif", "-o", "{o}/x.tif"],
         "is a `plenocli crosstalk --mixing-out` output; bias takes"),
        (["decode", made / "mixing.tif", "-o", "{o}/x.tif"],
         "`plenocli crosstalk --mixing-out` output, not a raw capture"),
    ]
    plenocli_tiff(made / "mixing.tif", np.ones((2, 8, 8), np.float32),
                  provenance={"stage": "crosstalk"})
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
    plenocli_tiff(made / "colour_sai.tif", np.ones((12, 16, 16), np.float32), views=names,
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


def test_a_side_file_role_names_the_plenocli_output_it_is_given(inputs, tmp_path):
    """audit 13 E3: flat --gain of a depth map said "no CFA ... use the output of plenocli
    bias", of a panorama "white image is 897x401 but ..."; a grid or transform given a TIFF
    was "not a YAML lens grid". Every side-file role names what a plenocli output is and what
    it takes (pipeline/kinds.SIDE_INPUTS)."""
    made = tmp_path / "made"
    made.mkdir()
    simulate("dualpixel-depth", made / "dd", pixels="96x128", seed=2)
    result = CliRunner().invoke(cli, [str(a) for a in [
        "depth", made / "dd" / "views.tif", "-o", made / "disp.tif"]])
    assert result.exit_code == 0, result.output
    views, meta = tiffio.read_image(inputs / "biased.tif")
    plenocli_tiff(made / "pano.tif", views[:3], views=["R", "G", "B"],
                  provenance={"stage": "stitch"})
    cases = [(["flat", "{i}/biased.tif", "--gain", made / "disp.tif"],
              "disp.tif is a `plenocli depth` output; flat takes as gain the gain map"),
             (["flat", "{i}/biased.tif", "--gain", made / "pano.tif"],
              "pano.tif is a `plenocli stitch` output; flat takes as gain"),
             (["stitch", "{i}/biased.tif", "--views", "A,B", "--transform-in",
               made / "disp.tif"], "stitch takes as transform-in the JSON transform"),
             (["refocus", "{i}/rt/frames.tif", "--grid", "{i}/biased.tif"],
              "`plenocli bias` output; refocus takes as grid a lens grid")]
    for args, words in cases:
        result = run_bad(inputs, tmp_path / "out", [*map(str, args), "-o", "{o}/x.tif"])
        assert_one_line(result, 1, (words,))


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
    plenocli_tiff(side / "views.tif", clean + 64, views=["A", "B"], **levels)
    plenocli_tiff(side / "views2.tif", clean[::-1] + 64, views=["A", "B"], **levels)
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
    plenocli_tiff(made / "views.tif", np.concatenate([clean, clean.sum(0, keepdims=True)]),
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
        assert_one_line(result, 1, ("`plenocli unmix --noise-map` output",))


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
    frames, meta = tiffio.read_image(inputs / "rt" / "frames.tif")
    # as decode --camera raytrix writes them (its --calib is refused on frames that show no
    # lattice, as these: the camera is what sai reads)
    tiffio.write_image(made / "rt_frames.tif", frames, {**meta, "camera": "raytrix"})
    result = CliRunner().invoke(cli, ["decode", str(made / "rgb.tif"), "-o",
                                      str(made / "rgb_frames.tif")])
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


@pytest.mark.parametrize("args, words", [
    (["calibrate", "{i}/rt/grid.yaml", "-o", "{o}/g.yaml"], ("is a plenocli lens grid",
                                                             "calibrate's --start")),
    (["calibrate", "{i}/rt/calib.xml", "-o", "{o}/g.yaml"], ("is a Raytrix RayCalibData XML",)),
    (["bias", "{i}/rt/truth.json", "-o", "{o}/b.tif"], (
        "is the ground truth `plenocli simulate` writes", "not an image bias can take as input")),
    (["unmix", "{i}/biased.tif", "--mixing", "{i}/rt/grid.yaml", "-o", "{o}/u.tif"],
     ("not an image unmix can take as mixing", "the output of crosstalk --mixing-out")),
    # audit 16 M3: another stage's JSON report in a side role is named, with what to give
    (["unmix", "{i}/biased.tif", "--mixing", "{i}/crosstalk.json", "-o", "{o}/u.tif"],
     ("a JSON document `plenocli crosstalk` writes", "not an image unmix can take as mixing",
      "unmix takes as mixing the output of crosstalk --mixing-out")),
    (["develop", "{i}/biased.tif", "--view", "S", "--wb-from", "{i}/crosstalk.json", "-o",
      "{o}/d.jpg"], ("`plenocli crosstalk` writes", "develop takes as wb-from the output of")),
    (["stitch", "{i}/biased.tif", "--views", "A,B", "--rig", "{i}/crosstalk.json", "-o",
      "{o}/p.tif"], ("`plenocli crosstalk` writes; stitch takes as rig a prism rig YAML",)),
    (["refocus", "{i}/rt/frames.tif", "--grid", "{i}/crosstalk.json", "-o", "{o}/r.tif"],
     ("`plenocli crosstalk` writes; refocus takes as grid a lens grid",)),
    (["decode", "{i}/rt/calib.xml", "-o", "{o}/d.tif"], ("RayCalibData XML",
                                                         "not a raw capture or sensor image")),
])
def test_a_document_given_as_an_image_is_named(inputs, tmp_path, args, words):
    # audit 10 E3: calibrate called a sound grid YAML (a JSON report, an XML) "unreadable
    # image; the file may be truncated, damaged or of another type"
    assert_one_line(run_bad(inputs, tmp_path / "out", args), 1, words)


def test_a_stages_own_json_in_its_side_role_is_left_to_its_reader(tmp_path):
    """A stitch report given as --rig holds the rig it used (the rig reader takes it, and names
    a transform given there as one): the document check refuses only other stages' JSON."""
    from plenocli.pipeline.kinds import check_kinds

    report = tmp_path / "report.json"
    report.write_text(json.dumps({"provenance": {"stage": "stitch"}, "rig": {}}))
    check_kinds("stitch", {"input": [], "rig": [report]})
    other = tmp_path / "crosstalk.json"
    other.write_text(json.dumps({"provenance": {"stage": "crosstalk"}}))
    with pytest.raises(InputError, match="`plenocli crosstalk` writes; stitch takes as rig"):
        check_kinds("stitch", {"input": [], "rig": [other]})
