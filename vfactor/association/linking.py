"""Vehicles of consecutive frames linked into tracks: a gated optimal assignment on predicted positions.

Each track predicts where its vehicle is at the next frame's time: constant
velocity fitted by weighted least squares to its last five positions on the
road plane, a position seen by one camera only weighing ``single_view_weight``
(its depth is metres off, which would otherwise skew the velocity), and left
out of a track of two positions whose other one two cameras saw (two
positions define a velocity exactly, whatever their weights); a track whose
speed is not known yet (one position fitted) may have moved up to
``max_speed`` times the time since it. A frame's
vehicles are assigned to the live tracks by the Hungarian method
(:func:`scipy.optimize.linear_sum_assignment`) on the distance between
prediction and position, minus ``track_bonus`` where the vehicle holds a
camera track id (``Detection.track``) that the track held, and gated at
``link_distance`` plus what the motion allows over the step. The distance to
a vehicle seen by one camera only, whose camera track id the track held, is
shaped like its uncertainty (:func:`ray_distance`): its depth, along its
camera's ray, is metres off (about a tenth of the distance), its direction is
not, so the offset along the ray counts ``link_distance / (link_distance +
single_view_depth * depth)`` of its length and the offset across it in full.
A single view its camera's tracker does not tie to the track is measured as
it is: a false detection that happens to lie along a track's ray would
continue it otherwise. A track that may itself be a false detection's (fewer
than ``min_track_frames`` positions, none seen by two cameras at once) is not
continued by a vehicle whose camera track ids are all others': its gate is wide
(its speed unknown), and geometry alone would let a false detection's track
take over a vehicle coming into view. An unassigned
vehicle starts a track; a track without a vehicle for ``max_missed`` seconds
ends, and one that finds its vehicle again within them keeps its id.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vfactor.association.cross_camera import AssociationOptions

__all__ = ["Track", "TrackLinker", "constant_velocity", "ray_distance"]

_FAR = 1e9  # cost of a link outside the gate
_FIT_POSITIONS = 5  # positions of a track its velocity is fitted to


def constant_velocity(times: np.ndarray, xy: np.ndarray, weights: np.ndarray | None = None):
    """Weighted least-squares constant velocity through positions: (position at the last time, velocity).

    Args:
        times: (n,) seconds, not all equal.
        xy: (n, 2) world x, y, metres.
        weights: (n,) weights of the positions (default: equal).

    Returns:
        (2,) position at ``times[-1]`` (metres) and (2,) velocity (m/s) of the fitted line.
    """
    w = np.sqrt(np.ones(len(times)) if weights is None else np.asarray(weights, dtype=float))
    design = np.stack([np.ones(len(times)), np.asarray(times, dtype=float) - times[-1]], axis=1) * w[:, None]
    coefficients, *_ = np.linalg.lstsq(design, np.asarray(xy, dtype=float) * w[:, None], rcond=None)
    return coefficients[0], coefficients[1]


def ray_distance(offset: np.ndarray, position: np.ndarray, viewpoint: np.ndarray | None,
                 options: AssociationOptions) -> float:
    """The linking's distance (metres) of an ``offset`` from a vehicle's ``position`` (world x, y, metres).

    For a vehicle seen by several cameras (``viewpoint`` None) the offset's length. For one seen by one camera
    only, whose centre lies at ``viewpoint`` (world x, y), the offset along the ray from the camera through the
    position is shortened by ``link_distance / (link_distance + single_view_depth * depth)`` (``depth``: the
    position's distance from the camera on the road): a single view's depth is uncertain by about
    ``single_view_depth`` of it, its direction by far less. Across the ray the offset counts in full.
    """
    offset = np.asarray(offset, dtype=float)
    if viewpoint is None:
        return float(np.linalg.norm(offset))
    ray = np.asarray(position, dtype=float) - np.asarray(viewpoint, dtype=float)
    depth = float(np.linalg.norm(ray))
    if depth < 1e-6:
        return float(np.linalg.norm(offset))
    u = ray / depth
    along = float(offset @ u)
    across = offset - along * u
    spread = options.link_distance + options.single_view_depth * depth
    scale = options.link_distance / spread if spread > 0 else 1.0
    return float(np.sqrt(across @ across + (scale * along) ** 2))


@dataclass
class Track:
    """A track of the linker: its id, positions over time and the camera track ids it holds."""

    id: str
    times: list[float] = field(default_factory=list)
    positions: list[np.ndarray] = field(default_factory=list)  # (2,) world x, y, metres
    weights: list[float] = field(default_factory=list)  # of each position in the velocity fit
    camera_tracks: set = field(default_factory=set)  # (camera, camera track id) pairs seen last
    seen_together: bool = False  # whether any of its positions was seen by two cameras at once

    def _fit(self) -> tuple[float, np.ndarray, np.ndarray | None]:
        """The time, position and velocity (None while unknown) of the constant-velocity fit to the last five
        positions, weighted. Of a track of two, one seen by two cameras and one single view, the former alone: two
        positions define a velocity exactly, so no weight keeps the single view's depth error (metres along its
        camera's ray) out of it. On association_3cam at hard noise (seed 6, a tuning seed) that error became 73 m/s
        for a vehicle driving at 10, and its next, accurate position fell outside the track's gate; with three
        positions or more the weights do."""
        n = min(len(self.positions), _FIT_POSITIONS)
        times, positions, weights = (np.array(self.times[-n:]), np.array(self.positions[-n:]),
                                     np.array(self.weights[-n:]))
        several = weights >= 1.0  # seen by two cameras or more (single views weigh single_view_weight < 1)
        if n == 2 and several.sum() == 1:
            times, positions, weights = times[several], positions[several], weights[several]
        if len(times) < 2 or times[-1] <= times[0]:
            return float(times[-1]), positions[-1], None
        position, velocity = constant_velocity(times, positions, weights)
        return float(times[-1]), position, velocity

    def predict(self, t: float) -> np.ndarray:
        """The position at ``t`` seconds: the fitted position moved on at the fitted velocity (none while unknown)."""
        t_fit, position, velocity = self._fit()
        return position if velocity is None else position + velocity * (t - t_fit)

    def gate(self, t: float, options: AssociationOptions) -> float:
        """The largest distance (metres) from :meth:`predict` at which a vehicle may continue the track:
        ``link_distance`` plus ``max_speed`` times the time since the fitted position while the velocity is unknown,
        ``max_acceleration`` times its square once it is known."""
        t_fit, _, velocity = self._fit()
        dt = max(t - t_fit, 0.0)
        return options.link_distance + (options.max_speed * dt if velocity is None else options.max_acceleration * dt * dt)


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

    def link(self, t: float, positions: list[np.ndarray | None], camera_tracks: list[set],
             viewpoints: list[np.ndarray | None] | None = None) -> list[str]:
        """The track id of each of a frame's vehicles.

        Args:
            t: the frame's time, seconds (frames in time order).
            positions: per vehicle its (2,) world x, y (metres), or None where it was not solved (it then starts
                a track of its own and continues none).
            camera_tracks: per vehicle the (camera, camera track id) pairs of its detections.
            viewpoints: per vehicle seen by one camera only, that camera's centre (world x, y, metres): its
                distance to the prediction of a track that held its camera track id is :func:`ray_distance`'s,
                and its position weighs ``single_view_weight`` in its track's velocity fit; None for a vehicle
                of several cameras (default: every vehicle).

        Returns:
            Per vehicle the id of the track it continues or starts.
        """
        viewpoints = viewpoints or [None] * len(positions)
        single_view = [v is not None for v in viewpoints]
        live = [k for k in self.tracks if t - k.times[-1] <= self._reach(k) + 1e-9]
        cost = np.full((len(live), len(positions)), _FAR)
        for a, track in enumerate(live):
            predicted, gate = track.predict(t), track.gate(t, self.options)
            for b, p in enumerate(positions):
                if p is None:
                    continue
                shared = bool(track.camera_tracks & camera_tracks[b])
                if not shared and self._unconfirmed(track) and track.camera_tracks and camera_tracks[b]:
                    continue  # geometry alone does not continue a track that may be a false detection's
                # a single view's depth is metres off; measured along its ray only where its camera's tracker ties
                # it to the track (a false detection along a track's ray would continue it otherwise)
                distance = ray_distance(predicted - p, p, viewpoints[b] if shared else None, self.options)
                bonus = self.options.track_bonus if shared else 0.0
                if distance <= gate + bonus:
                    cost[a, b] = distance - bonus
        ids: list[str | None] = [None] * len(positions)
        if live and positions:
            from scipy.optimize import linear_sum_assignment  # scipy.optimize costs ~0.3 s to import: only when used

            rows, cols = linear_sum_assignment(cost)
            for a, b in zip(rows, cols):
                if cost[a, b] < _FAR:
                    ids[b] = live[a].id
                    live[a].times.append(t)
                    live[a].positions.append(np.asarray(positions[b], dtype=float))
                    live[a].weights.append(self.options.single_view_weight if single_view[b] else 1.0)
                    live[a].camera_tracks = set(camera_tracks[b])
                    live[a].seen_together |= not single_view[b]
        for b, p in enumerate(positions):
            if ids[b] is None:
                track = Track(self._new_id())
                if p is not None:
                    track.times.append(t)
                    track.positions.append(np.asarray(p, dtype=float))
                    track.weights.append(self.options.single_view_weight if single_view[b] else 1.0)
                    track.camera_tracks = set(camera_tracks[b])
                    track.seen_together = not single_view[b]
                    self.tracks.append(track)
                ids[b] = track.id
        self.tracks = [k for k in self.tracks if t - k.times[-1] <= self._reach(k) + 1e-9 or k.id in ids]
        return ids

    def _unconfirmed(self, track: Track) -> bool:
        """Whether a track may be a false detection's: fewer than ``min_track_frames`` positions, none seen by two
        cameras at once."""
        return len(track.positions) < self.options.min_track_frames and not track.seen_together

    def _reach(self, track: Track) -> float:
        """Seconds a track waits for its vehicle: ``max_missed``, or ``tentative_missed`` while it has fewer than
        ``min_track_frames`` positions (a track just born, or a false detection's, must not lie in wait with a
        gate grown wide)."""
        if len(track.positions) < self.options.min_track_frames:
            return min(self.options.tentative_missed, self.options.max_missed)
        return self.options.max_missed

