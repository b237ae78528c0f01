"""Errors the user sees as one line: what was wrong, with which value, and what to do."""

import errno
import os
import re


class PlenocliError(Exception):
    """Base class; the message is shown to the user as it is (no traceback unless --debug)."""


class InputError(PlenocliError):
    """An input file is missing, unreadable, of the wrong kind, or does not match another input."""


class ConfigError(PlenocliError):
    """A pipeline configuration or a parameter value is invalid."""


class OptionError(ConfigError):
    """An option given where it has no effect (a usage error: exit 2)."""


class CalibrationError(PlenocliError):
    """A calibration (lens grid, white image) cannot be estimated or does not fit the data."""


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived: unwind like Ctrl-C (every ``except KeyboardInterrupt`` cleans up, and
    temporaries are removed), then exit 143. Raised by the command edge's one SIGTERM handler
    (``cli/options``) and by a batch worker's."""


_terminated = [False]  # a SIGTERM arrived in this command (its exception may have been lost)


def raise_terminated() -> None:
    """A SIGTERM handler's body: note the request, then raise :class:`Terminated`. Python
    only prints and drops an exception raised while it runs a ``__del__`` or a weakref
    callback; the note survives, and :func:`check_terminated` acts on it before any output
    lands."""
    _terminated[0] = True
    raise Terminated()


def check_terminated() -> None:
    """Raise :class:`Terminated` if a SIGTERM arrived whose exception was lost."""
    if _terminated[0]:
        raise Terminated()


def clear_terminated() -> None:
    """Start of a command (or a batch worker's capture): no SIGTERM yet."""
    _terminated[0] = False


def note_interrupt(interrupt: KeyboardInterrupt, words: str) -> None:
    """Add what the command could not undo to an interruption (Ctrl-C or :class:`Terminated`):
    the command edge says it after "no partial output was kept"."""
    interrupt.plenocli_note = words  # type: ignore[attr-defined]


def interrupt_note(interrupt: KeyboardInterrupt) -> str | None:
    """The words :func:`note_interrupt` added, if any."""
    return getattr(interrupt, "plenocli_note", None)


_OS_HINTS = {
    errno.EACCES: "permission denied; choose a folder you can write to",
    errno.EPERM: "operation not permitted; choose a folder you can write to",
    errno.EROFS: "read-only file system; choose another folder",
    errno.ENOSPC: "no space left on the device; free some space or write elsewhere",
    errno.EDQUOT: "disk quota exceeded; free some space or write elsewhere",
    errno.EFBIG: ("the output could not be written whole (a file size limit, see ulimit -f, "
                  "or a full disk); raise the limit or write elsewhere"),
    errno.ENAMETOOLONG: "file name too long; shorten it",
    errno.ENOTDIR: "a part of the path is a file, not a folder",
    errno.EISDIR: "it is a folder; give a file name",
    errno.ENOENT: "no such file or folder",
    errno.EEXIST: "it exists already",
    errno.EIO: "input/output error on the device",
    errno.EMFILE: "too many open files",
}


def os_error_message(err: OSError) -> str:
    """One line for an operating-system error: the path and the cause, and what to do."""
    path = err.filename if err.filename is not None else ""
    cause = _OS_HINTS.get(err.errno) or err.strerror or str(err) or type(err).__name__
    if err.errno in (errno.EACCES, errno.EPERM) and path and os.path.isfile(path):
        # an existing file: outputs are always new files (temporaries), so it was being read
        cause = "permission denied; it cannot be read: ask for read access or copy it"
    return f"{path}: {cause}" if path else cause


def not_a_file(path: "str | os.PathLike") -> InputError:
    """The error for an input path that is not a file to read: missing, a folder, or a device,
    pipe or socket (which would block or read nothing)."""
    if os.path.isdir(path):
        return InputError(f"{path}: is a folder; pass a file")
    if os.path.exists(path):
        return InputError(f"{path}: not a regular file (a device, pipe or socket); pass a file")
    if os.path.islink(path):  # a link to nothing: say where it leads
        try:
            os.stat(path)
        except OSError as err:
            if err.errno == errno.ELOOP:
                return InputError(f"{path}: a symbolic link loop ({path} -> "
                                  f"{os.readlink(path)} -> ...); pass the file itself")
        return InputError(f"{path}: a symbolic link to {os.readlink(path)}, which does not "
                          "exist; pass the file itself")
    return InputError(f"{path}: no such file")


# Python's own phrases in a library's exception, and what they mean for a file being read: a
# message names what is wrong with the file, not the line of Python that tripped on it.
_PYTHON_PHRASES = (
    (re.compile(r"unpack requires a buffer of \d+ bytes"), "it ends inside a header or table"),
    (re.compile(r"(?:list |tuple )?index -?\d* ?out of range(?:\(\d+\))?"),
     "a table is shorter than its header says"),
    (re.compile(r"\braised (\w+)\((['\"])(.*?)\2\)"), r": \3"),   # tifffile's log lines
    (re.compile(r"\bb(['\"])(.*?)\1"), r"\2"),                      # bytes reprs (LibRaw)
    (re.compile(r"\bnp\.\w+\(([^()]*)\)"), r"\1"),                # numpy scalar reprs
    (re.compile(r"\s@(\d+)"), r" at byte \1"),
)


# Codec libraries (imagecodecs, zlib, ...) report "FUNCTION returned CODE": said as which
# compressed data does not decode and why, in words.
_CODECS = (("lzw", "LZW"), ("packbits", "PackBits"), ("deflate", "Deflate"), ("zlib", "Deflate"),
           ("zstd", "Zstandard"), ("lzma", "LZMA"), ("jpeg", "JPEG"), ("webp", "WebP"),
           ("lerc", "LERC"), ("jxl", "JPEG XL"))
_CODEC_FAILURE = re.compile(r"\b([A-Za-z]\w*_\w+)\s+returned\s+(?:'([^']*)'|\"([^\"]*)\"|(-?\w+))")


def _codec_failure(match: "re.Match") -> str:
    function = match.group(1).lower()
    codec = next((name for key, name in _CODECS if key in function), "compressed")
    code = next(g for g in match.groups()[1:] if g is not None)
    detail = re.sub(r"^(?:(?:IMCD|LIBDEFLATE|LZMA|ZSTD|LZW|JPEG|Z)_)+", "", code)
    return f"its {codec} data does not decode: {detail.replace('_', ' ').lower()}"


# tifffile's enum reprs (<COMPRESSION.JPEG_99: 99>) as the TIFF tag's name and value
_ENUM_REPR = re.compile(r"<([A-Z]+)\.\w+: (-?\d+)>")
_ENUM_NAMES = {"COMPRESSION": "Compression", "PHOTOMETRIC": "Photometric",
               "SAMPLEFORMAT": "SampleFormat", "PLANARCONFIG": "PlanarConfiguration",
               "PREDICTOR": "Predictor", "FILLORDER": "FillOrder", "EXTRASAMPLE": "ExtraSamples",
               "ORIENTATION": "Orientation", "RESUNIT": "ResolutionUnit"}


def library_words(err: BaseException) -> str:
    """A third-party library's exception (tifffile, LibRaw, Pillow, ...) as plain words for a
    one-line message: bytes decoded, Python's phrases said as what they mean for the file
    (a buffer too short: the file ends inside a header; an index out of range: a table shorter
    than its header says), numpy reprs as numbers, whitespace on one line."""
    args = [a.decode("utf-8", "replace") if isinstance(a, bytes) else a for a in err.args]
    if isinstance(err, KeyError):
        text = f"no {args[0]} entry" if args else "a required entry is missing"
    elif len(args) == 1 and isinstance(args[0], str):
        text = args[0]
    else:
        text = str(err)
    return plain_words(text) or type(err).__name__


def plain_words(text: str) -> str:
    """``text`` with Python's phrases and reprs replaced (see ``library_words``), one line."""
    for pattern, words in _PYTHON_PHRASES:
        text = pattern.sub(words, text)
    text = _CODEC_FAILURE.sub(_codec_failure, text)
    text = _ENUM_REPR.sub(lambda m: f"{_ENUM_NAMES.get(m.group(1), m.group(1).title())} "
                                    f"{m.group(2)}", text)
    return " ".join(text.replace(" :", ":").split()).rstrip(".")


def numbers(values) -> str:
    """Numbers for a message: '0, 900, 0.5' (whole numbers whole, others :g), not a list of
    numpy reprs."""
    return ", ".join(_number(float(v)) for v in values)


def _number(v: float) -> str:
    return str(int(v)) if v.is_integer() and abs(v) < 1e15 else f"{v:g}"


def value_words(value, *, limit: int = 60) -> str:
    """A value read from YAML (or JSON) for a message, in plain words: text quoted, numbers and
    true/false as written, and for the kinds YAML's tags make (``!!binary``, ``!!set``,
    ``!!timestamp``, ``!!omap``) what they are, never Python's repr (``b'9'``, ``{'a.dng'}``);
    a long list or mapping by its size."""
    import datetime

    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "no value (null)"
    if isinstance(value, str):
        return repr(value) if len(value) <= limit else f"a text of {len(value)} characters"
    if isinstance(value, (int, float)):
        return str(value)
    if isinstance(value, (bytes, bytearray)):
        return f"binary data (!!binary, {_count(len(value), 'byte')})"
    if isinstance(value, (datetime.date, datetime.datetime)):
        return f"a date (!!timestamp {value.isoformat()})"
    if isinstance(value, (set, frozenset)):
        return f"a set (!!set) of {_count(len(value))}"
    if isinstance(value, dict):
        return f"a mapping of {_count(len(value), 'key')}"
    if isinstance(value, tuple):  # YAML makes tuples only of !!omap and !!pairs items
        return "a key: value pair (!!omap or !!pairs)"
    if isinstance(value, list) and not value:
        return "an empty list"
    if isinstance(value, list):
        if all(isinstance(v, (str, int, float)) for v in value):
            said = ", ".join(value_words(v, limit=limit) for v in value)
            if len(said) <= limit:
                return f"a list ({said})"
        return f"a list of {_count(len(value))}"
    return "a value that is not text, a number, true or false"


def _count(n: int, what: str = "value") -> str:
    return f"{n} {what}" + ("" if n == 1 else "s")
