"""A camera's Orientation (tag 274; a CR2's via LibRaw's flip, tests/test_raw.py): decode
records it, the stages carry it, develop's photograph stands upright as LibRaw develops it
(audit 15 W3: dropped, a portrait photograph came out on its side without an Orientation tag,
exit 0); a value outside 1-8 is refused in one line naming the tag."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rawpy
import tifffile
from click.testing import CliRunner
from PIL import Image, ImageOps
from scipy.stats import spearmanr

from plenocli.cli.main import cli
from plenocli.io import tiffio
from plenocli.io.photo import photo_record
from plenocli.model import orientation

ROWS, COLS = 48, 64  # not square: the four turns that swap the sides show in the shape


def _scene() -> np.ndarray:
    """Grey, smooth and asymmetric along both axes: every wrong turn decorrelates it."""
    y, x = np.mgrid[0:ROWS, 0:COLS] / np.array([ROWS, COLS])[:, None, None]
    scene = 0.1 + 0.6 * x * (1 - 0.6 * y)
    scene[5:15, 8:20] += 0.3
    return scene


def _dng(path, turned: int | None, *, ifd0: bool = True) -> None:
    """An RGGB DNG of the grey scene, black 0, white 4095, Orientation ``turned`` (None: no
    tag) in IFD 0."""
    mosaic = np.round(_scene() * 3000).astype(np.uint16)
    tags = [(50706, "B", 4, (1, 4, 0, 0), True), (50707, "B", 4, (1, 4, 0, 0), True),
            (50708, "s", 0, "orientation test", True), (50717, "I", 1, (4095,), True),
            (33421, "H", 2, (2, 2), True), (33422, "B", 4, (0, 1, 1, 2), True),
            (50728, "2I", 3, (1, 1, 1, 1, 1, 1), True)]
    if turned is not None:
        tags.append((274, "H", 1, (turned,), True))
    tifffile.imwrite(path, mosaic, photometric=32803, metadata=None, extratags=tags)


def _run(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert "Traceback" not in result.output + result.stderr
    return result


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Rank correlation: the two developments differ by a tone curve and by their clipping."""
    return float(spearmanr(a.ravel(), b.ravel())[0])


@pytest.mark.parametrize("value", range(1, 9))
def test_the_photograph_writer_turns_as_pillow_reads_the_tag(value):
    from plenocli.io.photo import _upright

    pixels = np.random.default_rng(value).integers(0, 255, (5, 7, 3)).astype(np.uint8)
    pil = Image.fromarray(pixels, mode="RGB")
    pil.getexif()[274] = value
    assert np.array_equal(_upright(pixels, value), np.asarray(ImageOps.exif_transpose(pil)))
    wide = pixels.astype(np.uint16) * 257  # 16-bit TIFF photographs take the same turns
    assert np.array_equal(_upright(wide, value), _upright(pixels, value).astype(np.uint16) * 257)


@pytest.mark.parametrize("turned", range(1, 9))
def test_develop_stands_every_orientation_upright_as_libraw_does(turned, tmp_path):
    raw, frames = tmp_path / "x.dng", tmp_path / "x.f.tif"
    photo, linear = tmp_path / "x.tif", tmp_path / "x.lin.tif"
    _dng(raw, turned)
    assert _run("decode", raw, "-o", frames).exit_code == 0
    assert tiffio.read_meta(frames)["orientation"] == turned
    result = _run("develop", frames, "-o", photo, "--wb", "1,1,1", "--matrix", "none",
                  "--linear", linear, "--preview", tmp_path / "x.png")
    assert result.exit_code == 0, result.stderr
    ours = tifffile.imread(photo).astype(np.float64).mean(axis=-1)
    with rawpy.imread(str(raw)) as libraw:
        theirs = libraw.postprocess(output_bps=16, gamma=(1, 1), no_auto_bright=True,
                                    user_wb=[1, 1, 1, 1]).astype(np.float64).mean(axis=-1)
    assert ours.shape == theirs.shape
    with Image.open(tmp_path / "x.png") as preview:
        assert preview.size[::-1] == ours.shape
    assert _correlation(ours, theirs) > 0.99
    assert _correlation(ours[::-1], theirs) < 0.5  # the check tells a wrong turn apart
    # the photograph holds the turned pixels, says so in its record, and has no tag to turn
    # them again; the --linear TIFF stays as stored and carries the value on
    with Image.open(photo) as image:
        assert 274 not in image.getexif()
    params = photo_record(photo)["plenocli"]["parameters"]
    assert (params["orientation"], params["turned"]) == (turned, orientation.TURNS[turned])
    assert tifffile.imread(linear).shape == (3, ROWS, COLS)
    assert tiffio.read_meta(linear)["orientation"] == turned


def test_a_dng_without_the_tag_is_as_stored(tmp_path):
    _dng(tmp_path / "x.dng", None)
    assert _run("decode", tmp_path / "x.dng", "-o", tmp_path / "f.tif").exit_code == 0
    assert tiffio.read_meta(tmp_path / "f.tif")["orientation"] == 1


def test_info_says_how_the_capture_stands(tmp_path):
    _dng(tmp_path / "x.dng", 6)
    assert _run("decode", tmp_path / "x.dng", "-o", tmp_path / "f.tif").exit_code == 0
    for path in ("x.dng", "f.tif"):
        result = _run("info", tmp_path / path)
        assert "orientation    6 (rotated 90 degrees clockwise" in result.output, result.output


@pytest.mark.parametrize("value", [0, 9, 65535])
@pytest.mark.parametrize("command", ["decode", "info"])
def test_an_orientation_outside_1_to_8_is_refused(value, command, tmp_path):
    _dng(tmp_path / "x.dng", value)
    out = tmp_path / "out"
    out.mkdir()
    args = ["-o", out / "f.tif"] if command == "decode" else []
    result = _run(command, tmp_path / "x.dng", *args)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.exit_code == 1 and len(lines) == 1, result.stderr
    assert f"Orientation (tag 274) {value} is not one of 1-8" in lines[0]
    assert not list(out.iterdir())


@pytest.mark.parametrize("value", [9, "6", True, 6.0])
def test_an_edited_orientation_in_the_metadata_is_refused(value, tmp_path):
    _dng(tmp_path / "x.dng", 6)
    assert _run("decode", tmp_path / "x.dng", "-o", tmp_path / "f.tif").exit_code == 0
    frames, meta = tiffio.read_image(tmp_path / "f.tif")
    edited = tmp_path / "edited.tif"
    tifffile.imwrite(edited, frames, photometric="minisblack", metadata=None,
                     description=json.dumps({tiffio.FORMAT_KEY: 1,
                                             **{**meta, "orientation": value}}))
    result = _run("develop", edited, "--wb", "1,1,1", "-o", tmp_path / "x.jpg")
    assert result.exit_code == 1 and "Orientation (tag 274)" in result.stderr, result.stderr
    assert not (tmp_path / "x.jpg").exists()


def test_a_panorama_keeps_the_orientation_of_the_camera():
    from plenocli.pipeline.stages.stitch import _of_the_camera

    assert _of_the_camera({"orientation": 6, "sai": {}})["orientation"] == 6
