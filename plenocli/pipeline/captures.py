"""The captures of a batch: ``--inputs`` globs, plain paths and ``@LIST`` files.

A glob is matched against the files there are now, and a batch writes its outputs (often under
the folder a glob walks, ``'shoot/**/*.tif'`` with ``--out shoot/out``): the files the batch
itself writes are left out of a glob's matches (said in a message), so that a second run is the
same batch as the first, not one whose outputs have become captures.
"""

from __future__ import annotations

import glob
from collections.abc import Callable, Sequence
from pathlib import Path

from plenocli.errors import InputError, OptionError
from plenocli.pipeline.config import Template
from plenocli.progress import log, shown


def _list_lines(pattern: str, listing: Path) -> list[str]:
    """The lines of an ``@LIST`` file, refused in one line when it is no text file."""
    from plenocli.errors import not_a_file, os_error_message
    from plenocli.io.yamlfile import DocumentError, read_text

    if not listing.is_file():
        raise InputError(f"--inputs {pattern}: {not_a_file(listing)} (the list of captures)")
    try:
        return read_text(listing).splitlines()
    except OSError as err:
        raise InputError(f"--inputs {pattern}: {os_error_message(err)}") from err
    except DocumentError as err:
        raise InputError(f"--inputs {pattern}: {listing} is not a list of captures, one path "
                         f"a line ({err})") from err


def expand_inputs(patterns: Sequence[str], *,
                  template: Template | Callable[[], Template] | None = None,
                  out: str | None = None) -> list[Path]:
    """Capture paths from glob patterns, plain paths and ``@LIST`` files (one path a line).

    Order is kept (globs sorted), duplicates dropped (a file reached by two names, through a
    link, with a warning); a pattern that matches nothing is an error.
    With the batch's ``template`` (and its ``out`` root), a glob's matches that the batch writes
    (a shared step's output, or a capture's output, in or under its folder) are left out; a
    function giving the template is called only when a glob matched (the config is read then).
    """
    found: list[tuple[str, list[Path], bool]] = []  # pattern, its files, whether a glob
    for pattern in patterns:
        if not pattern.strip():
            raise OptionError("--inputs '': the pattern is empty; give a quoted glob, a capture "
                              "file or @LIST, e.g. --inputs 'shoot/*.CR2'")
        if pattern.startswith("@"):
            listing = Path(pattern[1:])
            files = [listing.parent / ln.strip() for ln in _list_lines(pattern, listing)
                     if ln.strip() and not ln.lstrip().startswith("#")]
            if not files:
                raise InputError(f"--inputs {pattern}: {listing} lists no captures (one a line)")
        elif glob.has_magic(pattern):
            files = [Path(p) for p in sorted(glob.glob(pattern, recursive=True))
                     if Path(p).is_file()]
        else:
            files = [Path(pattern)]
        if not files:
            raise InputError(f"--inputs {pattern!r} matches no file; quote globs so that "
                             "plenocli expands them, e.g. --inputs 'shoot/*.CR2'")
        folder = next((p for p in files if p.is_dir()), None)
        if folder is not None:  # a capture is a file: the folder's captures are a glob
            raise OptionError(f"--inputs {pattern!r}: {folder} is a folder, not a capture; give "
                              f"its captures as a quoted glob, e.g. --inputs '{folder}/*.CR2'")
        found.append((pattern, files, glob.has_magic(pattern) and not pattern.startswith("@")))
    if template is not None and any(is_glob for _, _, is_glob in found):
        found = _without_outputs(found, template if isinstance(template, Template)
                                 else template(), out)
    unique = _one_name_per_file(dict.fromkeys(capture_path(p) for _, files, _ in found
                                              for p in files))
    stems: dict[str, Path] = {}
    for p in unique:
        if p.stem in stems:
            raise InputError(f"captures {stems[p.stem]} and {p} have the same name {p.stem!r} "
                             "and would share an output folder; rename one or run them apart")
        stems[p.stem] = p
    return unique


def capture_path(path: str | Path) -> Path:
    """``path`` with its folder's real path and its own name as given: ``{name}`` is the file
    name the user gave (a link's, not its target's), and a worker elsewhere finds the folder."""
    path = Path(path)
    try:
        return path.parent.resolve() / path.name
    except RuntimeError as err:  # Python 3.11 says a symbolic-link loop so
        raise InputError(f"capture {path}: its folder is a symbolic-link loop; give the "
                         "capture's real folder") from err


def _one_name_per_file(paths: Sequence[Path]) -> list[Path]:
    """``paths`` with a file reached by several names (a symbolic or hard link beside its
    target) kept once, under its first name, with a warning naming the others: processing it
    twice would give the same results twice under two names."""
    first: dict[object, Path] = {}
    twins: dict[Path, list[Path]] = {}
    for path in paths:
        try:
            info = path.stat()
        except OSError:  # missing or unreadable: its decode step says so, under its own name
            key: object = path
        else:
            key = (info.st_dev, info.st_ino)
        if key in first:
            twins.setdefault(first[key], []).append(path)
        else:
            first[key] = path
    for kept, others in twins.items():
        log.warning("captures %s are the same file as %s (linked): processed once, as %r",
                    ", ".join(_as_given(p) for p in others), _as_given(kept), kept.stem)
    return list(first.values())


def _as_given(path: Path) -> str:
    """``path`` relative to the working folder when inside it, its links not followed."""
    try:
        return str(path.relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def _without_outputs(found: list[tuple[str, list[Path], bool]], template: Template,
                     out: str | None) -> list[tuple[str, list[Path], bool]]:
    """``found`` with the files this batch writes for the captures found left out of the
    globs' matches; a glob that matches only files a batch of any captures writes is refused."""
    candidates = list(dict.fromkeys(str(capture_path(p)) for _, files, _ in found
                                    for p in files))
    made = template.outputs_of(candidates, out=out)
    written = template.written_by(out=out)

    def ours(path: Path) -> bool:
        full = str(path.resolve())
        return full in made or any(str(parent) in made for parent in Path(full).parents)

    kept = []
    for pattern, files, is_glob in found:
        if is_glob and all(written.fullmatch(str(p.resolve())) for p in files):
            raise InputError(f"--inputs {pattern!r} matches only files this batch writes "
                             f"({len(files)}, e.g. {shown(files[0])}): its own outputs, not "
                             "captures; give a pattern that matches the captures alone")
        left_out = [p for p in files if is_glob and ours(p)]
        if left_out:
            log.info("--inputs %r: %d file(s) this batch writes (e.g. %s) left out of the "
                     "captures", pattern, len(left_out), shown(left_out[0]))
        kept.append((pattern, [p for p in files if p not in left_out], is_glob))
    return kept
