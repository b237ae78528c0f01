"""plenocli optics end to end."""

import json

from click.testing import CliRunner

from plenocli.cli.main import cli
from tests.conftest import ROOT

TABLE2 = str(ROOT / "configs" / "lenses" / "paper_table2.yaml")


def test_prints_the_figures_and_writes_json(tmp_path):
    out = tmp_path / "t2.json"
    res = CliRunner().invoke(cli, ["optics", TABLE2, "--sensor-mm", "3.6", "--json", str(out)])
    assert res.exit_code == 0, res.output
    for words in ("effective focal length    6.165", "field of view", "max |distortion|",
                  "exit pupil", "RMS spot radius", "prism n 1.74"):
        assert words in res.output
    doc = json.loads(out.read_text())
    assert abs(doc["efl_mm"] - 6.165) < 1e-3
    assert doc["provenance"]["stage"] == "optics"
    assert doc["provenance"]["inputs"][0]["name"] == "paper_table2.yaml"


def test_bad_lens_file_is_one_line_and_leaves_nothing(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("surfaces:\n  - {radius: 3.0, glass: unobtainium, thickness: 1}\n")
    out = tmp_path / "out.json"
    res = CliRunner().invoke(cli, ["optics", str(bad), "--json", str(out)])
    assert res.exit_code == 1
    assert "unknown glass" in res.output and len(res.output.strip().splitlines()) == 1
    assert not out.exists()


def test_missing_file_and_usage_error(tmp_path):
    res = CliRunner().invoke(cli, ["optics", str(tmp_path / "nope.yaml")])
    assert res.exit_code == 1 and "no such lens file" in res.output
    res = CliRunner().invoke(cli, ["optics", TABLE2, "--sensor-mm", "wide"])
    assert res.exit_code == 2
