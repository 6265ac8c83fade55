"""The compiled motion and ground-plane factors against their former NumPy form and GTSAM's own maps.

The references below are the factors as they were before the kernels (issue
14): GTSAM's Python ``Pose3.between`` and ``Pose3.Logmap`` with their
Jacobians, chained in NumPy. The compiled factors must give the same whitened
errors and Jacobians (to ~1e-9 relative) at random poses; the contract tests
(test_motion_factors.py) check them against numerical derivatives.
"""

from __future__ import annotations

from functools import partial

import gtsam
import numpy as np
import pytest

from vfactor.factors.ground_plane import GroundPlane, ground_plane_factor
from vfactor.factors.motion import MotionModel, acceleration_factor, nonholonomic_factor, step_twist
from vfactor.testing import check_factor_jacobians

X = [gtsam.symbol("x", i) for i in range(3)]


# --- the former NumPy factors (reference) ----------------------------------------------------------

def reference_step_twist(T1, T2, jacobians=False):
    if not jacobians:
        return gtsam.Pose3.Logmap(T1.between(T2)), None, None
    H1, H2, Hlog = (np.zeros((6, 6), order="F") for _ in range(3))
    xi = gtsam.Pose3.Logmap(T1.between(T2, H1, H2), Hlog)
    return xi, Hlog @ H1, Hlog @ H2


def _reference_nonholonomic_error(dt, model, this, values, H):
    k1, k2 = this.keys()
    xi, J1, J2 = reference_step_twist(values.atPose3(k1), values.atPose3(k2), H is not None)
    yaw_rate = xi[2] / dt
    over = yaw_rate - np.clip(yaw_rate, -model.max_yaw_rate, model.max_yaw_rate)
    r = np.array([xi[4] / (model.sigma_lateral * dt), xi[5] / (model.sigma_vertical * dt),
                  xi[0] / (model.sigma_tilt * dt), xi[1] / (model.sigma_tilt * dt), over / model.yaw_rate_sigma])
    if H is not None:
        S = np.zeros((5, 6))
        S[0, 4] = 1 / (model.sigma_lateral * dt)
        S[1, 5] = 1 / (model.sigma_vertical * dt)
        S[2, 0] = S[3, 1] = 1 / (model.sigma_tilt * dt)
        S[4, 2] = (over != 0) / (dt * model.yaw_rate_sigma)
        H[0], H[1] = S @ J1, S @ J2
    return r


def reference_nonholonomic(key1, key2, dt, model=MotionModel()):
    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(5), [key1, key2],
                              partial(_reference_nonholonomic_error, dt, model))


def _reference_acceleration_error(dt1, dt2, model, this, values, H):
    k0, k1, k2 = this.keys()
    T0, T1, T2 = values.atPose3(k0), values.atPose3(k1), values.atPose3(k2)
    want = H is not None
    xa, Ja0, Ja1 = reference_step_twist(T0, T1, want)
    xb, Jb1, Jb2 = reference_step_twist(T1, T2, want)
    mid = 0.5 * (dt1 + dt2)
    ca, cb = 1 / (model.sigma_acceleration * mid), 1 / (model.sigma_yaw_acceleration * mid)
    r = np.array([ca * (xb[3] / dt2 - xa[3] / dt1), cb * (xb[2] / dt2 - xa[2] / dt1)])
    if want:
        Sa, Sb = np.zeros((2, 6)), np.zeros((2, 6))
        Sa[0, 3], Sb[0, 3] = -ca / dt1, ca / dt2
        Sa[1, 2], Sb[1, 2] = -cb / dt1, cb / dt2
        H[0], H[1], H[2] = Sa @ Ja0, Sa @ Ja1 + Sb @ Jb1, Sb @ Jb2
    return r


def reference_acceleration(key0, key1, key2, dt1, dt2, model=MotionModel()):
    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(2), [key0, key1, key2],
                              partial(_reference_acceleration_error, dt1, dt2, model))


def _reference_ground_error(plane, hub_height, sigma_height, sigma_tilt, this, values, H):
    T = values.atPose3(this.keys()[0])
    R, t = T.rotation().matrix(), T.translation()
    n = np.asarray(plane.normal)
    v = R.T @ n
    r = np.array([(n @ t - plane.offset - hub_height) / sigma_height, v[0] / sigma_tilt, v[1] / sigma_tilt])
    if H is not None:
        J = np.zeros((3, 6))
        J[0, 3:] = (n @ R) / sigma_height
        skew = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
        J[1:, :3] = skew[:2] / sigma_tilt
        H[0] = J
    return r


def reference_ground(key, plane, hub_height, sigma_height, sigma_tilt):
    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(3), [key],
                              partial(_reference_ground_error, plane, hub_height, sigma_height, sigma_tilt))


# --- random poses ----------------------------------------------------------------------------------

def random_track(rng, n, rotation_sigma, translation_sigma=1.0):
    """``n`` poses: a random start, then random steps (rotation first, rad and metres)."""
    T = gtsam.Pose3.Expmap(np.r_[rng.normal(0, 1.0, 3), rng.normal(0, 20.0, 3)])
    poses = [T]
    for _ in range(n - 1):
        step = np.r_[rng.normal(0, rotation_sigma, 3), rng.normal(0, translation_sigma, 3)]
        poses.append(poses[-1].compose(gtsam.Pose3.Expmap(step)))
    values = gtsam.Values()
    for key, pose in zip(X, poses):
        values.insert(key, pose)
    return values


def assert_same_linearisation(factor, reference, values, rtol=1e-9):
    A, b = factor.linearize(values).jacobian()
    A_ref, b_ref = reference.linearize(values).jacobian()
    scale = max(1.0, float(np.abs(A_ref).max()), float(np.abs(b_ref).max()))
    np.testing.assert_allclose(b, b_ref, rtol=0, atol=rtol * scale)
    np.testing.assert_allclose(A, A_ref, rtol=0, atol=rtol * scale)
    assert np.isclose(factor.error(values), reference.error(values), rtol=1e-9, atol=1e-12)


# a car's step (0.1 s at up to 15 m/s, yaw rates to 3 rad/s: 0.3 rad), generic steps (about 1 rad),
# and near-standstill (rotations of 1e-6 rad, below the kernel's Taylor threshold)
STEPS = [(0.05, 1.0), (0.8, 3.0), (1e-6, 0.01)]


@pytest.mark.parametrize("rotation_sigma, translation_sigma", STEPS)
@pytest.mark.parametrize("seed", range(10))
def test_nonholonomic_equals_the_numpy_reference(seed, rotation_sigma, translation_sigma):
    rng = np.random.default_rng(seed)
    values = random_track(rng, 2, rotation_sigma, translation_sigma)
    dt = float(rng.uniform(0.05, 0.5))
    model = MotionModel(max_yaw_rate=float(rng.uniform(0.05, 2.5)))  # inside and beyond the yaw-rate bound
    assert_same_linearisation(nonholonomic_factor(X[0], X[1], dt, model),
                              reference_nonholonomic(X[0], X[1], dt, model), values)


@pytest.mark.parametrize("rotation_sigma, translation_sigma", STEPS)
@pytest.mark.parametrize("seed", range(10))
def test_acceleration_equals_the_numpy_reference(seed, rotation_sigma, translation_sigma):
    rng = np.random.default_rng(100 + seed)
    values = random_track(rng, 3, rotation_sigma, translation_sigma)
    dt1, dt2 = (float(v) for v in rng.uniform(0.05, 0.5, 2))
    model = MotionModel(sigma_acceleration=float(rng.uniform(0.5, 4)),
                        sigma_yaw_acceleration=float(rng.uniform(0.2, 2)))
    assert_same_linearisation(acceleration_factor(X[0], X[1], X[2], dt1, dt2, model),
                              reference_acceleration(X[0], X[1], X[2], dt1, dt2, model), values)


@pytest.mark.parametrize("seed", range(10))
def test_ground_plane_equals_the_numpy_reference(seed):
    rng = np.random.default_rng(200 + seed)
    values = random_track(rng, 1, 0.0)
    plane = GroundPlane(tuple(np.r_[rng.normal(0, 0.1, 2), 1.0]), float(rng.normal(0, 1)))
    args = (plane, float(rng.uniform(0.2, 0.5)), float(rng.uniform(0.02, 0.1)), float(rng.uniform(0.01, 0.05)))
    assert_same_linearisation(ground_plane_factor(X[0], *args), reference_ground(X[0], *args), values)


@pytest.mark.parametrize("rotation_sigma", [1.0, 0.1, 1e-2, 1e-3, 1e-5, 1e-8, 0.0])
def test_step_twist_equals_gtsam(rotation_sigma):
    """``Log(T1^-1 T2)`` and its Jacobians as GTSAM's, from large rotations to none."""
    rng = np.random.default_rng(7)
    for _ in range(50):
        values = random_track(rng, 2, rotation_sigma, 3.0)
        T1, T2 = values.atPose3(X[0]), values.atPose3(X[1])
        if np.linalg.norm(gtsam.Rot3.Logmap(T1.rotation().between(T2.rotation()))) > 3.0:
            continue  # near pi GTSAM's own Logmap is off by up to 1e-7 (test_step_twist_near_pi)
        for got, want in zip(step_twist(T1, T2, True), reference_step_twist(T1, T2, True)):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-10)
        assert step_twist(T1, T2)[1:] == (None, None)


def test_step_twist_near_pi():
    """Rotations within 1e-1 .. 1e-7 rad of pi: the exact twist, and Jacobians that match numerical ones."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        twist = np.r_[axis * (np.pi - 10 ** rng.uniform(-7, -1)), rng.normal(0, 3, 3)]
        T1 = gtsam.Pose3.Expmap(rng.normal(0, 2, 6))
        T2 = T1.compose(gtsam.Pose3.Expmap(twist))
        xi, J1, J2 = step_twist(T1, T2, True)
        np.testing.assert_allclose(xi, twist, rtol=0, atol=1e-10)
        if np.pi - np.linalg.norm(twist[:3]) > 1e-3:  # numerical derivatives would cross pi
            for J, perturb in ((J1, lambda d: (T1.retract(d), T2)), (J2, lambda d: (T1, T2.retract(d)))):
                numeric = np.column_stack([
                    (step_twist(*perturb(h))[0] - step_twist(*perturb(-h))[0]) / 2e-6 for h in 1e-6 * np.eye(6)])
                np.testing.assert_allclose(J, numeric, rtol=0, atol=1e-6)


@pytest.mark.parametrize("rotation_sigma", [0.3, 1e-3, 1e-6])
def test_step_twist_jacobians_match_numerical(rotation_sigma):
    """The compiled factors' Jacobians against numerical ones at generic and near-identity steps."""
    rng = np.random.default_rng(11)
    # the yaw-rate hinge active (but not at standstill, where the numerical step would cross its kink)
    model = MotionModel(max_yaw_rate=1e-9) if rotation_sigma > 1e-4 else MotionModel()
    for _ in range(5):
        values = random_track(rng, 3, rotation_sigma, 1.0)
        check_factor_jacobians(nonholonomic_factor(X[0], X[1], 0.1, model), values)
        check_factor_jacobians(acceleration_factor(X[0], X[1], X[2], 0.1, 0.12), values)


def test_linearisations_do_not_share_the_factors_buffers():
    """Each factor reuses its output arrays: what GTSAM got from one call must not change with the next."""
    rng = np.random.default_rng(5)
    factors = [nonholonomic_factor(X[0], X[1], 0.1, MotionModel(max_yaw_rate=0.1)),
               acceleration_factor(X[0], X[1], X[2], 0.1, 0.1), ground_plane_factor(X[0])]
    for factor in factors:
        first_values, second_values = random_track(rng, 3, 0.2), random_track(rng, 3, 0.2)
        first = factor.linearize(first_values)
        A, b = (m.copy() for m in first.jacobian())
        error = factor.unwhitenedError(first_values)
        factor.linearize(second_values)
        factor.unwhitenedError(second_values)
        np.testing.assert_array_equal(first.jacobian()[0], A)
        np.testing.assert_array_equal(first.jacobian()[1], b)
        np.testing.assert_array_equal(error, factor.unwhitenedError(first_values))
        assert not np.allclose(factor.unwhitenedError(second_values), error)
