"""The layers of docs/architecture.md, checked on the imports of every module (top level and
inside functions): cli -> pipeline -> processing -> io -> model, never upwards."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "plenocli"
LAYERS = ("cli", "pipeline", "processing", "io", "model")  # top to bottom
BASE = {"plenocli", "plenocli.errors", "plenocli.progress"}  # usable from every layer
ENTRY_POINTS = {"plenocli.__main__"}
# TEMPORARY (issue 14, optics owner): io/lensfile.py builds the lens types of optics/lens.py and
# optics/glass.py; the prescription types belong below io (model/) or the reader in optics/.
KNOWN_UPWARD = {("plenocli.io.lensfile", "plenocli.optics.glass"),
                ("plenocli.io.lensfile", "plenocli.optics.lens")}
IMPORTERS = {"import_module", "__import__"}  # importlib.import_module(...), __import__(...)


def layer(module: str) -> str:
    parts = module.split(".")
    if len(parts) > 1 and parts[1] in ("cli", "pipeline", "io", "model"):
        return parts[1]
    return "processing"


def imports() -> list[tuple[str, str]]:
    """(importing module, imported plenocli module) for every import in plenocli/: statements
    (top level and inside functions, relative ones resolved) and dynamic imports of a name
    written in the code (``importlib.import_module(f"plenocli.x.{name}")`` imports from
    ``plenocli.x``)."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        module = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        found += [(module, name) for name in imported(path.read_text(encoding="utf-8"), package)
                  if name.startswith("plenocli.") and _is_module(name)]
    return found


def imported(source: str, package: str) -> list[str]:
    """Every module name ``source`` (a module of ``package``) imports, statically or by a
    string handed to import_module/__import__ (for an f-string, the package its fixed start
    names)."""
    names = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{parent}.{base}".rstrip(".")
            names += [base] + [f"{base}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.Call) and _called(node.func) in IMPORTERS and node.args:
            names += _named(node.args[0])
    return names


def _called(func: ast.expr) -> str:
    return func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")


def _named(arg: ast.expr) -> list[str]:
    """The module a module-name argument names: the name itself, or for an f-string the
    package its fixed start names (``f"plenocli.cli.{name}"``: plenocli.cli)."""
    if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
        return [arg.value]
    if isinstance(arg, ast.JoinedStr) and arg.values and isinstance(arg.values[0], ast.Constant):
        return [str(arg.values[0].value).rpartition(".")[0]]
    return []


def _is_module(name: str) -> bool:
    path = ROOT.joinpath(*name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def test_imports_point_down():
    upward = [(src, dst) for src, dst in imports()
              if dst not in BASE and src not in BASE | ENTRY_POINTS
              and (src, dst) not in KNOWN_UPWARD
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


def test_nothing_below_the_command_line_imports_it():
    """The pipeline, the Dask workers and the library run without plenocli.cli (and click)."""
    above = [(src, dst) for src, dst in imports()
             if dst.startswith("plenocli.cli") and layer(src) != "cli" and src not in ENTRY_POINTS]
    assert not above, above


@pytest.mark.parametrize("source", [
    "import importlib\nimportlib.import_module(f'plenocli.cli.{name}')",
    "from importlib import import_module\nimport_module('plenocli.cli.params')",
    "__import__('plenocli.cli.main')",
    "from ..cli import options",
    "from ...cli.params import resolve",
])
def test_dynamic_and_relative_imports_are_seen(source):
    package = "plenocli.pipeline.stages" if "..." in source else "plenocli.pipeline"
    assert any(name.startswith("plenocli.cli") for name in imported(source, package)), source
