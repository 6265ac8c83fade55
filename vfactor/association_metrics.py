"""How well detections were associated: cross-camera pairs, and CLEAR-MOT / IDF1 on the vehicles' positions.

Two views of one association (docs/association.md, "Measuring association"):

- :func:`cross_camera_pairs` scores the grouping of each frame's detections
  into vehicles, over pairs of detections from different cameras: a predicted
  pair is two detections given the same vehicle, a true pair two detections of
  the same true vehicle; precision and recall of the predicted pairs, pooled
  over the frames.
- :func:`clear_mot` scores the vehicles over time, on their world positions
  (x, y of ``world_T_vehicle``, metres): CLEAR-MOT (MOTA, MOTP, ID switches,
  fragmentations; Bernardin and Stiefelhagen 2008) and IDF1 (Ristani et al.
  2016), computed by py-motmetrics (the ``test`` extra) with a distance gate.

Inputs are plain lists and dicts, so that any association can be scored;
:func:`assigned_ids_from_results`, :func:`positions_from_results` and
:func:`truth_positions` read them off :class:`vfactor.result.FrameResult`
lists (whose vehicles name the detections they used in
``extras["detections"]``) and off a simulation's truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import combinations

import numpy as np

__all__ = ["PairScores", "MOT_METRICS", "DEFAULT_MAX_DISTANCE", "cross_camera_pairs", "clear_mot",
           "truth_positions", "positions_from_results", "assigned_ids_from_results", "association_table"]

#: Distance gate of :func:`clear_mot`, metres: about half a car's length, well under the 3.5 m between lanes.
DEFAULT_MAX_DISTANCE = 2.0

#: The figures :func:`clear_mot` returns (py-motmetrics' names) and what each is.
MOT_METRICS: dict[str, str] = {
    "num_frames": "frames",
    "num_objects": "true vehicle-frames (GT)",
    "num_predictions": "estimated vehicle-frames",
    "num_matches": "matched true-estimated pairs that are not ID switches, summed over the frames (matched pairs "
                   "in all: num_matches + num_switches)",
    "num_misses": "true vehicle-frames left unmatched (FN)",
    "num_false_positives": "estimated vehicle-frames left unmatched (FP)",
    "num_switches": "ID switches: a true vehicle matched to another estimated id than at its last match",
    "num_fragmentations": "times a true vehicle's matched run is interrupted (matched, then unmatched)",
    "mota": "1 - (FN + FP + ID switches) / GT",
    "motp": "mean distance of the matched pairs, metres (lower is better)",
    "idf1": "2 IDTP / (2 IDTP + IDFP + IDFN) under the best one-to-one map of true to estimated ids",
    "idp": "IDTP / (IDTP + IDFP)",
    "idr": "IDTP / (IDTP + IDFN)",
    "mostly_tracked": "true vehicles matched in at least 80 % of their frames",
    "mostly_lost": "true vehicles matched in at most 20 % of their frames",
}


@dataclass(frozen=True)
class PairScores:
    """Cross-camera pair scores of an association (:func:`cross_camera_pairs`).

    Attributes:
        precision: correct / predicted pairs (NaN when nothing was paired).
        recall: correct / true pairs (NaN when there is no true pair).
        predicted: pairs of detections from different cameras given the same vehicle, over all frames.
        true: pairs of detections from different cameras of the same true vehicle.
        correct: pairs that are both.
        same_camera: pairs of detections of one camera given the same vehicle (a vehicle is seen at
            most once per camera and frame: each is a wrong merge; not in ``predicted``).
        false_detections: detections of no true vehicle (truth id None).
        false_attached: false detections given a vehicle.
        real_unassigned: detections of a true vehicle given none.
    """

    precision: float
    recall: float
    predicted: int
    true: int
    correct: int
    same_camera: int
    false_detections: int
    false_attached: int
    real_unassigned: int


def _ratio(a: int, b: int) -> float:
    return a / b if b else math.nan


def cross_camera_pairs(truth_ids, assigned_ids, cameras) -> PairScores:
    """Precision and recall of the cross-camera pairs of an association, pooled over the frames.

    In each frame, over the pairs of detections from different cameras: a
    predicted pair is two detections given the same (not None) vehicle id, a
    true pair two detections of the same true vehicle (a false detection, truth
    id None, is in no true pair). The assigned ids need not be the true ones:
    only which detections share an id counts, within each frame.

    Args:
        truth_ids: per frame, per detection: the true vehicle id, or None for a false detection
            (:attr:`vfactor.sim.anonymise.AnonymousScene.truth_ids`).
        assigned_ids: per frame, per detection (same order): the vehicle id the association gave it,
            or None (left unassigned, e.g. rejected as false).
        cameras: per frame, per detection: its camera name.

    Returns:
        :class:`PairScores`.

    Raises:
        ValueError: the lists differ in length (frames or detections).
    """
    truth_ids, assigned_ids, cameras = list(truth_ids), list(assigned_ids), list(cameras)
    if not len(truth_ids) == len(assigned_ids) == len(cameras):
        raise ValueError(f"expected as many frames of truth ids ({len(truth_ids)}), assigned ids "
                         f"({len(assigned_ids)}) and cameras ({len(cameras)})")
    predicted = true = correct = same_camera = false_detections = false_attached = real_unassigned = 0
    for f, (truth, assigned, cams) in enumerate(zip(truth_ids, assigned_ids, cameras)):
        truth, assigned, cams = list(truth), list(assigned), list(cams)
        if not len(truth) == len(assigned) == len(cams):
            raise ValueError(f"frame {f}: expected one truth id, assigned id and camera per detection, got "
                             f"{len(truth)}, {len(assigned)} and {len(cams)}")
        for t, a in zip(truth, assigned):
            false_detections += t is None
            false_attached += t is None and a is not None
            real_unassigned += t is not None and a is None
        for i, j in combinations(range(len(truth)), 2):
            paired = assigned[i] is not None and assigned[i] == assigned[j]
            if cams[i] == cams[j]:
                same_camera += paired
                continue
            is_true = truth[i] is not None and truth[i] == truth[j]
            predicted += paired
            true += is_true
            correct += paired and is_true
    return PairScores(_ratio(correct, predicted), _ratio(correct, true), predicted, true, correct, same_camera,
                      false_detections, false_attached, real_unassigned)


def _xy(value) -> np.ndarray | None:
    """World (x, y) of a position, a pose or None."""
    if value is None:
        return None
    if hasattr(value, "translation"):  # gtsam.Pose3
        value = value.translation()
    p = np.asarray(value, dtype=float).reshape(-1)
    if p.shape[0] < 2 or not np.all(np.isfinite(p[:2])):
        raise ValueError(f"expected a world position (x, y[, z]) in metres, got {value!r}")
    return p[:2]


def clear_mot(truth, estimates, max_distance: float = DEFAULT_MAX_DISTANCE) -> dict[str, float]:
    """CLEAR-MOT and IDF1 of estimated vehicles against the true ones, on world positions.

    In each frame the true vehicles are matched one-to-one to the estimated
    ones (py-motmetrics: a true vehicle keeps its estimate of the previous frame
    while still within the gate, the others by least total distance, Hungarian);
    a true and an estimated vehicle more than ``max_distance`` apart (on the
    road plane) can never match. IDF1 matches whole trajectories under the
    same gate. See :data:`MOT_METRICS` for the figures.

    Args:
        truth: per frame, true vehicle id -> world position (x, y or x, y, z, metres; or a
            ``gtsam.Pose3``, whose translation is taken). :func:`truth_positions` makes it from a
            simulation's truth.
        estimates: per frame (as many as ``truth``), estimated vehicle id -> world position as
            above, or None (an unsolved vehicle: not an estimate). The ids need not be the true
            ones; :func:`positions_from_results` makes it from frame results.
        max_distance: distance gate on the road plane, metres (> 0).

    Returns:
        metric name (:data:`MOT_METRICS`) -> value; counts as floats.

    Raises:
        ValueError: frames differ in number, a bad position or gate.
        ImportError: py-motmetrics is not installed (``pip install motmetrics``, in the ``test`` extra).
    """
    truth, estimates = list(truth), list(estimates)
    if len(truth) != len(estimates):
        raise ValueError(f"expected as many frames of estimates ({len(estimates)}) as of truth ({len(truth)})")
    if not (max_distance > 0 and math.isfinite(max_distance)):
        raise ValueError(f"max_distance: expected a positive number of metres, got {max_distance}")
    try:
        import motmetrics
    except ImportError as exc:
        raise ImportError("clear_mot needs py-motmetrics: pip install motmetrics (the 'test' extra)") from exc

    # py-motmetrics with pandas >= 3 wants numeric ids: number them, truth and estimates apart.
    truth_index: dict[str, int] = {}
    estimate_index: dict[str, int] = {}
    acc = motmetrics.MOTAccumulator(auto_id=True)
    for f, (true_f, est_f) in enumerate(zip(truth, estimates)):
        true_xy = {vid: _xy(p) for vid, p in dict(true_f).items()}
        est_xy = {vid: xy for vid, p in dict(est_f).items() if (xy := _xy(p)) is not None}
        t_ids, e_ids = list(true_xy), list(est_xy)
        distances = np.full((len(t_ids), len(e_ids)), np.nan)
        for i, t in enumerate(t_ids):
            for j, e in enumerate(e_ids):
                d = float(np.linalg.norm(true_xy[t] - est_xy[e]))
                if d <= max_distance:
                    distances[i, j] = d
        acc.update([truth_index.setdefault(t, len(truth_index)) for t in t_ids],
                   [estimate_index.setdefault(e, len(estimate_index)) for e in e_ids], distances)
    host = motmetrics.metrics.create()
    summary = host.compute(acc, metrics=list(MOT_METRICS), name="association")
    out = {name: float(summary[name].iloc[0]) for name in MOT_METRICS}
    if out["num_matches"] == 0:
        out["motp"] = math.nan
    return out


def truth_positions(truth) -> list[dict[str, np.ndarray]]:
    """Per frame, vehicle id -> world (x, y), metres, of a simulation's truth (``Simulation.truth``)."""
    return [{vid: _xy(v.world_T_vehicle) for vid, v in frame.items()} for frame in truth]


def positions_from_results(results) -> list[dict[str, np.ndarray | None]]:
    """Per frame, vehicle id -> world (x, y), metres, or None where unsolved, of :class:`vfactor.result.FrameResult` lists."""
    return [{v.id: _xy(v.world_T_vehicle) for v in frame.vehicles} for frame in results]


def assigned_ids_from_results(results, num_detections) -> list[list[str | None]]:
    """Per frame, per detection, the id of the vehicle that used it (None: no vehicle did).

    Args:
        results: :class:`vfactor.result.FrameResult` per frame; each vehicle's ``extras["detections"]``
            lists the indices (into its frame's detections) of the detections it used (none: no entry).
        num_detections: per frame, the number of detections (``len(frame.detections)``).

    Raises:
        ValueError: frames differ in number, an index out of range, or a detection used by two vehicles.
    """
    results, num_detections = list(results), list(num_detections)
    if len(results) != len(num_detections):
        raise ValueError(f"expected as many frame results ({len(results)}) as frames ({len(num_detections)})")
    out = []
    for f, (frame, n) in enumerate(zip(results, num_detections)):
        ids: list[str | None] = [None] * int(n)
        for vehicle in frame.vehicles:
            for j in vehicle.extras.get("detections", ()):
                j = int(j)
                if not 0 <= j < n:
                    raise ValueError(f"frame {f}: vehicle {vehicle.id} uses detection {j} of {n}")
                if ids[j] is not None:
                    raise ValueError(f"frame {f}: detection {j} is used by vehicles {ids[j]} and {vehicle.id}")
                ids[j] = vehicle.id
        out.append(ids)
    return out


def _cell(value, count: bool = False) -> str:
    """A table cell: ``-`` for a missing or NaN value, a count as an integer, a ratio with three decimals."""
    if value is None or math.isnan(value):
        return "-"
    return str(int(value)) if count else f"{value:.3f}"


def association_table(rows: dict[str, dict]) -> str:
    """A Markdown table of association scores, one row per method or setting.

    Args:
        rows: name -> ``{"pairs": PairScores, "mot": clear_mot(...)}``; either key may be left
            out (its cells are ``-``).
    """
    lines = [
        "| method | pair precision | pair recall | same-camera merges | false attached | MOTA | MOTP (m) | IDF1 | "
        "ID switches | false positives | misses | fragmentations |",
        "| --- " * 12 + "|",
    ]
    for name, row in rows.items():
        pairs, mot = row.get("pairs"), row.get("mot") or {}
        cells = [name]
        if pairs is None:
            cells += ["-"] * 4
        else:
            attached = f"{pairs.false_attached} / {pairs.false_detections}"
            cells += [_cell(pairs.precision), _cell(pairs.recall), str(pairs.same_camera), attached]
        cells += [_cell(mot.get(k)) for k in ("mota", "motp", "idf1")]
        cells += [_cell(mot.get(k), count=True) for k in ("num_switches", "num_false_positives", "num_misses",
                                                          "num_fragmentations")]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
