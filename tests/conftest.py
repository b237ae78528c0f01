"""Shared test fixtures: the real-data folder (skipped when absent) and temp outputs."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
REALDATA = (ROOT / ".." / "shared" / "realdata").resolve()
FIXTURES = ROOT / "fixtures"


@pytest.fixture
def realdata() -> Path:
    """Path of ../shared/realdata; the test is skipped when the folder is absent."""
    if not REALDATA.is_dir():
        pytest.skip(f"real captures not found at {REALDATA}")
    return REALDATA


@pytest.fixture
def project(tmp_path):
    """A copy of the demo config and fixture in a temp folder (outputs land there too)."""
    (tmp_path / "configs").mkdir()
    shutil.copy(ROOT / "configs" / "demo_dualpixel.yaml", tmp_path / "configs")
    shutil.copytree(ROOT / "fixtures" / "dualpixel", tmp_path / "fixtures" / "dualpixel")
    return tmp_path / "configs" / "demo_dualpixel.yaml"
