import json

import numpy as np
import pytest
import tifffile
from PIL import Image

from plenocli.errors import InputError
from plenocli.io import tiffio, tiffsegments
from plenocli.io.atomic import atomic_path
from plenocli.model.provenance import sha256_file, stage_record


def test_round_trip_keeps_views_nan_and_metadata(tmp_path):
    views = np.random.default_rng(0).random((3, 10, 12)).astype(np.float32)
    views[1, 2, 3] = np.nan
    src = tmp_path / "in.bin"
    src.write_bytes(b"abc")
    record = stage_record("bias", {"smooth": 9}, {"input": src})
    meta = tiffio.derived_meta({"views": ["A", "B", "S"], "cfa": "RGGB"}, record)
    tiffio.write_image(tmp_path / "x.tif", views, meta)
    data, back = tiffio.read_image(tmp_path / "x.tif")
    np.testing.assert_array_equal(data, views)
    assert back["views"] == ["A", "B", "S"] and back["cfa"] == "RGGB"
    prov = back["provenance"]
    assert prov["stage"] == "bias" and prov["parameters"] == {"smooth": 9}
    assert prov["inputs"][0]["sha256"] == sha256_file(src)
    assert prov["version"]


def test_any_tiff_reader_opens_the_pages(tmp_path):
    views = np.arange(2 * 5 * 7, dtype=np.float32).reshape(2, 5, 7)
    tiffio.write_image(tmp_path / "x.tif", views, {"views": ["a", "b"]})
    with Image.open(tmp_path / "x.tif") as im:  # Pillow: page 1 is view 0
        np.testing.assert_array_equal(np.asarray(im), views[0])
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "x.tif", key=1), views[1])


def test_history_grows_stage_by_stage():
    first = tiffio.derived_meta({}, {"stage": "decode"})
    second = tiffio.derived_meta(first, {"stage": "bias"})
    assert [r["stage"] for r in second["history"]] == ["decode"]
    assert second["provenance"]["stage"] == "bias"


def test_failed_write_leaves_nothing(tmp_path):
    dest = tmp_path / "out.tif"
    with pytest.raises(RuntimeError):
        with atomic_path(dest) as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError("interrupted")
    assert list(tmp_path.iterdir()) == []


def test_output_may_not_be_an_input(tmp_path):
    src = tmp_path / "a.tif"
    tiffio.write_image(src, np.zeros((2, 2), np.float32), {})
    before = src.read_bytes()
    with pytest.raises(InputError, match="also an input"):
        tiffio.write_image(src, np.ones((2, 2), np.float32), {}, protect=(src,))
    assert src.read_bytes() == before


def test_foreign_and_broken_files(tmp_path):
    tifffile.imwrite(tmp_path / "plain.tif", np.ones((3, 4), np.uint16))
    data, meta = tiffio.read_image(tmp_path / "plain.tif")
    assert data.shape == (1, 3, 4) and meta == {}
    (tmp_path / "bad.tif").write_bytes(b"not a tiff at all")
    with pytest.raises(InputError, match="not a readable TIFF"):
        tiffio.read_image(tmp_path / "bad.tif")
    with pytest.raises(InputError, match="no such file"):
        tiffio.read_image(tmp_path / "missing.tif")


@pytest.mark.parametrize("views", [
    np.full((2, 8, 8), np.nan, np.float32),
    np.stack([np.ones((8, 8), np.float32), np.full((8, 8), np.inf, np.float32)]),
])
def test_a_view_without_a_finite_pixel_is_not_written(tmp_path, views):
    with pytest.raises(InputError, match="no valid pixel"):
        tiffio.write_image(tmp_path / "out.tif", views, {})
    assert list(tmp_path.iterdir()) == []


def test_a_view_with_one_finite_pixel_is_written(tmp_path):
    views = np.full((300, 8), np.nan, np.float32)
    views[299, 7] = 1.0  # past the first band the check looks at
    tiffio.write_image(tmp_path / "out.tif", views, {})
    assert np.isfinite(tiffio.read_image(tmp_path / "out.tif")[0]).sum() == 1


@pytest.mark.parametrize("dtype, words", [(np.complex64, "not real-valued"),
                                          (np.bool_, "1-bit"), (np.int8, "not real-valued")])
def test_samples_that_are_not_real_sensor_values_are_refused(tmp_path, dtype, words):
    tifffile.imwrite(tmp_path / "x.tif", np.zeros((4, 4), dtype))
    with pytest.raises(InputError, match=words):
        tiffio.read_image(tmp_path / "x.tif")


def test_truncation_is_found_in_the_header_before_reading(tmp_path):
    tiffio.write_image(tmp_path / "a.tif", np.ones((3, 64, 64), np.float32), {"views": list("abc")})
    data = (tmp_path / "a.tif").read_bytes()
    (tmp_path / "cut.tif").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="truncated|damaged") as err:
        tiffio.read_image(tmp_path / "cut.tif")
    assert "tifffile" not in str(err.value) and "\n" not in str(err.value)
    assert tiffio.read_meta(tmp_path / "cut.tif") == {}


def test_a_header_claiming_a_huge_image_is_refused_before_allocating(tmp_path, monkeypatch):
    tifffile.imwrite(tmp_path / "a.tif", np.zeros((64, 64), np.uint16))
    monkeypatch.setattr(tiffsegments, "MAX_PAGE_PIXELS", 64 * 64 - 1)
    with pytest.raises(InputError, match="64 x 64 samples"):
        tiffio.read_image(tmp_path / "a.tif")


@pytest.mark.parametrize("meta,words", [
    ({"active_area": [0, 0, 9, 8]}, "active_area"),
    ({"active_area": [4, 0, 4, 8]}, "active_area"),
    ({"masked_areas": [[0, 0, 8, 2.5]]}, "masked area"),
    ({"active_area": [0, 2, 8, 8], "masked_areas": [[0, 0, 8, 3]]}, "overlaps active_area"),
    ({"views": ["a", "b"]}, "names"),
    ({"origin": [0.5, 0]}, "origin"),
])
def test_metadata_geometry_must_fit_the_image(tmp_path, meta, words):
    description = json.dumps({tiffio.FORMAT_KEY: 1, **meta})
    tifffile.imwrite(tmp_path / "a.tif", np.zeros((8, 8), np.float32), description=description,
                     metadata=None)
    with pytest.raises(InputError, match=words):
        tiffio.read_image(tmp_path / "a.tif")


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    from plenocli.io.dng import write_dng
    from plenocli.synth.dualpixel import dng_options, dualpixel_capture

    folder = tmp_path_factory.mktemp("pristine")
    raw, truth = dualpixel_capture(seed=3, rows=48, cols=64, top=8, left=16)
    write_dng(folder / "dp.dng", raw, **dng_options(truth))
    views = np.random.default_rng(0).random((2, 40, 50)).astype(np.float32)
    tiffio.write_image(folder / "p.tif", views, {"views": ["a", "b"],
                                                 "active_area": [0, 0, 40, 50],
                                                 "masked_areas": []})
    return folder


@pytest.mark.parametrize("name", ["dp.dng", "p.tif"])
@pytest.mark.parametrize("seed", range(150))
def test_damaged_files_are_read_or_refused_in_one_line(pristine, tmp_path, name, seed):
    """Seeded damage (cut anywhere, or bytes changed in the header or anywhere): every reader
    returns a result or raises InputError, nothing else."""
    from plenocli.io import raw
    from plenocli.io.info import describe

    rng = np.random.default_rng(seed)
    data = bytearray((pristine / name).read_bytes())
    if seed % 3 == 0:
        data = data[: int(rng.integers(8, len(data)))]
    else:
        reach = 600 if seed % 3 == 1 else len(data)
        for _ in range(int(rng.integers(1, 6))):
            where = int(rng.integers(0, reach))
            data[where] = int(rng.integers(0, 256))
    damaged = tmp_path / name
    damaged.write_bytes(bytes(data))
    for read in (tiffio.read_image, raw.decode, describe):
        try:
            read(damaged)
        except InputError as err:
            assert "\n" not in str(err)



def test_a_record_names_each_input_by_an_absolute_path_too(tmp_path, monkeypatch):
    """audit 7 P5: a shell run recorded its inputs as typed (relative), without the folder it
    ran in, so the history could not find them from anywhere else."""
    from plenocli.model.provenance import stage_record

    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "in.tif").write_bytes(b"x")
    monkeypatch.chdir(tmp_path)
    (entry,) = stage_record("bias", {}, {"input": "sub/in.tif"})["inputs"]
    assert entry["path"] == "sub/in.tif"
    assert entry["absolute_path"] == str(tmp_path / "sub" / "in.tif")


@pytest.mark.parametrize("planar", ["contig", "separate"])
def test_samples_of_one_page_are_views_whatever_their_layout(planar, tmp_path):
    """audit 8 E6: a plenocli file rewritten as one page of three planar samples was read as
    128 views (the samples-first axis taken for the last)."""
    views = np.random.default_rng(0).random((3, 16, 24)).astype(np.float32)
    description = json.dumps({tiffio.FORMAT_KEY: tiffio.FORMAT_VERSION,
                              "views": ["A", "B", "S"]})
    data = views if planar == "separate" else np.moveaxis(views, 0, -1)
    tifffile.imwrite(tmp_path / "p.tif", data, planarconfig=planar, photometric="minisblack",
                     extrasamples=[0, 0] if planar == "contig" else None,
                     description=description, metadata=None)
    read, meta = tiffio.read_image(tmp_path / "p.tif")
    assert np.array_equal(read, views) and meta["views"] == ["A", "B", "S"]
