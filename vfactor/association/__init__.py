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

from vfactor.association.cross_camera import AssociationOptions, FrameGroups, associate_frame
from vfactor.association.linking import Track, TrackLinker
from vfactor.observations import UNASSIGNED, Frame, Scene
from vfactor.track import frame_order

__all__ = ["AssociationOptions", "Association", "FrameGroups", "Track", "TrackLinker", "associate_frame",
           "associate_scene"]


@dataclass
class Association:
    """What :func:`associate_scene` found.

    Attributes:
        scene: the scene with every associated detection's ``vehicle`` set (the detections in their order).
        groups: per frame (scene order), vehicle id -> the indices of its detections in the frame's
            ``detections``; empty for frames that were left as they were (their ids given).
        single_view: per frame, the vehicle ids seen by one camera only.
        messages: notes (cameras split off a group, frames out of time order).
    """

    scene: Scene
    groups: list[dict[str, list[int]]]
    single_view: list[list[str]]
    messages: list[str] = field(default_factory=list)

    @property
    def vehicle_ids(self) -> list[str]:
        """Every vehicle id made, in order of first appearance."""
        return list(dict.fromkeys(vid for frame in self.groups for vid in frame))


def associate_scene(scene: Scene, options: AssociationOptions = AssociationOptions(), force: bool = False,
                    progress: Callable[[int, int], None] | None = None) -> Association:
    """Gives every detection of the scene that names no vehicle its vehicle (see the module docstring).

    Frames are associated in time order; the ids made are ``t1``, ``t2``, ... (never one the scene already
    uses) and follow a vehicle through the frames as far as the linking can.

    Args:
        scene: the scene; frames whose detections are :data:`~vfactor.observations.UNASSIGNED` are associated.
        options: the association's settings.
        force: associate every frame, ignoring the vehicle ids the scene gives (ids that are not trusted).
        progress: called with (frames done, frames) after each frame.

    Returns:
        The :class:`Association`: the scene with ids, and per frame which detections each vehicle has.

    Raises:
        InputError: a detection still waits for the keypoint network (it has no keypoints to associate by).
    """
    pending = scene.undetected()
    if pending:
        scene.require_keypoints()  # names the first detection that still waits for the keypoint network
    taken = set() if force else {d.vehicle for f in scene.frames for d in f.detections if d.vehicle != UNASSIGNED}
    linker = TrackLinker(options, taken=taken)
    frames = list(scene.frames)
    groups: list[dict[str, list[int]]] = [{} for _ in frames]
    single: list[list[str]] = [[] for _ in frames]
    messages: list[str] = []
    order = frame_order(scene)
    for n, f in enumerate(order):
        frame = frames[f]
        todo = [j for j, d in enumerate(frame.detections) if force or d.vehicle == UNASSIGNED]
        if todo:
            found = associate_frame(frame, scene.cameras, options, todo)
            messages += [f"frames[{f}]: {m}" for m in found.messages]
            positions = [r.world_T_vehicle.translation()[:2] if r.ok else None for r in found.results]
            camera_tracks = [{(frame.detections[j].camera, frame.detections[j].track) for j in g
                              if frame.detections[j].track is not None} for g in found.groups]
            ids = linker.link(frame.t, positions, camera_tracks)
            vehicle_of = {j: vid for vid, g in zip(ids, found.groups) for j in g}
            frames[f] = Frame(frame.t, [dataclasses.replace(d, vehicle=vehicle_of[j]) if j in vehicle_of else d
                                        for j, d in enumerate(frame.detections)], frame.images)
            groups[f] = {vid: list(g) for vid, g in zip(ids, found.groups)}
            single[f] = [vid for vid, g in zip(ids, found.groups) if len(g) == 1]
        if progress is not None:
            progress(n + 1, len(order))
    return Association(dataclasses.replace(scene, frames=frames), groups, single, messages)
