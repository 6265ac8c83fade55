"""Vehicles of consecutive frames linked into tracks: a gated optimal assignment on predicted positions.

Each track predicts where its vehicle is at the next frame's time (constant
velocity from its last two positions on the road plane; a track of one
position may have moved up to ``max_speed`` times the step). A frame's
vehicles are assigned to the live tracks by the Hungarian method
(:func:`scipy.optimize.linear_sum_assignment`) on the distance between
prediction and position, minus ``track_bonus`` where the vehicle holds a
camera track id (``Detection.track``) that the track held, and gated at
``link_distance`` plus what the motion allows over the step. An unassigned
vehicle starts a track; a track without a vehicle for ``max_missed`` seconds
ends, and one that finds its vehicle again within them keeps its id.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from vfactor.association.cross_camera import AssociationOptions

__all__ = ["Track", "TrackLinker"]

_FAR = 1e9  # cost of a link outside the gate


@dataclass
class Track:
    """A track of the linker: its id, positions over time and the camera track ids it holds."""

    id: str
    times: list[float] = field(default_factory=list)
    positions: list[np.ndarray] = field(default_factory=list)  # (2,) world x, y, metres
    camera_tracks: set = field(default_factory=set)  # (camera, camera track id) pairs seen last

    def predict(self, t: float) -> np.ndarray:
        """The position at ``t`` seconds under constant velocity from the last two positions."""
        if len(self.positions) < 2 or self.times[-1] <= self.times[-2]:
            return self.positions[-1]
        velocity = (self.positions[-1] - self.positions[-2]) / (self.times[-1] - self.times[-2])
        return self.positions[-1] + velocity * (t - self.times[-1])

    def gate(self, t: float, options: AssociationOptions) -> float:
        """The largest distance (metres) from :meth:`predict` at which a vehicle may continue the track."""
        dt = max(t - self.times[-1], 0.0)
        motion = options.max_speed * dt if len(self.positions) < 2 else options.max_acceleration * dt * dt
        return options.link_distance + motion


class TrackLinker:
    """Links each frame's vehicles to tracks (see the module docstring); ids ``prefix`` + a running number.

    Args:
        options: the association's settings.
        taken: ids already in use (the scene's own vehicle ids), never given out.
        prefix: the prefix of the ids made.
    """

    def __init__(self, options: AssociationOptions = AssociationOptions(), taken=(), prefix: str = "t"):
        self.options = options
        self.tracks: list[Track] = []
        self._taken = set(taken)
        self._prefix = prefix
        self._count = 0

    def _new_id(self) -> str:
        while True:
            self._count += 1
            name = f"{self._prefix}{self._count}"
            if name not in self._taken:
                self._taken.add(name)
                return name

    def link(self, t: float, positions: list[np.ndarray | None], camera_tracks: list[set]) -> list[str]:
        """The track id of each of a frame's vehicles.

        Args:
            t: the frame's time, seconds (frames in time order).
            positions: per vehicle its (2,) world x, y (metres), or None where it was not solved (it then starts
                a track of its own and continues none).
            camera_tracks: per vehicle the (camera, camera track id) pairs of its detections.

        Returns:
            Per vehicle the id of the track it continues or starts.
        """
        live = [k for k in self.tracks if t - k.times[-1] <= self.options.max_missed + 1e-9]
        cost = np.full((len(live), len(positions)), _FAR)
        for a, track in enumerate(live):
            predicted, gate = track.predict(t), track.gate(t, self.options)
            for b, p in enumerate(positions):
                if p is None:
                    continue
                distance = float(np.linalg.norm(p - predicted))
                shared = bool(track.camera_tracks & camera_tracks[b])
                if distance <= gate + (self.options.track_bonus if shared else 0.0):
                    cost[a, b] = distance - (self.options.track_bonus if shared else 0.0)
        ids: list[str | None] = [None] * len(positions)
        if live and positions:
            rows, cols = linear_sum_assignment(cost)
            for a, b in zip(rows, cols):
                if cost[a, b] < _FAR:
                    ids[b] = live[a].id
                    live[a].times.append(t)
                    live[a].positions.append(np.asarray(positions[b], dtype=float))
                    live[a].camera_tracks = set(camera_tracks[b])
        for b, p in enumerate(positions):
            if ids[b] is None:
                track = Track(self._new_id())
                if p is not None:
                    track.times.append(t)
                    track.positions.append(np.asarray(p, dtype=float))
                    track.camera_tracks = set(camera_tracks[b])
                    self.tracks.append(track)
                ids[b] = track.id
        self.tracks = [k for k in self.tracks if t - k.times[-1] <= self.options.max_missed + 1e-9 or k.id in ids]
        return ids

