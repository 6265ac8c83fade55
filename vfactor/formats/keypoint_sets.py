"""Other tools' vehicle keypoint definitions and how each gives vfactor's 12 keypoints.

A :class:`KeypointSet` names a detector's or data set's keypoints in its own
order and says, for every vfactor keypoint (:data:`vfactor.keypoints.KEYPOINT_NAMES`),
which of its points give it: one point (taken as is), several (their mean, seen
only when all are seen, with the confidence of the weakest), or none (the set
has no such point: the keypoint is not seen, confidence 0).

"Left" is the vehicle's own left in every set here, as in vfactor; the
evidence for each set is in docs/keypoint-sets.md, with the full tables and
where each order comes from. ``flip_pairs`` is each set's own left/right swap
table, transcribed from its source (mmpose's ``swap`` fields, OpenPifPaf's
``HFLIP_24`` / ``HFLIP_ids``); the tests check the mappings against it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vfactor.errors import InputError
from vfactor.keypoints import KEYPOINT_NAMES, LEFT_RIGHT_PAIRS, NUM_KEYPOINTS

__all__ = ["KeypointSet", "KEYPOINT_SETS", "keypoint_set"]


@dataclass(frozen=True)
class KeypointSet:
    """A keypoint definition of another tool, mapped to vfactor's 12 keypoints.

    Attributes:
        name: the set's name in vfactor (``"carfusion14"``, ...).
        keypoint_names: the set's own names, in its own order (index = position
            in a COCO ``keypoints`` list divided by 3).
        sources: for each of vfactor's 12 keypoints (fixed order), the indices
            of the set's points that give it: one index (taken as is), several
            (their mean; seen only when all are seen; confidence of the
            weakest) or none (not in this set: never seen).
        flip_pairs: the set's own (left, right) index pairs, from its source's
            horizontal-flip table; points in no pair are on the medial plane.
        source: where the names and their order come from (file and version).
    """

    name: str
    keypoint_names: tuple[str, ...]
    sources: tuple[tuple[int, ...], ...]
    flip_pairs: tuple[tuple[int, int], ...]
    source: str

    def __post_init__(self):
        n = len(self.keypoint_names)
        if len(self.sources) != NUM_KEYPOINTS:
            raise ValueError(f"{self.name}.sources: expected {NUM_KEYPOINTS} entries, got {len(self.sources)}")
        for k, src in enumerate(self.sources):
            if any(not 0 <= i < n for i in src) or len(set(src)) != len(src):
                raise ValueError(f"{self.name}.sources[{k}]: expected distinct indices in 0..{n - 1}, got {src}")
        flat = [i for pair in self.flip_pairs for i in pair]
        if len(set(flat)) != len(flat) or any(not 0 <= i < n for i in flat):
            raise ValueError(f"{self.name}.flip_pairs: expected disjoint pairs of indices in 0..{n - 1}")

    @property
    def num_keypoints(self) -> int:
        """Number of points in the set (a COCO ``keypoints`` list holds 3 numbers per point)."""
        return len(self.keypoint_names)

    @property
    def coverage(self) -> tuple[int, ...]:
        """Indices of the vfactor keypoints this set can give."""
        return tuple(k for k, src in enumerate(self.sources) if src)

    def flip_permutation(self) -> np.ndarray:
        """``points[perm]`` swaps every left point of the set with its right partner, as its own flip table does."""
        perm = np.arange(self.num_keypoints)
        for a, b in self.flip_pairs:
            perm[a], perm[b] = b, a
        return perm

    def to_vfactor(self, xy: np.ndarray, confidence: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """vfactor's 12 keypoints from the set's points.

        Args:
            xy: (N, 2) pixels of the set's N points (any value where unseen).
            confidence: (N,) in [0, 1]; 0 = not seen.

        Returns:
            uv: (12, 2) pixels in vfactor's order, NaN where not seen.
            confidence: (12,) in [0, 1]: a taken point's own, the weakest of
            combined points, 0 where a combined point or the set lacks it.
        """
        xy = np.asarray(xy, dtype=float).reshape(self.num_keypoints, 2)
        confidence = np.asarray(confidence, dtype=float).reshape(self.num_keypoints)
        uv = np.full((NUM_KEYPOINTS, 2), np.nan)
        out = np.zeros(NUM_KEYPOINTS)
        for k, src in enumerate(self.sources):
            if not src:
                continue
            c = float(confidence[list(src)].min())
            if c > 0:
                uv[k] = xy[list(src)].mean(axis=0)
                out[k] = c
        return uv, out


def _pairs_from(mapping: dict[int, int]) -> tuple[tuple[int, int], ...]:
    return tuple(sorted((min(a, b), max(a, b)) for a, b in mapping.items()))


VFACTOR12 = KeypointSet(
    name="vfactor12",
    keypoint_names=KEYPOINT_NAMES,
    sources=tuple((k,) for k in range(NUM_KEYPOINTS)),
    flip_pairs=LEFT_RIGHT_PAIRS,
    source="vfactor.keypoints.KEYPOINT_NAMES (docs/conventions.md)",
)

#: CarFusion (Reddy, Vo, Narasimhan, CVPR 2018), 14 points. mmpose has no
#: CarFusion config in its releases (1.3.2); this is the order of the dataset
#: config of mmpose pull request #1510 (``configs/_base_/datasets/carfusion.py``,
#: head c80e7d42, not merged), which matches CarFusion's own COCO converter
#: (dineshreddy91/carfusion_to_coco, ``carfusion2coco.py``: index = label id - 1,
#: its skeleton) and Occlusion-Net's name list.
CARFUSION14 = KeypointSet(
    name="carfusion14",
    keypoint_names=(
        "Right Front Wheel", "Left Front Wheel", "Right Back Wheel", "Left Back Wheel",
        "Right Front HeadLight", "Left Front HeadLight", "Right Back HeadLight", "Left Back HeadLight",
        "Exhaust", "Right Front Top", "Left Front Top", "Right Back Top", "Left Back Top", "misc",
    ),
    sources=((1,), (0,), (3,), (2,), (5,), (4,), (7,), (6,), (10,), (9,), (12,), (11,)),
    flip_pairs=((0, 1), (2, 3), (4, 5), (6, 7), (9, 10), (11, 12)),
    source="mmpose PR #1510 configs/_base_/datasets/carfusion.py (head c80e7d42, 2022-10-30); "
           "dineshreddy91/carfusion_to_coco carfusion2coco.py (ac241a9c, 2019-11-18)",
)

#: OpenPifPaf's ApolloCar3D plugin, ``CAR_KEYPOINTS_24`` (openpifpaf 0.13.11,
#: ``src/openpifpaf/plugins/apollocar3d/constants.py``).
APOLLOCAR3D24 = KeypointSet(
    name="apollocar3d24",
    keypoint_names=(
        "front_up_right", "front_up_left", "front_light_right", "front_light_left",
        "front_low_right", "front_low_left", "central_up_left", "front_wheel_left",
        "rear_wheel_left", "rear_corner_left", "rear_up_left", "rear_up_right",
        "rear_light_left", "rear_light_right", "rear_low_left", "rear_low_right",
        "central_up_right", "rear_corner_right", "rear_wheel_right", "front_wheel_right",
        "rear_plate_left", "rear_plate_right", "mirror_edge_left", "mirror_edge_right",
    ),
    sources=((7,), (19,), (8,), (18,), (3,), (2,), (12,), (13,), (1,), (0,), (10,), (11,)),
    flip_pairs=((0, 1), (2, 3), (4, 5), (6, 16), (7, 19), (8, 18), (9, 17), (10, 11), (12, 13), (14, 15),
                (20, 21), (22, 23)),
    source="openpifpaf 0.13.11 (37aacead, 2024-08-04) src/openpifpaf/plugins/apollocar3d/constants.py "
           "CAR_KEYPOINTS_24, HFLIP_24",
)

#: OpenPifPaf's ApolloCar3D plugin, ``CAR_KEYPOINTS_66`` (ApolloCar3D's own 66
#: points, same file). The lamps are given by their four corners: vfactor's
#: light keypoint is their mean.
APOLLOCAR3D66 = KeypointSet(
    name="apollocar3d66",
    keypoint_names=(
        "top_left_c_left_front_car_light", "bottom_left_c_left_front_car_light",
        "top_right_c_left_front_car_light", "bottom_right_c_left_front_car_light",
        "top_right_c_left_front_fog_light", "bottom_right_c_left_front_fog_light",
        "front_section_left_front_wheel", "center_left_front_wheel",
        "top_right_c_front_glass", "top_left_c_left_front_door",
        "bottom_left_c_left_front_door", "top_right_c_left_front_door",
        "middle_c_left_front_door", "front_c_car_handle_left_front_door",
        "rear_c_car_handle_left_front_door", "bottom_right_c_left_front_door",
        "top_right_c_left_rear_door", "front_c_car_handle_left_rear_door",
        "rear_c_car_handle_left_rear_door", "bottom_right_c_left_rear_door",
        "center_left_rear_wheel", "rear_section_left_rear_wheel",
        "top_left_c_left_rear_car_light", "bottom_left_c_left_rear_car_light",
        "top_left_c_rear_glass", "top_right_c_left_rear_car_light",
        "bottom_right_c_left_rear_car_light", "bottom_left_c_trunk",
        "Left_c_rear_bumper", "Right_c_rear_bumper",
        "bottom_right_c_trunk", "bottom_left_c_right_rear_car_light",
        "top_left_c_right_rear_car_light", "top_right_c_rear_glass",
        "bottom_right_c_right_rear_car_light", "top_right_c_right_rear_car_light",
        "rear_section_right_rear_wheel", "center_right_rear_wheel",
        "bottom_left_c_right_rear_car_door", "rear_c_car_handle_right_rear_car_door",
        "front_c_car_handle_right_rear_car_door", "top_left_c_right_rear_car_door",
        "bottom_left_c_right_front_car_door", "rear_c_car_handle_right_front_car_door",
        "front_c_car_handle_right_front_car_door", "middle_c_right_front_car_door",
        "top_left_c_right_front_car_door", "bottom_right_c_right_front_car_door",
        "top_right_c_right_front_car_door", "top_left_c_front_glass",
        "center_right_front_wheel", "front_section_right_front_wheel",
        "bottom_left_c_right_fog_light", "top_left_c_right_fog_light",
        "bottom_left_c_right_front_car_light", "top_left_c_right_front_car_light",
        "bottom_right_c_right_front_car_light", "top_right_c_right_front_car_light",
        "top_right_c_front_lplate", "top_left_c_front_lplate",
        "bottom_right_c_front_lplate", "bottom_left_c_front_lplate",
        "top_left_c_rear_lplate", "top_right_c_rear_lplate",
        "bottom_right_c_rear_lplate", "bottom_left_c_rear_lplate",
    ),
    sources=((7,), (50,), (20,), (37,), (0, 1, 2, 3), (54, 55, 56, 57), (22, 23, 25, 26), (31, 32, 34, 35),
             (8,), (49,), (24,), (33,)),
    flip_pairs=_pairs_from({**{k: 57 - k for k in range(29)}, 59: 58, 61: 60, 62: 63, 65: 64}),
    source="openpifpaf 0.13.11 (37aacead, 2024-08-04) src/openpifpaf/plugins/apollocar3d/constants.py "
           "CAR_KEYPOINTS_66, HFLIP_ids",
)

#: The keypoint sets by name.
KEYPOINT_SETS: dict[str, KeypointSet] = {s.name: s for s in (VFACTOR12, CARFUSION14, APOLLOCAR3D24, APOLLOCAR3D66)}


def keypoint_set(name: str | KeypointSet) -> KeypointSet:
    """The :class:`KeypointSet` of a name in :data:`KEYPOINT_SETS` (a set is returned as is).

    Raises:
        InputError: (field ``keypoint_set``) an unknown name.
    """
    if isinstance(name, KeypointSet):
        return name
    if not isinstance(name, str) or name not in KEYPOINT_SETS:
        raise InputError("keypoint_set", f"expected one of {', '.join(KEYPOINT_SETS)}, got {name!r}")
    return KEYPOINT_SETS[name]
