"""Keypoint projection factor: Jacobians with distortion and every robust loss, and its behaviour."""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np
import pytest

from vfactor.factors.projection import KeypointObservations, project_keypoints, projection_factor
from vfactor.factors.robust import LOSSES, RobustLoss
from vfactor.keys import KeyScheme
from vfactor.wireframe import PRESETS

from ..conftest import K, look_at
from .contract import FactorContract
from vfactor.testing import check_factor_jacobians
from vfactor.camera import Camera

KEYS = KeyScheme()
CAMERAS = (
    Camera("a", K, look_at([15, 10, 7], [0, 0, 0])),
    Camera("b", K, look_at([-15, -8, 8], [0, 0, 0]), dist=[-0.08, 0.02, 0.002, -0.001, 0.003]),
)
TRUTH_POSE = gtsam.Pose3(gtsam.Rot3.Ypr(0.6, 0.02, -0.03), np.array([0.8, -0.4, 0.33]))
TRUTH_SHAPE = PRESETS["hatchback"].wireframe()


#: Cameras with the other lens models: 8 and 14 OpenCV coefficients (rational, thin prism, tilt), fisheye.
LENS_CAMERAS = (
    Camera("rational", K, look_at([15, 10, 7], [0, 0, 0]), dist=[-0.2, 0.05, 0.001, -0.002, 0.01, 0.08, -0.02, 0.004]),
    Camera("full", K, look_at([-15, -8, 8], [0, 0, 0]),
           dist=[-0.2, 0.05, 0.001, -0.002, 0.01, 0.08, -0.02, 0.004, 0.001, -0.0006, 0.002, 0.0004, 0.02, -0.015]),
    Camera("fisheye", K, look_at([12, -12, 6], [0, 0, 0]), dist=[0.04, -0.012, 0.003, -0.0008], model="fisheye"),
)


def observations(noise_px: float = 0.0, rng=None, anisotropic: bool = False, cameras=CAMERAS) -> KeypointObservations:
    n = 12 * len(cameras)
    cam_idx = np.repeat(np.arange(len(cameras)), 12)
    kp_idx = np.tile(np.arange(12), len(cameras))
    obs = KeypointObservations(cameras, cam_idx, kp_idx, np.zeros((n, 2)), np.tile(np.eye(2) / 3.0, (n, 1, 1)))
    uv, _, _, _ = project_keypoints(obs, TRUTH_POSE, TRUTH_SHAPE.vehicle_p_keypoints, jacobians=False)
    if noise_px:
        uv = uv + rng.normal(0, noise_px, uv.shape)
    L = np.tile(np.array([[0.4, 0.1], [0.0, 0.25]]), (n, 1, 1)) if anisotropic else obs.sqrt_information
    return KeypointObservations(cameras, cam_idx, kp_idx, uv, L)


def values_at(pose, wireframe):
    values = gtsam.Values()
    values.insert(KEYS.pose_key(), pose)
    for key, vec in zip(KEYS.layer_keys(), wireframe.layer_vectors().values()):
        values.insert(key, vec)
    return values


class ProjectionContract(FactorContract):
    loss = RobustLoss("none")
    anisotropic = False
    cameras = CAMERAS

    def make_factor(self):
        obs = observations(2.0, np.random.default_rng(11), self.anisotropic, self.cameras)
        return projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, self.loss)

    def make_values(self, rng):
        pose = TRUTH_POSE.retract(rng.normal(0, [0.05, 0.05, 0.2, 0.3, 0.3, 0.1]))
        shape = TRUTH_SHAPE.vehicle_p_keypoints + rng.normal(0, 0.1, (12, 3))
        return values_at(pose, type(TRUTH_SHAPE)(shape))

    def make_truth_values(self):
        return values_at(TRUTH_POSE, TRUTH_SHAPE)

    def test_zero_at_truth(self):
        obs = observations(cameras=self.cameras)
        factor = projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, self.loss)
        assert factor.error(self.make_truth_values()) < 1e-12


class TestProjectionGaussian(ProjectionContract):
    pass


class TestProjectionAnisotropic(ProjectionContract):
    anisotropic = True


class TestProjectionHuber(ProjectionContract):
    loss = RobustLoss("huber", 1.0)


class TestProjectionCauchy(ProjectionContract):
    loss = RobustLoss("cauchy", 1.0)


class TestProjectionGemanMcClure(ProjectionContract):
    loss = RobustLoss("geman_mcclure", 1.0)


class TestProjectionEveryLens(ProjectionContract):
    """Rational (8), full (14: thin prism, tilt) and fisheye cameras in one factor."""

    cameras = LENS_CAMERAS


class TestProjectionEveryLensCauchyAnisotropic(ProjectionContract):
    cameras = LENS_CAMERAS
    loss = RobustLoss("cauchy", 1.0)
    anisotropic = True


OFFSET_KEY = KEYS.offset_key(0, 1)


class TestProjectionWithDetectorOffset(ProjectionContract):
    """The fifth key: a detector pose offset ``vehicle_T_seen`` (Pose3) that moves the vehicle these observations see."""

    loss = RobustLoss("cauchy", 1.0)

    def make_factor(self):
        obs = observations(2.0, np.random.default_rng(11), True, self.cameras)
        return projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, self.loss, offset_key=OFFSET_KEY)

    def make_values(self, rng):
        values = super().make_values(rng)
        values.insert(OFFSET_KEY, gtsam.Pose3.Expmap(rng.normal(0, [0.05, 0.05, 0.1, 0.1, 0.1, 0.05])))
        return values

    def make_truth_values(self):
        values = super().make_truth_values()
        values.insert(OFFSET_KEY, gtsam.Pose3())
        return values

    def test_zero_at_truth(self):
        obs = observations(cameras=self.cameras)
        factor = projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, self.loss, offset_key=OFFSET_KEY)
        assert factor.error(self.make_truth_values()) < 1e-12

    def test_the_offset_moves_the_vehicle_these_observations_see(self):
        rng = np.random.default_rng(5)
        obs = observations(2.0, rng, cameras=self.cameras)
        vehicle_T_seen = gtsam.Pose3.Expmap(np.array([0.01, -0.02, 0.03, 0.05, -0.04, 0.02]))
        moved = values_at(TRUTH_POSE.compose(vehicle_T_seen), TRUTH_SHAPE)
        plain = projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, self.loss)
        values = self.make_truth_values()
        values.update(OFFSET_KEY, vehicle_T_seen)
        with_offset = projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, self.loss, offset_key=OFFSET_KEY)
        np.testing.assert_allclose(with_offset.unwhitenedError(values), plain.unwhitenedError(moved), atol=1e-9)
        assert with_offset.error(values) > 1.0  # a few centimetres and a degree are seen



CAMERA_KEY = gtsam.symbol("e", 0)


def one_camera(obs: KeypointObservations, c: int = 1) -> KeypointObservations:
    return obs.subset(obs.camera_index == c)


class TestProjectionWithCameraError(ProjectionContract):
    """The last key: the error ``E`` (Pose3) of the one camera the observations come from, its true pose
    ``world_T_camera * E`` (vfactor.extrinsics_fit); a distorting lens, the Cauchy loss, anisotropic sigmas."""

    loss = RobustLoss("cauchy", 1.0)

    def make_factor(self):
        obs = one_camera(observations(2.0, np.random.default_rng(11), True, self.cameras))
        return projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, self.loss, camera_key=CAMERA_KEY)

    def make_values(self, rng):
        values = super().make_values(rng)
        values.insert(CAMERA_KEY, gtsam.Pose3.Expmap(rng.normal(0, [0.01, 0.01, 0.01, 0.05, 0.05, 0.05])))
        return values

    def make_truth_values(self):
        values = super().make_truth_values()
        values.insert(CAMERA_KEY, gtsam.Pose3())
        return values

    def test_zero_at_truth(self):
        obs = one_camera(observations(cameras=self.cameras))
        factor = projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, self.loss, camera_key=CAMERA_KEY)
        assert factor.error(self.make_truth_values()) < 1e-12

    def test_the_error_is_the_cameras_true_pose_against_the_given_one(self):
        """Keypoints seen by a camera at ``world_T_camera * E`` fit that camera's factor at ``E`` exactly, and the
        given camera's plain factor not."""
        E = gtsam.Pose3.Expmap(np.array([0.004, -0.006, 0.005, 0.05, -0.03, 0.04]))
        given = self.cameras[1]
        true = dataclasses.replace(given, world_T_camera=given.pose.compose(E).matrix())
        seen = one_camera(observations(cameras=(self.cameras[0], true)))  # pixels of the true camera
        obs = KeypointObservations(self.cameras, seen.camera_index, seen.keypoint_index, seen.uv,
                                   seen.sqrt_information)  # ... given at the surveyed pose
        values = self.make_truth_values()
        values.update(CAMERA_KEY, E)
        factor = projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, self.loss, camera_key=CAMERA_KEY)
        assert factor.error(values) < 1e-12
        assert projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, self.loss).error(values) > 1.0

    def test_with_a_detector_offset_too(self):
        obs = one_camera(observations(2.0, np.random.default_rng(11), True, self.cameras))
        factor = projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, self.loss, offset_key=OFFSET_KEY,
                                   camera_key=CAMERA_KEY)
        for seed in (0, 1):
            rng = np.random.default_rng(seed)
            values = self.make_values(rng)
            values.insert(OFFSET_KEY, gtsam.Pose3.Expmap(rng.normal(0, [0.05, 0.05, 0.1, 0.1, 0.1, 0.05])))
            check_factor_jacobians(factor, values, rtol=self.rtol, atol=self.atol)

    def test_observations_of_several_cameras_are_refused(self):
        with pytest.raises(ValueError, match="one camera"):
            projection_factor(KEYS.pose_key(), KEYS.layer_keys(), observations(), self.loss, camera_key=CAMERA_KEY)

def test_detector_offset_prior_is_the_keypoints_sigma_on_rigid_motions():
    """The pose offset's prior costs what ``sigma`` per coordinate costs on the keypoints (and their half turn)
    that the small rigid motion moves, and the same in either gauge of the body frame."""
    from vfactor.graph import detector_offset_prior

    sigma, points = 0.038, TRUTH_SHAPE.vehicle_p_keypoints
    prior = detector_offset_prior(OFFSET_KEY, sigma, points)
    both = np.concatenate([points, points * [-1.0, -1.0, 1.0]])
    half_turn = gtsam.Pose3(gtsam.Rot3.Rz(np.pi), np.zeros(3))
    rng = np.random.default_rng(2)
    for _ in range(5):
        offset = gtsam.Pose3.Expmap(rng.normal(0, [2e-3, 2e-3, 2e-3, 5e-3, 5e-3, 5e-3]))
        values = gtsam.Values()
        values.insert(OFFSET_KEY, offset)
        moved = offset.transformFrom(both.T).T - both
        expected = 0.5 * np.sum(moved**2) / (2 * sigma**2)  # half the squared whitened norm, the doubled points once
        assert prior.error(values) == pytest.approx(expected, rel=2e-2)
        turned = gtsam.Values()
        turned.insert(OFFSET_KEY, half_turn.between(offset).compose(half_turn))
        assert prior.error(turned) == pytest.approx(prior.error(values), rel=1e-9)


def test_kernel_matches_numpy_projection_for_every_lens():
    """The compiled factor's residuals equal the NumPy projection's (project_pinhole) for mixed lenses."""
    from vfactor.factors.projection import whitened_residuals, whitened_residuals_numpy

    for cameras in (LENS_CAMERAS, CAMERAS + LENS_CAMERAS[2:]):
        obs = observations(2.0, np.random.default_rng(3), cameras=cameras)
        values = ProjectionContract().make_values(np.random.default_rng(8))
        factor = projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, RobustLoss("none"))
        points = np.concatenate([values.atVector(k) for k in KEYS.layer_keys()]).reshape(12, 3)
        e = whitened_residuals_numpy(obs, values.atPose3(KEYS.pose_key()), points)
        assert np.isclose(factor.error(values), 0.5 * np.sum(e * e), rtol=1e-12)
        assert np.allclose(whitened_residuals(obs, values.atPose3(KEYS.pose_key()), points), e, rtol=1e-12, atol=1e-12)


def test_whitened_pose_jacobian_is_the_residuals_numerical_derivative():
    """whitened_pose_jacobian: the residuals of whitened_residuals and their derivative under GTSAM's right
    perturbation of the pose, against central differences, for mixed lenses."""
    from vfactor.factors.projection import whitened_pose_jacobian, whitened_residuals

    obs = observations(2.0, np.random.default_rng(4), cameras=CAMERAS + LENS_CAMERAS[2:])
    values = ProjectionContract().make_values(np.random.default_rng(9))
    pose = values.atPose3(KEYS.pose_key())
    points = np.concatenate([values.atVector(k) for k in KEYS.layer_keys()]).reshape(12, 3)
    e, J = whitened_pose_jacobian(obs, pose, points)
    np.testing.assert_array_equal(e, whitened_residuals(obs, pose, points))
    numerical = np.empty_like(J)
    for i in range(6):
        d = np.zeros(6)
        d[i] = 1e-6
        plus = whitened_residuals(obs, pose.compose(gtsam.Pose3.Expmap(d)), points)
        minus = whitened_residuals(obs, pose.compose(gtsam.Pose3.Expmap(-d)), points)
        numerical[:, :, i] = (plus - minus) / 2e-6
    np.testing.assert_allclose(J, numerical, rtol=1e-5, atol=1e-5 * np.abs(J).max())


def test_every_lens_matches_opencv_in_the_factor():
    from tests.conftest import opencv_pixels

    obs = observations(cameras=LENS_CAMERAS)
    world = TRUTH_SHAPE.in_world(TRUTH_POSE)
    for c, camera in enumerate(LENS_CAMERAS):
        assert np.allclose(obs.uv[obs.camera_index == c], opencv_pixels(camera, world), atol=1e-6)


def test_matches_opencv_projection():
    import cv2

    obs = observations()
    world = TRUTH_SHAPE.in_world(TRUTH_POSE)
    for c, camera in enumerate(CAMERAS):
        T = camera.camera_T_world
        expected, _ = cv2.projectPoints(world, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], camera.K, camera.dist)
        assert np.allclose(obs.uv[obs.camera_index == c], expected.reshape(-1, 2), atol=1e-6)


def test_matches_gtsam_native_projection_factor():
    """Same whitened error as GenericProjectionFactorCal3_S2 with the inverse pose as its variable."""
    camera = CAMERAS[0]
    obs = observations(2.0, np.random.default_rng(5)).subset(np.arange(24) < 12)
    values = ProjectionContract().make_values(np.random.default_rng(4))
    ours = projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, RobustLoss("none"))
    fx, s, cx = camera.K[0]
    cal = gtsam.Cal3_S2(fx, camera.K[1, 1], s, cx, camera.K[1, 2])
    native_graph = gtsam.NonlinearFactorGraph()
    native_values = gtsam.Values()
    native_values.insert(0, values.atPose3(KEYS.pose_key()).inverse())
    points = np.concatenate([values.atVector(k) for k in KEYS.layer_keys()]).reshape(12, 3)
    for i, k in enumerate(obs.keypoint_index):
        native_graph.add(
            gtsam.GenericProjectionFactorCal3_S2(obs.uv[i], gtsam.noiseModel.Isotropic.Sigma(2, 3.0), 0, 1 + k, cal, camera.pose)
        )
        native_values.insert(1 + k, points[k])
    assert np.isclose(ours.error(values), native_graph.error(native_values), rtol=1e-9)


@pytest.mark.parametrize("name", LOSSES)
def test_robust_loss_is_exact_and_downweights_outliers(name):
    loss = RobustLoss(name, 2.0)
    n = np.array([0.0, 1.0, 3.0, 30.0])
    s, _ = loss.scale(n)
    assert np.allclose(0.5 * (s * n) ** 2, loss.rho(n))
    w = loss.weight(n)
    assert w[0] == pytest.approx(1.0)
    if name != "none":
        assert w[-1] < 0.1


def test_robust_loss_rejects_bad_settings():
    with pytest.raises(ValueError, match="robust loss name"):
        RobustLoss("tukey-ish")
    with pytest.raises(ValueError, match="threshold"):
        RobustLoss("huber", -1.0)


def test_jacobians_hold_for_points_behind_a_camera():
    """Behind a camera the depth is clamped; the Jacobian must be that of the clamped projection."""
    from vfactor.testing import check_factor_jacobians

    obs = observations(2.0, np.random.default_rng(2))
    factor = projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, RobustLoss("cauchy", 2.0))
    behind = gtsam.Pose3(gtsam.Rot3.Yaw(0.3), np.array([30.0, 20.0, 0.3]))  # behind camera "a" at (15, 10, 7)
    assert CAMERAS[0].to_camera(TRUTH_SHAPE.in_world(behind))[:, 2].max() < 0
    check_factor_jacobians(factor, values_at(behind, TRUTH_SHAPE), rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("name", LOSSES)
def test_compiled_kernel_matches_the_numpy_projection_and_loss(name):
    """The factor's compiled residuals equal NumPy's projection, whitening and robust scaling."""
    from vfactor.factors.projection import whitened_residuals, whitened_residuals_numpy
    from vfactor.testing import whitened_error

    loss = RobustLoss(name, 1.5)
    obs = observations(3.0, np.random.default_rng(8), anisotropic=True)
    values = ProjectionContract().make_values(np.random.default_rng(9))
    factor = projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, loss)
    points = np.concatenate([values.atVector(k) for k in KEYS.layer_keys()]).reshape(12, 3)
    e = whitened_residuals_numpy(obs, values.atPose3(KEYS.pose_key()), points)
    assert np.allclose(whitened_residuals(obs, values.atPose3(KEYS.pose_key()), points), e, rtol=1e-12, atol=1e-12)
    s, _ = loss.scale(np.linalg.norm(e, axis=1))
    assert np.allclose(whitened_error(factor, values), (e * s[:, None]).ravel(), rtol=1e-10, atol=1e-10)


class TestProjectionTruncated(ProjectionContract):
    """Observations with a window that cuts through the vehicle: the truncated-mean residual."""

    loss = RobustLoss("cauchy", 2.0)

    @staticmethod
    def window(obs):
        # a window whose edges run through the middle of each camera's view of the vehicle
        centre = obs.uv.mean(axis=0)
        return np.tile([centre[0] - 20.0, -0.5, 5000.0, centre[1] + 10.0], (len(obs), 1))

    def make_factor(self):
        obs = observations(2.0, np.random.default_rng(11), self.anisotropic)
        obs = KeypointObservations(obs.cameras, obs.camera_index, obs.keypoint_index, obs.uv, obs.sqrt_information,
                                   self.window(obs))
        return projection_factor(KEYS.pose_key(), KEYS.layer_keys(), obs, self.loss)

    def test_zero_at_truth(self):
        obs = observations()
        windowed = KeypointObservations(obs.cameras, obs.camera_index, obs.keypoint_index, obs.uv,
                                        obs.sqrt_information, self.window(obs))
        expected, slope = windowed.expected_pixels(obs.uv)
        assert np.abs(expected - obs.uv).max() > 0.5 and slope.min() < 0.9  # the window matters here
        at_mean = KeypointObservations(obs.cameras, obs.camera_index, obs.keypoint_index, expected,
                                       obs.sqrt_information, windowed.window)
        factor = projection_factor(KEYS.pose_key(), KEYS.layer_keys(), at_mean, self.loss)
        assert factor.error(self.make_truth_values()) < 1e-12

    def test_kernel_matches_numpy(self):
        from vfactor.factors.projection import whitened_residuals, whitened_residuals_numpy
        from vfactor.testing import whitened_error

        factor = self.make_factor()
        obs = observations(2.0, np.random.default_rng(11))
        obs = KeypointObservations(obs.cameras, obs.camera_index, obs.keypoint_index, obs.uv, obs.sqrt_information,
                                   self.window(obs))
        values = self.make_values(np.random.default_rng(4))
        points = np.concatenate([values.atVector(k) for k in KEYS.layer_keys()]).reshape(12, 3)
        e = whitened_residuals_numpy(obs, values.atPose3(KEYS.pose_key()), points)
        assert np.allclose(whitened_residuals(obs, values.atPose3(KEYS.pose_key()), points), e, rtol=1e-12, atol=1e-12)
        s, _ = self.loss.scale(np.linalg.norm(e, axis=1))
        assert np.allclose(whitened_error(factor, values), (e * s[:, None]).ravel(), rtol=1e-10, atol=1e-10)


def test_window_shape_is_checked():
    obs = observations()
    with pytest.raises(ValueError, match="window"):
        KeypointObservations(obs.cameras, obs.camera_index, obs.keypoint_index, obs.uv, obs.sqrt_information,
                             np.zeros((3, 4)))
    for wrong in (-1, len(obs.cameras)):  # a negative index named the last camera without a word
        index = obs.camera_index.copy()
        index[0] = wrong
        with pytest.raises(IndexError, match="camera_index"):
            KeypointObservations(obs.cameras, index, obs.keypoint_index, obs.uv, obs.sqrt_information)
    upside_down = np.tile([0.0, 0.0, 640.0, 480.0], (len(obs), 1))
    upside_down[3] = [0.0, 480.0, 640.0, 0.0]
    with pytest.raises(ValueError, match="v_lo < v_hi"):
        KeypointObservations(obs.cameras, obs.camera_index, obs.keypoint_index, obs.uv, obs.sqrt_information,
                             upside_down)


def test_scaled_observations_equal_freshly_built_ones():
    """KeypointObservations.scaled keeps the camera tables and rescales the noise as a new object would have it."""
    from vfactor.graph import observations_from_detections
    from vfactor.sim import simulate

    sim = simulate("tracks_3cam", seed=2, num_frames=6)  # vehicles cut by the image border: truncation windows
    for frame in sim.scene.frames:
        for vid in frame.vehicle_ids():
            obs = observations_from_detections(frame.detections_of(vid), sim.scene.cameras)
            scaled = obs.scaled(0.37)
            fresh = KeypointObservations(obs.cameras, obs.camera_index, obs.keypoint_index, obs.uv,
                                         scaled.sqrt_information, obs.window, obs.min_sigma)
            np.testing.assert_allclose(scaled._sigma_table, fresh._sigma_table)
            np.testing.assert_allclose(scaled.sqrt_information, obs.sqrt_information / np.maximum(
                0.37, obs.min_sigma * np.linalg.norm(obs.sqrt_information, ord=2, axis=(1, 2)))[:, None, None])


def _tables(obs: KeypointObservations) -> dict:
    """Every array KeypointObservations holds, by name (the kernel's tables included)."""
    out = {name: value for name, value in obs.__dict__.items() if isinstance(value, np.ndarray)}
    out.update({f"_intrinsics{i}": column for i, column in enumerate(obs._intrinsics)})
    return out


@pytest.mark.parametrize("cameras", [CAMERAS, LENS_CAMERAS, CAMERAS[:1]], ids=["plain+distorted", "every lens", "plain"])
def test_subset_and_relabelled_equal_freshly_built_observations(cameras):
    """subset and relabelled take their tables from the observations; a new object would build the same, to the bit."""
    rng = np.random.default_rng(5)
    obs = observations(cameras=cameras)
    n = len(obs)
    window = np.where(rng.random((n, 1)) < 0.5, np.array([[-0.5, -0.5, 1279.5, 719.5]]), np.nan)
    calibrated = rng.random(n) < 0.5
    obs = KeypointObservations(obs.cameras, obs.camera_index, obs.keypoint_index, obs.uv,
                               obs.sqrt_information * rng.uniform(0.5, 2.0, (n, 1, 1)), window, 1.0, calibrated)
    for mask in (rng.random(n) < 0.6, obs.camera_index != 0, np.zeros(n, dtype=bool), np.flatnonzero(rng.random(n) < 0.3)):
        got = obs.subset(mask)
        fresh = KeypointObservations(obs.cameras, obs.camera_index[mask], obs.keypoint_index[mask], obs.uv[mask],
                                     obs.sqrt_information[mask], window[mask], 1.0, calibrated[mask])
        expected, found = _tables(fresh), _tables(got)
        assert expected.keys() == found.keys()
        for name in expected:
            np.testing.assert_array_equal(found[name], expected[name], err_msg=name)
            assert found[name].dtype == expected[name].dtype, name
        assert (got._fisheye is False) == (fresh._fisheye is False) and (got._dist is None) == (fresh._dist is None)
    labels = np.array([1, 0, 3, 2, 5, 4, 7, 6, 9, 8, 11, 10])[obs.keypoint_index]
    got = obs.relabelled(labels)
    fresh = KeypointObservations(obs.cameras, obs.camera_index, labels, obs.uv, obs.sqrt_information, window, 1.0,
                                 calibrated)
    for name, value in _tables(fresh).items():
        np.testing.assert_array_equal(_tables(got)[name], value, err_msg=name)
    with pytest.raises(ValueError, match="integer labels"):
        obs.relabelled(labels[:-1])
