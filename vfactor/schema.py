"""JSON Schemas of vfactor's scene and result files (``vfactor schema`` prints them).

The schemas (draft 2020-12) live in ``vfactor/data/scene.schema.json`` and
``vfactor/data/result.schema.json`` and describe every field that
docs/scene-format.md explains. A file that vfactor's loaders accept always
validates; the loaders check more than a schema can say (a rotation is a
rotation, detections name existing cameras, keypoints_world agrees with the
pose, paths stay inside the scene's folder) and name the field of any
problem, so use :func:`vfactor.load_scene` to read a scene and a schema to
check files written by other tools, or in editors.
"""

from __future__ import annotations

import json
from functools import lru_cache
from importlib import resources

__all__ = ["SCHEMAS", "load_schema", "schema_text", "validate"]

#: Schema name -> the file in ``vfactor/data``.
SCHEMAS = {"scene": "scene.schema.json", "result": "result.schema.json"}


def schema_text(which: str = "scene") -> str:
    """The schema ``which`` (``"scene"`` or ``"result"``) as JSON text, as shipped.

    Raises:
        ValueError: an unknown schema name.
    """
    if which not in SCHEMAS:
        raise ValueError(f"which: expected one of {', '.join(SCHEMAS)}, got {which!r}")
    return resources.files("vfactor.data").joinpath(SCHEMAS[which]).read_text(encoding="utf-8")


@lru_cache(maxsize=None)
def _schema(which: str) -> dict:
    return json.loads(schema_text(which))


def load_schema(which: str = "scene") -> dict:
    """The schema ``which`` (``"scene"`` or ``"result"``) as a dictionary (a fresh copy)."""
    return json.loads(json.dumps(_schema(which)))


def validate(data, which: str = "scene") -> list[str]:
    """Checks parsed JSON against a schema with :mod:`jsonschema`; returns the problems, one line each.

    Each line names the field by its path in vfactor's style (``frames[0].detections[1].keypoints[3]``): where
    a field may take one of several forms (``oneOf``), the deepest part of the most relevant form that fails
    (:func:`jsonschema.exceptions.best_match`), and the value shown is cut to :data:`_SHOWN` characters.

    Returns:
        The problems (empty when the data validates), in the order of their paths.
    """
    import jsonschema
    from jsonschema.exceptions import best_match

    validator = jsonschema.Draft202012Validator(_schema(which))
    problems = []
    for error in sorted(validator.iter_errors(data), key=lambda e: [str(p) for p in e.absolute_path]):
        error = best_match([error])  # into a oneOf's context: the row or number at fault, not the whole list
        path = ""
        for part in error.absolute_path:
            path += f"[{part}]" if isinstance(part, int) else (f".{part}" if path else str(part))
        message = error.message if len(error.message) <= _SHOWN else error.message[:_SHOWN - 3] + "..."
        problems.append(f"{path or '(top level)'}: {message}")
    return problems


_SHOWN = 200  # characters of a problem's message (jsonschema writes the whole value into it)
