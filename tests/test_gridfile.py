"""Lens-grid YAML: the fast lens-row reader gives exactly what a YAML parser gives."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
import yaml

from plenocli.errors import InputError
from plenocli.io import gridfile, yamlfile
from plenocli.model.lensgrid import LensGrid, fit_lattice


def _grid(seed: int = 0) -> LensGrid:
    base = LensGrid(13.7, 0.21, (201.3, 149.8), image_shape=(300, 400))
    idx, ideal = base.lens_centres()
    rng = np.random.default_rng(seed)
    centres = ideal + rng.normal(0, 0.3, ideal.shape)
    centres[0] = (-0.4, 0.00001)   # a negative and a tiny value keep their sign and digits
    return LensGrid(base.pitch_px, base.angle_rad, base.offset_xy, image_shape=(300, 400),
                    centres_xy=centres, indices=idx)


def _plain(path) -> LensGrid:
    """The reference: the whole file through PyYAML's pure-Python parser (with plenocli's YAML
    1.2 scalars: 020 is twenty, as the shell reads it)."""
    doc = yaml.load(path.read_text(), Loader=yamlfile.PyLoader)  # noqa: S506 (a safe loader)
    return LensGrid.from_dict(doc["lens_grid"])


def _same(a: LensGrid, b: LensGrid) -> None:
    assert a == b
    np.testing.assert_array_equal(a.indices, b.indices)
    np.testing.assert_array_equal(a.centres_xy, b.centres_xy)
    assert a.indices.dtype == b.indices.dtype and a.centres_xy.dtype == b.centres_xy.dtype


def test_written_grid_reads_fast_and_equal_to_yaml(tmp_path):
    grid = _grid()
    path = tmp_path / "grid.yaml"
    gridfile.write_grid(path, grid, {"stage": "calibrate", "params": {"rows": 3}},
                        extra={"residuals": {"rms_px": 0.1}})
    text = path.read_text()
    assert gridfile._fast_load(text) is not None          # the numpy path is taken
    got = gridfile.read_grid(path)
    _same(got, _plain(path))
    assert len(got.centres_xy) == len(grid.centres_xy) > 500
    np.testing.assert_allclose(got.centres_xy, grid.centres_xy, atol=5e-6)


def _edit_row(text: str, k: int, new: str) -> str:
    lines = text.split("\n")
    first = lines.index("    rows:") + 1
    lines[first + k] = new
    return "\n".join(lines)


# rows edited to a lens not in the table (20, 16; 8, 16): a grid lists each lens once
EDITS = {
    "exponent": lambda t: _edit_row(t, 3, "    - [20, 16, 1.5e+2, 2.0]"),
    "leading_zero_int": lambda t: _edit_row(t, 3, "    - [020, 16, 1.5, 2.0]"),
    "block_row": lambda t: _edit_row(t, 3, "    - - 20\n      - 16\n      - 1.5\n      - 2.0"),
    "comment_inside": lambda t: _edit_row(t, 3, "    # checked by hand\n    - [20, 16, 1.5, 2.0]"),
    "blank_inside": lambda t: _edit_row(t, 3, "\n    - [20, 16, 1.5, 2.0]"),
    "extra_spaces": lambda t: _edit_row(t, 3, "    - [ 20, 16, 1.5, 2.0 ]"),
    "rows_indented": lambda t: t.replace("\n    - [", "\n      - ["),
    "trailing_comment": lambda t: _edit_row(t, 3, "    - [20, 16, 1.5, 2.0]  # moved"),
}


@pytest.mark.parametrize("edit", sorted(EDITS))
def test_hand_edited_grid_falls_back_to_yaml(tmp_path, edit):
    path = tmp_path / "grid.yaml"
    gridfile.write_grid(path, _grid(1), {"stage": "calibrate"})
    text = EDITS[edit](path.read_text())
    path.write_bytes(text.encode())
    assert gridfile._fast_load(path.read_text()) is None
    got = gridfile.read_grid(path)
    _same(got, _plain(path))
    assert edit == "rows_indented" or [20, 16] in got.indices.tolist()  # the edited row


def test_crlf_file_reads_the_same(tmp_path):
    path = tmp_path / "grid.yaml"
    gridfile.write_grid(path, _grid(3), {"stage": "calibrate"})
    path.write_bytes(path.read_bytes().replace(b"\n", b"\r\n"))
    _same(gridfile.read_grid(path), _plain(path))


def test_rows_elsewhere_are_not_taken_for_lenses(tmp_path):
    """A `    rows:` block outside lens_grid.lenses is left to the YAML parser."""
    path = tmp_path / "grid.yaml"
    text = ("lens_grid:\n  lattice: hex\n  pitch_px: 10.0\n  angle_rad: 0.0\n"
            "  offset_xy: [5.0, 5.0]\n  image_shape: null\n"
            "notes:\n  table:\n    rows:\n    - [1, 2, 3.0, 4.0]\n")
    path.write_text(text)
    assert gridfile._fast_load(text) is None
    got = gridfile.read_grid(path)
    assert got.centres_xy is None and got.pitch_px == 10.0


def test_broken_yaml_is_one_input_error(tmp_path):
    path = tmp_path / "grid.yaml"
    gridfile.write_grid(path, _grid(2), {"stage": "calibrate"})
    path.write_text(path.read_text().replace("lattice: hex", "lattice: [hex"))
    with pytest.raises(InputError, match="not a YAML lens grid"):
        gridfile.read_grid(path)


@pytest.mark.parametrize("change,words", [
    ({"angle_rad": float("nan")}, "angle_rad"), ({"pitch_px": float("inf")}, "pitch_px"),
    ({"pitch_px": 0.01}, "pitch_px"), ({"offset_xy": [float("nan"), 0.0]}, "offset_xy"),
    ({"image_shape": [0, 10]}, "image_shape"), ({"image_shape": [1e300, 10]}, "image_shape"),
])
def test_grids_that_describe_no_lattice_are_refused(tmp_path, change, words):
    doc = {"lens_grid": {"lattice": "hex", "pitch_px": 20.0, "angle_rad": 0.1,
                         "offset_xy": [3.0, 4.0], **change}}
    (tmp_path / "g.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(InputError, match=words):
        gridfile.read_grid(tmp_path / "g.yaml")


@pytest.mark.parametrize("field,text,words", [
    ("pitch_px", "0x14", "pitch_px must be a number, got '0x14'"),
    ("pitch_px", "2_0.2", "pitch_px must be a number, got '2_0.2'"),   # Python's float() took it
    ("pitch_px", "'20.2'", "pitch_px must be a number, got '20.2'"),   # text, as in a camera file
    ("angle_rad", "true", "angle_rad must be a number, got True"),
    ("offset_xy", "[3.0, '4']", "offset_xy must be a number, got '4'"),
    ("offset_xy", "5", "offset_xy must be two numbers"),
    ("image_shape", "['480', 640]", "image_shape must hold whole numbers"),
    ("lenses", "{rows: [[0, 0, a, 4.0]]}", "lenses.rows must be rows [i, j, x, y]"),
    ("lenses", "{rows: [[0, 0, 3.0]]}", "lenses.rows must be rows [i, j, x, y]"),
    ("lenses", "5", "lenses must be a mapping with rows"),
])
def test_grid_fields_of_the_wrong_kind_are_named_in_plenocli_words(tmp_path, field, text, words):
    # audit 7 E12: "missing or bad could not convert string to float: '0x14'"; 2_0.2 read as 20.2
    fields = {"lattice": "hex", "pitch_px": "20.0", "angle_rad": "0.0", "offset_xy": "[3.0, 4.0]",
              field: text}
    (tmp_path / "g.yaml").write_text("lens_grid:\n" + "".join(
        f"  {key}: {value}\n" for key, value in fields.items()))
    with pytest.raises(InputError) as err:
        gridfile.read_grid(tmp_path / "g.yaml")
    assert words in str(err.value) and "could not convert" not in str(err.value)
    assert "missing or bad" not in str(err.value)


@pytest.mark.parametrize("text,words", [("[1, 2]\n", "no lens_grid"),
                                        ("lens_grid: 5\n", "lens_grid must be a mapping"),
                                        ("lens_grid: {pitch_px: 20}\n", "no angle_rad")])
def test_a_document_that_is_no_grid_says_what_is_missing(tmp_path, text, words):
    (tmp_path / "g.yaml").write_text(text)
    with pytest.raises(InputError, match=words):
        gridfile.read_grid(tmp_path / "g.yaml")
    (tmp_path / "l.yaml").write_bytes(b"lens_grid:\n  name: caf\xe9\n")
    with pytest.raises(InputError, match=r"not UTF-8 text \(byte"):
        gridfile.read_grid(tmp_path / "l.yaml")


@pytest.mark.parametrize("centres,indices,words", [
    ([[1.0, np.nan]], [[0, 0]], "finite"),
    ([[1.0, 2.0], [3.0, 4.0]], [[0, 0], [0, 100000]], "compact block"),
    ([[1.0, 2.0]], [[0, 0], [0, 1]], "shapes"),
])
def test_lens_tables_must_be_finite_and_compact(centres, indices, words):
    with pytest.raises(ValueError, match=words):
        LensGrid(pitch_px=20.0, angle_rad=0.0, offset_xy=(0.0, 0.0),
                 centres_xy=np.array(centres), indices=np.array(indices))


def test_numpy_numbers_in_the_extra_fields_are_written_as_plain_numbers(tmp_path):
    path = tmp_path / "grid.yaml"
    extra = {"calibration": {"pitch_px": np.float64(23.8323), "lenses": np.int64(451),
                             "residuals": np.array([0.25, 0.5])}}
    gridfile.write_grid(path, _grid(), {"stage": "calibrate"}, extra=extra)
    doc = yaml.safe_load(path.read_text())
    assert doc["calibration"] == {"pitch_px": 23.8323, "lenses": 451, "residuals": [0.25, 0.5]}


@pytest.mark.parametrize("listed", ["measured", "bent", "moved"])
def test_lens_rows_must_be_calibrates_own(listed):
    """Rows as calibrate lists them (measured centres about their least-squares lattice, or the
    lattice bent by a smooth field under FIELD_MAX pitch) pass; the same rows moved do not."""
    grid = LensGrid(20.0, 0.1, (100.0, 80.0), image_shape=(160, 200))
    idx, places = grid.lens_centres()
    u = (places - places.mean(axis=0)) / 100.0
    rows = {"measured": places + np.random.default_rng(1).normal(0, 0.05, places.shape),
            "bent": places + 0.6 * np.stack([u[:, 0] ** 2, u[:, 0] * u[:, 1]], axis=1),
            "moved": places + np.random.default_rng(1).normal(0, 0.05, places.shape) + 0.3}
    measured = LensGrid(*fit_lattice(idx, rows["measured"]), image_shape=(160, 200))
    listed_grid = measured if listed == "measured" else grid
    found = gridfile.rows_misfit(LensGrid(listed_grid.pitch_px, listed_grid.angle_rad,
                                          listed_grid.offset_xy, centres_xy=rows[listed],
                                          indices=idx))
    assert (found is None) == (listed != "moved"), found


def test_a_record_vouches_only_for_the_lens_grid_its_stage_wrote(tmp_path):
    """audit 19 W2: where the frames show no lattice, a grid is used only as calibrate or
    simulate wrote it (its record's sha256 of the lens_grid section). A pitch scaled by 1 %
    and saved again, a record of no measuring stage, or an XML is not vouched for; the
    residuals beside the grid and line ends (CRLF) may change."""
    path = tmp_path / "grid.yaml"
    gridfile.write_grid(path, _grid(), {"stage": "calibrate"}, extra={"residuals": {"n": 1}})
    assert gridfile.vouched_by(path) == ("calibrate", "")
    text = path.read_text()
    (tmp_path / "crlf.yaml").write_bytes(
        text.replace("n: 1", "n: 2").replace("\n", "\r\n").encode())
    assert gridfile.vouched_by(tmp_path / "crlf.yaml")[0] == "calibrate"
    doc = yaml.safe_load(text)
    doc["lens_grid"]["pitch_px"] *= 1.01
    (tmp_path / "scaled.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    stage, why = gridfile.vouched_by(tmp_path / "scaled.yaml")
    assert stage is None and "changed since `plenocli calibrate` wrote it" in why
    gridfile.write_grid(tmp_path / "made.yaml", _grid(), {"stage": "refocus"})
    assert gridfile.vouched_by(tmp_path / "made.yaml")[0] is None
    (tmp_path / "g.xml").write_text("<RayCalibData></RayCalibData>\n")
    assert "XML" in gridfile.vouched_by(tmp_path / "g.xml")[1]


def test_a_grid_re_saved_unchanged_by_another_writer_is_still_vouched_for(tmp_path):
    """audit 23 M2: the record's checksum is of the grid as read (every field and lens row),
    not of its text: PyYAML's re-save (keys sorted, rows in block style, the record first) is
    the same grid; one lens moved by 0.01 px is not. A record of the earlier text checksum
    still vouches for the text it was written with."""
    gridfile.write_grid(tmp_path / "grid.yaml", _grid(), {"stage": "simulate"})
    doc = yaml.safe_load((tmp_path / "grid.yaml").read_text())
    (tmp_path / "resaved.yaml").write_text(yaml.safe_dump(doc))
    assert gridfile.vouched_by(tmp_path / "resaved.yaml") == ("simulate", "")
    doc["lens_grid"]["lenses"]["rows"][7][2] += 0.01
    (tmp_path / "moved.yaml").write_text(yaml.safe_dump(doc))
    assert gridfile.vouched_by(tmp_path / "moved.yaml")[0] is None
    text = (tmp_path / "grid.yaml").read_text()
    section = text[:text.index("\nprovenance:") + 1]
    earlier = text.replace(doc["provenance"]["lens_grid_sha256"],
                           hashlib.sha256(section.encode()).hexdigest())
    (tmp_path / "earlier.yaml").write_text(earlier)
    assert gridfile.vouched_by(tmp_path / "earlier.yaml") == ("simulate", "")
