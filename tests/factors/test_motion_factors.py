"""Motion and ground-plane factors: the contract, and what they measure."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from vfactor.factors.ground_plane import GroundPlane, ground_plane_factor, hub_height_prior
from vfactor.factors.motion import MotionModel, acceleration_factor, nonholonomic_factor

from .contract import FactorContract

X = [gtsam.symbol("x", i) for i in range(3)]


def arc_pose(s: float, speed: float = 8.0, yaw_rate: float = 0.3, yaw0: float = 0.4) -> gtsam.Pose3:
    """A car driving a constant-curvature arc on the road, ``s`` seconds from its start."""
    twist = np.array([0, 0, yaw_rate * s, speed * s, 0, 0])
    return gtsam.Pose3(gtsam.Rot3.Yaw(yaw0), np.array([1.0, 2.0, 0.34])).compose(gtsam.Pose3.Expmap(twist))


def poses(values_from, rng, noise):
    values = gtsam.Values()
    for i, key in enumerate(X):
        values.insert(key, values_from(i).retract(rng.normal(0, noise, 6) if noise else np.zeros(6)))
    return values


class TestNonholonomic(FactorContract):
    def make_factor(self):
        return nonholonomic_factor(X[0], X[1], 0.1, MotionModel(max_yaw_rate=0.5))

    def make_values(self, rng):
        return poses(lambda i: arc_pose(0.1 * i, yaw_rate=0.9), rng, 0.05)  # beyond the yaw-rate bound too

    def make_truth_values(self):
        return poses(lambda i: arc_pose(0.1 * i), None, 0)


class TestAcceleration(FactorContract):
    def make_factor(self):
        return acceleration_factor(X[0], X[1], X[2], 0.1, 0.15)

    def make_values(self, rng):
        return poses(lambda i: arc_pose([0, 0.1, 0.25][i]), rng, 0.05)

    def make_truth_values(self):
        return poses(lambda i: arc_pose([0, 0.1, 0.25][i]), None, 0)


class TestGroundPlane(FactorContract):
    plane = GroundPlane((0.02, -0.01, 1.0), 0.1)

    def make_factor(self):
        return ground_plane_factor(X[0], self.plane, hub_height=0.34)

    def make_values(self, rng):
        return poses(lambda i: arc_pose(0.1 * i), rng, 0.1)

    def make_truth_values(self):
        n = np.asarray(self.plane.normal)
        z = n
        x = np.cross([0.0, 1.0, 0.0], z)
        x /= np.linalg.norm(x)
        R = np.column_stack([x, np.cross(z, x), z])
        t = np.array([1.0, 2.0, 0.0])
        t = t + (self.plane.offset + 0.34 - n @ t) * n
        values = gtsam.Values()
        for key in X:
            values.insert(key, gtsam.Pose3(gtsam.Rot3(R), t))
        return values



HUB = gtsam.symbol("h", 0)


class TestGroundPlaneWithHubHeight(TestGroundPlane):
    """The same factor with the hub height a variable (a track's wheel radius, shared by its poses)."""

    def make_factor(self):
        return ground_plane_factor(X[0], self.plane, sigma_height=0.02, hub_key=HUB)

    def make_values(self, rng):
        values = super().make_values(rng)
        values.insert(HUB, np.array([0.34 + rng.normal(0, 0.05)]))
        return values

    def make_truth_values(self):
        values = super().make_truth_values()
        values.insert(HUB, np.array([0.34]))
        return values


def test_the_hub_height_variable_moves_the_height_residual_as_the_given_hub_height_does():
    plane = GroundPlane((0.02, -0.01, 1.0), 0.1)
    values = gtsam.Values()
    values.insert(X[0], arc_pose(0.3))
    values.insert(HUB, np.array([0.41]))
    given = ground_plane_factor(X[0], plane, hub_height=0.41, sigma_height=0.02)
    variable = ground_plane_factor(X[0], plane, hub_height=0.34, sigma_height=0.02, hub_key=HUB)
    assert list(variable.keys()) == [X[0], HUB]
    assert np.isclose(variable.error(values), given.error(values), rtol=1e-12)
    prior = hub_height_prior(HUB, 0.34, 0.05)
    assert np.isclose(prior.error(values), 0.5 * ((0.41 - 0.34) / 0.05) ** 2)


def test_sideways_motion_is_penalised_but_forward_is_not():
    factor = nonholonomic_factor(X[0], X[1], 0.1)
    values = gtsam.Values()
    values.insert(X[0], gtsam.Pose3())
    values.insert(X[1], gtsam.Pose3(gtsam.Rot3(), np.array([1.0, 0.0, 0.0])))
    assert factor.error(values) < 1e-12
    values.update(X[1], gtsam.Pose3(gtsam.Rot3(), np.array([1.0, 0.1, 0.0])))
    assert factor.error(values) > 10


def test_bad_settings_raise():
    with pytest.raises(ValueError, match="time step"):
        nonholonomic_factor(X[0], X[1], 0.0)
    with pytest.raises(ValueError, match="MotionModel.sigma_lateral"):
        MotionModel(sigma_lateral=-1)
    with pytest.raises(ValueError, match="point up"):
        GroundPlane((0, 0, -1), 0)
