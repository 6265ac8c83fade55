"""Errors raised for bad user input.

Every error names the offending field (a dotted/indexed path such as
``frames[3].detections[0].keypoints[5]``), what was expected and what was found.
They subclass ``ValueError`` so that callers who already catch ``ValueError``
keep working; the CLI turns any :class:`InputError` into a one-line message and
exit code 2.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["InputError", "SceneError", "CalibrationError", "ScenarioError", "check_numbers"]


class InputError(ValueError):
    """Bad input: ``field`` names where, the message says what is wrong.

    Attributes:
        field: path of the offending field, e.g. ``cameras[1].K``; empty when the
            whole input is at fault.
        problem: what is wrong, without the field name.
    """

    def __init__(self, field: str, problem: str):
        self.field = _printable(str(field))  # a key or name from the input may hold a newline, a tab, a NUL
        self.problem = _printable(str(problem))
        super().__init__(f"{self.field}: {self.problem}" if self.field else self.problem)

    def within(self, prefix: str) -> "InputError":
        """Returns the same error with ``prefix`` put in front of its field path."""
        if not prefix:
            return self
        field = f"{prefix}.{self.field}" if self.field and not self.field.startswith("[") else f"{prefix}{self.field}"
        return type(self)(field, self.problem)


def _printable(text: str) -> str:
    """``text`` with its unprintable characters (newline, tab, NUL, ...) written as escapes, so that a message is
    one line whatever the input's keys and names hold."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


class SceneError(InputError):
    """A scene (input) or result file is malformed."""


class CalibrationError(InputError):
    """A camera calibration (intrinsics, distortion or extrinsic) is invalid."""


class ScenarioError(InputError):
    """A simulation scenario file (``graphs/*.json`` or the user's own) is malformed."""


def check_numbers(owner: str, obj, names, minimum: float = 0.0, strict: bool = True) -> None:
    """Checks that attributes of a settings object are finite real numbers above a bound.

    The one validation that the settings dataclasses (``GraphConfig``,
    ``CpoOptions``, the network's ``TrainConfig`` ...) share.

    Args:
        owner: the object's name in messages (e.g. ``"GraphConfig"``).
        obj: the object whose attributes are checked.
        names: attribute names.
        minimum: the bound.
        strict: the value must exceed ``minimum`` (else it may equal it).

    Raises:
        ValueError: ``"<owner>.<name>: expected a number > <minimum>, got <value>"`` for the
            first attribute that is not a finite real number (Python's or NumPy's; bools are refused)
            above the bound.
    """
    for name in names:
        value = getattr(obj, name)
        ok = isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_)) and math.isfinite(value)
        if not ok or (value <= minimum if strict else value < minimum):
            raise ValueError(f"{owner}.{name}: expected a number {'>' if strict else '>='} {minimum:g}, got {value!r}")
