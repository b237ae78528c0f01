"""The layers of docs/architecture.md, checked on the imports of every module (top level and
inside functions): cli -> pipeline -> processing -> io -> model, never upwards."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "plenocli"
LAYERS = ("cli", "pipeline", "processing", "io", "model")  # top to bottom
BASE = {"plenocli", "plenocli.errors", "plenocli.progress"}  # usable from every layer
ENTRY_POINTS = {"plenocli.__main__"}
# TEMPORARY (issue 14, optics owner): io/lensfile.py builds the lens types of optics/lens.py and
# optics/glass.py; the prescription types belong below io (model/) or the reader in optics/.
KNOWN_UPWARD = {("plenocli.io.lensfile", "plenocli.optics.glass"),
                ("plenocli.io.lensfile", "plenocli.optics.lens")}
# By design: the click commands are the one definition of every stage parameter, so the pipeline
# parses a YAML step with them (plenocli.cli.params), lazily; nothing else in it knows click.
SCHEMA = {("plenocli.pipeline.registry", "plenocli.cli.params"),
          ("plenocli.pipeline.makefile", "plenocli.cli.params")}


def layer(module: str) -> str:
    parts = module.split(".")
    if len(parts) > 1 and parts[1] in ("cli", "pipeline", "io", "model"):
        return parts[1]
    return "processing"


def imports() -> list[tuple[str, str]]:
    """(importing module, imported plenocli module) for every import in plenocli/."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        module = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            found += [(module, name) for name in names
                      if name.startswith("plenocli.") and _is_module(name)]
    return found


def _is_module(name: str) -> bool:
    path = ROOT.joinpath(*name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def test_imports_point_down():
    upward = [(src, dst) for src, dst in imports()
              if dst not in BASE and src not in BASE | ENTRY_POINTS
              and (src, dst) not in KNOWN_UPWARD | SCHEMA
              and LAYERS.index(layer(dst)) < LAYERS.index(layer(src))]
    assert not upward, f"imports against the layers: {upward}"


def test_no_stage_imports_another_stage():
    crossing = [(src, dst) for src, dst in imports()
                if src.startswith("plenocli.pipeline.stages.")
                and dst.startswith("plenocli.pipeline.stages.") and dst != src]
    assert not crossing, crossing


def test_only_the_cli_imports_click():
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if "cli" in path.relative_to(PACKAGE).parts[:1]:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module] if isinstance(node, ast.ImportFrom) else [])
            if any(n and n.split(".")[0] == "click" for n in names):
                offenders.append(path.relative_to(ROOT).as_posix())
    assert not offenders, offenders
