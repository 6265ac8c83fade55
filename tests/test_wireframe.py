"""Keypoint order, wireframes, presets, shape prior and HWC bounds."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from vfactor.keypoints import KEYPOINT_NAMES, LAYERS, LEFT_RIGHT_PAIRS, MIRROR_PERMUTATION, layer_of
from vfactor.shape_model import default_hwc_bounds, default_shape_prior
from vfactor.wireframe import PRESETS, Wireframe, pascal3d_shapes, preset


def test_keypoint_order_is_the_design_order():
    assert KEYPOINT_NAMES[0] == "left_front_wheel" and KEYPOINT_NAMES[11] == "right_up_rear_window"
    assert all(KEYPOINT_NAMES[l].startswith("left") and KEYPOINT_NAMES[r].startswith("right") for l, r in LEFT_RIGHT_PAIRS)
    assert [layer_of(i) for i in LAYERS["roof"]] == ["roof"] * 4
    assert sorted(MIRROR_PERMUTATION) == list(range(12))


def test_pascal3d_shapes_are_in_the_body_frame():
    shapes = pascal3d_shapes()
    assert shapes.shape == (9, 12, 3)
    assert np.allclose(shapes[:, :4].mean(axis=1), 0, atol=1e-3)  # hub centroid at the origin
    assert np.all(shapes[:, [0, 2, 4, 6, 8, 10], 1] > 0)  # left is +y


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_presets_match_their_published_dimensions(name):
    p = preset(name)
    w = p.wireframe()
    assert w.wheelbase == pytest.approx(p.wheelbase, abs=1e-9)
    pts = w.vehicle_p_keypoints
    assert np.ptp(pts[[4, 6], 0]) == pytest.approx(p.light_span * p.length, rel=1e-9)
    assert pts[8:, 2].mean() + p.wheel_radius + p.roof_gap == pytest.approx(p.height, rel=1e-9)
    assert np.allclose(pts[:4].mean(0), 0, atol=1e-12)
    assert w == w.mirrored()  # exactly symmetric


def test_unknown_preset_lists_known_names():
    with pytest.raises(ValueError, match="lincoln_mkz"):
        preset("trabant")


def test_wireframe_validates_and_transforms():
    with pytest.raises(ValueError, match="shape"):
        Wireframe(np.zeros((11, 3)))
    w = PRESETS["suv"].wireframe()
    T = gtsam.Pose3(gtsam.Rot3.Yaw(np.pi / 2), np.array([1.0, 2.0, 0.4]))
    world = w.in_world(T)
    assert np.allclose(world[0], T.transformFrom(w.vehicle_p_keypoints[0]))
    assert Wireframe.from_layer_vectors(w.layer_vectors()) == w


def test_shape_prior_is_positive_definite_and_symmetric():
    prior = default_shape_prior()
    assert np.all(np.linalg.eigvalsh(prior.covariance) > 0)
    assert Wireframe(prior.mean) == Wireframe(prior.mean).mirrored()
    assert 2.6 < Wireframe(prior.mean).wheelbase < 2.9


def test_hwc_bounds_contain_every_reference_shape():
    bounds = default_hwc_bounds()
    assert np.all(bounds.distance[:, 0] < bounds.distance[:, 1])
    for name in ("light", "roof"):
        lo, hi = bounds.width_ratio[name]
        assert 0.5 < lo < 1.0 < hi < 1.6
