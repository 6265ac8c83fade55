"""Keys of vfactor's variables in a GTSAM graph, under a configurable scheme.

Every variable is a ``gtsam.Symbol``: a character and an index. The default
scheme uses ``x`` for vehicle poses (``world_T_vehicle``, one per vehicle per
frame) and ``w``, ``l``, ``r`` for the wheel, light and roof shape layers (one
12-vector each per vehicle, shared by all frames of its track), ``o`` for
a track's detector pose offsets (a ``gtsam.Pose3`` per camera that sees it,
where the detections carry a ``shape_sigma``, and one all its cameras share,
where they carry a ``bias_sigma``), and ``h`` for a track's hub
height above a given road plane (a 1-vector, metres: its wheel radius, shared
by its poses). Choose other characters when those collide with a graph of your
own.

Index layout: a pose of vehicle ``v`` in frame ``f`` has index
``v * frame_stride + f``; a layer of vehicle ``v`` has index ``v``; offset
``j`` of vehicle ``v`` has index ``v * frame_stride + j``; the hub height of vehicle ``v`` has index ``v``.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam

from vfactor.keypoints import LAYER_NAMES

__all__ = ["KeyScheme"]


@dataclass(frozen=True)
class KeyScheme:
    """Which ``gtsam.Symbol`` characters vfactor's variables use.

    Attributes:
        pose: character of ``world_T_vehicle`` (``gtsam.Pose3``) keys.
        wheel: character of the wheel layer (12-vector, body frame, metres).
        light: character of the light layer.
        roof: character of the roof layer.
        offset: character of a track's detector pose offsets (``vehicle_T_seen``, ``gtsam.Pose3``; one per
            camera that sees the track, where its detections carry a ``shape_sigma``, and the one its cameras
            share, where they carry a ``bias_sigma``).
        hub: character of a track's hub height above the road plane (a 1-vector, metres; where a plane is given).
        frame_stride: pose index = vehicle * frame_stride + frame (and offset index = vehicle *
            frame_stride + offset number).
    """

    pose: str = "x"
    wheel: str = "w"
    light: str = "l"
    roof: str = "r"
    offset: str = "o"
    hub: str = "h"
    frame_stride: int = 1_000_000

    def __post_init__(self):
        names = ("pose", "wheel", "light", "roof", "offset", "hub")
        chars = tuple(getattr(self, name) for name in names)
        for name, c in zip(names, chars):  # a GTSAM symbol's character is one byte; 0 would make plain integer keys
            if not isinstance(c, str) or len(c) != 1 or not (c.isascii() and c.isprintable() and not c.isspace()):
                raise ValueError(f"KeyScheme.{name}: expected a single printable ASCII character, got {c!r}")
        if len(set(chars)) != len(chars):
            raise ValueError(f"KeyScheme: the six characters must differ, got {chars}")
        if not isinstance(self.frame_stride, int) or isinstance(self.frame_stride, bool) or \
                not 1 <= self.frame_stride <= _MAX_STRIDE:
            raise ValueError(f"KeyScheme.frame_stride: expected an integer from 1 to 2^40, got {self.frame_stride!r}")

    def pose_key(self, vehicle: int = 0, frame: int = 0) -> int:
        """Key of ``world_T_vehicle`` of vehicle ``vehicle`` in frame ``frame``."""
        if not 0 <= frame < self.frame_stride:
            raise ValueError(f"frame: expected 0 <= frame < {self.frame_stride}, got {frame}")
        return gtsam.symbol(self.pose, _index(vehicle * self.frame_stride + frame, vehicle))

    def offset_key(self, vehicle: int = 0, number: int = 0) -> int:
        """Key of a vehicle's detector pose offset number ``number`` (a track numbers its offsets as it makes
        them: one per camera and the common one, a new one where the smoother has marginalised the previous)."""
        if not 0 <= number < self.frame_stride:
            raise ValueError(f"number: expected 0 <= number < {self.frame_stride}, got {number}")
        return gtsam.symbol(self.offset, _index(vehicle * self.frame_stride + number, vehicle))

    def hub_key(self, vehicle: int = 0) -> int:
        """Key of a vehicle's hub height above the road plane (a 1-vector, metres), shared by the poses of its
        track (:func:`vfactor.factors.ground_plane.hub_height_prior`)."""
        return gtsam.symbol(self.hub, _index(vehicle, vehicle))

    def layer_key(self, layer: str, vehicle: int = 0) -> int:
        """Key of one shape layer ("wheel", "light" or "roof") of a vehicle."""
        char = {"wheel": self.wheel, "light": self.light, "roof": self.roof}.get(layer)
        if char is None:
            raise ValueError(f"layer: expected one of {LAYER_NAMES}, got {layer!r}")
        return gtsam.symbol(char, _index(vehicle, vehicle))

    def layer_keys(self, vehicle: int = 0) -> tuple[int, int, int]:
        """Keys of the (wheel, light, roof) layers of a vehicle."""
        return tuple(self.layer_key(name, vehicle) for name in LAYER_NAMES)


_MAX_STRIDE = 2 ** 40  # a symbol's index has 56 bits: 2^16 vehicles at the largest stride
_MAX_INDEX = 2 ** 56


def _index(index: int, vehicle: int) -> int:
    """A symbol's index, checked: a vehicle index below 0 (or too large for the 56 bits) is a one-line error."""
    if not 0 <= index < _MAX_INDEX or vehicle < 0:
        raise ValueError(f"vehicle: expected an index from 0 whose keys fit GTSAM's 56-bit symbol index, got {vehicle}")
    return index
