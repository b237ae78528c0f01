"""plenocli: raw-processing pipeline for plenoptic captures (dual-pixel, Raytrix, N x N sensors)."""

import os

__version__ = "0.1.0"


def numba_cache_dir(package_dir: str, environ: dict) -> str | None:
    """Where numba should keep compiled kernels when the installed package is read-only.

    numba caches next to the source by default and fails with "no locator available" when it
    cannot write there (a system-wide or container install); a user cache folder is used then.
    Returns None when nothing needs setting (writable package, or NUMBA_CACHE_DIR already set).
    """
    if environ.get("NUMBA_CACHE_DIR") or os.access(package_dir, os.W_OK):
        return None
    cache = environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(cache, "plenocli", "numba")


_cache = numba_cache_dir(os.path.dirname(os.path.abspath(__file__)), dict(os.environ))
if _cache:
    os.environ["NUMBA_CACHE_DIR"] = _cache
