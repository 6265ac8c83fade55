"""The network's shape-like error: the fit recovers a known one, the command fits and writes it, the pipeline sets it."""

from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from vfactor.net.calibrate import CovarianceCalibration, write_calibration  # noqa: E402
from vfactor.net.commands import main  # noqa: E402
from vfactor.net.infer import KeypointDetector, default_weights_path  # noqa: E402
from vfactor.net.shape_error import VehicleErrors, fit_shape_sigma, keypoint_nees_at, pose_nees_at  # noqa: E402


def synthetic_vehicles(shape_sigma: float, n: int = 400, seed: int = 0) -> list[VehicleErrors]:
    """Vehicles whose keypoint errors are drawn from their covariance plus ``shape_sigma^2 / cameras``."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        A = rng.normal(0.0, 0.03, (12, 3, 3))
        cov = A @ np.swapaxes(A, 1, 2) + 1e-4 * np.eye(3)
        cameras = 2 + i % 2
        true = cov + shape_sigma ** 2 / cameras * np.eye(3)
        error = np.einsum("kij,kj->ki", np.linalg.cholesky(true), rng.normal(size=(12, 3)))
        out.append(VehicleErrors(error, cov, cameras, "sedan"))
    return out


def test_the_fit_recovers_a_known_shape_error():
    vehicles = synthetic_vehicles(0.05)
    assert np.mean(keypoint_nees_at(vehicles, 0.0)) > 3.5
    sigma = fit_shape_sigma(vehicles)
    assert sigma == pytest.approx(0.05, rel=0.1)
    assert np.mean(keypoint_nees_at(vehicles, sigma)) == pytest.approx(3.0, abs=1e-6)
    assert fit_shape_sigma(synthetic_vehicles(0.0)) < 0.01  # consistent keypoints need (almost) none
    with pytest.raises(ValueError, match="no solved vehicles"):
        fit_shape_sigma([])
    with pytest.raises(ValueError, match="still leaves"):
        fit_shape_sigma(synthetic_vehicles(0.05), upper=0.001)


def test_the_fit_recovers_a_shape_error_that_grows_with_the_vehicle():
    """Vehicles of three sizes whose shape error is ``sigma (V / V0) ** 1.5``: fitted with that law, ``sigma``
    comes back and every size is consistent; one size for all leaves the small ones wide, the large ones narrow."""
    from vfactor.graph import shape_sigma_at_size

    box = np.array([[x, y, z] for x in (0.0, 4.5) for y in (0.0, 1.6) for z in (0.0, 1.25)] * 2)[:12]  # 9 m^3
    rng = np.random.default_rng(1)
    vehicles = []
    for i, v in enumerate(synthetic_vehicles(0.0, n=600, seed=2)):
        points = box * (0.8, 1.0, 1.3)[i % 3]
        sigma = shape_sigma_at_size(0.04, points, 1.5)
        true = v.covariance + sigma ** 2 / v.cameras * np.eye(3)
        error = np.einsum("kij,kj->ki", np.linalg.cholesky(true), rng.normal(size=(12, 3)))
        vehicles.append(VehicleErrors(error, v.covariance, v.cameras, "sedan", points))
    assert fit_shape_sigma(vehicles, size_exponent=1.5) == pytest.approx(0.04, rel=0.1)
    fitted = fit_shape_sigma(vehicles, size_exponent=1.5)
    for scale in range(3):
        group = [v for i, v in enumerate(vehicles) if i % 3 == scale]
        assert np.mean(keypoint_nees_at(group, fitted, 1.5)) == pytest.approx(3.0, rel=0.15)
    one_size = fit_shape_sigma(vehicles)  # the law ignored
    small, large = ([v for i, v in enumerate(vehicles) if i % 3 == k] for k in (0, 2))
    assert np.mean(keypoint_nees_at(small, one_size)) < 2.5 < 3.5 < np.mean(keypoint_nees_at(large, one_size))


def test_the_fit_takes_each_vehicles_own_widening_through_the_fit_and_the_pose_with_it():
    """Vehicles whose keypoint and pose errors are drawn from their covariances plus ``sigma^2`` times their own
    ``unit_covariance`` and ``pose_unit_covariance`` (the error through the fit: not ``I / cameras``): the fit
    recovers ``sigma`` and the poses come out consistent at it; ``I / cameras`` in place of each vehicle's own
    widening fits another sigma."""
    rng = np.random.default_rng(3)
    vehicles = []
    for v in synthetic_vehicles(0.0, n=500, seed=4):
        B = rng.normal(0.0, 1.0, (12, 3, 3))
        unit = B @ np.swapaxes(B, 1, 2) + 0.2 * np.eye(3)  # per m^2 of sigma^2
        error = np.einsum("kij,kj->ki", np.linalg.cholesky(v.covariance + 0.03 ** 2 * unit), rng.normal(size=(12, 3)))
        Q = rng.normal(0.0, 0.01, (6, 6))
        pose_cov, pose_unit = Q @ Q.T + 1e-6 * np.eye(6), np.diag(rng.uniform(0.5, 2.0, 6))
        pose_error = np.linalg.cholesky(pose_cov + 0.03 ** 2 * pose_unit) @ rng.normal(size=6)
        vehicles.append(dataclasses.replace(v, error=error, unit_covariance=unit, pose_error=pose_error,
                                            pose_covariance=pose_cov, pose_unit_covariance=pose_unit))
    sigma = fit_shape_sigma(vehicles)
    assert sigma == pytest.approx(0.03, rel=0.1)
    assert np.mean(pose_nees_at(vehicles, sigma)) == pytest.approx(6.0, rel=0.1)
    assert np.mean(pose_nees_at(vehicles, 0.0)) > 9.0
    block = [dataclasses.replace(v, unit_covariance=None) for v in vehicles]
    assert fit_shape_sigma(block) > 1.5 * sigma  # I / cameras is narrower than these vehicles' own widening


def test_calibrate_shape_command_fits_and_writes_and_the_pipeline_uses_it(tmp_path, capsys):
    weights = tmp_path / "keypoints.pt"
    shutil.copy(default_weights_path(), weights)
    write_calibration(weights, CovarianceCalibration(**{**KeypointDetector(weights).calibration.to_dict(),
                                                        "shape_sigma": 0.0}))
    code = main(["calibrate-shape", "--weights", str(weights), "--scenario", "library_2cam", "--seed", "7",
                 "--seeds", "1", "--frames", "3", "--write"])
    assert code == 0
    out = capsys.readouterr()
    assert "| all | 3 |" in out.out and "written to" in out.err and "fitted to the class alone" in out.out
    assert " cm (" in out.out.split("| all | 3 |", 1)[1].splitlines()[0]  # the class-alone fit beside the pooled one
    printed = float(out.out.split("shape_sigma ", 1)[1].split(" m", 1)[0])
    calibration = KeypointDetector(weights).calibration
    assert calibration.shape_sigma == pytest.approx(printed, abs=1e-4) and 0.0 <= calibration.shape_sigma < 0.5
    assert calibration.scale == KeypointDetector(default_weights_path()).calibration.scale  # the pixels' is kept
    write_calibration(weights, CovarianceCalibration(**{**calibration.to_dict(), "shape_sigma": 0.05}))
    from vfactor.net.pipeline import detect_scene
    from vfactor.render.scenes import render_simulation
    from vfactor.sim import load_scenario, simulate

    sim = simulate(load_scenario("library_2cam"), seed=7, num_frames=1)
    rendered = render_simulation(sim, tmp_path / "render", seed=7)
    detected = detect_scene(rendered.scene, KeypointDetector(weights))
    assert {d.shape_sigma for d in detected.frames[0].detections} == {0.05}
    bias = KeypointDetector(weights).calibration.bias_sigma  # calibrate-bias's, kept by calibrate-shape --write
    assert bias is not None and {d.bias_sigma for d in detected.frames[0].detections} == {bias}


def test_vehicle_errors_unit_covariances_are_what_the_solve_adds_at_any_sigma():
    """vehicle_errors' decomposition, which calibrate-shape fits on: the solve's covariances with a detector shape
    error of sigma (taken at the vehicle's size) are the ones without it plus sigma^2 times the unit covariances,
    for the pose and every keypoint; the part through the fit widens the pose."""
    from vfactor.evaluation import solve_held_out
    from vfactor.graph import observations_from_detections, shape_sigma_at_size
    from vfactor.net.shape_error import vehicle_errors
    from vfactor.sim import simulate
    from vfactor.solve import SolveOptions

    sim = simulate("library_2cam", seed=7, num_frames=2)
    options = SolveOptions()
    vehicles = vehicle_errors(sim, sim.scene, options)
    seen = [(f, vid) for f, frame in enumerate(sim.scene.frames) for vid in frame.vehicle_ids()]
    assert len(vehicles) == len(seen) >= 2
    for (f, vid), v in zip(seen, vehicles):
        detections = [dataclasses.replace(d, shape_sigma=0.05) for d in sim.scene.frames[f].detections_of(vid)]
        result = solve_held_out(observations_from_detections(detections, sim.scene.cameras, options.graph),
                                sim.truth[f][vid].preset, options, vid)
        sigma = shape_sigma_at_size(0.05, v.vehicle_p_keypoints, options.graph.shape_sigma_size_exponent)
        np.testing.assert_allclose(result.keypoint_covariances_world, v.covariance + sigma ** 2 * v.unit_covariance,
                                   rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(result.pose_covariance, v.pose_covariance + sigma ** 2 * v.pose_unit_covariance,
                                   rtol=1e-6, atol=1e-14)
        assert np.trace(v.pose_unit_covariance) > 0
        assert pose_nees_at([v], 0.05, options.graph.shape_sigma_size_exponent)[0] < pose_nees_at([v], 0.0)[0]
