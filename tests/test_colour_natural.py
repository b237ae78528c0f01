"""Natural photographs recorded as a Canon 5D Mark IV records them (its ColorMatrix, as-shot
neutral, RGGB, black 512, white 16383, shot and read noise) in a DNG: ``decode -> bias ->
develop --linear`` against the scene, and LibRaw (rawpy, AHD) on the same DNG in the same run.
"""

from __future__ import annotations

import numpy as np
import pytest
import rawpy
import skimage.data
from click.testing import CliRunner
from scipy import ndimage

from plenocli.cli.main import cli
from plenocli.colour import demosaic as dm
from plenocli.colour.metrics import colour_error
from plenocli.io.dng import write_dng
from plenocli.io.tiffio import read_image
from plenocli.model.colour import camera_to_srgb, gains_from_neutral
from plenocli.synth.natural import natural_capture

PICTURES = ("astronaut", "coffee", "chelsea", "rocket")  # bundled with scikit-image


def invoke(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result


def _dng(path, capture):
    write_dng(path, capture.raw, cfa=capture.cfa, black_levels=[capture.black],
              white_level=capture.white, active_area=[0, 0, *capture.raw.shape],
              frame_names=["S"], model="Canon EOS 5D Mark IV (simulated)",
              as_shot_neutral=capture.as_shot_neutral,
              color_matrix=capture.xyz_to_camera.ravel())


def _developed(tmp_path, capture, *extra):
    """decode -> bias -> develop --linear, in the scene's units (as-shot white = 1)."""
    _dng(tmp_path / "shot.dng", capture)
    invoke("decode", tmp_path / "shot.dng", "-o", tmp_path / "frames.tif", "-q")
    invoke("bias", tmp_path / "frames.tif", "-o", tmp_path / "biased.tif", "-q")
    invoke("develop", tmp_path / "biased.tif", "-o", tmp_path / "photo.tif", "--linear",
           tmp_path / "linear.tif", "-q", *extra)
    linear, _ = read_image(tmp_path / "linear.tif")
    return np.moveaxis(linear, 0, -1) / (capture.dn_per_unit * capture.as_shot_neutral[1])


def _libraw_ahd(path, truth):
    """LibRaw's development (AHD, camera white balance, linear sRGB), scaled to the scene by
    least squares: its best possible exposure, an advantage it is given."""
    with rawpy.imread(str(path)) as raw:
        rgb = raw.postprocess(demosaic_algorithm=rawpy.DemosaicAlgorithm.AHD,
                              use_camera_wb=True, output_color=rawpy.ColorSpace.sRGB,
                              gamma=(1, 1), no_auto_bright=True, output_bps=16,
                              user_flip=0).astype(np.float32)
    return rgb * float((rgb * truth).sum() / (rgb * rgb).sum())


def test_default_develop_is_at_least_as_good_as_libraw_ahd_on_every_photograph(tmp_path):
    for seed, name in enumerate(PICTURES):
        capture = natural_capture(getattr(skimage.data, name)(), seed=seed)
        ours = colour_error(_developed(tmp_path, capture), capture.truth)
        libraw = colour_error(_libraw_ahd(tmp_path / "shot.dng", capture.truth), capture.truth)
        assert ours.psnr_db >= libraw.psnr_db, (name, ours, libraw)
        assert ours.delta_e_mean <= libraw.delta_e_mean, (name, ours, libraw)
        assert ours.psnr_db >= 38.0 and ours.delta_e_mean <= 2.2, (name, ours)  # docs/colour.md


def test_white_balance_before_demosaicing_is_what_makes_the_difference():
    capture = natural_capture(skimage.data.coffee(), seed=7)
    mosaic = capture.raw.astype(np.float32) - capture.black
    gains = gains_from_neutral(capture.as_shot_neutral)
    to_srgb = camera_to_srgb(capture.xyz_to_camera).astype(np.float32).T
    scale = capture.dn_per_unit * capture.as_shot_neutral[1]
    psnr = {}
    for label, demosaic_gains in (("balanced", gains), ("camera RGB", (1, 1, 1))):
        camera = dm.demosaic(mosaic, capture.cfa, gains=demosaic_gains)
        psnr[label] = colour_error(camera * gains.astype(np.float32) @ to_srgb / scale,
                                   capture.truth).psnr_db
    assert psnr["balanced"] > psnr["camera RGB"] + 2.0, psnr


def test_balanced_output_is_camera_rgb_times_the_gains():
    capture = natural_capture(skimage.data.chelsea()[:64, :96], seed=3)
    mosaic = capture.raw.astype(np.float32) - capture.black
    gains = np.array([2.0, 1.0, 1.5])
    camera = dm.demosaic(mosaic, "RGGB", gains=gains)
    balanced = dm.demosaic(mosaic, "RGGB", gains=gains, balanced=True)
    np.testing.assert_allclose(balanced, camera * gains.astype(np.float32), rtol=1e-5, atol=1e-3)
    np.testing.assert_allclose(camera[0::2, 0::2, 0], mosaic[0::2, 0::2], rtol=1e-6)  # red kept


@pytest.mark.parametrize("method", ["rcd", "menon2007"])
def test_overexposed_highlights_are_never_magenta(tmp_path, method):
    capture = natural_capture(skimage.data.astronaut(), seed=5, peak=3.0)  # clips in places
    clipped = capture.raw >= capture.white
    assert 0.02 < clipped.mean() < 0.3
    _dng(tmp_path / "shot.dng", capture)
    invoke("decode", tmp_path / "shot.dng", "-o", tmp_path / "frames.tif", "-q")
    invoke("develop", tmp_path / "frames.tif", "-o", tmp_path / "photo.png", "--method", method,
           "-q")
    from PIL import Image

    photo = np.asarray(Image.open(tmp_path / "photo.png"), np.float32) / 255.0
    near = ndimage.binary_dilation(clipped, np.ones((25, 25), bool))  # where highlights bleed
    truly_purple = capture.truth[..., 1] < capture.truth[..., [0, 2]].min(axis=-1)
    magenta = photo[..., 1] < photo[..., [0, 2]].min(axis=-1) - 0.08
    assert near.sum() > 20000
    assert (magenta & near & ~truly_purple).sum() <= 1e-3 * near.sum()
