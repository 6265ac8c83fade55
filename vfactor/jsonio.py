"""The one reader and the one writer of the JSON files vfactor reads from users and writes for them.

Reading (:func:`read_json`, :func:`parse_json`): JSON allows what a float or
Python cannot hold; these are refused as bad input (an
:class:`~vfactor.errors.InputError` of the caller's kind) instead of ending in
an ``OverflowError``, ``ValueError`` or ``RecursionError``:

* a number too large for a float (``1`` and 400 zeros, ``1e400``) and an
  integer of more than :data:`MAX_INT_DIGITS` digits (Python refuses to convert
  those above 4300 digits) are read as an :class:`OutOfRange` value, so the
  caller's field checks refuse it *at its field* ("expected a finite number,
  got a number too large for a float (401 digits)");
* ``NaN`` / ``Infinity`` literals are read as :class:`NonFinite`, likewise;
* nesting deeper than :data:`MAX_DEPTH` arrays/objects is refused with the path
  of the first too-deep value;
* a key given twice in one object is refused.

Writing (:func:`write_text_atomic`): a temporary file in the target's folder,
flushed and ``fsync``-ed, then ``os.replace``-d onto the target, so a crash or
a full disk never leaves a half-written result (docs/reliability.md).
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from vfactor.errors import InputError, SceneError

__all__ = [
    "describe",
    "is_int",
    "is_number",
    "not_a_file",
    "MAX_DEPTH",
    "MAX_INT_DIGITS",
    "NonFinite",
    "OutOfRange",
    "parse_json",
    "read_json",
    "read_text",
    "write_text_atomic",
]

#: Deepest nesting of arrays and objects accepted (a scene file needs 5).
MAX_DEPTH = 64
#: Integers with more digits are out of range (a float holds up to about 1.8e308; 20 digits exceed int64).
MAX_INT_DIGITS = 308
_INT_DIGITS_EXACT = 18  # integers up to this many digits stay Python ints; longer ones become floats


class NonFinite:
    """Stands in for the ``NaN`` / ``Infinity`` literals Python's json accepts, so that
    the field checks report them at their field."""

    __slots__ = ("text",)

    def __init__(self, text: str):
        self.text = text

    def __repr__(self):
        return self.text


class OutOfRange:
    """Stands in for a JSON number no float can hold (its magnitude is above about 1.8e308)."""

    __slots__ = ("text",)

    def __init__(self, text: str):
        self.text = text

    def __repr__(self):
        if self.text.lstrip("-").isdigit():
            return f"a number too large for a float (an integer of {len(self.text.lstrip('-'))} digits)"
        head = self.text if len(self.text) <= 24 else self.text[:20] + "..."
        return f"a number too large for a float ({head})"


class _DuplicateKey(Exception):
    pass


def _no_duplicate_keys(pairs):
    out = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(key)
        out[key] = value
    return out


def _parse_int(text: str):
    digits = len(text.lstrip("-"))
    if digits <= _INT_DIGITS_EXACT:
        return int(text)
    if digits <= MAX_INT_DIGITS:
        return float(text)  # Python parses decimal floats of any length correctly rounded
    return OutOfRange(text)


def _parse_float(text: str):
    value = float(text)
    if value in (float("inf"), float("-inf")):
        return OutOfRange(text)
    return value


def _too_deep(data) -> str | None:
    """The path of the first value nested deeper than :data:`MAX_DEPTH`, or None."""
    stack = [(data, "", 0)]
    while stack:
        value, path, depth = stack.pop()
        if isinstance(value, dict):
            items = ((f"{path}.{k}" if path else str(k), v) for k, v in value.items())
        elif isinstance(value, list):
            items = ((f"{path}[{i}]", v) for i, v in enumerate(value))
        else:
            continue
        if depth >= MAX_DEPTH:
            return path if len(path) <= 60 else path[:48] + "..." + path[-9:]
        stack.extend((v, p, depth + 1) for p, v in items if isinstance(v, (dict, list)))
    return None


def parse_json(text: str, where: str, error: type[InputError] = SceneError):
    """Parses JSON text under the rules of this module.

    Args:
        text: the JSON text.
        where: what the text is (a file path), the field of errors about the whole text.
        error: the :class:`~vfactor.errors.InputError` subclass to raise.

    Returns:
        The parsed value; numbers out of range and NaN / Infinity literals as
        :class:`OutOfRange` / :class:`NonFinite` (for the caller's field checks).

    Raises:
        InputError: (``error``) not JSON, a key twice in one object, or nested
            deeper than :data:`MAX_DEPTH`.
    """
    try:
        data = json.loads(text, parse_constant=NonFinite, parse_int=_parse_int, parse_float=_parse_float,
                          object_pairs_hook=_no_duplicate_keys)
    except json.JSONDecodeError as exc:
        raise error(where, f"not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}") from None
    except _DuplicateKey as exc:
        raise error(where, f"not valid: key {str(exc.args[0])[:40]!r} appears twice in one object") from None
    except RecursionError:
        raise error(where, f"not valid: arrays/objects nested deeper than {MAX_DEPTH} levels") from None
    deep = _too_deep(data)
    if deep is not None:
        raise error(where, f"not valid: arrays/objects nested deeper than {MAX_DEPTH} levels at {deep}")
    return data


def read_json(path: str | os.PathLike, error: type[InputError] = SceneError):
    """Reads a JSON file a user gives (scene, result, scenario, truth, settings), see :func:`parse_json`.

    Raises:
        InputError: (``error``, field: the path) the file is missing, a folder,
            unreadable, not UTF-8, or not valid JSON under :func:`parse_json`.
    """
    return parse_json(read_text(path, error), str(path), error)


def not_a_file(path: Path) -> str:
    """Why ``path``, which is no regular file, cannot be read as one: missing, a folder, or another kind of entry."""
    if not path.exists():
        return "file not found"
    if path.is_dir():
        return "expected a file, got a directory"
    return "expected a regular file, got a device, pipe or socket"


def read_text(path: str | os.PathLike, error: type[InputError] = SceneError) -> str:
    """The UTF-8 text of a file a user gives (:func:`read_json`'s, a recorded stream's).

    Raises:
        InputError: (``error``, field: the path) the file is missing, a folder, unreadable or not UTF-8.
    """
    path = Path(path)
    if not path.is_file():
        raise error(str(path), not_a_file(path))
    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise error(str(path), f"could not read the file: {exc}") from None


def write_text_atomic(path: str | os.PathLike, text: str | Iterable[str]) -> None:
    """Writes ``text`` (UTF-8) to ``path`` atomically: readers see the old file or the whole new one.

    A temporary file in the same folder is written, flushed and ``fsync``-ed,
    then moved onto ``path`` with ``os.replace``; on any failure it is removed
    and ``path`` is left as it was. The folder is created when missing. A
    ``path`` that is a link is followed: its target is written, the link kept.
    ``text`` may be an iterable of pieces, written as they come (a result file
    written while its frames are still being solved); an exception raised by
    the iterable leaves ``path`` as it was.

    Raises:
        OSError: the folder cannot be created or written, or the disk is full.
    """
    path = Path(os.path.realpath(path)) if os.path.islink(path) else Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    folder.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            for piece in ([text] if isinstance(text, str) else text):
                f.write(piece)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def describe(value) -> str:
    """A short description of a value found in user input, for error messages (``the string 'x'``, ``a list of
    3``, ``NaN``, ``an object``, ...): the one wording of scene, result, calibration and COCO files."""
    if value is None:
        return "null"
    if isinstance(value, (NonFinite, OutOfRange)):
        return repr(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float, np.integer, np.floating)):
        f = float(value)
        if math.isnan(f):
            return "NaN"
        if math.isinf(f):
            return "Infinity" if f > 0 else "-Infinity"
        return repr(value.item() if isinstance(value, np.generic) else value)
    if isinstance(value, str):
        text = value if len(value) <= 40 else value[:37] + "..."
        return f"the string {text!r}"
    if isinstance(value, (list, tuple)):
        return f"a list of {len(value)}"
    if isinstance(value, dict):
        return "an object"
    return f"a {type(value).__name__}"


def is_number(value) -> bool:
    """A number (int or float, NumPy's too), not a bool."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def is_int(value) -> bool:
    """An integer (NumPy's too), not a bool."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
