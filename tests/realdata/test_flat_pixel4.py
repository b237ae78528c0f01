"""Real dual-pixel vignetting: the Google Pixel 4 white-sheet pair (left and right views).

16-bit PNGs holding 14-bit data with black level 1024 (see ../shared/realdata/README.md).
"""

import numpy as np
import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io.tiffio import read_image

pytestmark = pytest.mark.realdata


def run(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result


def block_means(view, blocks=6):
    rows, cols = (s // blocks * blocks for s in view.shape)
    v = view[:rows, :cols].reshape(blocks, rows // blocks, blocks, cols // blocks)
    return np.nanmean(v, axis=(1, 3))


@pytest.mark.parametrize("side", ["left", "right"])
def test_white_sheet_flattens_with_its_own_gain(realdata, tmp_path, side):
    white = realdata / "dualpixel" / "pixel4" / f"white_sheet_{side}.png"
    run("decode", white, "--black", 1024, "--white", 16383, "-o", tmp_path / "w.tif", "-q")
    run("bias", tmp_path / "w.tif", "--overscan", "none", "-o", tmp_path / "wb.tif", "-q")
    raw, _ = read_image(tmp_path / "wb.tif")
    before = block_means(raw[0])
    assert before.max() / before.min() > 1.5  # strong vignetting and dual-pixel falloff
    run("flat", tmp_path / "wb.tif", "--white", tmp_path / "wb.tif", "--median", 5,
        "--save-gain", tmp_path / "gain.tif",  # a white by itself: the gain is the point
        "-o", tmp_path / "flat.tif", "--preview", tmp_path / "flat.png", "-q")
    flat, meta = read_image(tmp_path / "flat.tif")
    after = block_means(flat[0])
    assert after.max() / after.min() - 1 < 0.02  # flat within 2 % over 6 x 6 blocks
    assert meta["provenance"]["stage"] == "flat"


def test_left_and_right_fall_off_on_opposite_sides(realdata, tmp_path):
    means = {}
    for side in ("left", "right"):
        path = realdata / "dualpixel" / "pixel4" / f"white_sheet_{side}.png"
        run("decode", path, "--black", 1024, "-o", tmp_path / f"{side}.tif", "-q")
        run("bias", tmp_path / f"{side}.tif", "--overscan", "none", "-o",
            tmp_path / f"{side}_b.tif", "-q")
        view, _ = read_image(tmp_path / f"{side}_b.tif")
        means[side] = block_means(view[0]).mean(axis=0)  # left to right across the frame
    ratio = means["left"] / means["right"]  # A/B changes across the frame, as on the Canon
    assert abs(ratio[-1] - ratio[0]) > 0.05
