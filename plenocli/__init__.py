"""plenocli: raw-processing pipeline for plenoptic captures (dual-pixel, Raytrix, N x N sensors)."""

import os
import stat
import tempfile

__version__ = "0.1.0"


def _writable(folder: str) -> bool:
    """Whether ``folder`` can be created and written, tested the way numba tests its cache."""
    try:
        os.makedirs(folder, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


def _private(folder: str) -> bool:
    """A cache folder in a shared place (the temp folder) must be ours alone: numba loads
    pickled code from it."""
    try:
        os.makedirs(folder, mode=0o700, exist_ok=True)
        info = os.lstat(folder)
    except OSError:
        return False
    return (stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid()
            and not info.st_mode & 0o022 and _writable(folder))


def numba_cache_dir(package_dir: str, environ: dict) -> str | None:
    """Where numba should keep compiled kernels: None for numba's own choice (the folder in
    NUMBA_CACHE_DIR, or the package's ``__pycache__``, when writable), else the first writable
    of the user's cache folder and a private folder in the temp folder; "" when no folder can
    be written (then kernels are compiled in every process, uncached).

    numba fails with "cannot cache function" when no cache folder it knows is writable (a
    system-wide or container install, HOME not writable); the folders are tried here with a
    real write, like numba does, as os.access says yes to root on a read-only mount."""
    chosen = environ.get("NUMBA_CACHE_DIR")
    if (chosen and _writable(chosen)) or _writable(os.path.join(package_dir, "__pycache__")):
        return None  # numba tries the package folder itself when NUMBA_CACHE_DIR fails
    home = environ.get("HOME") or os.path.expanduser("~")
    user = environ.get("XDG_CACHE_HOME") or os.path.join(home, ".cache")
    if _writable(os.path.join(user, "plenocli", "numba")):
        return os.path.join(user, "plenocli", "numba")
    temp = os.path.join(tempfile.gettempdir(), f"plenocli-numba-{os.getuid()}")
    return temp if _private(temp) else ""


def _without_numba_cache() -> None:
    """Compile numba kernels without caching them: ``cache=True`` kernels otherwise raise at
    import when no folder is writable. Only then is numba imported here."""
    from numba.core.dispatcher import Dispatcher

    Dispatcher.enable_caching = lambda self: None


_cache = numba_cache_dir(os.path.dirname(os.path.abspath(__file__)), dict(os.environ))
if _cache:
    os.environ["NUMBA_CACHE_DIR"] = _cache
elif _cache == "":
    _without_numba_cache()
