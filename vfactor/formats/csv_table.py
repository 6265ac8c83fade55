"""CSV: one row per vehicle per frame, with a header (:data:`CSV_COLUMNS`).

Units: metres, radians, seconds. ``x y z`` is the box centre in the world
frame; ``yaw pitch roll`` are the box rotation's Z-Y-X angles
(``world_R_box = Rz(yaw) Ry(pitch) Rx(roll)``, so ``yaw`` is the box's
``heading``); ``length width height`` its size. The sigmas are the box's
standard deviations (``x_sigma`` ... along the world axes, ``yaw_sigma`` of
the heading), empty where not computed. A vehicle that was not solved has a
row with its ``status`` and ``message`` and empty numbers. Written with
Python's ``csv`` module (RFC 4180 quoting, ``\\r\\n`` line ends).
"""

from __future__ import annotations

import csv
import io
import math
import os

import gtsam
import numpy as np

from vfactor.errors import InputError
from vfactor.formats.common import (
    ReadBox,
    WriteReport,
    box_from_centre,
    check_output_path,
    check_results,
    solved_box,
    unsolved_of,
)
from vfactor.jsonio import write_text_atomic
from vfactor.observations import Scene
from vfactor.result import FrameResult

__all__ = ["CSV_COLUMNS", "csv_rows", "write_csv", "read_csv"]

#: The header, in order.
CSV_COLUMNS = ("frame", "t", "id", "status", "x", "y", "z", "yaw", "pitch", "roll", "length", "width", "height",
               "x_sigma", "y_sigma", "z_sigma", "yaw_sigma", "length_sigma", "width_sigma", "height_sigma",
               "body_type", "body_type_probability", "message")


def csv_rows(results: list[FrameResult]) -> list[dict[str, str]]:
    """The rows (column -> text) of :func:`write_csv`, in frame then vehicle order."""
    check_results(results, None, False, "CSV")
    rows = []
    for i, frame in enumerate(results):
        for v in frame.vehicles:
            row = dict.fromkeys(CSV_COLUMNS, "")
            row.update(frame=str(i), t=_text(frame.t), id=str(v.id), status=getattr(v.status, "value", str(v.status)),
                       message=str(v.message or ""))
            box = solved_box(v)
            if box is not None:
                T = np.asarray(box.world_T_box.matrix(), dtype=float)
                yaw, pitch, roll = gtsam.Rot3(T[:3, :3]).ypr()
                row.update(zip(("x", "y", "z"), map(_text, T[:3, 3])))
                row.update(yaw=_text(yaw), pitch=_text(pitch), roll=_text(roll))
                row.update(zip(("length", "width", "height"), map(_text, box.size)))
                if box.centre_sigma is not None:
                    row.update(zip(("x_sigma", "y_sigma", "z_sigma"), map(_text, box.centre_sigma)))
                if box.size_sigma is not None:
                    row.update(zip(("length_sigma", "width_sigma", "height_sigma"), map(_text, box.size_sigma)))
                row["yaw_sigma"] = _text(box.heading_sigma)
                if v.body_type is not None:
                    row["body_type"] = str(v.body_type)
                    row["body_type_probability"] = _text(v.body_type_probability)
            rows.append(row)
    return rows


def write_csv(path: str | os.PathLike, results: list[FrameResult], scene: Scene | None = None) -> WriteReport:
    """Writes the results as CSV, atomically (module docstring); ``scene`` is only checked to pair with them.

    Unsolved vehicles keep their row (status, message, empty numbers), so ``skipped`` is empty.

    Raises:
        InputError: results not a list of FrameResult, or not paired with ``scene``.
        OSError: the file cannot be written.
    """
    path = check_output_path(path, "CSV")
    check_results(results, scene, False, "CSV")
    buffer = io.StringIO(newline="")
    writer = csv.DictWriter(buffer, fieldnames=CSV_COLUMNS)
    writer.writeheader()
    writer.writerows(csv_rows(results))
    write_text_atomic(path, buffer.getvalue())
    return WriteReport("csv", [path], unsolved_of(results), [])


def read_csv(path: str | os.PathLike) -> list[ReadBox]:
    """Reads a CSV written by :func:`write_csv` back into boxes (with their sigmas).

    Raises:
        InputError: missing file, a header without the columns, or a number that is not one (names the row).
    """
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
            header = rows and list(rows[0])
    except OSError as exc:
        raise InputError(str(path), f"could not read the file: {exc}") from None
    if rows and set(CSV_COLUMNS) - set(header):
        raise InputError(str(path), f"missing columns {sorted(set(CSV_COLUMNS) - set(header))}")
    out = []
    for n, row in enumerate(rows):
        where = f"{path}: row {n + 1}"
        if None in row or any(row[k] is None for k in CSV_COLUMNS):  # more or fewer fields than the header's
            raise InputError(where, f"expected the header's {len(header)} fields, got another number")
        try:
            values = {k: float(row[k]) if row[k] != "" else None for k in CSV_COLUMNS[4:20]}
            frame = int(row["frame"])
            probability = float(row["body_type_probability"]) if row["body_type_probability"] else None
        except ValueError as exc:
            raise InputError(where, f"expected numbers: {exc}") from None
        box = None
        if values["x"] is not None:
            R = gtsam.Rot3.Ypr(values["yaw"], values["pitch"], values["roll"]).matrix()

            def triple(*names):
                got = [values[k] for k in names]
                return None if any(g is None for g in got) else np.array(got)

            heading_sigma = values["yaw_sigma"]
            box = box_from_centre(triple("x", "y", "z"), R, triple("length", "width", "height"), where,
                                  size_sigma=triple("length_sigma", "width_sigma", "height_sigma"),
                                  centre_sigma=triple("x_sigma", "y_sigma", "z_sigma"), heading_sigma=heading_sigma)
        out.append(ReadBox(frame=frame, id=row["id"], box=box, status=row["status"], label=row["body_type"] or None,
                           score=probability, extras={"t": float(row["t"]), "message": row["message"]}))
    return out


def _text(x) -> str:
    """A number as CSV text: ``repr`` of the float (exact round trip); empty for None or non-finite."""
    if x is None:
        return ""
    x = float(x)
    return repr(x) if math.isfinite(x) else ""
