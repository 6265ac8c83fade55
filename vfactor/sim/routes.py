"""Vehicle routes on the road: planar paths, speed profiles with stops, and the trajectories they make.

A :class:`Trajectory` is a :class:`Path` (straight lines and circular arcs, by
arc length) driven with a :class:`SpeedProfile` (piecewise-constant
acceleration: cruise, brake to a stop, wait, accelerate again). The vehicle is
non-holonomic: it always moves along its heading, which is the path's tangent,
and its yaw rate is ``speed * curvature``. It stands on the road (roll = pitch
= 0, hubs ``wheel_radius`` above ``z = 0``).

:func:`intersection_path` builds the path of a vehicle driving through a
four-way intersection whose roads run along the world x and y axes and cross
at the origin: a straight approach in its lane, an optional quarter-turn arc of
radius ``R`` to the left or right, and a straight exit. Traffic drives on the
right when ``lane_offset > 0`` (on the left when it is negative).

Everything here is deterministic; the random draws live in
:mod:`vfactor.sim.simulate`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import gtsam
import numpy as np

from vfactor.sim.vehicles import road_pose

__all__ = [
    "ARMS",
    "TURNS",
    "Path",
    "SpeedProfile",
    "drive_profile",
    "Trajectory",
    "TrajectoryStates",
    "IntersectionRoute",
    "intersection_path",
]

#: Arm of the intersection a vehicle comes from -> its heading on the approach, degrees.
ARMS: dict[str, float] = {"west": 0.0, "south": 90.0, "east": 180.0, "north": 270.0}

#: Manoeuvres at the intersection -> turn angle, degrees (left positive).
TURNS: dict[str, float] = {"straight": 0.0, "left": 90.0, "right": -90.0}

# A closed loop must end within these of its start.
_CLOSE_POSITION = 0.05
_CLOSE_YAW = math.radians(0.5)


def _wrap(angle):
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi


@dataclass(frozen=True)
class Path:
    """A planar path of straight segments and circular arcs, parametrised by arc length ``s``.

    Before ``s = 0`` the path continues straight backwards from its start, after
    its end straight on from its end pose; a closed loop (``loop=True``)
    repeats instead (``s`` is taken modulo the loop's length).

    Attributes:
        start: ``(x, y, yaw)`` at ``s = 0``: world metres and radians (yaw from world x, counter-clockwise).
        segments: ``(length, curvature)`` pairs: metres and 1/metres, curvature
            positive for a left (counter-clockwise) turn, 0 for a straight.
        loop: the path is closed and repeats.
    """

    start: tuple[float, float, float]
    segments: tuple[tuple[float, float], ...] = ()
    loop: bool = False
    _starts: np.ndarray = field(init=False, repr=False, compare=False)
    _s: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        for length, curvature in self.segments:
            if not (length > 0 and math.isfinite(length) and math.isfinite(curvature)):
                raise ValueError(
                    f"Path: a segment needs a positive length and a finite curvature, got {(length, curvature)}"
                )
        poses = [tuple(float(v) for v in self.start)]
        s = [0.0]
        for length, curvature in self.segments:
            poses.append(_advance(poses[-1], length, curvature))
            s.append(s[-1] + length)
        object.__setattr__(self, "_starts", np.array(poses))
        object.__setattr__(self, "_s", np.array(s))
        if self.loop:
            if not self.segments:
                raise ValueError("Path: a loop needs at least one segment")
            end, begin = self._starts[-1], self._starts[0]
            gap = float(np.hypot(*(end[:2] - begin[:2])))
            turn = abs(float(_wrap(end[2] - begin[2])))
            if gap > _CLOSE_POSITION or turn > _CLOSE_YAW:
                raise ValueError(
                    f"Path: the loop does not close: it ends {gap:.3f} m and {math.degrees(turn):.2f} deg "
                    "from its start"
                )

    @property
    def length(self) -> float:
        """Total length of the segments, metres (one lap of a loop)."""
        return float(self._s[-1])

    def end(self) -> tuple[float, float, float]:
        """``(x, y, yaw)`` at the end of the last segment."""
        return tuple(float(v) for v in self._starts[-1])

    def at(self, s) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(x, y, yaw, curvature)`` at arc lengths ``s`` (arrays of the shape of ``s``)."""
        s = np.asarray(s, dtype=float)
        flat = s.reshape(-1)
        if self.loop:
            flat = np.mod(flat, self.length)
        n = len(self.segments)
        # Segment index: -1 before the start (straight backwards), n after the end (straight on).
        index = np.searchsorted(self._s, flat, side="right") - 1
        if self.loop:
            index = np.clip(index, 0, n - 1)
        index = np.where(flat < 0.0, -1, np.minimum(index, n))
        out = np.empty((4, len(flat)))
        for i in np.unique(index):
            sel = index == i
            if i < 0:
                base, d, curvature = self._starts[0], flat[sel], 0.0
            elif i >= n:
                base, d, curvature = self._starts[n], flat[sel] - self._s[n], 0.0
            else:
                base, d, curvature = self._starts[i], flat[sel] - self._s[i], self.segments[i][1]
            x, y, yaw = _advance_many(base, d, curvature)
            out[0, sel], out[1, sel], out[2, sel], out[3, sel] = x, y, yaw, curvature
        out[2] = _wrap(out[2])
        return tuple(a.reshape(s.shape) for a in out)


def _advance(pose, length, curvature):
    x, y, yaw = _advance_many(np.asarray(pose, dtype=float), np.array([length]), curvature)
    return float(x[0]), float(y[0]), float(yaw[0])


def _advance_many(base, d, curvature):
    """Poses at distances ``d`` along a segment of constant curvature starting at ``base``."""
    x0, y0, yaw0 = (float(v) for v in base)
    d = np.asarray(d, dtype=float)
    if curvature == 0.0:
        return x0 + d * math.cos(yaw0), y0 + d * math.sin(yaw0), np.full_like(d, yaw0)
    yaw = yaw0 + curvature * d
    return (
        x0 + (np.sin(yaw) - math.sin(yaw0)) / curvature,
        y0 - (np.cos(yaw) - math.cos(yaw0)) / curvature,
        yaw,
    )


@dataclass(frozen=True, eq=False)
class SpeedProfile:
    """Arc length, speed and acceleration over time: phases of constant acceleration.

    Phase ``i`` starts at time ``t[i]`` at arc length ``s[i]`` with speed
    ``v[i]`` and keeps the acceleration ``a[i]`` until the next phase starts; the
    last phase lasts for ever. Before ``t[0]`` the first phase is extrapolated
    (a vehicle cruising in from far away).

    Attributes:
        t, s, v, a: (P,) phase start times (s, increasing), arc lengths (m),
            speeds (m/s) and accelerations (m/s^2).
    """

    t: np.ndarray
    s: np.ndarray
    v: np.ndarray
    a: np.ndarray

    def state(self, times) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(s, speed, acceleration)`` at ``times`` (arrays of the shape of ``times``)."""
        times = np.asarray(times, dtype=float)
        i = np.clip(np.searchsorted(self.t, times, side="right") - 1, 0, len(self.t) - 1)
        tau = times - self.t[i]
        a = self.a[i]
        s = self.s[i] + self.v[i] * tau + 0.5 * a * tau * tau
        v = np.maximum(self.v[i] + a * tau, 0.0)
        return s, v, a

    def time_at(self, s: float) -> float:
        """The first time at which the arc length reaches ``s`` (before ``t[0]``: the first phase extrapolated)."""
        s = float(s)
        if s < self.s[0]:
            if abs(self.a[0]) < 1e-12 and self.v[0] > 0:
                return float(self.t[0] + (s - self.s[0]) / self.v[0])
            raise ValueError(f"SpeedProfile.time_at: the arc length {s} lies before the profile starts")
        for i in range(len(self.t)):
            s_end = self.s[i + 1] if i + 1 < len(self.t) else math.inf
            if s > s_end + 1e-12:
                continue
            ds, v, a = s - self.s[i], self.v[i], self.a[i]
            if abs(a) < 1e-12:
                if v > 0:
                    return float(self.t[i] + ds / v)
                if ds <= 1e-9:
                    return float(self.t[i])
                continue
            return float(self.t[i] + (math.sqrt(max(v * v + 2.0 * a * ds, 0.0)) - v) / a)
        raise ValueError(f"SpeedProfile.time_at: the arc length {s} is never reached")

    def shifted(self, dt: float) -> "SpeedProfile":
        """The same profile ``dt`` seconds later."""
        return SpeedProfile(self.t + dt, self.s, self.v, self.a)


def drive_profile(
    cruise: float,
    accel: float,
    decel: float,
    stops=(),
    s0: float = 0.0,
    t0: float = 0.0,
    v0: float | None = None,
) -> SpeedProfile:
    """The speed profile of a vehicle that drives at ``cruise`` speed and halts at each stop.

    From ``(t0, s0)`` at speed ``v0`` (default ``cruise``), the vehicle
    accelerates at ``accel`` up to ``cruise``, cruises, and brakes at ``decel``
    to come to rest exactly at each stop's arc length, waits there, and sets off
    again; where two stops are too close to reach ``cruise`` between them it
    brakes from a lower peak speed. After the last stop it accelerates back to
    ``cruise`` and cruises for ever. If ``v0`` is too fast to stop at the first
    stop at ``decel``, it is lowered to ``sqrt(2 * decel * distance)`` (the
    vehicle was already braking).

    Args:
        cruise: cruise speed, m/s (> 0).
        accel: acceleration when speeding up, m/s^2 (> 0).
        decel: deceleration when braking, m/s^2 (> 0).
        stops: ``(arc_length, wait_seconds)`` pairs, arc lengths increasing and >= ``s0``.
        s0: arc length at ``t0``.
        t0: start time, s.
        v0: speed at ``t0`` (``0 <= v0 <= cruise``); default ``cruise``.
    """
    if not (cruise > 0 and accel > 0 and decel > 0):
        raise ValueError(f"drive_profile: cruise, accel and decel must be > 0, got {cruise}, {accel}, {decel}")
    v = cruise if v0 is None else float(v0)
    if not 0.0 <= v <= cruise + 1e-12:
        raise ValueError(f"drive_profile: v0 must be within [0, cruise={cruise}], got {v0}")
    phases: list[tuple[float, float, float, float]] = []
    t, s = float(t0), float(s0)

    def add(duration, a):
        nonlocal t, s, v
        if duration <= 0.0:
            return
        phases.append((t, s, v, a))
        t += duration
        s += v * duration + 0.5 * a * duration * duration
        v = max(v + a * duration, 0.0)

    for s_stop, wait in stops:
        distance = s_stop - s
        if distance < -1e-9:
            raise ValueError(f"drive_profile: stop at {s_stop} m lies behind the vehicle at {s} m")
        distance = max(distance, 0.0)
        if v * v / (2.0 * decel) > distance:
            v = math.sqrt(2.0 * decel * distance)
        d_accel = (cruise * cruise - v * v) / (2.0 * accel)
        d_brake = cruise * cruise / (2.0 * decel)
        if d_accel + d_brake <= distance:
            add((cruise - v) / accel, accel)
            add((distance - d_accel - d_brake) / cruise, 0.0)
            peak = cruise
        else:
            peak = math.sqrt((distance + v * v / (2.0 * accel)) / (0.5 / accel + 0.5 / decel))
            peak = max(peak, v)
            add((peak - v) / accel, accel)
        add(peak / decel, -decel)
        s, v = float(s_stop), 0.0  # exactly at rest at the stop
        add(wait, 0.0)
    add((cruise - v) / accel, accel)
    phases.append((t, s, v, 0.0))
    t_, s_, v_, a_ = (np.array(c, dtype=float) for c in zip(*phases))
    return SpeedProfile(t_, s_, v_, a_)


@dataclass
class TrajectoryStates:
    """A trajectory sampled at times; every array has one entry per time.

    Attributes:
        t: times, s.
        x, y: hub-centroid position on the road, world metres.
        yaw: heading, radians in [-pi, pi).
        speed: forward speed along the heading, m/s (>= 0).
        yaw_rate: rad/s (``speed * curvature``).
        acceleration: longitudinal acceleration, m/s^2.
        curvature: path curvature, 1/m.
        s: arc length along the path, m.
        exists: whether the vehicle is in the scene at that time.
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    yaw_rate: np.ndarray
    acceleration: np.ndarray
    curvature: np.ndarray
    s: np.ndarray
    exists: np.ndarray


@dataclass(frozen=True)
class Trajectory:
    """A vehicle driving a path with a speed profile, on the road.

    Attributes:
        path: the path (arc length ``s``).
        profile: ``s``, speed and acceleration over time.
        wheel_radius: hub height above the road, metres.
        start_time: the vehicle exists from this time on (None: always).
        scene_radius: the vehicle exists only while its hub centroid is within this
            distance of the world origin, metres (None: anywhere).
        info: how the trajectory was made (route parameters after the random draws).
    """

    path: Path
    profile: SpeedProfile
    wheel_radius: float = 0.33
    start_time: float | None = None
    scene_radius: float | None = None
    info: dict = field(default_factory=dict, compare=False)

    def states(self, times) -> TrajectoryStates:
        """The state at each of ``times`` (s)."""
        times = np.atleast_1d(np.asarray(times, dtype=float))
        s, speed, acceleration = self.profile.state(times)
        x, y, yaw, curvature = self.path.at(s)
        exists = np.ones(len(times), bool)
        if self.start_time is not None:
            exists &= times >= self.start_time - 1e-9
        if self.scene_radius is not None:
            exists &= np.hypot(x, y) <= self.scene_radius
        return TrajectoryStates(
            times, x, y, yaw, speed, speed * curvature, acceleration, curvature, s, exists
        )

    def pose(self, t: float) -> gtsam.Pose3:
        """``world_T_vehicle`` at time ``t``."""
        st = self.states([t])
        return road_pose(float(st.x[0]), float(st.y[0]), float(st.yaw[0]), self.wheel_radius)


@dataclass(frozen=True)
class IntersectionRoute:
    """A route through the intersection at the origin, in route coordinates.

    Attributes:
        path: the path; its arc length is the route coordinate minus ``offset``.
        offset: route coordinate of the path's ``s = 0``.
        stop_s: route coordinate of the stop point (on the approach).
        middle_s: route coordinate of the middle of the manoeuvre (0 when straight).
        turn_start_s: route coordinate where the turn begins (None when straight).
    """

    path: Path
    offset: float
    stop_s: float
    middle_s: float
    turn_start_s: float | None


def intersection_path(
    arm: str, turn: str, radius: float, lane_offset: float = 1.75, stop_at: float = 7.0
) -> IntersectionRoute:
    """The path of a vehicle driving through the intersection of two roads along the world axes.

    The route coordinate runs along the path, 0 abeam the intersection centre on
    the approach lane (the approach lane is the line at ``-lane_offset`` to the
    right of the centre, heading into the intersection from ``arm``). A turn is
    a 90 degree arc of ``radius`` tangent to the approach lane and to the exit
    lane (``lane_offset`` to the right of the centre on the exit road), so it
    begins ``radius`` before the lanes' corner.

    Args:
        arm: where the vehicle comes from: ``"west"``, ``"south"``, ``"east"`` or ``"north"``.
        turn: ``"straight"``, ``"left"`` or ``"right"``.
        radius: turn radius of the hub centroid, metres (ignored when straight).
        lane_offset: distance of the lanes from the road axes, metres (negative: left-hand traffic).
        stop_at: distance of the stop point before the centre along the approach,
            metres; a vehicle that must stop halts there, or where its turn begins if that comes first.
    """
    heading = math.radians(ARMS[arm])
    c, s_ = math.cos(heading), math.sin(heading)

    def world(x, y):  # canonical (approach heading +x, centre at the origin) -> world
        return c * x - s_ * y, s_ * x + c * y

    if turn == "straight":
        start_x = 0.0
        segments: tuple = ()
        middle = 0.0
        turn_start = None
    else:
        sign = 1.0 if turn == "left" else -1.0
        corner_x = sign * lane_offset
        start_x = corner_x - radius
        segments = ((0.5 * math.pi * radius, sign / radius),)
        middle = start_x + 0.25 * math.pi * radius
        turn_start = start_x
    x, y = world(start_x, -lane_offset)
    path = Path((x, y, heading), segments)
    stop_s = -stop_at if turn_start is None else min(-stop_at, turn_start)
    return IntersectionRoute(path, start_x, stop_s, middle, turn_start)
