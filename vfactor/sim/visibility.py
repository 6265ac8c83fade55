"""Which keypoints a camera cannot see because a vehicle body is in the way.

A vehicle body is modelled as a convex polytope: the convex hull of its 12
keypoints, of its wheel hubs pushed sideways out to the body side (a wheel is
seen by its outer face), of the road points under those pushed hubs and of the
fender tops above them (the pushed hubs raised to the height of the lights at
the same end, so that the body keeps its full width up to the lights). A
keypoint is hidden from a camera when the segment from the camera centre to
the keypoint runs through the inside of a body: its own (self-occlusion; the
last ``tail`` metres are ignored because the keypoint lies on its own hull) or
another vehicle's.

The segment test is exact (Cyrus-Beck clipping against the hull's facet
planes), not sampled.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
from scipy.spatial import ConvexHull

from vfactor.camera import Camera
from vfactor.keypoints import LAYERS
from vfactor.wireframe import Wireframe

__all__ = ["HUB_PUSH", "VehicleBody", "occluded_keypoints", "self_occluded"]

#: Default sideways distance from a wheel hub keypoint to the body side, metres.
HUB_PUSH = 0.10

_INSET = 1e-3  # a segment must go this deep (m) inside a facet plane to count as inside
_TAIL = 0.05  # ignore the last 5 cm of a segment to a keypoint of the same body


@dataclass(frozen=True)
class VehicleBody:
    """The convex body of one vehicle in the world frame.

    Attributes:
        world_p_hull: (N, 3) points whose convex hull is the body, metres.
        world_p_targets: (12, 3) the points tested for visibility: the keypoints,
            with each wheel hub replaced by its pushed-out point on the body side.
        facets: (F, 4) hull facet planes ``[n, d]`` with ``n . x + d <= 0`` inside
            (``n`` unit, outward).
    """

    world_p_hull: np.ndarray
    world_p_targets: np.ndarray
    facets: np.ndarray

    @classmethod
    def from_vehicle(
        cls, wireframe: Wireframe, world_T_vehicle: gtsam.Pose3, wheel_radius: float, hub_push: float = HUB_PUSH
    ) -> "VehicleBody":
        """Builds the body of a vehicle standing on its wheels.

        Args:
            wireframe: body-frame keypoints, metres.
            world_T_vehicle: vehicle pose.
            wheel_radius: hub height above the road, metres (the road is body ``z = -wheel_radius``).
            hub_push: how far each hub is pushed sideways (away from ``y = 0``) to the body side, metres.
        """
        p = np.array(wireframe.vehicle_p_keypoints)
        hubs = list(LAYERS["wheel"])
        targets = p.copy()
        targets[hubs, 1] += np.sign(p[hubs, 1]) * hub_push
        road = targets[hubs].copy()
        road[:, 2] = -wheel_radius
        # The body side over each wheel reaches up to the lights of that end (the fender top).
        fenders = targets[hubs].copy()
        fenders[:, 2] = p[list(LAYERS["light"]), 2]
        vehicle_p_hull = np.concatenate([p, targets[hubs], road, fenders])
        T = world_T_vehicle.matrix()
        world_p_hull = vehicle_p_hull @ T[:3, :3].T + T[:3, 3]
        world_p_targets = targets @ T[:3, :3].T + T[:3, 3]
        return cls(world_p_hull, world_p_targets, ConvexHull(world_p_hull).equations)

    def blocks(self, origin, targets, tail: float = 0.0) -> np.ndarray:
        """Whether the segments from ``origin`` to each target pass through the body.

        Args:
            origin: (3,) segment start (a camera centre), world metres.
            targets: (M, 3) segment ends, world metres.
            tail: length at the end of each segment that is ignored, metres.

        Returns:
            (M,) boolean: True where some part of ``[origin, target - tail]`` is
            deeper than 1 mm inside the body.
        """
        origin = np.asarray(origin, dtype=float).reshape(3)
        targets = np.asarray(targets, dtype=float).reshape(-1, 3)
        delta = targets - origin
        length = np.linalg.norm(delta, axis=1)
        normals, offsets = self.facets[:, :3], self.facets[:, 3]
        start = normals @ origin + offsets + _INSET  # (F,): inside when start + t * rate <= 0
        rate = delta @ normals.T  # (M, F)
        t_enter = np.zeros(len(targets))
        t_exit = 1.0 - tail / np.maximum(length, 1e-12)
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = -start / rate
        entering, leaving = rate < -1e-12, rate > 1e-12
        t_enter = np.maximum(t_enter, np.where(entering, bound, -np.inf).max(axis=1))
        t_exit = np.minimum(t_exit, np.where(leaving, bound, np.inf).min(axis=1))
        parallel_outside = (~entering & ~leaving & (start > 0)).any(axis=1)
        return (t_exit > t_enter) & ~parallel_outside


def occluded_keypoints(
    camera_center, body: VehicleBody, others: tuple[VehicleBody, ...] | list[VehicleBody] = (), tail: float = _TAIL
) -> np.ndarray:
    """(12,) mask of a vehicle's keypoints hidden from a camera centre.

    Args:
        camera_center: (3,) camera centre, world metres.
        body: the vehicle whose keypoints are tested.
        others: bodies of other vehicles that may stand in the way.
        tail: length at the end of each segment ignored for the vehicle's own body, metres.
    """
    hidden = body.blocks(camera_center, body.world_p_targets, tail=tail)
    for other in others:
        hidden |= other.blocks(camera_center, body.world_p_targets)
    return hidden


def self_occluded(
    camera: Camera, wireframe: Wireframe, world_T_vehicle: gtsam.Pose3, wheel_radius: float, hub_push: float = HUB_PUSH
) -> np.ndarray:
    """(12,) mask of the keypoints a vehicle hides from ``camera`` by itself."""
    body = VehicleBody.from_vehicle(wireframe, world_T_vehicle, wheel_radius, hub_push)
    return occluded_keypoints(camera.center, body)
