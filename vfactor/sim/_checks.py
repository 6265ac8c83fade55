"""Field checks for scenario files: each failure raises ScenarioError naming the field path."""

from __future__ import annotations

import math
from numbers import Real

import numpy as np

from vfactor.errors import ScenarioError

_MISSING = object()


def join(prefix: str, key: str | int) -> str:
    if isinstance(key, int):
        return f"{prefix}[{key}]"
    return f"{prefix}.{key}" if prefix else key


def check_mapping(value, field: str, allowed, required=()) -> dict:
    """A JSON object with only ``allowed`` keys and every ``required`` key."""
    if not isinstance(value, dict):
        raise ScenarioError(field, f"expected an object, got {type(value).__name__}")
    for key in value:
        if key not in allowed:
            raise ScenarioError(join(field, key), f"unknown key; allowed: {sorted(allowed)}")
    for key in required:
        if key not in value:
            raise ScenarioError(join(field, key), "missing")
    return value


def is_number(value) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool)


def number(value, field: str, lo=None, hi=None, lo_open=False, hi_open=False, integer=False):
    """A finite number (an int when ``integer``) within ``[lo, hi]`` (open ends where asked)."""
    if integer:
        if not isinstance(value, (int, np.integer)) or isinstance(value, bool):
            raise ScenarioError(field, f"expected an integer, got {value!r}")
        value = int(value)
    else:
        if not is_number(value):
            raise ScenarioError(field, f"expected a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ScenarioError(field, f"expected a finite number, got {value!r}")
    if lo is not None and (value < lo or (lo_open and value == lo)):
        raise ScenarioError(field, f"expected a value {'>' if lo_open else '>='} {lo}, got {value}")
    if hi is not None and (value > hi or (hi_open and value == hi)):
        raise ScenarioError(field, f"expected a value {'<' if hi_open else '<='} {hi}, got {value}")
    return value


def vector(value, field: str, size: int) -> np.ndarray:
    """A list of ``size`` finite numbers."""
    if not isinstance(value, (list, tuple)) or len(value) != size or not all(is_number(v) for v in value):
        raise ScenarioError(field, f"expected a list of {size} numbers, got {value!r}")
    out = np.array(value, dtype=float)
    if not np.all(np.isfinite(out)):
        raise ScenarioError(field, f"expected finite numbers, got {value!r}")
    return out


def interval(value, field: str, lo=None, hi=None, allow_empty=True) -> tuple[float, float]:
    """``[min, max]`` with ``min <= max`` (``min < max`` unless ``allow_empty``), within ``[lo, hi]``."""
    a, b = vector(value, field, 2)
    if b < a or (not allow_empty and b == a):
        relation = "<=" if allow_empty else "<"
        raise ScenarioError(field, f"expected [min, max] with min {relation} max, got {list(value)}")
    if (lo is not None and a < lo) or (hi is not None and b > hi):
        raise ScenarioError(field, f"expected values within [{lo}, {hi}], got {list(value)}")
    return float(a), float(b)


def string(value, field: str, choices=None) -> str:
    if not isinstance(value, str) or not value:
        raise ScenarioError(field, f"expected a non-empty string, got {value!r}")
    if choices is not None and value not in choices:
        raise ScenarioError(field, f"expected one of {sorted(choices)}, got {value!r}")
    return value


def matrix(value, field: str, shape: tuple[int, int]) -> np.ndarray:
    rows, cols = shape
    if not isinstance(value, (list, tuple)) or len(value) != rows:
        raise ScenarioError(field, f"expected a {rows}x{cols} matrix (a list of {rows} rows), got {value!r}")
    return np.array([vector(row, join(field, i), cols) for i, row in enumerate(value)])
