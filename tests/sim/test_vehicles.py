"""Simulated vehicle shapes and poses."""

from __future__ import annotations

import numpy as np
import pytest

from vfactor.keypoints import LAYERS, MIRROR_PERMUTATION
from vfactor.shape_model import car_hwc_bounds
from vfactor.sim import (
    RandomShape,
    footprint,
    footprints_overlap,
    random_wireframe,
    road_pose,
    vehicle_shape,
    within_hwc_bounds,
)
from vfactor.wireframe import PRESETS, Wireframe, pascal3d_shapes

HUBS = list(LAYERS["wheel"])


def test_random_wireframes_are_symmetric_metric_cars_within_the_hwc_bounds():
    rng = np.random.default_rng(3)
    wheelbases = []
    for _ in range(40):
        w = random_wireframe(rng)
        p = w.vehicle_p_keypoints
        np.testing.assert_allclose(p, p[MIRROR_PERMUTATION] * [1, -1, 1], atol=1e-12)
        np.testing.assert_allclose(p[HUBS].mean(0), 0.0, atol=1e-12)
        assert within_hwc_bounds(w)
        wheelbases.append(w.wheelbase)
    assert 2.4 < min(wheelbases) and max(wheelbases) < 3.1
    assert max(wheelbases) - min(wheelbases) > 0.2  # really drawn over the range


def test_random_wireframe_without_jitter_is_a_scaled_pascal3d_model():
    w = random_wireframe(np.random.default_rng(0), RandomShape(wheelbase=(2.7, 2.7), jitter=0.0))
    shapes = pascal3d_shapes() * 2.7
    shapes = 0.5 * (shapes + shapes[:, MIRROR_PERMUTATION] * [1, -1, 1])
    shapes -= shapes[:, HUBS].mean(1, keepdims=True)
    assert min(np.abs(s - w.vehicle_p_keypoints).max() for s in shapes) < 1e-12


def test_random_wireframe_is_deterministic():
    a = random_wireframe(np.random.default_rng(11))
    b = random_wireframe(np.random.default_rng(11))
    assert a == b


def test_within_hwc_bounds_rejects_a_squashed_car():
    """The car bounds (15 % margins) refuse a car at 60 % of its height; the default bounds (50 % of each range,
    spanning vans and a bus) one at 20 %. (At 30 % it was refused only while the layer offsets were stored
    transposed, which held the roof at least 0.68 m above the hubs instead of 0.26 m.)"""
    w = PRESETS["lincoln_mkz"].wireframe()
    assert within_hwc_bounds(w) and within_hwc_bounds(w, car_hwc_bounds())
    assert not within_hwc_bounds(Wireframe(w.vehicle_p_keypoints * [1.0, 1.0, 0.6]), car_hwc_bounds())
    assert not within_hwc_bounds(Wireframe(w.vehicle_p_keypoints * [1.0, 1.0, 0.2]))


def test_vehicle_shape_gives_presets_and_random_cars():
    rng = np.random.default_rng(0)
    w, radius = vehicle_shape("bmw_x5", rng)
    assert w == PRESETS["bmw_x5"].wireframe() and radius == PRESETS["bmw_x5"].wheel_radius
    w, radius = vehicle_shape("random", rng, RandomShape(wheel_radius=0.31))
    assert radius == 0.31 and within_hwc_bounds(w)
    with pytest.raises(ValueError, match="unknown name"):
        vehicle_shape("tractor", rng)


def test_road_pose_puts_the_hubs_at_wheel_radius_with_zero_roll_and_pitch():
    w = PRESETS["toyota_prius"].wireframe()
    pose = road_pose(1.0, -2.0, 2.5, 0.32)
    hubs = w.in_world(pose)[HUBS]
    np.testing.assert_allclose(hubs[:, 2], 0.32, atol=1e-12)
    rpy = pose.rotation().rpy()
    assert rpy[0] == pytest.approx(0.0) and rpy[1] == pytest.approx(0.0) and rpy[2] == pytest.approx(2.5)
    forward = pose.rotation().matrix()[:, 0]
    np.testing.assert_allclose(forward, [np.cos(2.5), np.sin(2.5), 0.0], atol=1e-12)


def test_footprints_overlap_by_separating_axes():
    w = PRESETS["lincoln_mkz"].wireframe()
    a = footprint(w, road_pose(0, 0, 0, 0.34))
    length = np.ptp(w.vehicle_p_keypoints[:, 0]) + 0.2
    assert footprints_overlap(a, footprint(w, road_pose(length - 0.1, 0, 0, 0.34)))
    assert not footprints_overlap(a, footprint(w, road_pose(length + 0.1, 0, 0, 0.34)))
    assert footprints_overlap(a, footprint(w, road_pose(length + 0.1, 0, 0, 0.34)), gap=0.5)
    # rotated 90 degrees, beside the first car
    assert not footprints_overlap(a, footprint(w, road_pose(0, 4.0, np.pi / 2, 0.34)))
    assert footprints_overlap(a, footprint(w, road_pose(1.0, 2.0, np.pi / 2, 0.34)))
