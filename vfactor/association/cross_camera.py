"""Which detections of one frame show the same vehicle: cross-camera association from geometry.

The cameras are calibrated and the keypoints semantic, so two detections of
one vehicle in two cameras can be solved together: one pose and one shape
that explain both. Two detections of different vehicles cannot: the joint
solve rejects one camera's keypoints, which the solver's camera-disagreement
check reports (:func:`vfactor.solve.solve_observations`; 0 false alarms in
10,001 consistent vehicles, docs/reliability.md). The association is built on
that test:

1. every detection is solved alone (one view: a pose whose depth the mean
   shape fixes to about a tenth of the distance);
2. every pair of detections of different cameras whose single-view positions
   may be one vehicle's (each near the other's viewing ray,
   :attr:`AssociationOptions.gate_distance`), and whose single views slid along their viewing rays can fit
   both detections (:attr:`AssociationOptions.slide_gate`), is solved jointly;
   the pair is *compatible* when that solve is sane, no camera disagrees, and
   neither detection's keypoints fit the joint vehicle much worse than they
   fit their own: the rise of the robust reprojection cost of each
   detection's keypoints (Cauchy, at the detector's sigmas, per seen
   keypoint) from its single-view solve (0 for one too weak to solve) to the
   joint solve is at most :attr:`AssociationOptions.gate_cost` for both. This
   is a likelihood ratio per camera: one vehicle explains both views about
   as well as each explains its own, two vehicles cannot;
3. compatible pairs are merged greedily, smallest rise first, into groups of
   at most one detection per camera whose every pair is compatible; then single
   detections move, or swap with the same camera's detection of another group,
   while that raises the groups' agreement (:func:`_improve`: a wrong best pair
   first kept a third camera's view out of its vehicle);
4. each group of three or more detections is solved once more as a whole, and
   a camera that disagrees there is split off into a vehicle of its own; two
   groups of several views, of different cameras, that put the vehicle in one
   place are solved together and merged when every view still fits
   (:func:`_merge_split_vehicles`: one vehicle seen in two halves);
5. each detection still alone, and then each one too weak to be solved alone, is tried once
   more with each group that projects near it, solved together with it: it
   joins when the group's detections fit the joint vehicle about as well as
   their own (:func:`_attach_leftovers`).

A detection that joins no group is a vehicle seen by one camera only.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from vfactor.camera import Camera
from vfactor.errors import InputError
from vfactor.factors.projection import robust_costs, whitened_residuals
from vfactor.graph import observations_from_detections
from vfactor.observations import Detection, Frame, class_hints
from vfactor.result import VehicleResult
from vfactor.solve import SolveOptions, solve_observations

__all__ = ["AssociationOptions", "FrameGroups", "PairTests", "associate_frame", "group_detections", "join_test",
           "pair_tests"]


@dataclass(frozen=True)
class AssociationOptions:
    """Settings of the association (docs/association.md).

    Attributes:
        gate_distance: metres, on the road plane, of the pre-gate of a pair (:func:`_may_meet`): each
            single-view position must lie within half of it (plus 5 % of the depth) of the other's viewing ray
            and within it (plus 30 % of the depth) along that ray: a single view's depth is uncertain by metres
            (3 m at 20 m seen on intersection_multi, more than 8 m on library_tracks_2cam).
        link_distance: metres between a track's predicted position and a frame's vehicle beyond which they are
            not linked (plus ``max_speed`` times the step for a track of one position, whose speed is unknown,
            and ``max_acceleration`` times the step squared otherwise).
        max_speed: m/s a track of one position may have had (54 km/h: urban traffic at intersections).
        max_acceleration: m/s^2 of change of velocity a track may show between its frames.
        max_missed: seconds a track is kept (predicted on) without detections before it ends; a vehicle that
            comes back within them keeps its id.
        track_bonus: metres taken off a link's cost when the vehicle holds a camera track id (``track``) the
            track held before: a camera's own 2D tracker as evidence, never as a rule.
        single_view_weight: weight of a position seen by one camera only in a track's velocity fit (1 for
            several cameras): a single view's depth is metres off.
        single_view_depth: the share of its distance from the camera by which a vehicle seen by one camera
            only may be off along that camera's ray: the linking counts such an offset
            ``link_distance / (link_distance + single_view_depth * depth)`` of its length
            (:func:`vfactor.association.linking.ray_distance`).
        tentative_missed: seconds a track of fewer than ``min_track_frames`` positions waits for its vehicle.
        gate_cost: the largest rise, per seen keypoint, of the robust reprojection cost of a detection's
            keypoints from its single-view solve to a pair's joint solve, for two detections of at least
            ``strong_keypoints`` keypoints each. Set on intersection_multi, tracks_3veh, tracks_3cam and
            library_tracks (seed 0; 792 pairs within the distance gate): the same vehicle's pairs rose by at
            most 0.55 per keypoint, different vehicles' pairs that the joint solve did not refuse by at least 0.8.
        quick_gate: a pair is first solved quickly (one Levenberg-Marquardt run with the shape model's pooled
            prior at the detector's sigmas: no refinement, relabelling or restarts); where that solve fails (a
            camera disagrees) or either detection's rise is beyond ``quick_gate`` times the pair's gate, the pair
            is not compatible without the full joint solve, whose robust steps (the swap search, the refit
            without gross outliers, the restarts) cost different vehicles' pairs about four times a same
            vehicle's. Set on the scenes of ``gate_cost`` (seed 0, paper-like and hard noise, 806 pairs): the
            compatible pairs' quick rise reached 1.43 times their gate, and 1 of 442 compatible pairs (hard
            noise) was refused by the quick solve's camera check; 0 tests every pair in full.
        slide_gate: before its quick solve, each of the pair's single-view solutions is slid along its camera's
            viewing ray (its distance from the camera times 0.5 to 1.5, the direction in which a single view is
            uncertain; pose and shape otherwise as solved) and both detections' robust costs are taken there in
            one compiled pass (:func:`_slid_rise`); where even the best of these positions raises one detection's
            cost by more than ``slide_gate`` times the pair's gate, the pair is not compatible without a solve.
            Set on the frames of ``benchmarks/association_time.py`` (30 vehicles, seed 100, paper-like and hard
            noise; 2,230 pairs): the same vehicle's pairs that the quick solve passes slid to at most 4.3 times
            their gate; on ``association_4cam`` seed 53 one weak pair of one vehicle slid to 8.3 times, so 10,
            which refuses 38-42 % of the different vehicles' pairs of those scenes, each for about a fifteenth
            of a quick solve's cost. 0 solves every pair quickly.
        gate_cost_weak: the same gate where the weaker detection has ``min_keypoints`` to ``strong_keypoints``
            - 1 keypoints (its single-view solve fits its few keypoints closely, so any joint solve raises their
            cost more): same vehicles rose up to 1.5 (6-7 keypoints) and 5.4 (4-5), different vehicles by at
            least 2.9 and 2.1; also the gate of a weaker detection's attachment (below).
        strong_keypoints: keypoints a detection needs for ``gate_cost``.
        min_keypoints: keypoints a detection needs to be solved alone and tested in pairs; one with fewer
            (1-3 keypoints, which fit any vehicle near them) is tried only against groups, in the second pass
            (:func:`_attach_leftovers`).
        leftover_rise: in the second pass, the largest rise per keypoint of a group's detections' cost when a
            leftover detection joins it (true joins seen: up to 0.84; tuning scenes as for ``gate_cost``).
        leftover_cost: in the second pass, the largest cost per keypoint of the leftover detection's own
            keypoints in the joint solve (true joins seen: up to 5.4).
        hint_relax: how much wider both second-pass gates are for a group the cameras' own track ids point to.
        hint_bonus: taken off the score (the rise over its gate) of a pair whose two detections' camera tracks
            last showed the same vehicle, so that the merging and the moves prefer it to a pairing the cameras'
            trackers do not support (two vehicles side by side may fit either way); the gate itself is unchanged.
        min_track_frames: a track never seen by two cameras at once is kept only when it moves steadily over at
            least this many frames: its positions within ``max_track_residual`` metres (RMS) of a constant
            velocity (:func:`vfactor.association.associate_scene`); otherwise it is a detector's flicker, as false
            detections are, chained by the linking or not.
        max_track_residual: see ``min_track_frames``.
        min_hit_ratio: a track never seen by two cameras at once must also be seen in this share of the frames
            from its first to its last (false detections chained by the linking come and go).
        solve: settings of the single-view and joint solves (no covariances, and no further starts for a poor
            fit, ``poor_fit_restarts=0``: each solve is a hypothesis, most poor fits are detections of different
            vehicles, and the vehicles found are solved again in full by whoever takes the association).
    """

    gate_distance: float = 8.0
    gate_cost: float = 0.7
    gate_cost_weak: float = 2.2
    quick_gate: float = 3.0
    slide_gate: float = 10.0
    strong_keypoints: int = 8
    min_keypoints: int = 4
    leftover_rise: float = 1.0
    leftover_cost: float = 6.0
    hint_relax: float = 2.0
    hint_bonus: float = 0.5
    min_track_frames: int = 3
    max_track_residual: float = 1.5
    min_hit_ratio: float = 0.6
    link_distance: float = 2.0
    max_speed: float = 15.0
    max_acceleration: float = 8.0
    max_missed: float = 1.0
    track_bonus: float = 1.0
    single_view_weight: float = 0.1
    single_view_depth: float = 0.1
    tentative_missed: float = 0.3
    solve: SolveOptions = field(default_factory=lambda: SolveOptions(covariance=False, poor_fit_restarts=0))

    def __post_init__(self):
        for name in ("gate_distance", "gate_cost", "gate_cost_weak", "quick_gate", "slide_gate", "strong_keypoints",
                     "min_keypoints", "leftover_rise", "leftover_cost", "hint_relax", "hint_bonus", "min_track_frames",
                     "max_track_residual", "min_hit_ratio", "link_distance", "max_speed", "max_acceleration",
                     "max_missed", "track_bonus", "single_view_weight", "single_view_depth", "tentative_missed"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise InputError(f"AssociationOptions.{name}", f"expected a finite number >= 0, got {value!r}")


@dataclass
class FrameGroups:
    """The vehicles of one frame found by :func:`associate_frame`.

    Attributes:
        groups: per vehicle, the indices of its detections in the frame's ``detections`` (one per camera at
            most), in the order of their first detection.
        results: per group, its joint solve (no covariance; ``ok`` False where it failed).
        pairs: (i, j) with i < j -> (compatible, score) of every pair tested: solved jointly, or refused by its
            slid single views (:attr:`AssociationOptions.slide_gate`; its score then their least rise over the
            gate) or by its quick solve (:attr:`AssociationOptions.quick_gate`; its score then that solve's rise
            over the gate, ``inf`` where it failed).
        messages: cameras split off a group because they disagreed with the others.
    """

    groups: list[list[int]]
    results: list[VehicleResult]
    pairs: dict = field(default_factory=dict)
    messages: list[str] = field(default_factory=list)


#: A pair's quick solve (:attr:`AssociationOptions.quick_gate`) stops when an iteration lowers the cost by less than
#: this share (``SolveOptions.relative_error_tol``, 1e-6 by default): its rises are compared with three times the
#: pair's gate, which the last iterations do not move. On the tuning scenes (``benchmarks/association_time.py``'s
#: 30 vehicles, seed 100, paper-like and hard noise) 1e-4 took 43 % fewer iterations and changed no pair's test; 1e-3
#: changed two of 785.
QUICK_RELATIVE_ERROR_TOL = 1e-4


def _solve(detections: list[Detection], cameras: dict[str, Camera], options: AssociationOptions,
           name: str, initial: VehicleResult | None = None, quick: bool = False) -> VehicleResult:
    """A solve of some detections as one vehicle; any failure is a result that is not ``ok``. ``quick``: a pair's
    quick solve (:attr:`AssociationOptions.quick_gate`): one Levenberg-Marquardt run with the default shape model's
    pooled prior at the detector's sigmas (no refinement, relabelling or restarts; stopped at
    :data:`QUICK_RELATIVE_ERROR_TOL`), the solver's checks included."""
    from vfactor.result import Status
    from vfactor.sanity import summarise_error
    from vfactor.shape_model import default_shape_model

    solve, prior, hints = options.solve, None, ()
    if quick:
        solve = replace(solve, estimate_noise=False, relabel_swaps=False, num_starts=1, poor_fit_restarts=0,
                        relative_error_tol=max(solve.relative_error_tol, QUICK_RELATIVE_ERROR_TOL))
        prior = default_shape_model().pooled
    else:
        hints = class_hints(detections)
    try:
        obs = observations_from_detections(detections, cameras, solve.graph)
        start = (initial.world_T_vehicle, initial.wireframe) if initial is not None and initial.ok else None
        return solve_observations(obs, solve, name, prior, initial=start, hints=hints)
    except (InputError, RuntimeError, np.linalg.LinAlgError) as exc:
        return VehicleResult(name, Status.FAILED, message=summarise_error(exc))


@dataclass
class PairTests:
    """The part of a frame's association that no hint changes (:func:`pair_tests`): each detection solved alone
    and each pair tested; :func:`group_detections` makes the groups from it. Picklable, so that frames' tests can
    run on workers (:func:`vfactor.association.associate_scene` with an engine).

    Attributes:
        indices: the detections grouped (indices into the frame's ``detections``).
        seen: detection index -> its seen keypoints.
        alone: detection index -> its single-view solve (detections of at least ``min_keypoints`` keypoints).
        pairs: (i, j) with i < j -> (compatible, score) of every pair tested, before any hint (as
            :attr:`FrameGroups.pairs`).
        joint: (i, j) -> the joint solve of every pair solved in full (the pairs a hint may favour).
        own: detection index -> its observations at the detector's sigmas (None where it has none usable); not
            kept where the tests ran on a worker (:func:`group_detections` makes them again).
    """

    indices: list[int]
    seen: dict[int, int]
    alone: dict[int, VehicleResult]
    pairs: dict[tuple[int, int], tuple[bool, float]]
    joint: dict[tuple[int, int], VehicleResult]
    own: dict | None = None


def associate_frame(frame: Frame, cameras: dict[str, Camera], options: AssociationOptions = AssociationOptions(),
                    indices: list[int] | None = None, hints: dict[int, str] | None = None) -> FrameGroups:
    """Groups the detections of one frame into vehicles, across cameras (see the module's docstring):
    :func:`group_detections` of :func:`pair_tests`.

    Args:
        frame: the frame.
        cameras: camera name -> camera.
        options: the association's settings.
        indices: the detections to group (indices into ``frame.detections``); default: all.
        hints: detection index -> the vehicle its camera's own track (``Detection.track``) showed last: a pair
            of detections of the same hint has ``hint_bonus`` taken off its score, and a detection left alone
            is tried with a group holding a detection of the same hint with gates ``hint_relax`` times wider,
            the cameras' trackers agreeing that they follow one vehicle.

    Returns:
        The groups, each group's joint solve, the pairs tested and notes.
    """
    return group_detections(frame, cameras, options, pair_tests(frame, cameras, options, indices), hints)


def pair_tests(frame: Frame, cameras: dict[str, Camera], options: AssociationOptions = AssociationOptions(),
               indices: list[int] | None = None) -> PairTests:
    """Steps 1 and 2 of the module's docstring for one frame: every detection solved alone, every pair that may be
    one vehicle's tested (slid single views, quick solve, full joint solve). Most of the association's cost, and
    independent of the other frames (of the hints, which only :func:`group_detections` takes).

    Args:
        frame, cameras, options, indices: as for :func:`associate_frame`.
    """
    det = frame.detections
    indices = list(range(len(det))) if indices is None else list(indices)
    seen = {i: int(det[i].seen.sum()) for i in indices}
    strong = [i for i in indices if seen[i] >= options.min_keypoints]
    alone = {i: _solve([det[i]], cameras, options, f"d{i}") for i in strong}
    own = {i: _observations(det[i], cameras, options) for i in indices}
    baseline = {i: _cost(own[i], alone[i], options) if alone[i].ok else 0.0 for i in strong}
    position = {i: r.world_T_vehicle.translation()[:2] for i, r in alone.items() if r.ok}

    pairs: dict[tuple[int, int], tuple[bool, float]] = {}
    joint: dict[tuple[int, int], VehicleResult] = {}

    def rise_on(result: VehicleResult, pair: tuple[int, int]) -> float:  # the pair's larger rise, per keypoint
        return max((_cost(own[k], result, options) - baseline[k]) / seen[k] for k in pair) if result.ok else math.inf

    for i, j in itertools.combinations(strong, 2):
        if det[i].camera == det[j].camera:
            continue
        if i in position and j in position and not _may_meet(
                position[i], cameras[det[i].camera], position[j], cameras[det[j].camera], options):
            continue
        if i not in position and j not in position:
            continue  # neither says where it is: no test
        better = i if seen[i] >= seen[j] else j
        gate = options.gate_cost if min(seen[i], seen[j]) >= options.strong_keypoints else options.gate_cost_weak
        if options.slide_gate > 0:
            slid = _slid_rise((i, j), det, cameras, alone, own, baseline, seen, options)
            if slid > options.slide_gate * gate:
                pairs[(i, j)] = (False, slid / gate)
                continue
        if options.quick_gate > 0:
            quick = rise_on(_solve([det[i], det[j]], cameras, options, "quick", alone[better], quick=True), (i, j))
            if quick > options.quick_gate * gate:
                pairs[(i, j)] = (False, quick / gate)
                continue
        result = _solve([det[i], det[j]], cameras, options, f"d{i}+d{j}", initial=alone[better])
        joint[(i, j)] = result
        rise = rise_on(result, (i, j))
        pairs[(i, j)] = (rise <= gate, rise / gate)  # scored against its gate: strong and weak pairs comparable
    return PairTests(indices, seen, alone, pairs, joint, own)


def group_detections(frame: Frame, cameras: dict[str, Camera], options: AssociationOptions, tests: PairTests,
                     hints: dict[int, str] | None = None) -> FrameGroups:
    """Steps 3 to 5 of the module's docstring for one frame, from its :func:`pair_tests`: the pairs merged into
    groups (a pair solved in full whose two detections have the same hint has ``hint_bonus`` taken off its score),
    groups of three or more solved and split where a camera disagrees, vehicles seen in two halves merged, and the
    detections left alone tried with the groups.

    Args:
        frame, cameras, options, hints: as for :func:`associate_frame`; ``tests`` the frame's :func:`pair_tests`
            with the same ``options``.
    """
    det = frame.detections
    indices, seen, alone, joint = tests.indices, tests.seen, tests.alone, tests.joint
    weak = [i for i in indices if seen[i] < options.min_keypoints]
    strong = [i for i in indices if seen[i] >= options.min_keypoints]
    own = tests.own if tests.own is not None else {i: _observations(det[i], cameras, options) for i in indices}
    pairs = dict(tests.pairs)
    if hints:
        for (i, j), (ok, score) in pairs.items():
            if (i, j) in joint and i in hints and hints.get(j) == hints[i]:
                pairs[(i, j)] = (ok, score - options.hint_bonus)  # the cameras' trackers say they showed one vehicle

    # greedy merging, best pair first, keeping one detection per camera and every pair compatible
    camera = {i: det[i].camera for i in strong}
    group_of = {i: i for i in strong}
    members = {i: [i] for i in strong}
    for (i, j), (ok, _) in sorted(pairs.items(), key=lambda item: item[1][1]):
        if not ok:
            continue
        a, b = group_of[i], group_of[j]
        if a == b:
            continue
        if any(_agreement(k, members[a], pairs, camera) == -math.inf for k in members[b]):
            continue  # a camera in both, or a pair across them not compatible
        members[a] = sorted(members[a] + members[b])
        for k in members.pop(b):
            group_of[k] = a
    _improve(members, group_of, pairs, camera)

    groups, results, messages = [], [], []
    pending = sorted(members.values(), key=lambda g: g[0])
    while pending:
        group = pending.pop(0)
        if len(group) == 1:
            result = alone[group[0]]
        elif len(group) == 2:
            result = joint[(group[0], group[1])]
        else:
            result = _solve([det[k] for k in group], cameras, options, "+".join(f"d{k}" for k in group))
            blamed = _blamed_cameras(result)
            if blamed:
                kept = [k for k in group if det[k].camera not in blamed]
                split = [k for k in group if det[k].camera in blamed]
                messages.append(f"detections {split} (camera(s) {', '.join(sorted(blamed))}) disagree with the "
                                f"rest of their group {group}: a vehicle of their own")
                pending = sorted(pending + [kept] + [[k] for k in split], key=lambda g: g[0])
                continue
        groups.append(group)
        results.append(result)
    _merge_split_vehicles(det, own, groups, results, cameras, options)
    _attach_leftovers(det, weak, own, groups, results, cameras, options, hints or {})
    order = sorted(range(len(groups)), key=lambda g: groups[g][0])
    return FrameGroups([groups[g] for g in order], [results[g] for g in order], pairs, messages)


def _agreement(k: int, group, pairs: dict, camera: dict[int, str]) -> float:
    """Detection ``k``'s agreement with the others of ``group``: the sum of ``1 - score`` over its pairs with them;
    ``-inf`` where one is of its camera or a pair is not compatible (it may not be in that group)."""
    total = 0.0
    for m in group:
        if m == k:
            continue
        if camera[m] == camera[k]:
            return -math.inf
        ok, score = pairs.get((min(k, m), max(k, m)), (False, math.inf))
        if not ok:
            return -math.inf
        total += 1.0 - score
    return total


def _improve(members: dict[int, list[int]], group_of: dict[int, int], pairs: dict, camera: dict[int, str],
             max_rounds: int = 20) -> None:
    """Moves and swaps of single detections between the greedy groups, in place, while they raise the groups'
    agreement: the sum, over the pairs within each group, of ``1 - score`` (a pair's rise over its gate), with
    every pair within a group compatible and one detection per camera.

    The greedy merging takes the best pair first; where that pair is wrong (two vehicles side by side, seen
    along similar rays) it keeps a third camera's view out of the right group, which agrees with two of its
    detections. Such a view moves to where it agrees with more; a detection swaps with the same camera's
    detection of another group where both agree better after the swap.
    """
    def gain(k: int, group) -> float:
        return _agreement(k, group, pairs, camera)

    for _ in range(max_rounds):
        changed = False
        for k in sorted(group_of):
            a = group_of[k]
            here = gain(k, members[a])
            best, target = here + 1e-9, None
            for b, group in members.items():
                if b != a and group:
                    g = gain(k, group)
                    if g > best:
                        best, target = g, b
            if target is None:
                continue  # (alone it would gain 0, never more than it has)
            members[a] = [m for m in members[a] if m != k]
            members[target] = sorted(members[target] + [k])
            group_of[k] = target
            changed = True
        for k, m in itertools.combinations(sorted(group_of), 2):
            a, b = group_of[k], group_of[m]
            if a == b or camera[k] != camera[m]:
                continue
            rest_a = [x for x in members[a] if x != k]
            rest_b = [x for x in members[b] if x != m]
            delta = gain(k, rest_b) + gain(m, rest_a) - gain(k, rest_a) - gain(m, rest_b)
            if delta > 1e-9:
                members[a], members[b] = sorted(rest_a + [m]), sorted(rest_b + [k])
                group_of[k], group_of[m] = b, a
                changed = True
        if not changed:
            break
    for b in [b for b, group in members.items() if not group]:
        del members[b]


def _attach_leftovers(det: list[Detection], weak: list[int], own: dict, groups: list[list[int]],
                      results: list[VehicleResult], cameras: dict[str, Camera], options: AssociationOptions,
                      hints: dict[int, str]) -> None:
    """A second pass for the detections left alone: too weak to be solved alone (under ``min_keypoints``), or
    whose pairs failed a gate (a weak view's single-view pose is metres off, so pair tests miss).

    Each is tried with every group that has no detection of its camera and whose vehicle projects near its
    keypoints in its camera (within the projected keypoints' box grown by half its size): the group and the
    detection are solved together, and the detection joins when that solve is sane, the group's own detections
    fit it about as well as they fit the group (each detection's cost rises by at most ``leftover_rise`` per
    keypoint: they are seen well, so a vehicle elsewhere would move them), and the detection's keypoints cost at
    most ``leftover_cost`` each. Of several groups that pass, the one where the sum of its detections' rises and the
    detection's own cost per keypoint is least (a weak view's few keypoints barely move any group, so its own fit
    decides); a detection that joins none stays a vehicle of its own (one too weak to solve is reported ``degenerate``).
    A group holding a detection of the leftover's hint (the same vehicle by the cameras' own trackers) is
    tried wherever it projects, with both gates ``hint_relax`` times wider.
    """
    from vfactor.result import Status

    # the detections alone first (solved alone: they may join a group of several), then the weak ones (which may
    # also join a detection alone); every detection ends in exactly one group
    leftovers = sorted(g[0] for g in groups if len(g) == 1) + sorted(set(weak))
    for k in leftovers:
        if own[k] is None:
            continue
        home = next((g for g, group in enumerate(groups) if k in group), None)
        if home is not None and len(groups[home]) > 1:
            continue  # a weak detection joined it: no longer alone
        camera = cameras[det[k].camera]
        uv = det[k].keypoints[det[k].seen]
        best = None
        for g, (group, result) in enumerate(zip(groups, results)):
            if g == home or not group or not result.ok or any(det[m].camera == det[k].camera for m in group):
                continue
            hinted = k in hints and any(hints.get(m) == hints[k] for m in group)
            if not hinted and not _projects_near(uv, camera, result):
                continue
            joined = join_test(det, k, group, result, cameras, options, options.hint_relax if hinted else 1.0,
                               f"g{g}+d{k}", own)
            if joined is not None and (best is None or joined[0] < best[0]):
                best = (joined[0], g, joined[1])
        if best is not None:
            _, g, together = best
            groups[g] = sorted(groups[g] + [k])
            results[g] = together
            if home is not None:
                groups[home], results[home] = [], None
        elif home is None:
            groups.append([k])
            results.append(VehicleResult(f"d{k}", Status.DEGENERATE,
                                         message="too few keypoints to associate or to solve alone"))
    keep = [g for g, group in enumerate(groups) if group]
    groups[:] = [groups[g] for g in keep]
    results[:] = [results[g] for g in keep]


def _merge_split_vehicles(det: list[Detection], own: dict, groups: list[list[int]], results: list[VehicleResult],
                          cameras: dict[str, Camera], options: AssociationOptions) -> None:
    """Merges, in place, two groups of two or more detections each, of different cameras, whose joint solves put
    their vehicles within ``link_distance`` of each other, when solved together no detection's cost rises by more
    than ``leftover_rise`` per keypoint: one vehicle seen in two halves (the greedy merging needs every pair
    compatible, and a pair of views far apart in angle may fail its test where each half is sure). The closest
    two first, again until no two merge.
    """
    while True:
        candidates = []
        for a, b in itertools.combinations(range(len(groups)), 2):
            if len(groups[a]) < 2 or len(groups[b]) < 2 or not results[a].ok or not results[b].ok:
                continue
            if {det[m].camera for m in groups[a]} & {det[m].camera for m in groups[b]}:
                continue
            gap = float(np.linalg.norm(results[a].world_T_vehicle.translation()[:2]
                                       - results[b].world_T_vehicle.translation()[:2]))
            if gap <= options.link_distance:
                candidates.append((gap, a, b))
        for _, a, b in sorted(candidates):
            together = _solve([det[m] for m in groups[a] + groups[b]], cameras, options, f"g{a}+g{b}",
                              initial=results[a] if len(groups[a]) >= len(groups[b]) else results[b])
            if not together.ok:
                continue
            rises = [_rise(own[m], det[m], results[g], together, options) for g in (a, b) for m in groups[g]]
            if max(rises) <= options.leftover_rise:
                groups[a], results[a] = sorted(groups[a] + groups[b]), together
                del groups[b], results[b]
                break
        else:
            return


def _projects_near(uv: np.ndarray, camera: Camera, result: VehicleResult) -> bool:
    """Whether pixels ``uv`` (n, 2) lie within the box of a solved vehicle's keypoints projected into ``camera``,
    grown by half its size."""
    predicted, depth = camera.project(result.keypoints_world)
    predicted = predicted[depth > 0]
    if len(predicted) == 0:
        return False
    lo, hi = predicted.min(0), predicted.max(0)
    grow = 0.5 * (hi - lo)
    return bool(np.all((uv >= lo - grow) & (uv <= hi + grow)))


def join_test(det: list[Detection], k: int, group: list[int], result: VehicleResult, cameras: dict[str, Camera],
              options: AssociationOptions, relax: float = 1.0, name: str = "joined",
              own: dict | None = None) -> tuple[float, VehicleResult] | None:
    """The second pass's test of detection ``k`` joining ``group`` (solved as ``result``; no detection of
    ``k``'s camera), with both gates ``relax`` times wider.

    The group and the detection are solved together, from the group's solution (the joint vehicle must stay where
    the group's detections put it: their rises are the test); the detection joins when that solve is sane, each of
    the group's detections' cost per keypoint rises by at most ``leftover_rise`` and the detection's own keypoints
    cost at most ``leftover_cost`` each.

    Args:
        det: the frame's detections.
        own: detection index -> its observations at the detector's sigmas, where already made (the others, of
            ``k`` and the group, are made here).

    Returns:
        (score: the sum of the rises and the detection's own cost per keypoint, the joint solve), or None when
        it does not join (or has no keypoint to test).
    """
    own = dict(own or {})
    for m in [*group, k]:
        if m not in own:
            own[m] = _observations(det[m], cameras, options)
    if own[k] is None or len(own[k]) == 0:
        return None  # no keypoint to test
    together = _solve([det[m] for m in group] + [det[k]], cameras, options, name, initial=result)
    if not together.ok:
        return None
    rises = [_rise(own[m], det[m], result, together, options) for m in group]
    mine = _cost(own[k], together, options) / max(int(det[k].seen.sum()), 1)
    if max(rises) <= relax * options.leftover_rise and mine <= relax * options.leftover_cost:
        return sum(rises) + mine, together
    return None


#: The factors by which :func:`_slid_rise` scales a single view's distance from its camera (along its viewing ray).
SLIDE_FACTORS = np.linspace(0.5, 1.5, 21)


def _slid_rise(pair: tuple[int, int], det: list[Detection], cameras: dict[str, Camera], alone: dict, own: dict,
               baseline: dict, seen: dict, options: AssociationOptions) -> float:
    """The least, over each of the pair's single-view solutions slid along its camera's viewing ray
    (:data:`SLIDE_FACTORS` of its distance from the camera, its shape and rotation as solved), of the larger of
    the two detections' rises of robust cost per seen keypoint (from their single-view solves, as
    :func:`associate_frame` scores a joint solve): a cheap test before the pair's quick solve
    (:attr:`AssociationOptions.slide_gate`). ``inf`` where neither single view was solved."""
    loss = options.solve.graph.loss
    least = math.inf
    for a in pair:
        if not alone[a].ok:
            continue
        world_T_vehicle = alone[a].world_T_vehicle.matrix()
        centre = cameras[det[a].camera].center
        poses = np.repeat(world_T_vehicle[None], len(SLIDE_FACTORS), axis=0)
        poses[:, :3, 3] = centre + SLIDE_FACTORS[:, None] * (world_T_vehicle[:3, 3] - centre)
        points = np.repeat(alone[a].wireframe.vehicle_p_keypoints[None], len(SLIDE_FACTORS), axis=0)
        rises = [(robust_costs(own[k], poses, points, loss) if own[k] is not None and len(own[k])
                  else np.zeros(len(poses))) - baseline[k] for k in pair]
        larger = np.maximum(rises[0] / seen[pair[0]], rises[1] / seen[pair[1]])
        if np.isnan(larger).any():
            return -math.inf  # a projection that is not finite: no bound, the quick solve decides
        least = min(least, float(np.min(larger)))
    return least


def _may_meet(p_i: np.ndarray, camera_i: Camera, p_j: np.ndarray, camera_j: Camera,
              options: AssociationOptions) -> bool:
    """Whether two single-view positions (world x, y, metres) may be one vehicle's: each lies near the other's
    viewing ray on the road, the direction in which a single view is uncertain.

    For each view: the other position's distance from the ray (camera centre through the position) is at most
    ``gate_distance / 2 + 0.05 depth``, and its distance along the ray differs from the position's by at most
    ``gate_distance + 0.3 depth`` (``depth``: the position's distance from the camera on the road).
    """
    for p, camera, q in ((p_i, camera_i, p_j), (p_j, camera_j, p_i)):
        ray = p - camera.center[:2]
        depth = float(np.linalg.norm(ray))
        if depth < 1e-6:
            continue
        u = ray / depth
        w = q - camera.center[:2]
        along = float(w @ u)
        lateral = float(np.linalg.norm(w - along * u))
        if lateral > 0.5 * options.gate_distance + 0.05 * depth or abs(along - depth) > options.gate_distance + 0.3 * depth:
            return False
    return True


def _observations(detection: Detection, cameras: dict[str, Camera], options: AssociationOptions):
    """One detection's keypoint observations at the detector's sigmas (None when it has none usable)."""
    try:
        return observations_from_detections([detection], cameras, options.solve.graph)
    except InputError:
        return None


def _cost(obs, result: VehicleResult, options: AssociationOptions) -> float:
    """The robust reprojection cost of ``obs`` (one detection, nominal sigmas) on a solved vehicle."""
    if obs is None or len(obs) == 0:
        return 0.0
    e = whitened_residuals(obs, result.world_T_vehicle, result.wireframe.vehicle_p_keypoints)
    return float(np.sum(options.solve.graph.loss.rho(np.linalg.norm(e, axis=1))))


def _rise(obs, detection: Detection, before: VehicleResult, after: VehicleResult, options: AssociationOptions) -> float:
    """How much a detection's cost (:func:`_cost` of its observations ``obs``) rises from the vehicle it was part
    of (``before``) to a joint one (``after``), per seen keypoint."""
    return (_cost(obs, after, options) - _cost(obs, before, options)) / max(int(detection.seen.sum()), 1)


def _blamed_cameras(result: VehicleResult) -> set[str]:
    """The cameras a failed joint solve says disagree with the others (none for other failures)."""
    return set() if result.ok else set(result.extras.get("disagreeing_cameras", ()))
