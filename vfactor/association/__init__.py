"""Vehicles matched across cameras and frames when detections carry no shared vehicle id (docs/association.md).

Every camera's 2D detector numbers its own boxes, so real detections do not
name one vehicle for all cameras and frames. :func:`associate_scene` finds the
vehicles: within each frame across cameras (:mod:`vfactor.association.cross_camera`:
detections of one vehicle can be solved together, those of different vehicles
cannot), then across frames (:mod:`vfactor.association.linking`: a gated
optimal assignment on predicted positions, with the cameras' own track ids as
evidence). ``vfactor solve`` and ``vfactor track`` run it on scenes whose
frames name no vehicles (``--associate`` also on scenes that do).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from vfactor.association.cross_camera import (AssociationOptions, FrameGroups, PairTests, associate_frame,
                                              group_detections, join_test, pair_tests)
from vfactor.association.linking import Track, TrackLinker, constant_velocity
from vfactor.observations import UNASSIGNED, Frame, Scene
from vfactor.result import VehicleResult
from vfactor.track import frame_order

__all__ = ["AssociationOptions", "Association", "FrameGroups", "PairTests", "Track", "TrackLinker", "associate_frame",
           "associate_scene", "group_detections", "pair_tests"]


@dataclass
class Association:
    """What :func:`associate_scene` found.

    Attributes:
        scene: the scene with every associated detection's ``vehicle`` set, without the detections left out.
        groups: per frame (scene order), vehicle id -> the indices of its detections in the frame's
            ``detections`` of the scene given; empty for frames that were left as they were (their ids given).
        kept: per frame, the index in the scene given of each detection of :attr:`scene`'s frame.
        left_out: (frame, detection index in the scene given, why) of every detection left out: those of a
            track never seen by two cameras at once and not moving steadily (constant velocity within
            ``AssociationOptions.max_track_residual``) over ``min_track_frames`` frames: a detector's flicker,
            as false detections are; and those too weak to associate.
        messages: notes (cameras split off a group).
    """

    scene: Scene
    groups: list[dict[str, list[int]]]
    kept: list[list[int]] = field(default_factory=list)
    left_out: list[tuple[int, int, str]] = field(default_factory=list)
    messages: list[str] = field(default_factory=list)

    def restore_indices(self, results, first: int = 0) -> None:
        """Makes each result's ``extras["detections"]`` (indices into :attr:`scene`'s frames) indices into the
        scene given, in place: results of ``solve_scene(association.scene)`` or ``track_scene(...).frames``,
        or those of the frames from ``first`` on."""
        for f, frame in enumerate(results, first):
            for v in frame.vehicles:
                if v.extras.get("detections") is not None:
                    v.extras["detections"] = [self.kept[f][j] for j in v.extras["detections"]]

    @property
    def single_view(self) -> list[list[str]]:
        """Per frame, the vehicle ids seen by one camera only."""
        return [[vid for vid, g in frame.items() if len(g) == 1] for frame in self.groups]

    @property
    def vehicle_ids(self) -> list[str]:
        """Every vehicle id made, in order of first appearance."""
        return list(dict.fromkeys(vid for frame in self.groups for vid in frame))


def associate_scene(scene: Scene, options: AssociationOptions = AssociationOptions(), force: bool = False,
                    progress: Callable[[int, int], None] | None = None, engine=None) -> Association:
    """Gives every detection of the scene that names no vehicle its vehicle (see the module docstring).

    Frames are associated in time order; the ids made are ``t1``, ``t2``, ... (never one the scene already
    uses) and follow a vehicle through the frames as far as the linking can.

    Args:
        scene: the scene; frames whose detections are :data:`~vfactor.observations.UNASSIGNED` are associated.
        options: the association's settings; their solves take the scene's road plane where ``options.solve``
            names none (as :func:`vfactor.solve.solve_scene` does).
        force: associate every frame, ignoring the vehicle ids the scene gives (ids that are not trusted).
        progress: called with (frames done, frames) after each frame.
        engine: where the frames' pair tests run (:mod:`vfactor.parallel`; default: in this process): each
            frame's single-view solves and pair tests (:func:`~vfactor.association.cross_camera.pair_tests`, most
            of the cost, independent of the other frames) go to its workers, a few frames ahead; the grouping, which
            takes the hints of the frames before, and the linking run here in frame order (where no detection has a
            camera track id, and so no frame a hint, each frame's grouping runs on the workers too). The same
            association whatever the engine.

    Returns:
        The :class:`Association`: the scene with ids, and per frame which detections each vehicle has.

    Raises:
        InputError: a detection still waits for the keypoint network (it has no keypoints to associate by).
    """
    scene.require_detected()
    # the scene's road plane in every solve: without it one camera's keypoints of a bus fit a van several metres
    # nearer the camera and above the road just as well (the depth and the size trade off), and the track jumps
    options = dataclasses.replace(options, solve=options.solve.for_scene(scene))
    # never an id the scene uses, even where they are ignored (force): the same id would name two vehicles to a reader
    taken = {d.vehicle for f in scene.frames for d in f.detections if d.vehicle != UNASSIGNED}
    linker = TrackLinker(options, taken=taken)
    frames = list(scene.frames)
    groups: list[dict[str, list[int]]] = [{} for _ in frames]
    messages: list[str] = []
    weak: set[tuple[int, int]] = set()
    followed: dict[tuple[str, str], str] = {}  # (camera, camera track id) -> the vehicle it last showed
    path: dict[str, list[tuple[float, np.ndarray, int]]] = {}  # vehicle id -> (t, world x-y, n) of its solved frames
    solved: list[dict[str, VehicleResult]] = [{} for _ in frames]  # per frame, vehicle id -> its joint solve
    order = frame_order(scene)
    todo_of = {f: [j for j, d in enumerate(frames[f].detections) if force or d.vehicle == UNASSIGNED] for f in order}
    tests = _frame_tests(scene, order, todo_of, options, engine)
    for n, f in enumerate(order):
        frame = frames[f]
        todo = todo_of[f]
        if todo:
            hints = {j: followed[(frame.detections[j].camera, frame.detections[j].track)] for j in todo
                     if (frame.detections[j].camera, frame.detections[j].track) in followed}
            done = next(tests)
            found = done if isinstance(done, FrameGroups) else group_detections(frame, scene.cameras, options, done,
                                                                                 hints)
            messages += [f"frames[{f}]: {m}" for m in found.messages]
            positions = [r.world_T_vehicle.translation()[:2] if r.ok else None for r in found.results]
            camera_tracks = [{(frame.detections[j].camera, frame.detections[j].track) for j in g
                              if frame.detections[j].track is not None} for g in found.groups]
            viewpoints = [scene.cameras[frame.detections[g[0]].camera].center[:2] if len(g) == 1 else None
                          for g in found.groups]
            ids = linker.link(frame.t, positions, camera_tracks, viewpoints)
            for vid, xy in zip(ids, positions):
                if xy is not None:
                    path.setdefault(vid, []).append((frame.t, xy, n))
            vehicle_of = {j: vid for vid, g in zip(ids, found.groups) for j in g}
            weak |= {(f, g[0]) for g, r in zip(found.groups, found.results) if len(g) == 1 and not r.ok}
            frames[f] = Frame(frame.t, [dataclasses.replace(d, vehicle=vehicle_of[j]) if j in vehicle_of else d
                                        for j, d in enumerate(frame.detections)], frame.images)
            groups[f] = {vid: list(g) for vid, g in zip(ids, found.groups)}
            solved[f] = dict(zip(ids, found.results))
            for vid, g in groups[f].items():
                for j in g:
                    if frame.detections[j].track is not None:
                        followed[(frame.detections[j].camera, frame.detections[j].track)] = vid
        if progress is not None:
            progress(n + 1, len(order))
    _join_by_later_tracks(scene, frames, order, groups, solved, weak, path, options)
    return _confirmed(scene, frames, groups, weak, path, messages, options)


def _frame_tests(scene: Scene, order: list[int], todo_of: dict[int, list[int]], options: AssociationOptions, engine):
    """The :func:`~vfactor.association.cross_camera.pair_tests` of each frame of ``order`` with detections to
    associate, in that order: lazily in this process, or on the engine's workers where it has more than one; there,
    where no detection of the scene has a camera track id (no frame's grouping takes hints from the frames before),
    each frame's whole :func:`~vfactor.association.cross_camera.associate_frame`."""
    whole = not any(d.track is not None for f in order for d in scene.frames[f].detections)
    units = ((scene.frames[f], scene.cameras, options, todo_of[f], whole) for f in order if todo_of[f])
    if engine is None or engine.workers <= 1:
        return (pair_tests(*unit[:4]) for unit in units)
    return iter(engine.map(_frame_unit, units, total=sum(1 for f in order if todo_of[f])))


def _frame_unit(unit: tuple) -> PairTests | FrameGroups:
    """One frame's association on a worker (:func:`_frame_tests`): its pair tests, without the observations (made
    again where the frame is grouped: smaller to send back), or with ``whole`` its groups."""
    frame, cameras, options, todo, whole = unit
    if whole:
        return associate_frame(frame, cameras, options, todo)
    tests = pair_tests(frame, cameras, options, todo)
    tests.own = None
    return tests


def _join_by_later_tracks(scene: Scene, frames: list[Frame], order: list[int], groups, solved, weak, path,
                          options: AssociationOptions) -> None:
    """A detection left alone in its frame joins the vehicle that its camera's own track id (``Detection.track``)
    shows next, when that vehicle is in the frame and passes the second pass's test with ``hint_relax``
    (:func:`vfactor.association.cross_camera.join_test`); in place, frames latest first.

    The frames are associated in time order, so the hints of :func:`associate_frame` come from earlier frames
    only: a vehicle leaving a view is helped by them, one entering it (a wheel, then a light, then enough
    keypoints to pair) is not. Its camera's tracker says which vehicle those first views belong to once a later
    view of the same camera track has joined one.
    """
    following: dict[tuple[str, str], str] = {}  # (camera, camera track id) -> the vehicle it shows next
    for n in range(len(order) - 1, -1, -1):
        f = order[n]
        frame, frame_groups = frames[f], groups[f]
        for vid, g in list(frame_groups.items()):
            if len(g) != 1:
                continue
            j = g[0]
            d = frame.detections[j]
            target = following.get((d.camera, d.track)) if d.track is not None else None
            if target is None or target == vid or target not in frame_groups:
                continue
            group = frame_groups[target]
            result = solved[f].get(target)
            if result is None or not result.ok or any(frame.detections[m].camera == d.camera for m in group):
                continue
            joined = join_test(frame.detections, j, group, result, scene.cameras, options, options.hint_relax,
                               f"{target}+d{j}")
            if joined is None:
                continue
            together = joined[1]
            frame_groups[target] = sorted(group + [j])
            del frame_groups[vid]
            solved[f][target] = together
            weak.discard((f, j))
            path[vid] = [p for p in path.get(vid, []) if p[2] != n]
            path[target] = [(t, together.world_T_vehicle.translation()[:2], m) if m == n else (t, xy, m)
                            for t, xy, m in path.get(target, [])]
            frames[f].detections[j] = dataclasses.replace(d, vehicle=target)
        for vid, g in frame_groups.items():
            for j in g:
                d = frame.detections[j]
                if d.track is not None:
                    following[(d.camera, d.track)] = vid


def _steady(points: list[tuple[float, np.ndarray, int]], options: AssociationOptions) -> bool:
    """Whether a track is seen steadily: in at least ``min_track_frames`` frames, in at least ``min_hit_ratio`` of
    the frames from its first to its last, its positions within ``max_track_residual`` metres (RMS) of their
    least-squares constant-velocity line in time."""
    if len(points) < options.min_track_frames:
        return False
    span = points[-1][2] - points[0][2] + 1
    if len(points) < options.min_hit_ratio * span:
        return False
    times = np.array([t for t, _, _ in points])
    xy = np.array([p for _, p, _ in points])
    position, velocity = constant_velocity(times, xy)
    residual = xy - (position + np.outer(times - times[-1], velocity))
    return float(np.sqrt(np.mean(np.sum(residual ** 2, axis=1)))) <= options.max_track_residual


def _confirmed(scene: Scene, frames: list[Frame], groups, weak, path, messages, options) -> Association:
    """The association without the detections of unconfirmed tracks: never seen by two cameras at once, and not
    moving steadily over ``min_track_frames`` frames (a detector's flicker, or false detections chained)."""
    most_cameras: dict[str, int] = {}
    for frame_groups in groups:
        for vid, g in frame_groups.items():
            most_cameras[vid] = max(most_cameras.get(vid, 0), len(g))
    unconfirmed = {vid for vid in most_cameras if most_cameras[vid] < 2 and not _steady(path.get(vid, []), options)}
    left_out, kept, out_frames = [], [], []
    for f, frame in enumerate(frames):
        keep = []
        for j, d in enumerate(frame.detections):
            if (f, j) in weak:
                left_out.append((f, j, "too few keypoints to associate or to solve alone"))
            elif any(j in g for vid, g in groups[f].items() if vid in unconfirmed):
                left_out.append((f, j, f"a track never seen by two cameras at once and not moving steadily over "
                                       f"{options.min_track_frames} frames (a flicker of the detector, as a false "
                                       "detection is)"))
            else:
                keep.append(j)
        kept.append(keep)
        out_frames.append(Frame(frame.t, [frame.detections[j] for j in keep], frame.images))
        groups[f] = {vid: g for vid, g in groups[f].items() if all(j in keep for j in g)}
    return Association(dataclasses.replace(scene, frames=out_frames), groups, kept, left_out, messages)
