"""The pipeline runs without click (as a Dask worker or a script does): with click made
unimportable, a config naming every stage loads and resolves, ``--print-make``'s fragment is
written, and real steps run."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CONFIG = """\
steps:
  simulate: {kind: dualpixel, output: sim, pixels: 32x48, seed: 3, param: ['noise=0']}
  decode: {input: sim/capture.dng, output: frames.tif}
  bias: {input: frames.tif, output: biased.tif, smooth: 3}
  flat: {input: biased.tif, white: frames.tif, output: flat.tif}
  calibrate: {input: frames.tif, output: grid2.yaml, pitch: 10}
  refocus: {input: frames.tif, grid: grid.yaml, output: refocused.tif, g: [2, 3]}
  depth: {input: frames.tif, grid: grid.yaml, output: depth.tif, g: "2:8"}
  sai: {input: frames.tif, output: views.tif, n: 2}
  crosstalk: {inputs: [biased.tif], output: ct.json, views: [A, B]}
  unmix: {inputs: views.tif, mixing: mixing.tif, output: clean.tif, regularise: 0.05}
  stitch: {inputs: [flat.tif], output: pano.tif, views: 'A,B', layout: 1x2}
  develop: {input: biased.tif, view: S, wb: [2, 1, 1.5], output: photo.jpg}
  optics: {input: lens.yaml, json: optics.json, crosstalk: true}
"""

SCRIPT = """
import importlib.abc
import sys


class NoClick(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] == "click":
            raise ImportError(f"{name} is blocked by the test")
        return None


sys.meta_path.insert(0, NoClick())
try:
    import click  # noqa: F401
except ImportError:
    pass
else:
    raise SystemExit("click was not blocked")

from plenocli.pipeline.config import load_config
from plenocli.pipeline.makefile import make_fragment
from plenocli.pipeline.registry import get_stages
from plenocli.pipeline.runner import run_pipeline

steps = load_config("pipeline.yaml")
assert sorted(s.stage.name for s in steps) == sorted(get_stages())
print(make_fragment(steps, "pipeline.yaml"))
run_pipeline(steps[:3])
assert not [m for m in sys.modules if m.partition(".")[0] == "click"]
"""


def test_the_pipeline_needs_no_click(tmp_path):
    (tmp_path / "pipeline.yaml").write_text(CONFIG)
    for name in ("grid.yaml", "mixing.tif", "lens.yaml"):
        (tmp_path / name).write_text("")  # inputs made elsewhere: only named here
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=tmp_path, capture_output=True,
                          text=True, timeout=300, env={"PYTHONPATH": str(ROOT), "PATH": ""})
    assert done.returncode == 0, done.stderr
    fragment = done.stdout
    assert "refocused.tif : frames.tif grid.yaml pipeline.yaml" in fragment
    assert "$(PLENOCLI) refocus frames.tif --grid=grid.yaml --output=refocused.tif --g=2,3" \
        in fragment
    assert "--wb=2.0,1.0,1.5" in fragment and "--crosstalk" in fragment
    assert "$(PLENOCLI) crosstalk biased.tif --output=ct.json --views=A,B" in fragment
    assert (tmp_path / "biased.tif").is_file() and (tmp_path / "sim" / "truth.json").is_file()
    assert not (tmp_path / "flat.tif").exists()  # only the first three steps ran
