"""The road plane fitted to the traffic: a ground plane for a rig whose road nobody surveyed.

With fixed cameras the road under them is fixed too. Vehicles solved without a
plane put their wheel hubs on it, give or take their errors; a plane fitted to
many hub centres (robustly: a vehicle taken for the wrong type from one camera is
metres off along that camera's ray) is then a ground plane for every later
solve and track of the rig: the ground-plane factor holds each vehicle's
height and its roll and pitch to it (:mod:`vfactor.factors.ground_plane`).

Fit it to *tracks* (smoothed poses, :func:`vfactor.track.track_scene`), not to
one-frame solves: from the keypoint network's detections with two cameras of
little overlap, one-frame hubs gave planes 1.9-7.3 degrees off, smoothed ones
0.1-0.6 degrees (docs/results.md, "The road plane from the traffic"). The
command ``vfactor fit-ground`` tracks a scene and writes it back with the
fitted plane.

The plane ``n . x = offset`` is that of the hub centres (the mean of the four
hub keypoints, world frame), each moved down by its vehicle's wheel radius: the
mean of its body type's (``ShapePrior.hub_height`` of the default shape model,
as the ground-plane factor takes it: a hatchback's 0.32 m, a bus's 0.48 m), or
one ``hub_height`` for every vehicle where it is given. docs/factors.md gives the
maths.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from vfactor.errors import InputError
from vfactor.factors.ground_plane import GroundPlane
from vfactor.keypoints import LAYERS
from vfactor.result import FrameResult

__all__ = ["GroundFit", "fit_ground_plane", "MIN_GROUND_POINTS", "plane_heights", "plane_note", "PLANE_NOTE_HEIGHT",
           "PLANE_NOTE_TILT_DEG"]

#: At least this many solved vehicle poses (hub centres) make a plane.
MIN_GROUND_POINTS = 10
#: :func:`plane_note` speaks where the solved vehicles' hubs sit a median of more than this (metres) above or below
#: where a given road plane puts them ...
PLANE_NOTE_HEIGHT = 0.10
#: ... or where the plane fitted to them (:func:`fit_ground_plane`) is tilted more than this (degrees) against it.
PLANE_NOTE_TILT_DEG = 1.0
#: The hub centres must span at least this much (metres) in the plane's second direction: a plane is not fitted
#: to vehicles that all drove along one line.
MIN_SPREAD = 1.0
_HUBER = 1.5  # robust scales at which a hub centre starts to weigh less (Huber)
_ITERATIONS = 30


@dataclass(frozen=True)
class GroundFit:
    """A road plane fitted to hub centres.

    Attributes:
        plane: the road plane (world frame; hubs at ``hub_height`` above it).
        points: how many hub centres it was fitted to.
        inliers: how many of them lie within three robust scales of the hubs' plane.
        scale: robust scale (metres) of the hub centres' distances to their plane.
        tilt_deg: the plane's angle to the world's horizontal (degrees).
        hub_height: the hub height it was moved down by (metres): the vehicles' mean, weighted as the fit weighs
            them, where each vehicle's own was taken.
    """

    plane: GroundPlane
    points: int
    inliers: int
    scale: float
    tilt_deg: float
    hub_height: float


def _hub_centres(results: Iterable[FrameResult], hub_height: float | None) -> tuple[np.ndarray, np.ndarray]:
    """The hub centres (n, 3) of the solved vehicle poses and each one's wheel radius (n,), metres."""
    from vfactor.graph import DEFAULT_HUB_HEIGHT
    from vfactor.shape_model import default_shape_model

    hubs = list(LAYERS["wheel"])
    solved = [v for frame in results for v in frame.vehicles if v.ok and v.keypoints_world is not None]
    points = np.array([v.keypoints_world[hubs].mean(axis=0) for v in solved], dtype=float).reshape(-1, 3)
    if hub_height is not None:
        return points, np.full(len(solved), float(hub_height))
    types = default_shape_model().types
    own = {t: prior.hub_height for t, prior in types.items() if prior.hub_height is not None}
    return points, np.array([own.get(v.body_type, DEFAULT_HUB_HEIGHT) for v in solved], dtype=float)


def fit_ground_plane(results: Iterable[FrameResult], hub_height: float | None = None) -> GroundFit:
    """The road plane under the solved vehicles of ``results``.

    A plane through the hub centres of every solved vehicle pose (the
    converged and poor-fit ones), each moved down by its wheel radius, by
    iteratively reweighted total least squares with Huber weights at 1.5
    robust scales (the median absolute distance, made a sigma), its normal
    pointing up.

    Args:
        results: frames of results (``vfactor track`` or ``vfactor solve``; tracks are better: see the module).
        hub_height: height of the wheel hubs above the road, metres, for every vehicle; None (the default): each
            vehicle's body type's (``VehicleResult.body_type`` in the default shape model;
            :data:`vfactor.graph.DEFAULT_HUB_HEIGHT`, 0.34 m, for a vehicle without one).

    Raises:
        InputError: fewer than :data:`MIN_GROUND_POINTS` solved poses, hub centres that lie along one line (less
            than :data:`MIN_SPREAD` across it), or a plane whose upward normal is more than 45 degrees from the
            world's z (the world frame's z must point up: docs/conventions.md).
    """
    if hub_height is not None and not (np.isfinite(hub_height) and hub_height >= 0):
        raise InputError("hub_height", f"expected a non-negative number of metres, got {hub_height!r}")
    return _fitted(*_hub_centres(results, hub_height))


def _fitted(hubs: np.ndarray, radii: np.ndarray) -> GroundFit:
    """:func:`fit_ground_plane` of hub centres (n, 3) and their wheel radii (n,), metres."""
    normal = np.array([0.0, 0.0, 1.0])
    if len(hubs) < MIN_GROUND_POINTS:
        raise InputError("results", f"{len(hubs)} solved vehicle poses; a road plane needs at least "
                                    f"{MIN_GROUND_POINTS} (more frames, or tracks seen longer)")
    weights = np.ones(len(hubs))
    for _ in range(_ITERATIONS):
        points = hubs - radii[:, None] * normal  # each hub centre moved down to the road, along the plane's normal
        centre = weights @ points / weights.sum()
        _, singular, Vt = np.linalg.svd(np.sqrt(weights)[:, None] * (points - centre), full_matrices=False)
        normal = Vt[-1] if Vt[-1][2] >= 0 else -Vt[-1]
        distance = (points - centre) @ normal
        scale = max(1.4826 * float(np.median(np.abs(distance))), 1e-6)
        new = 1.0 / np.maximum(1.0, np.abs(distance) / (_HUBER * scale))
        if np.allclose(new, weights, atol=1e-6) and np.allclose(points, hubs - radii[:, None] * normal, atol=1e-9):
            break
        weights = new
    spread = singular[1] / np.sqrt(weights.sum())  # rms extent along the plane's second direction
    if spread < MIN_SPREAD:
        raise InputError("results", f"the vehicles' hub centres lie along one line ({spread:.2f} m across it): "
                                    "a road plane needs traffic that covers an area")
    tilt = float(np.degrees(np.arccos(np.clip(normal[2], -1.0, 1.0))))
    if tilt > 45.0:
        raise InputError("results", f"the hub centres' plane is {tilt:.0f} deg from horizontal: is the world "
                                    "frame's z up (docs/conventions.md)?")
    plane = GroundPlane(tuple(float(v) for v in normal), float(normal @ centre))
    inliers = int(np.sum(np.abs(distance) <= 3.0 * scale))
    return GroundFit(plane, len(points), inliers, scale, tilt, float(weights @ radii / weights.sum()))


def plane_heights(results: Iterable[FrameResult], plane: GroundPlane, hub_height: float | None = None) -> np.ndarray:
    """Each solved vehicle pose's hub centre above where ``plane`` puts it (metres, along the plane's normal; its
    hubs' height above the plane less its body type's wheel radius, as :func:`fit_ground_plane` takes it, or less
    ``hub_height`` for every vehicle where it is given): 0 for a vehicle standing on the plane."""
    return _heights(*_hub_centres(results, hub_height), plane)


def _heights(hubs: np.ndarray, radii: np.ndarray, plane: GroundPlane) -> np.ndarray:
    """:func:`plane_heights` of hub centres (n, 3) and their wheel radii (n,), metres."""
    return hubs @ np.asarray(plane.normal) - plane.offset - radii


def plane_note(results: Iterable[FrameResult], plane: GroundPlane, hub_height: float | None = None) -> str | None:
    """A line for the user where the vehicles solved on a given road plane do not stand on it: at least
    :data:`MIN_GROUND_POINTS` solved poses whose :func:`plane_heights` have a median beyond
    :data:`PLANE_NOTE_HEIGHT`, or whose own plane (:func:`fit_ground_plane`, where they cover an area) is tilted
    more than :data:`PLANE_NOTE_TILT_DEG` against it; None otherwise.

    The ground-plane factor holds each vehicle to the plane within its sigmas, so a plane given wrong pulls every
    vehicle towards it, and the keypoints pull back: on ``library_2cam`` seed 700 (paper-like noise) a plane 30 cm
    too high or too low left the hubs a median 16 cm from it and the translations 2.4-2.6 times worse, a plane 10 cm
    off 5 cm from it; a plane tilted 2.9 degrees left the hubs' own plane tilted 1.25-1.80 degrees against it on four
    scenes, one tilted 1.7 degrees 0.65-1.04, the true plane 0.02-0.39 (seven scenarios, solved and tracked; the
    median within 1.5 cm: docs/factors.md).
    """
    hubs, radii = _hub_centres(results, hub_height)  # once: the heights and the hubs' own plane
    heights = _heights(hubs, radii, plane)
    if len(heights) < MIN_GROUND_POINTS:
        return None
    median = float(np.median(heights))
    try:
        own = _fitted(hubs, radii).plane.normal
        tilt = float(np.degrees(np.arccos(np.clip(abs(np.dot(own, plane.normal)), 0.0, 1.0))))
    except InputError:  # the traffic along one line: no plane of its own
        tilt = 0.0
    if abs(median) <= PLANE_NOTE_HEIGHT and tilt <= PLANE_NOTE_TILT_DEG:
        return None
    side = "above" if median > 0 else "below"
    return (f"the vehicles' hubs sit a median {100 * abs(median):.0f} cm {side} where the scene's ground_plane puts "
            f"them, their own plane tilted {tilt:.1f} deg against it ({len(heights)} solved poses): is the plane "
            "right? A wrong plane pulls every vehicle towards it; vfactor fit-ground fits one to the traffic "
            "(docs/factors.md)")
