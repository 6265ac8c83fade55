"""Left/right label swaps: a camera's keypoints whose labels the solution says are swapped, relabelled.

Keypoint detectors confuse a vehicle's left and right side: a camera's
detection may give the left front wheel's pixel as the right front wheel's and
the other way round. To the robust loss a swapped pair is two outliers, so
the keypoints' information is lost, and where the shape is free (every
keypoint is a variable) the solve may bend the shape or turn the pose to
half-explain them. :func:`relabel_swaps` asks the solution instead: for each
camera and each left/right pair it compares the robust cost of the labels as
given with the cost of the pair swapped (for a pair of which the camera saw
one keypoint, that keypoint under its partner's label) and swaps where the
swapped labels cost at least :data:`SWAP_MARGIN` less. The margin is a log
prior odds against a swap: a pair is swapped only when the pixels say so
clearly, never where both labels fit alike (a camera looking along the
vehicle's axis sees left and right keypoints near each other).

The one-frame solve (:func:`vfactor.solve.solve_observations`) relabels after
its first solution and solves again from there; where the refined solution
still fits its keypoints worse than their sigmas say, it searches further:
each pair with a down-weighted keypoint (:func:`suspect_pairs`) is swapped in
turn and solved again, and the swap that lowers the cost most, by at least the
margin, is kept (a first solution bent around several swapped pairs judges
each of them wrongly; re-solved, the right swap shows); the tracker relabels each frame
at its motion prediction with the track's shape; the known-shape reference does
the same as the solve, so that it stays a bound for the same data
(docs/factors.md, "Left/right label swaps"). The camera-disagreement check
judges each camera with its labels as given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gtsam
import numpy as np

from vfactor.errors import SceneError
from vfactor.factors.projection import KeypointObservations, whitened_residuals
from vfactor.factors.robust import RobustLoss
from vfactor.keypoints import LEFT_RIGHT_PAIRS, MIRROR_PERMUTATION, TURN_PERMUTATION

__all__ = ["SWAP_MARGIN", "SwapFinding", "relabel_swaps", "apply_swaps", "suspect_pairs", "swapped_rows",
           "merge_findings", "TURN_COST_RATIO", "TURN_MIN_KEYPOINTS", "turned_cameras", "turn_cameras"]

#: A pair is swapped when its swapped labels' robust cost is at least this much lower (the units of the cost,
#: ``rho`` of the whitened residuals: a negative log-likelihood), about the log odds of a 5 % swap rate.
SWAP_MARGIN = 3.0

_PAIR_OF = np.empty(12, dtype=int)  # keypoint index -> the index of its pair in LEFT_RIGHT_PAIRS
for _p, _pair in enumerate(LEFT_RIGHT_PAIRS):
    _PAIR_OF[list(_pair)] = _p


@dataclass(frozen=True)
class SwapFinding:
    """One camera's left/right pair whose labels were swapped.

    Attributes:
        camera: the camera's name.
        pair: the pair's (left, right) keypoint indices (``vfactor.keypoints.LEFT_RIGHT_PAIRS``).
        seen: how many of the two the camera saw (2: both labels exchanged; 1: the one keypoint took its partner's label).
        gain: how much lower the robust cost is with the labels swapped (>= :data:`SWAP_MARGIN`): at the solution,
            or, for a swap found by solving for it (:func:`suspect_pairs`), after solving.
    """

    camera: str
    pair: tuple[int, int]
    seen: int
    gain: float

    def to_dict(self) -> dict:
        """The finding as the result file gives it (docs/scene-format.md, ``swapped_keypoints``)."""
        return {"camera": self.camera, "pair": [int(k) for k in self.pair], "seen": int(self.seen),
                "gain": float(self.gain)}

    @classmethod
    def from_dict(cls, data, path: str) -> "SwapFinding":
        """Reads :meth:`to_dict`'s form.

        Raises:
            SceneError: a field is missing or wrong (named by its path under ``path``).
        """
        if not isinstance(data, dict) or set(data) - {"camera", "pair", "seen", "gain"}:
            raise SceneError(path, "expected an object with camera, pair, seen and gain")
        for name in ("camera", "pair", "seen", "gain"):
            if name not in data:
                raise SceneError(f"{path}.{name}", "missing")
        if not isinstance(data["camera"], str) or not data["camera"]:
            raise SceneError(f"{path}.camera", f"expected a camera name, got {data['camera']!r}")
        pair = data["pair"]
        if not isinstance(pair, list) or tuple(pair) not in LEFT_RIGHT_PAIRS:
            raise SceneError(f"{path}.pair", f"expected one of the left/right pairs {[list(p) for p in LEFT_RIGHT_PAIRS]}, "
                                             f"got {pair!r}")
        if data["seen"] not in (1, 2) or isinstance(data["seen"], bool):
            raise SceneError(f"{path}.seen", f"expected 1 or 2, got {data['seen']!r}")
        gain = data["gain"]
        if isinstance(gain, bool) or not isinstance(gain, (int, float)) or not math.isfinite(gain):
            raise SceneError(f"{path}.gain", f"expected a finite number, got {gain!r}")
        return cls(data["camera"], (int(pair[0]), int(pair[1])), int(data["seen"]), float(gain))


def relabel_swaps(obs: KeypointObservations, world_T_vehicle: gtsam.Pose3, vehicle_p_keypoints: np.ndarray,
                  loss: RobustLoss, margin: float = SWAP_MARGIN) -> tuple[KeypointObservations, list[SwapFinding]]:
    """The observations with the labels that ``world_T_vehicle`` and the shape say are swapped exchanged.

    Args:
        obs: one vehicle's observations (their sigmas as the solve weighs them).
        world_T_vehicle: the solution's pose (vehicle -> world).
        vehicle_p_keypoints: (12, 3) the solution's body-frame keypoints, metres.
        loss: the solve's robust loss; the costs compared are ``sum rho(|e|)``.
        margin: the least gain in cost for a swap.

    Returns:
        (observations, findings): ``obs`` itself when no pair is swapped, else a
        copy with those rows' keypoint indices exchanged (every pixel, sigma and
        window kept with its row); a finding per swapped pair, by camera and pair.
    """
    if len(obs) == 0:
        return obs, []
    mirrored, as_given, as_swapped = _relabelled_costs(obs, MIRROR_PERMUTATION, world_T_vehicle, vehicle_p_keypoints,
                                                       loss)
    swap = np.zeros(len(obs), dtype=bool)
    findings = []
    for rows in _pairs(obs):
        gain = float(as_given[rows].sum() - as_swapped[rows].sum())
        if gain >= margin:
            swap |= rows
            findings.append(_finding(obs, rows, gain))
    if not findings:
        return obs, []
    return obs.relabelled(np.where(swap, mirrored.keypoint_index, obs.keypoint_index)), findings


def _relabelled_costs(obs: KeypointObservations, permutation: np.ndarray, world_T_vehicle: gtsam.Pose3,
                      vehicle_p_keypoints: np.ndarray, loss: RobustLoss) -> tuple[KeypointObservations, np.ndarray,
                                                                                  np.ndarray]:
    """(every observation relabelled by ``permutation``, each observation's robust cost ``rho(|e|)`` as labelled,
    and relabelled) at the pose and shape."""
    relabelled = obs.relabelled(permutation[obs.keypoint_index])
    costs = [loss.rho(np.linalg.norm(whitened_residuals(o, world_T_vehicle, vehicle_p_keypoints), axis=1))
             for o in (obs, relabelled)]
    return relabelled, costs[0], costs[1]


def apply_swaps(obs: KeypointObservations, findings: list[SwapFinding]) -> KeypointObservations:
    """The observations with the labels of each finding's camera and pair exchanged (as :func:`relabel_swaps` did).

    For observations of the same detections that the findings were made on, e.g. at other sigmas.
    """
    if not findings:
        return obs
    names = [camera.name for camera in obs.cameras]
    swap = np.zeros(len(obs), dtype=bool)
    for finding in findings:
        swap |= (obs.camera_index == names.index(finding.camera)) & np.isin(obs.keypoint_index, finding.pair)
    return obs.relabelled(np.where(swap, MIRROR_PERMUTATION[obs.keypoint_index], obs.keypoint_index))


def suspect_pairs(obs: KeypointObservations, world_T_vehicle: gtsam.Pose3, vehicle_p_keypoints: np.ndarray,
                  loss: RobustLoss, weight: float = 0.5) -> list[np.ndarray]:
    """Each camera's left/right pair of which a keypoint is down-weighted by the solution: the swaps worth solving for.

    Args:
        obs, world_T_vehicle, vehicle_p_keypoints, loss: as for :func:`relabel_swaps`.
        weight: a keypoint whose robust-loss weight is below this is down-weighted (0.5: its whitened residual beyond
            the loss's threshold).

    Returns:
        one boolean row mask of ``obs`` per suspect (camera, pair), in camera then pair order; a pair whose camera gave
        one label twice is left out (no one-to-one swap).
    """
    if len(obs) == 0:
        return []
    weights = loss.weight(np.linalg.norm(whitened_residuals(obs, world_T_vehicle, vehicle_p_keypoints), axis=1))
    return [rows for rows in _pairs(obs) if (weights[rows] < weight).any()]


def swapped_rows(obs: KeypointObservations, rows: np.ndarray) -> tuple[KeypointObservations, SwapFinding]:
    """The observations with the labels of ``rows`` (one camera's pair, :func:`suspect_pairs`) exchanged, and the
    finding that says so (its ``gain`` 0 until the caller measures it)."""
    finding = _finding(obs, rows, 0.0)
    return apply_swaps(obs, [finding]), finding


def _pairs(obs: KeypointObservations):
    """Each (camera, left/right pair) the observations hold, as a boolean row mask, in camera then pair order; a
    pair whose camera gave one label twice (two detections of it) is left out: no one-to-one swap to judge."""
    groups = obs.camera_index * len(LEFT_RIGHT_PAIRS) + _PAIR_OF[obs.keypoint_index]
    for group in np.unique(groups):
        rows = groups == group
        if len(np.unique(obs.keypoint_index[rows])) == rows.sum():
            yield rows


def _finding(obs: KeypointObservations, rows: np.ndarray, gain: float) -> SwapFinding:
    """The finding that ``rows`` (one camera's pair, :func:`_pairs`) are swapped."""
    camera = int(obs.camera_index[rows][0])
    return SwapFinding(obs.cameras[camera].name, LEFT_RIGHT_PAIRS[int(_PAIR_OF[obs.keypoint_index[rows][0]])],
                       int(rows.sum()), gain)


def merge_findings(first: list[SwapFinding], then: list[SwapFinding]) -> list[SwapFinding]:
    """The swaps of ``first`` followed by those of ``then`` (made on the relabelled observations): a pair swapped
    twice is back as given and drops out."""
    merged = {(f.camera, f.pair): f for f in first}
    for finding in then:
        if merged.pop((finding.camera, finding.pair), None) is None:
            merged[(finding.camera, finding.pair)] = finding
    return list(merged.values())


#: A camera's keypoints are taken as turned by half a turn (:func:`turned_cameras`) where, so relabelled, they cost at
#: most this share of their cost as labelled (the tracker's test for a jump, ``vfactor.track._JUMP_COST_RATIO``)...
TURN_COST_RATIO = 0.25
#: ... and at least this many keypoints of the camera were seen: fewer, and a half turn of a few points is no sign.
TURN_MIN_KEYPOINTS = 6


def turned_cameras(obs: KeypointObservations, world_T_vehicle: gtsam.Pose3, vehicle_p_keypoints: np.ndarray,
                   loss: RobustLoss, ratio: float = TURN_COST_RATIO) -> list[str]:
    """The cameras whose keypoints ``world_T_vehicle`` and the shape say are labelled as a vehicle turned by half a
    turn: a detector that read the vehicle's front as its back (and so its left as its right).

    A learnt detector that sees a vehicle nearly end-on may take its back for its front: every keypoint then has the
    label of the one diagonally across (:data:`~vfactor.keypoints.TURN_PERMUTATION`), and the pose of those labels
    alone is the vehicle turned round in place. Given a pose known otherwise (a track's prediction), a camera whose
    keypoints, so relabelled, cost at most ``ratio`` of their cost as labelled (robust cost, ``sum rho(|e|)``), and
    at least :data:`SWAP_MARGIN` less, with at least :data:`TURN_MIN_KEYPOINTS` keypoints, is one.

    Returns:
        the names of those cameras, in the observations' camera order (empty where none is).
    """
    if len(obs) == 0:
        return []
    _, as_given, as_turned = _relabelled_costs(obs, TURN_PERMUTATION, world_T_vehicle, vehicle_p_keypoints, loss)
    out = []
    for c in np.unique(obs.camera_index):
        rows = obs.camera_index == c
        given, turn = float(as_given[rows].sum()), float(as_turned[rows].sum())
        if rows.sum() >= TURN_MIN_KEYPOINTS and turn <= ratio * given and given - turn >= SWAP_MARGIN:
            out.append(obs.cameras[int(c)].name)
    return out


def turn_cameras(obs: KeypointObservations, cameras: list[str]) -> KeypointObservations:
    """The observations with the keypoints of ``cameras`` (names) relabelled by half a turn (:func:`turned_cameras`);
    every pixel, sigma and window kept with its row; ``obs`` itself where ``cameras`` is empty."""
    if not cameras:
        return obs
    names = [camera.name for camera in obs.cameras]
    rows = np.isin(obs.camera_index, [names.index(name) for name in cameras if name in names])
    return obs.relabelled(np.where(rows, TURN_PERMUTATION[obs.keypoint_index], obs.keypoint_index))
