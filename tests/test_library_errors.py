"""The library's errors (docs/architecture.md): a processing module raises ValueError (or its
own subclasses); the stage that calls it turns that into the pipeline's InputError or
ConfigError, adding which file or option was wrong."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "plenocli"
EDGE = ("cli", "pipeline", "io")  # the layers that speak in files and options
PIPELINE_ERRORS = {"InputError", "ConfigError"}


def _raised_names(tree: ast.AST) -> set[str]:
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Raise) and node.exc is not None:
            call = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
            if isinstance(call, ast.Name):
                names.add(call.id)
            elif isinstance(call, ast.Attribute):
                names.add(call.attr)
    return names


def test_processing_modules_raise_no_pipeline_error():
    offenders = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE).parts
        if len(parts) > 1 and parts[0] in EDGE:
            continue
        raised = _raised_names(ast.parse(path.read_text(encoding="utf-8"))) & PIPELINE_ERRORS
        if raised and path.name != "errors.py":
            offenders[path.relative_to(PACKAGE).as_posix()] = sorted(raised)
    assert not offenders, offenders
