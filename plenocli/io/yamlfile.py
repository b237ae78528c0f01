"""The one reader of YAML and JSON text: configs, ``--set`` and ``--param`` values, side files.

Scalars follow YAML 1.2's core schema in its decimal forms, which are the words a shell option
takes: ``10``, ``010`` (ten, not YAML 1.1's octal eight), ``-3``, ``0.5``, ``1e30`` (a number,
not YAML 1.1's text), ``.inf``, ``.nan``, ``true``/``false``, ``null``/``~``/empty.
Everything else is text: ``2:6`` (not YAML 1.1's base-60 126), ``yes``/``on``, dates, ``0x10``
and ``0o10`` (the shell's int() refuses them: left out of the core schema here so that both say
the same); a validator then reads that text exactly as it reads the shell's word, so a value
means the same wherever it is written. A key given twice in one mapping or object is refused
(PyYAML and ``json`` keep the last one silently: a file would be read with one of two values
it states); so are two keys that Python reads as one (``1``, ``1.0`` and ``true``). An alias
(``*name``) is refused before anything is built: one to its own anchor makes a list that holds
itself (every reader walking it recurses without end), and a few hundred bytes of aliases to
aliases stand for millions of values (hours to walk); no file plenocli writes or ships uses one.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path
from typing import Any

import yaml

from plenocli.errors import InputError, not_a_file, os_error_message

MAX_TEXT_BYTES = 1 << 28  # 256 MiB: far above any config, grid, record or list; bounds memory
_INT = re.compile(r"^[-+]?[0-9]+$")
_FLOAT = re.compile(r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?"
                    r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$")
_RESOLVERS = (  # (tag, pattern, first characters); the first match wins
    ("bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"), "tTfF"),
    ("int", _INT, "-+0123456789"),
    ("float", _FLOAT, "-+0123456789."),
    ("null", re.compile(r"^(?:~|null|Null|NULL|)$"), ["~", "n", "N", ""]),
    ("merge", re.compile(r"^(?:<<)$"), "<"),   # '<<: {camera: dng}' (no aliases: see above)
)


class DocumentError(ValueError):
    """A YAML or JSON document that cannot be read, in one line: where and what."""


class YamlError(DocumentError, yaml.YAMLError):
    """Also a YAMLError, for readers that catch PyYAML's errors."""


class JsonError(DocumentError, json.JSONDecodeError):
    """Also a JSONDecodeError, for readers that catch the json module's errors."""

    def __init__(self, message: str, doc: str = "", pos: int = 0):
        json.JSONDecodeError.__init__(self, message, doc, pos)
        self.args = (message,)

    def __str__(self) -> str:
        return self.msg


class IntWord(int):
    """A whole number that keeps the word it was written as (``010``, ``+5``)."""

    def __str__(self) -> str:
        return self.word


class FloatWord(float):
    """A number that keeps the word it was written as (``1e3``, ``0.50``)."""

    def __str__(self) -> str:
        return self.word


def _special(kind, text: str, node):
    if text.lower().lstrip("+-") in (".inf", ".nan"):
        return kind(text.replace(".", "", 1))
    raise yaml.constructor.ConstructorError(
        None, None, f"{text!r} is not a {kind.__name__}", node.start_mark)


def _number(kind, word_kind=None):
    def construct(loader, node):
        text = loader.construct_scalar(node)
        try:
            value = kind(text)
        except ValueError:
            value = _special(kind, text, node)   # .inf, .nan: Python's inf, nan
        if word_kind is None:
            return value
        word = word_kind(value)
        # '!!float 9' is the number 9.0: its word must say so, or an integer option would take
        # what the file calls a float (the plain word 9.0 is refused there)
        as_written = (text[-1:].isdigit() or text[-1:] == ".") and not (
            kind is float and _INT.match(text))
        word.word = text if as_written else str(value)
        return word
    return construct


def _core_bool(loader, node):
    """true/false only, tagged or not: '!!bool yes' is refused as the plain word yes is text."""
    text = loader.construct_scalar(node)
    if text.lower() not in ("true", "false"):
        raise yaml.constructor.ConstructorError(
            None, None, f"{text!r} is not a bool (true or false)", node.start_mark)
    return text.lower() == "true"


def _unique_mapping(self, node, deep=False):
    seen = {}  # key as Python compares it -> its YAML tag
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue  # '<<: {...}': the merged keys may be given again (YAML's merge)
        key = self.construct_object(key_node, deep=True)
        if not isinstance(key, (str, int, float, bool)):
            continue  # an unhashable key: the base loader reports it
        if key in seen and seen[key] == key_node.tag:
            raise yaml.constructor.ConstructorError(
                None, None, f"key {key!r} is given twice in one mapping; keep one",
                key_node.start_mark)
        if key in seen:
            # 1, 1.0 and true are three YAML keys but one Python key: a dict would keep one
            # of the two entries silently
            raise yaml.constructor.ConstructorError(
                None, None, f"key {getattr(key_node, 'value', key)} is read as the same key "
                "as an earlier one (numbers and true/false as keys: 1, 1.0 and true are one); "
                "quote the keys to make them text", key_node.start_mark)
        seen[key] = key_node.tag
    return yaml.constructor.SafeConstructor.construct_mapping(self, node, deep=deep)


def _loader(base: type, *, words: bool = False) -> type:
    cls = type(f"Core{base.__name__}", (base,), {
        "yaml_implicit_resolvers": {}, "construct_mapping": _unique_mapping})
    for tag, pattern, first in _RESOLVERS:
        cls.add_implicit_resolver(f"tag:yaml.org,2002:{tag}", pattern, list(first))
    cls.add_constructor("tag:yaml.org,2002:int", _number(int, IntWord if words else None))
    cls.add_constructor("tag:yaml.org,2002:float", _number(float, FloatWord if words else None))
    cls.add_constructor("tag:yaml.org,2002:bool", _core_bool)
    return cls


# libyaml's parser when PyYAML was built with it (grids of 100k lenses: 10-50x faster); the
# resolvers and constructors above are Python in both
Loader = _loader(getattr(yaml, "CSafeLoader", yaml.SafeLoader))
PyLoader = _loader(yaml.SafeLoader)
# for stage parameters: a number also keeps its word, so a text parameter (a view named 00, a
# g list) gets exactly what the shell would pass, and a number parameter its value
WordLoader = _loader(getattr(yaml, "CSafeLoader", yaml.SafeLoader), words=True)


def yaml_problem(err: Exception) -> str:
    """A YAML error in a few words: where and what (PyYAML's own text spans several lines)."""
    mark = getattr(err, "problem_mark", None)
    problem = getattr(err, "problem", None) or str(err)
    where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
    return where + " ".join(str(problem).split())


def _refuse_aliases(text: str) -> None:
    """YamlError at the first alias (``*name``) of ``text``. libyaml's composer, which joins an
    alias to its anchor, cannot be told to refuse one, so the tokens are scanned first: only
    when a '*' is there at all, and in libyaml's scanner (a grid of 100k lenses has none)."""
    if "*" not in text:
        return
    try:
        for token in yaml.scan(text, Loader=Loader):
            if isinstance(token, yaml.AliasToken):
                mark = token.start_mark
                raise YamlError(f"line {mark.line + 1}, column {mark.column + 1}: an alias "
                                f"(*{token.value}) stands for its anchor's value; plenocli "
                                "does not read aliases: write the value out")
    except YamlError:
        raise
    except yaml.YAMLError:
        return  # a text that is not YAML: the loader says where


def load_yaml(text: str, *, words: bool = False) -> Any:
    """One YAML document; :class:`DocumentError` says what is wrong with it. ``words``: numbers
    are :class:`IntWord`/:class:`FloatWord`, printing as written (stage parameters)."""
    _refuse_aliases(text)
    try:
        return yaml.load(text, Loader=WordLoader if words else Loader)  # noqa: S506 (safe)
    except yaml.YAMLError as err:
        raise YamlError(yaml_problem(err)) from err


def comment_in(text: str) -> str | None:
    """The end of a one-line YAML value that YAML reads as a comment (``img #2.dng`` reads as
    ``img``), or None when the value is read whole. A shell word has no comments: a value given
    as one (``--set``) must not lose its end silently."""
    try:
        node = yaml.compose(text, Loader=WordLoader)
    except yaml.YAMLError:
        return None  # load_yaml says what is wrong
    rest = text if node is None else text[node.end_mark.index:]
    return rest.strip() or None


def comment_advice(target: str, value: str, comment: str) -> str:
    """What to say of a shell word ``target=value`` whose end YAML reads as a ``comment``: quote
    the value to keep it, or, when it was quoted already (quoting it again is no YAML), leave
    the comment out or put it inside the quotes."""
    kept = value.strip()[:-len(comment)].rstrip()
    if kept[:1] in ("'", '"'):
        return (f"YAML reads {comment!r} after the quoted value as a comment; leave it out "
                f"(--set '{target}={kept}') or put it inside the quotes")
    return (f"YAML reads {comment!r} as a comment, not as part of the value; quote the value "
            f"to keep it (--set '{target}=\"{value}\"')")


def _unique_pairs(pairs: list) -> dict:
    doc = {}
    for key, value in pairs:
        if key in doc:
            raise JsonError(f"key {key!r} is given twice in one object; keep one")
        doc[key] = value
    return doc


MAX_DEPTH = 100  # nesting of a document: plenocli's own files nest a few levels


def load_json(text: str) -> Any:
    """One JSON document; :class:`DocumentError` says what is wrong with it."""
    try:
        doc = json.loads(text, object_pairs_hook=_unique_pairs)
    except JsonError:
        raise
    except json.JSONDecodeError as err:
        raise JsonError(f"line {err.lineno}, column {err.colno}: {err.msg}", text,
                        err.pos) from err
    except RecursionError as err:
        raise _too_deep() from err
    if _deeper_than(doc, MAX_DEPTH):
        raise _too_deep()
    return doc


def _too_deep() -> JsonError:
    return JsonError(f"lists and objects nested more than {MAX_DEPTH} deep; not a document "
                     "plenocli writes (damaged?)")


def _deeper_than(doc: Any, limit: int) -> bool:
    """Whether lists/dicts in ``doc`` nest more than ``limit`` deep (walked without recursion,
    so every later reader can recurse safely)."""
    level = [doc]
    for _ in range(limit + 1):
        level = [item for node in level if isinstance(node, (list, dict))
                 for item in (node.values() if isinstance(node, dict) else node)]
        if not level:
            return False
    return True


def _text(path: str | os.PathLike) -> str:
    """The UTF-8 text of a regular file of at most MAX_TEXT_BYTES: a pipe would block and a
    device (/dev/zero) never end."""
    if os.path.exists(path) and not os.path.isdir(path) and not os.path.isfile(path):
        raise DocumentError("not a regular file (a device, pipe or socket)")
    with open(path, "rb") as fh:
        raw = fh.read(MAX_TEXT_BYTES + 1)
    if len(raw) > MAX_TEXT_BYTES:
        raise DocumentError(f"more than {MAX_TEXT_BYTES >> 20} MiB of text")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as err:
        raise DocumentError(f"not UTF-8 text (byte {err.start})") from err


def read_text(path: str | os.PathLike) -> str:
    """A text file (OSError when it cannot be read, DocumentError when it is not one)."""
    return _text(path)


def read_yaml(path: str | os.PathLike) -> Any:
    """A YAML file (OSError when it cannot be read, DocumentError when it is not YAML)."""
    return load_yaml(_text(path))


def read_json(path: str | os.PathLike) -> Any:
    """A JSON file (OSError when it cannot be read, DocumentError when it is not JSON)."""
    return load_json(_text(path))


def read_side_file(path: str | os.PathLike, kind: str, *, read=read_yaml,
                   hint: str = "") -> Any:
    """The document of a side file (a lens, a rig, a transform, a camera) by ``read``
    (:func:`read_yaml` or :func:`read_json`), refused in one line naming the file: not a file,
    unreadable, or not the ``kind`` it should be (``"YAML rig"``). ``hint`` ends the message:
    how to make a good one."""
    file = Path(path)
    end = f"; {hint}" if hint else ""
    if not file.is_file():
        raise InputError(f"{not_a_file(file)} (the {kind}){end}")
    try:
        return read(file)
    except OSError as err:
        raise InputError(os_error_message(err)) from err
    except DocumentError as err:
        raise InputError(f"{file}: not a {kind} ({err}){end}") from err
