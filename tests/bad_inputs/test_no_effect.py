"""Options with no effect, damaged PNGs, odd list files, and messages that name what is
wrong."""

from __future__ import annotations

import json
import os
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
import tifffile
import yaml
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.errors import ConfigError
from plenocli.io import tiffio
from plenocli.pipeline.config import load_config
from tests.bad_inputs.files import (
    assert_one_line,
    plenocli_tiff,
    png_chunk,
    run_bad,
)

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
    as from the shell (exit 1: the bound is the grid file's; naming the range it measures), from
    YAML and --set."""
    out = tmp_path / "out"
    config = tmp_path / "c.yaml"
    g = "2:1e308" if how == "yaml" else "2:8"
    config.write_text(f"steps:\n  depth:\n    input: {inputs}/rt/frames.tif\n"
                      f"    grid: {inputs}/rt/grid.yaml\n    g: \"{g}\"\n"
                      f"    output: {out}/d.tif\n")
    extra = ["--set", "depth.g=2:1e308"] if how == "set" else []
    result = run_bad(inputs, out, ["run", str(config), *extra])
    assert_one_line(result, 1, ("step 'depth'", "--g", "1 < g <="))


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
    ztxt = raw[:data] + png_chunk(b"zTXt", b"Comment\x00\x00" + cut) + raw[data:]
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
    config = Path(__file__).parents[2] / "configs" / "batch_dualpixel.yaml"
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


def test_a_palette_png_is_read_through_its_grey_table_and_grey_with_alpha_is_one_frame(
        inputs, tmp_path):
    """audit 8 E1: OpenCV expands a palette PNG, and a grey PNG with alpha, into three colour
    channels: the palette's indices were decoded as R, G, B light levels, and a grey image
    became three identical frames, exit 0. audit 18 P1: a table of greys is how the file stores
    a grey image (read through it, one frame); a table of colours is refused."""
    from PIL import Image

    side = tmp_path / "side"
    side.mkdir()
    grey = np.random.default_rng(5).integers(0, 255, (24, 32), dtype=np.uint8)
    Image.fromarray(grey).convert("P", palette=Image.Palette.ADAPTIVE).save(side / "pal.png")
    Image.fromarray(grey).convert("LA").save(side / "la.png")
    Image.fromarray(np.stack([grey, grey // 2, grey], -1)).convert(
        "P", palette=Image.Palette.ADAPTIVE).save(side / "colour.png")
    result = run_bad(inputs, tmp_path / "out", ["decode", str(side / "colour.png"), "-o",
                                                "{o}/p.tif"])
    assert_one_line(result, 1, ("colour-palette PNG", "no light levels"))
    for name in ("la", "pal"):
        result = CliRunner().invoke(cli, ["decode", str(side / f"{name}.png"), "-o",
                                          str(tmp_path / f"{name}.tif")])
        assert result.exit_code == 0, result.output
        frames, _ = tiffio.read_image(tmp_path / f"{name}.tif")
        assert frames.shape == (1, 24, 32) and np.array_equal(frames[0], grey), name


def test_a_focal_sweep_is_not_taken_for_pupil_views(inputs, tmp_path):
    """audit 8 W2: crosstalk took a refocus sweep's planes (raw@g2 .. raw@g6: one view at nine
    g) for views and reported r = 99.97 %, exit 0."""
    side = tmp_path / "side"
    side.mkdir()
    planes = np.random.default_rng(6).uniform(100, 200, (3, 32, 48)).astype(np.float32)
    plenocli_tiff(side / "sweep.tif", planes, views=["raw@g3", "raw@g4", "raw@g5"])
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
    plenocli_tiff(side / "scene.tif", np.stack([a, b]), views=["A", "B"])
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


def test_develop_method_on_colour_pages_is_refused_and_left_out_of_the_record(tmp_path):
    """audit 10 E4, P1: --method on a panorama's R, G, B pages (nothing to demosaic) was taken
    and recorded, and the record said view null where the photograph's provenance said RGB.
    From the shell and from a YAML step alike."""
    rgb = tmp_path / "rgb.tif"
    rng = np.random.default_rng(0)
    plenocli_tiff(rgb, 0.2 + 0.5 * rng.random((3, 24, 32), np.float32), views=["R", "G", "B"])
    out = tmp_path / "out"
    args = ["develop", str(rgb), "--wb", "1,1,1", "--matrix", "none", "-o", str(out / "p.jpg")]
    result = run_bad(tmp_path, out, [*args, "--method", "bilinear"])
    assert_one_line(result, 2, ("--method", "demosaiced already"))
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump({"steps": {"develop": {
        "input": str(rgb), "wb": "1,1,1", "matrix": "none", "method": "rcd",
        "output": str(out / "q.jpg")}}}))
    with pytest.raises(ConfigError, match="--method"):
        load_config(config)
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    record = json.loads((out / ".p.jpg.plenocli.json").read_text())["parameters"]
    assert record["view"] == "RGB" and "method" not in record
