"""``vfactor eval association``: the association on simulated scenes without ids, beside the true ids.

For each scenario and seed: the simulation is anonymised
(:func:`vfactor.sim.anonymise`: no vehicle ids, per-camera track ids with
switches, missed and false detections), associated
(:func:`vfactor.association.associate_scene`) and tracked
(:func:`vfactor.track.track_scene`); beside it, the same detections with the
true ids (false detections left out, as no true vehicle owns them) are
tracked too. Reported: the cross-camera pairs' precision and recall, CLEAR-MOT
and IDF1 on the tracked positions (:mod:`vfactor.association_metrics`), and
the pose errors of the tracked vehicles matched to the truth, for both.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from vfactor.association import AssociationOptions, associate_scene
from vfactor.association_metrics import (assigned_ids_from_results, clear_mot, cross_camera_pairs,
                                         positions_from_results, truth_positions)
from vfactor.metrics import pose_errors
from vfactor.observations import Frame
from vfactor.track import TrackOptions, track_scene

__all__ = ["AssociationRun", "DEFAULT_NOISE", "evaluate_association", "association_report", "body_type_report"]

#: The anonymiser's settings of the evaluation: a switch of two camera track ids in 2 % of a camera's frames,
#: 5 % of the detections missed, 0.3 false detections per camera and frame.
DEFAULT_NOISE = {"track_switch_rate": 0.02, "miss_rate": 0.05, "false_rate": 0.3}


@dataclass
class AssociationRun:
    """One scenario and seed of :func:`evaluate_association`."""

    scenario: str  # with the noise level in brackets where one replaced the scenario's
    seed: int
    cameras: int
    frames: int
    detections: int
    false_detections: int
    pairs: object  # PairScores
    mot: dict
    mot_true_ids: dict
    errors: dict  # rotation_deg, translation_cm: means over matched vehicles
    errors_true_ids: dict
    seconds_per_frame: float


def _with_true_ids(scene, truth_ids):
    frames = [Frame(f.t, [dataclasses.replace(d, vehicle=vid) for d, vid in zip(f.detections, ids) if vid is not None],
                    f.images) for f, ids in zip(scene.frames, truth_ids)]
    return dataclasses.replace(scene, frames=frames)


def _matched_errors(results, truth, max_distance: float) -> dict:
    """Pose errors of the tracked vehicles within ``max_distance`` (m, x-y) of a true vehicle (the nearest):
    their means, and per body type of the true vehicle (``"by_body_type"``: type -> lists of errors)."""
    from vfactor.evaluation import body_type_of

    by_type: dict[str, dict[str, list[float]]] = {}
    for frame, true in zip(results, truth):
        for v in frame.vehicles:
            if not v.ok or not true:
                continue
            p = v.world_T_vehicle.translation()[:2]
            _, t = min(true.items(), key=lambda item: np.linalg.norm(item[1].world_T_vehicle.translation()[:2] - p))
            if np.linalg.norm(t.world_T_vehicle.translation()[:2] - p) <= max_distance:
                e = pose_errors(v.world_T_vehicle, v.keypoints_world, t.world_T_vehicle, t.keypoints_world)
                errors = by_type.setdefault(body_type_of(t.preset), {"rotation_deg": [], "translation_cm": []})
                errors["rotation_deg"].append(e["rotation_deg"])
                errors["translation_cm"].append(e["translation_cm"])
    every = {key: [x for errors in by_type.values() for x in errors[key]] for key in ("rotation_deg", "translation_cm")}
    return {key: float(np.mean(every[key])) if every[key] else float("nan") for key in every} | {
        "count": len(every["rotation_deg"]), "by_body_type": by_type}


def evaluate_association(scenario: str, seeds, num_frames: int | None = None, noise: dict | None = None,
                         options: AssociationOptions = AssociationOptions(), max_distance: float = 2.0,
                         progress=None, engine=None, level: str | None = None) -> list[AssociationRun]:
    """Runs the experiment of the module docstring on ``scenario`` for each seed (the simulation's and the
    anonymiser's).

    Args:
        noise: the anonymiser's settings (default :data:`DEFAULT_NOISE`).
        level: a keypoint noise level of :data:`vfactor.evaluation.NOISE_LEVELS` in place of the scenario's own
            (default: the scenario's, the paper's noise for the association scenarios).
        progress: called as ``progress(done, total)`` with the seeds done.
        engine: where the seeds run (:mod:`vfactor.parallel`; default: in this process); the figures do not
            depend on it, but for the association's time per frame.
    """
    from vfactor.parallel import InProcess

    from vfactor.evaluation import NOISE_LEVELS

    if level is not None and level not in NOISE_LEVELS:
        raise ValueError(f"noise level: expected one of {list(NOISE_LEVELS)}, got {level!r}")
    units = [(scenario, seed, num_frames, noise, options, max_distance, level) for seed in seeds]
    return list((engine or InProcess()).map(_association_unit, units, progress=progress))


def _association_unit(unit: tuple) -> AssociationRun:
    """One seed of :func:`evaluate_association`."""
    from vfactor.evaluation import NOISE_LEVELS, noise_variant
    from vfactor.sim import anonymise, load_scenario, simulate

    scenario, seed, num_frames, noise, options, max_distance, level = unit
    variant = load_scenario(scenario)
    if level is not None:
        variant = noise_variant(variant, **NOISE_LEVELS[level])
    sim = simulate(variant, seed=seed, num_frames=num_frames)
    anon = anonymise(sim, seed=seed, **(DEFAULT_NOISE if noise is None else noise))
    t0 = time.perf_counter()
    found = associate_scene(anon.scene, options)
    seconds = (time.perf_counter() - t0) / max(len(anon.scene.frames), 1)
    cameras = [[d.camera for d in f.detections] for f in anon.scene.frames]
    tracked = track_scene(found.scene, TrackOptions(covariance=False)).frames
    found.restore_indices(tracked)
    pairs = cross_camera_pairs(anon.truth_ids, assigned_ids_from_results(tracked, [len(c) for c in cameras]),
                               cameras)
    with_ids = track_scene(_with_true_ids(anon.scene, anon.truth_ids), TrackOptions(covariance=False)).frames
    truth = truth_positions(sim.truth)
    return AssociationRun(
        scenario if level is None else f"{scenario} ({level})", seed, len(sim.scene.cameras), len(anon.scene.frames), sum(len(c) for c in cameras),
        sum(v is None for ids in anon.truth_ids for v in ids), pairs,
        clear_mot(truth, positions_from_results(tracked), max_distance),
        clear_mot(truth, positions_from_results(with_ids), max_distance),
        _matched_errors(tracked, sim.truth, max_distance), _matched_errors(with_ids, sim.truth, max_distance),
        seconds)


def body_type_report(runs: list[AssociationRun]) -> str:
    """A Markdown table of the pose errors per body type and camera count, pooled over the runs, beside the true
    ids."""
    pooled: dict[tuple[str, int], dict] = {}
    for r in runs:
        for source, errors in (("associated", r.errors), ("true ids", r.errors_true_ids)):
            for body_type, e in errors["by_body_type"].items():
                entry = pooled.setdefault((body_type, r.cameras), {}).setdefault(source, {"rotation_deg": [],
                                                                                        "translation_cm": []})
                for key in entry:
                    entry[key] += e[key]
    lines = ["| body type | cameras | vehicle-frames | rotation (deg) | translation (cm) | rotation, true ids | "
             "translation, true ids | translation ratio |", "|" + " --- |" * 8]
    for (body_type, cameras), entry in sorted(pooled.items()):
        a, b = entry.get("associated"), entry.get("true ids")
        if not a or not b:
            continue
        ta, tb = np.mean(a["translation_cm"]), np.mean(b["translation_cm"])
        lines.append(f"| {body_type} | {cameras} | {len(a['rotation_deg'])} | {np.mean(a['rotation_deg']):.2f} | "
                     f"{ta:.1f} | {np.mean(b['rotation_deg']):.2f} | {tb:.1f} | {ta / tb:.2f}x |")
    return "\n".join(lines)


def association_report(runs: list[AssociationRun]) -> str:
    """A Markdown table per run: association, tracking and pose errors, beside the true ids."""
    head = ("| scenario | seed | frames | detections (false) | pair precision | pair recall | false attached | "
            "MOTA | IDF1 | ID switches | MOTA, true ids | IDF1, true ids | ID sw., true ids | rotation (deg) | "
            "translation (cm) | rotation, true ids | translation, true ids | association (s/frame) |")
    lines = [head, "|" + " --- |" * (head.count("|") - 1)]
    for r in runs:
        m, t, e, et = r.mot, r.mot_true_ids, r.errors, r.errors_true_ids
        lines.append(
            f"| {r.scenario} | {r.seed} | {r.frames} | {r.detections} ({r.false_detections}) | "
            f"{r.pairs.precision:.3f} | {r.pairs.recall:.3f} | {r.pairs.false_attached} | {m['mota']:.3f} | "
            f"{m['idf1']:.3f} | {m['num_switches']} | {t['mota']:.3f} | {t['idf1']:.3f} | {t['num_switches']} | "
            f"{e['rotation_deg']:.2f} | {e['translation_cm']:.1f} | {et['rotation_deg']:.2f} | "
            f"{et['translation_cm']:.1f} | {r.seconds_per_frame:.2f} |")
    return "\n".join(lines)
