"""The 12 semantic vehicle keypoints: names, fixed order, layers and left/right pairs.

The order is the one of the paper's Table I and of docs/conventions.md; every array of
keypoints in vfactor (scene files, results, wireframes, heatmaps) uses it.
"Left" is the vehicle's own left as its driver sees it (``y > 0`` in the body
frame).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "NUM_KEYPOINTS",
    "KEYPOINT_NAMES",
    "LAYER_NAMES",
    "LAYERS",
    "LEFT_RIGHT_PAIRS",
    "MIRROR_PERMUTATION",
    "TURN_PERMUTATION",
    "WIREFRAME_EDGES",
    "layer_of",
]

NUM_KEYPOINTS = 12

KEYPOINT_NAMES: tuple[str, ...] = (
    "left_front_wheel",
    "right_front_wheel",
    "left_back_wheel",
    "right_back_wheel",
    "left_front_light",
    "right_front_light",
    "left_back_light",
    "right_back_light",
    "left_up_windshield",
    "right_up_windshield",
    "left_up_rear_window",
    "right_up_rear_window",
)

LAYER_NAMES: tuple[str, ...] = ("wheel", "light", "roof")

#: Keypoint indices of each layer, always (left front, right front, left back,
#: right back): the wheel hubs, the lights, the top corners of the windshield
#: (front) and of the rear window (back).
LAYERS: dict[str, tuple[int, int, int, int]] = {
    "wheel": (0, 1, 2, 3),
    "light": (4, 5, 6, 7),
    "roof": (8, 9, 10, 11),
}

#: (left, right) index pairs; each left keypoint mirrors its right partner
#: across the body x-z plane.
LEFT_RIGHT_PAIRS: tuple[tuple[int, int], ...] = ((0, 1), (2, 3), (4, 5), (6, 7), (8, 9), (10, 11))

#: ``points[MIRROR_PERMUTATION]`` swaps every left keypoint with its right partner.
MIRROR_PERMUTATION: np.ndarray = np.array([1, 0, 3, 2, 5, 4, 7, 6, 9, 8, 11, 10])
MIRROR_PERMUTATION.setflags(write=False)

#: ``labels[TURN_PERMUTATION]`` relabels the keypoints of a vehicle turned by half a turn about its z axis: each
#: keypoint takes the label of the one diagonally across (left front <-> right back), as a detector that reads the
#: vehicle's front as its back labels them.
TURN_PERMUTATION: np.ndarray = np.array([3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8])
TURN_PERMUTATION.setflags(write=False)


#: Edges drawn between keypoints: each layer's quadrilateral, then the struts
#: from the wheels to the lights and from the lights to the roof corners.
WIREFRAME_EDGES: tuple[tuple[int, int], ...] = (
    (0, 1), (2, 3), (0, 2), (1, 3),
    (4, 5), (6, 7), (4, 6), (5, 7),
    (8, 9), (10, 11), (8, 10), (9, 11),
    (0, 4), (1, 5), (2, 6), (3, 7),
    (4, 8), (5, 9), (6, 10), (7, 11),
)


def layer_of(index: int) -> str:
    """Returns the layer name ("wheel", "light" or "roof") of keypoint ``index``."""
    if not 0 <= index < NUM_KEYPOINTS:
        raise ValueError(f"keypoint index: expected 0..{NUM_KEYPOINTS - 1}, got {index}")
    return LAYER_NAMES[index // 4]
