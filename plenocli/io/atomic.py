"""Atomic writes: a failed or interrupted stage never leaves a half-written file.

Every file is written to a temporary beside its destination and renamed only on success. Inside
:func:`outputs_together` (what every stage runs in), the renames wait until the whole stage has
succeeded, so a command's outputs land together or not at all (and the messages that report them
are shown only once they have). Temporaries are named ``.NAME.HOST-PID.XXXX.part``: one left by
a killed run (its process gone) is removed the next time anything writes NAME. A NAME longer than
:data:`LONG_NAME` bytes is shortened there to its start and a hash (:func:`short_name`), so that
any name a file system with the common 255-byte limit takes has a temporary it takes too. An
output that is a symbolic link is written through: its target is replaced and the link stays (as
the shell's ``>`` does). An output that is there and is not a regular file (a pipe, a device, a
socket, or a link to one) is refused: the shell's ``>`` writes into it, a rename would replace
the node itself (as root, a link to /dev/null would replace /dev/null).
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import glob
import hashlib
import os
import signal
import socket
import stat
import tempfile
import threading
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from plenocli.errors import InputError, check_terminated
from plenocli.model.provenance import hash_ahead
from plenocli.progress import messages_held, release


@dataclass
class _Pending:
    """What a stage has written so far: (temporary, destination) pairs, and the folders made
    for them (removed again, when empty, if the stage fails)."""

    files: list[tuple[Path, Path]] = field(default_factory=list)
    folders: list[Path] = field(default_factory=list)


_PENDING: contextvars.ContextVar[_Pending | None] = contextvars.ContextVar(
    "plenocli_pending_outputs", default=None)
_HOST = (socket.gethostname().replace(".", "_").replace("-", "_") or "host")[:64]
LONG_NAME = 120  # bytes; longer names are shortened in temporaries and side files
NAME_MAX = 255   # the common file-name limit, when the file system does not say


def short_name(name: str) -> str:
    """``name``, or for a name over LONG_NAME bytes its start and a hash of the whole: the
    part of a temporary's or side file's name that says whose it is (stable for one name)."""
    raw = os.fsencode(name)  # the bytes on disk (a name that is not UTF-8 too)
    if len(raw) <= LONG_NAME:
        return name
    digest = hashlib.sha256(raw).hexdigest()[:16]
    return raw[:LONG_NAME - 17].decode(errors="ignore") + "~" + digest


@contextlib.contextmanager
def outputs_together(
        before_landing: Callable[[list[tuple[Path, Path]]], None] | None = None,
) -> Iterator[None]:
    """Hold back the renames of every atomic write in the block until the block succeeds.

    On any exception (or Ctrl-C) inside the block every temporary is removed and no destination
    is touched. Inside another such block it joins the outer one. ``before_landing`` is called
    with the (temporary, destination) pairs once the block succeeded and before any rename;
    what it writes atomically lands with them (a record of the outputs, say).
    """
    outer = _PENDING.get()
    if outer is not None:
        yield
        if before_landing is not None:
            before_landing(list(outer.files))
        return
    pending = _Pending()
    token = _PENDING.set(pending)
    try:
        with messages_held() as held:  # "IN -> OUT" is said once OUT has landed
            yield
            if before_landing is not None:
                before_landing(list(pending.files))
            check_terminated()  # a SIGTERM whose exception was lost still stops the landing
    except BaseException:
        _discard(pending.files)
        _remove_empty(pending.folders)
        raise
    finally:
        _PENDING.reset(token)
    landed = 0
    try:
        with _signals_held():
            for tmp, dest in pending.files:
                os.replace(tmp, dest)
                landed += 1
    except BaseException:
        _discard(pending.files[landed:])
        raise
    release(held)


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """SIGTERM and SIGINT that arrive in the block are noted and raised again once it ends
    (to the handlers they had): a signal between two renames would otherwise land some outputs
    and not the others. Python runs handlers in the main thread only; elsewhere (a Dask
    worker's thread) signals are not ours to hold."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrived: list[int] = []
    previous = {}
    for sig in (signal.SIGTERM, signal.SIGINT):
        if signal.getsignal(sig) is not None:  # None: a handler not set from Python
            previous[sig] = signal.signal(sig, lambda signum, frame: arrived.append(signum))
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        for sig in arrived:
            signal.raise_signal(sig)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, protect: tuple = (),
                through_links: bool = True) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` only on success.

    The temporary file lives in the destination folder so that the final rename is atomic on
    POSIX file systems. On any exception (or Ctrl-C) the temporary file is removed and the
    destination is left as it was. ``protect`` lists input files that must never be overwritten.
    Inside :func:`outputs_together` the rename waits for the end of the block. Not
    ``through_links``: a symbolic link at ``path`` is replaced, not written through (plenocli's
    own side files, whose names no one chose to point somewhere).
    """
    dest = written_path(path) if through_links else Path(path)
    for other in protect:
        if other is not None and _same_file(Path(other), dest):
            raise InputError(f"output {path} is also an input; choose another output path "
                             "(plenocli never overwrites its inputs)")
    if dest.is_dir() and (through_links or not dest.is_symlink()):
        raise InputError(f"output {dest} is a folder; give a file name")
    check_file_kind(dest, follow=through_links)
    pending = _PENDING.get()
    if pending is not None and any(_same_path(dest, d) for _, d in pending.files):
        raise InputError(f"{dest} is written twice by one command; give each output its own "
                         "path")
    if pending is not None:
        pending.folders.extend(_missing_folders(dest.parent))
    dest.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(dest)
    fd, tmp_name = tempfile.mkstemp(prefix=f"{_temporary_prefix(dest)}{os.getpid()}.",
                                    suffix=".part", dir=dest.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.chmod(tmp, _new_mode(dest))
        if pending is not None:  # its record's sha256, taken while the stage writes the rest
            hash_ahead([tmp])
        if pending is None:
            check_terminated()
            os.replace(tmp, dest)
        else:
            pending.files.append((tmp, dest))
    except OSError as err:
        full = err.errno is None and _device_full(dest.parent)  # before the space is freed
        tmp.unlink(missing_ok=True)
        if full:  # numpy and tifffile report a short write without errno
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(dest)) from err
        if err.errno is None or (err.errno == errno.EFBIG and err.filename is None):
            # a short write with space left: a file size limit (ulimit -f), or a full disk
            raise OSError(errno.EFBIG, os.strerror(errno.EFBIG), str(dest)) from err
        if err.filename is None or err.filename == str(tmp):
            # a write into the open temporary (no name), or of the temporary: the output it is
            raise OSError(err.errno, err.strerror, str(dest)) from err
        raise
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def written_path(path: str | os.PathLike) -> Path:
    """The file a write to ``path`` replaces: the target of a symbolic link (written through,
    as the shell's ``>`` and ``cp`` do; the link stays), else ``path`` itself."""
    dest = Path(path)
    return Path(os.path.realpath(dest)) if dest.is_symlink() else dest


def check_file_kind(dest: Path, *, follow: bool = True) -> None:
    """InputError when ``dest`` is there and is not a regular file (a folder is said by the
    callers): a pipe, a device or a socket, after following links when ``follow`` (else a
    link itself is fine: it is replaced)."""
    try:
        found = os.stat(dest) if follow else os.lstat(dest)
    except OSError:
        return  # not there (or a dangling link): a new file is made
    if not (stat.S_ISREG(found.st_mode) or stat.S_ISDIR(found.st_mode)
            or stat.S_ISLNK(found.st_mode)):
        raise InputError(f"output {dest}: not a regular file (a device, pipe or socket); "
                         "plenocli writes files, which would replace it: choose another "
                         "output path")


def _new_mode(dest: Path) -> int:
    """The permissions a plain ``open(dest, "w")`` would leave: those of the file it replaces,
    else 0666 less the umask (mkstemp makes its file 0600 whatever the umask)."""
    with contextlib.suppress(OSError):
        found = os.stat(dest)
        if stat.S_ISREG(found.st_mode):
            return stat.S_IMODE(found.st_mode)
    return 0o666 & ~current_umask()


_UMASK_LOCK = threading.Lock()


def current_umask() -> int:
    """The process's umask, read without changing it where Linux shows it (os.umask can only
    be read by setting it, which another thread could see)."""
    with contextlib.suppress(OSError, ValueError, IndexError):
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    with _UMASK_LOCK:
        mask = os.umask(0o022)
        os.umask(mask)
    return mask


def write_bytes(path: str | os.PathLike, data: bytes, *, protect: tuple = (),
                through_links: bool = True) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_path`)."""
    with atomic_path(path, protect=protect, through_links=through_links) as tmp:
        tmp.write_bytes(data)


def write_text(path: str | os.PathLike, text: str, *, protect: tuple = (),
               through_links: bool = True) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (see :func:`atomic_path`)."""
    write_bytes(path, text.encode("utf-8"), protect=protect, through_links=through_links)


def check_outputs(outputs: Iterable[Path], inputs: Iterable[Path] = (), *,
                  folders: Iterable[Path] = ()) -> None:
    """Before any work: every output distinct from the others and from the inputs, not a
    folder, with a name the file system takes, in a folder that exists or can be made and is
    writable. ``folders`` are output folders a stage fills: not a file, and writable (or
    makeable). Raises InputError naming the path and what to do."""
    outputs, inputs = [Path(p) for p in outputs], [Path(p) for p in inputs]
    for folder in (Path(p) for p in folders):
        if folder.exists() and not folder.is_dir():
            raise InputError(f"output folder {folder} is a file; give a folder")
        _check_folder(folder / "x", shown=f"into {folder}")  # any name in it
    for path in [*outputs, *folders]:
        _check_not_a_loop(Path(path))
    check_distinct(outputs, inputs)
    for out in outputs:
        if out.is_dir():
            raise InputError(f"output {out} is a folder; give a file name")
        check_file_kind(out)
        _check_folder(written_path(out))


def _check_not_a_loop(out: Path) -> None:
    """A symbolic link whose chain comes back to itself names no file to write through to (the
    shell's '>' says 'Too many levels of symbolic links')."""
    if not out.is_symlink():
        return
    try:
        os.stat(out)
    except OSError as err:
        if err.errno == errno.ELOOP:
            raise InputError(f"cannot write {out}: it is a symbolic link loop ({out} -> "
                             f"{os.readlink(out)} -> ...); remove the link or choose another "
                             "name") from err


def check_distinct(outputs: Iterable[Path], inputs: Iterable[Path] = ()) -> None:
    """Every output distinct from the others and from the inputs (InputError otherwise)."""
    outputs, inputs = [Path(p) for p in outputs], [Path(p) for p in inputs]
    for k, out in enumerate(outputs):
        for other in outputs[:k]:
            if _same_path(out, other):
                raise InputError(f"{out} is given for two outputs; give each output its own path")
        for src in inputs:
            if _same_path(out, src):
                raise InputError(f"output {out} is also an input; choose another output path "
                                 "(plenocli never overwrites its inputs)")


def remove_stale_temporaries(dest: Path) -> None:
    """Remove temporaries of ``dest`` left on this host by processes that no longer run."""
    with contextlib.suppress(OSError):
        prefix = _temporary_prefix(dest)
        for part in dest.parent.glob(f"{glob.escape(prefix)}*.part"):
            pid = part.name[len(prefix):].split(".", 1)[0]
            if pid.isdigit() and not process_alive(int(pid)):
                part.unlink(missing_ok=True)


def _temporary_prefix(dest: Path) -> str:
    return f".{short_name(dest.name)}.{_HOST}-"


def check_names_fit(out: Path) -> None:
    """InputError when a name in the path ``out`` (or the temporary plenocli writes beside it)
    is longer than the file system takes: what :func:`check_outputs` says before any work,
    checked alone where the outputs are only planned (``--dry-run``, ``--print-make``)."""
    out = Path(out)
    folder = out.parent
    while not _exists(folder) and folder != folder.parent:  # the file system it lands on
        folder = folder.parent
    _check_name_lengths(out, folder, str(out))


def _exists(path: Path) -> bool:
    try:
        return path.exists()
    except OSError:  # a name too long to look up: nothing by that name exists
        return False


def _check_name_lengths(out: Path, folder: Path, shown: str) -> None:
    name_max = NAME_MAX
    with contextlib.suppress(OSError, ValueError):
        name_max = os.pathconf(folder, "PC_NAME_MAX")
    temporary = f"{_temporary_prefix(out)}{os.getpid()}.xxxxxxxx.part"
    names = [*out.parent.parts, out.name, temporary]
    if any(len(os.fsencode(p)) > name_max for p in names):
        raise InputError(f"cannot write {shown}: a name in it is longer than this file system "
                         f"takes ({name_max} bytes); shorten it")


def _check_folder(out: Path, *, shown: str | None = None) -> None:
    shown = shown or str(out)
    folder = out.parent
    while not _exists(folder):
        if folder.is_symlink():
            raise InputError(f"cannot write {shown}: folder {folder} is a symbolic link to "
                             f"{os.readlink(folder)}, which does not exist; make that folder "
                             "or choose another")
        if folder == folder.parent:
            break
        folder = folder.parent
    if folder.exists() and not folder.is_dir():
        raise InputError(f"cannot write {shown}: {folder} is a file, not a folder")
    _check_name_lengths(out, folder, shown)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"cannot write {shown}: folder {folder} is not writable "
                         "(permission or a read-only file system); choose another folder")


def _device_full(folder: Path, margin: int = 1 << 20) -> bool:
    """Whether the file system of ``folder`` has less than ``margin`` bytes left."""
    try:
        stat = os.statvfs(folder)
    except (OSError, AttributeError):
        return False
    return stat.f_bavail * stat.f_frsize < margin


def _same_path(a: Path, b: Path) -> bool:
    """One file by two names: the same spelling, a link to one folder (the file need not exist
    yet: ``realpath`` follows the links of the folders), or one file already."""
    return (os.path.abspath(a) == os.path.abspath(b)
            or os.path.realpath(a) == os.path.realpath(b) or _same_file(a, b))


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` runs. A killed process stays a zombie until its parent reaps it
    (and a zombie still answers kill(pid, 0)), so /proc's state is read where there is one."""
    if os.path.exists("/proc/self/stat"):
        try:
            with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
                return fh.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
        except FileNotFoundError:
            return False
        except (OSError, IndexError):
            pass
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _missing_folders(folder: Path) -> list[Path]:
    """The folders ``mkdir(parents=True)`` would make for ``folder``, deepest first."""
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    return missing


def _remove_empty(folders: list[Path]) -> None:
    for folder in folders:  # deepest first
        with contextlib.suppress(OSError):
            folder.rmdir()


def _discard(pending: list[tuple[Path, Path]]) -> None:
    for tmp, _ in pending:
        with contextlib.suppress(OSError):
            tmp.unlink()

