"""``vfactor schema`` and ``vfactor plot``: the file formats' JSON Schemas, and pictures of a solved frame."""

from __future__ import annotations

__all__ = ["schema", "plot"]


def schema(args) -> int:
    raise NotImplementedError


def plot(args) -> int:
    raise NotImplementedError
