"""plenocli.warmup: the install-time numba warm-up runs and names what it warmed."""

from __future__ import annotations

from plenocli import warmup


def test_warmup_runs_every_warmer(capsys):
    warmup.main()
    out = capsys.readouterr().out
    for name in warmup.WARMERS:
        assert f"plenocli warm-up: {name} kernels ready" in out
