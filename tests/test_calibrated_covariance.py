"""Calibrated keypoint covariances (the keypoint network's) are a floor for the result's covariances (issue 16).

The network's errors are largely ones a pose and shape explain, so the fit
absorbs them and the residuals' noise scale understates them; a detection
whose covariances are calibrated against the detector's true errors
(``Detection.covariance_calibrated``) keeps at least them in the covariances
(docs/network.md, "Covariances in the factor graph").
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from vfactor.errors import SceneError
from vfactor.factors.projection import KeypointObservations
from vfactor.evaluation import NOISE_LEVELS, noise_variant
from vfactor.graph import (
    SHAPE_SIGMA_REFERENCE_VOLUME,
    GraphConfig,
    detector_offset_prior,
    observations_from_detections,
    shape_sigma_at_size,
)
from vfactor.scene import load_scene, save_scene
from vfactor.sim import load_scenario, simulate
from vfactor.schema import validate
from vfactor.solve import SolveOptions, detector_shape_covariance, detector_shape_variance, solve_observations


def _vehicles(seed: int = 7, frames: int = 6):
    """Clean simulated keypoints (0.3 % of the box: about 1-2 px) of held-out library vehicles, two cameras."""
    scenario = noise_variant(load_scenario("library_2cam"), **NOISE_LEVELS["clean"])
    sim = simulate(scenario, seed=seed, num_frames=frames)
    return [(sim, f, vid) for f, frame in enumerate(sim.scene.frames) for vid in frame.vehicle_ids()]


def _solve(sim, f, vid, sigma_px: float, calibrated: bool):
    """The vehicle solved with every keypoint given the covariance ``sigma_px^2 I``."""
    dets = [dataclasses.replace(d, covariance=np.tile(np.eye(2) * sigma_px**2, (12, 1, 1)),
                                covariance_calibrated=calibrated)
            for d in sim.scene.frames[f].detections_of(vid)]
    obs = observations_from_detections(dets, sim.scene.cameras, SolveOptions().graph)
    return solve_observations(obs, SolveOptions(), vid)


def test_calibrated_covariances_are_not_narrowed_by_the_residuals():
    """Keypoints far sharper (1-2 px) than their covariances (6 px): the residuals' scale narrows the covariances
    only when they are not calibrated; the estimate itself is the same."""
    cases = _vehicles()
    assert len(cases) >= 6
    ratios = []
    for sim, f, vid in cases:
        free, floored = _solve(sim, f, vid, 6.0, False), _solve(sim, f, vid, 6.0, True)
        assert free.ok and floored.ok
        np.testing.assert_allclose(floored.world_T_vehicle.matrix(), free.world_T_vehicle.matrix(), atol=1e-9)
        assert free.extras["noise_scale"] < 0.6  # the solve saw the sharp keypoints either way
        ratios.append(np.trace(floored.pose_covariance) / np.trace(free.pose_covariance))
        # at the floor the covariance is that of the nominal 6 px sigmas, with no Student-t factor
        assert floored.extras["covariance_inflation"] == 1.0 < free.extras["covariance_inflation"]
    # variances at 6 px against the 1-2 px the residuals show: many times wider
    assert min(ratios) > 5.0, ratios


def test_calibrated_covariances_still_widen_with_larger_residuals():
    """Covariances (0.3 px) sharper than the keypoints' noise: the residuals' scale widens them, calibrated or not."""
    for sim, f, vid in _vehicles()[:2]:
        free, floored = _solve(sim, f, vid, 0.3, False), _solve(sim, f, vid, 0.3, True)
        assert free.extras["noise_scale"] > 1.5
        np.testing.assert_allclose(floored.pose_covariance, free.pose_covariance, rtol=1e-9, atol=0.0)


def test_only_detections_that_say_so_are_calibrated():
    sim, f, vid = _vehicles(frames=1)[0]
    a, b = sim.scene.frames[f].detections_of(vid)[:2]
    cov = np.tile(np.eye(2) * 9.0, (12, 1, 1))
    dets = [dataclasses.replace(a, covariance=cov, covariance_calibrated=True), b]  # b: the simulator's, no covariance
    obs = observations_from_detections(dets, sim.scene.cameras)
    np.testing.assert_array_equal(obs.calibrated, obs.camera_index == list(sim.scene.cameras).index(a.camera))
    assert observations_from_detections([b], sim.scene.cameras).calibrated is None
    assert obs.subset(obs.calibrated).calibrated.all()
    # per-observation noise scales (the covariance graph's floor)
    factors = np.where(obs.calibrated, 1.0, 0.5)
    sigma = 1.0 / np.linalg.norm(obs.scaled(factors).sqrt_information, ord=2, axis=(1, 2))
    np.testing.assert_allclose(sigma, np.where(obs.calibrated, 3.0, 0.5 / np.linalg.norm(
        obs.sqrt_information, ord=2, axis=(1, 2))))


def test_the_flag_round_trips_through_a_scene_file(tmp_path):
    sim, f, vid = _vehicles(frames=1)[0]
    frame = sim.scene.frames[0]
    cov = np.tile(np.eye(2) * 4.0, (12, 1, 1))
    dets = [dataclasses.replace(d, covariance=cov, covariance_calibrated=(j == 0)) for j, d in enumerate(frame.detections)]
    scene = dataclasses.replace(sim.scene, frames=[dataclasses.replace(frame, detections=dets)])
    save_scene(scene, tmp_path / "scene.json")
    back = load_scene(tmp_path / "scene.json")
    assert [d.covariance_calibrated for d in back.frames[0].detections] == [j == 0 for j in range(len(dets))]
    text = (tmp_path / "scene.json").read_text()
    assert text.count('"covariances_calibrated"') == 1
    assert validate(json.loads(text), "scene") == []  # the schema knows the flag too
    bad = text.replace('"covariances_calibrated": true', '"covariances_calibrated": "yes"')
    (tmp_path / "bad.json").write_text(bad)
    with pytest.raises(SceneError, match="covariances_calibrated"):
        load_scene(tmp_path / "bad.json")


def test_a_detector_bias_round_trips_and_leaves_one_frame_solves_alone(tmp_path):
    """``Detection.bias_sigma``: written and read back (valid under the schema), bad values named; a one-frame
    solve does not use it (the bias is an error a track's frames share: tests/test_track.py)."""
    sim, f, vid = _vehicles(frames=1)[0]
    frame = sim.scene.frames[0]
    bias = (0.01, 0.012, 0.004, 0.03, 0.01, 0.02)
    dets = [dataclasses.replace(d, bias_sigma=bias) for d in frame.detections]
    scene = dataclasses.replace(sim.scene, frames=[dataclasses.replace(frame, detections=dets)])
    save_scene(scene, tmp_path / "scene.json")
    text = (tmp_path / "scene.json").read_text()
    assert validate(json.loads(text), "scene") == []
    assert [d.bias_sigma for d in load_scene(tmp_path / "scene.json").frames[0].detections] == [bias] * len(dets)
    written = json.dumps(list(bias))[1:-1]
    for bad in ("[0.01, 0.02]", "[0.01, -0.012, 0.004, 0.03, 0.01, 0.02]", '"1 deg"',
                "[0.01, 0.012, 0.004, 0.03, 0.01, \"x\"]"):
        assert f"[{written}]" in text
        (tmp_path / "bad.json").write_text(text.replace(f"[{written}]", bad, 1))
        with pytest.raises(SceneError, match="bias_sigma"):
            load_scene(tmp_path / "bad.json")
        assert validate(json.loads((tmp_path / "bad.json").read_text()), "scene") != []
    obs = observations_from_detections([d for d in dets if d.vehicle == vid], sim.scene.cameras, SolveOptions().graph)
    plain = observations_from_detections(frame.detections_of(vid), sim.scene.cameras, SolveOptions().graph)
    a, b = solve_observations(obs, SolveOptions(), vid), solve_observations(plain, SolveOptions(), vid)
    np.testing.assert_array_equal(a.world_T_vehicle.matrix(), b.world_T_vehicle.matrix())
    np.testing.assert_array_equal(a.pose_covariance, b.pose_covariance)


def test_a_detector_shape_error_round_trips_and_widens_the_covariances(tmp_path):
    """``Detection.shape_sigma``: written and read back (and valid under the schema); the solve is unchanged; with
    the error on the shape block alone (``shape_error_through_fit=0``) the shape and world keypoint covariances grow
    by ``1 / sum_c sigma_c^-2`` per axis and the pose covariance not; by default the error through the fit widens
    the pose too, and the keypoints by more."""
    sim, f, vid = _vehicles(frames=1)[0]
    frame = sim.scene.frames[0]
    sigmas = [0.04, 0.08, 0.06][: len(frame.detections)]
    dets = [dataclasses.replace(d, shape_sigma=s) for d, s in zip(frame.detections, sigmas)]
    scene = dataclasses.replace(sim.scene, frames=[dataclasses.replace(frame, detections=dets)])
    save_scene(scene, tmp_path / "scene.json")
    text = (tmp_path / "scene.json").read_text()
    assert validate(json.loads(text), "scene") == []
    back = load_scene(tmp_path / "scene.json").frames[0].detections
    assert [d.shape_sigma for d in back] == sigmas
    for bad, match in (('"shape_sigma": -0.1', "shape_sigma"), ('"shape_sigma": "5 cm"', "shape_sigma")):
        (tmp_path / "bad.json").write_text(text.replace('"shape_sigma": 0.04', bad))
        with pytest.raises(SceneError, match=match):
            load_scene(tmp_path / "bad.json")
        assert validate(json.loads((tmp_path / "bad.json").read_text()), "scene") != []

    config = SolveOptions().graph
    plain = solve_observations(observations_from_detections(frame.detections_of(vid), sim.scene.cameras, config),
                               SolveOptions(), vid)
    obs = observations_from_detections([d for d in dets if d.vehicle == vid], sim.scene.cameras, config)
    block = SolveOptions(graph=dataclasses.replace(config, shape_error_through_fit=0.0))
    widened = solve_observations(obs, block, vid)
    assert detector_shape_variance(observations_from_detections(frame.detections_of(vid), sim.scene.cameras,
                                                                config)) == 0.0
    seen_by = [s for d, s in zip(dets, sigmas) if d.vehicle == vid and np.any(d.confidence > 0)]
    assert detector_shape_variance(obs) == pytest.approx(1.0 / sum(s ** -2 for s in seen_by))  # as given
    points, exponent = widened.wireframe.vehicle_p_keypoints, config.shape_sigma_size_exponent
    size = shape_sigma_at_size(1.0, points, exponent)  # each sigma at the vehicle's size
    assert size != pytest.approx(1.0, abs=0.01) and exponent > 0
    variance = 1.0 / sum((size * s) ** -2 for s in seen_by)
    assert detector_shape_variance(obs, points, exponent) == pytest.approx(variance)
    assert widened.extras["detector_shape_sigma"] == pytest.approx(np.sqrt(variance))
    np.testing.assert_allclose(widened.keypoints_world, plain.keypoints_world, atol=1e-9)
    np.testing.assert_allclose(widened.pose_covariance, plain.pose_covariance, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(widened.keypoint_covariances_world,
                               plain.keypoint_covariances_world + variance * np.eye(3), rtol=1e-9, atol=1e-12)
    assert np.all(widened.box.size_sigma > plain.box.size_sigma)

    through = solve_observations(obs, SolveOptions(), vid)  # the default: the error through the fit as well
    np.testing.assert_allclose(through.keypoints_world, plain.keypoints_world, atol=1e-9)
    extra = through.pose_covariance - plain.pose_covariance
    assert np.linalg.eigvalsh(0.5 * (extra + extra.T)).min() > -1e-12 and np.trace(extra) > 0.05 * np.trace(
        plain.pose_covariance)
    for wider, narrower in zip(through.keypoint_covariances_world, widened.keypoint_covariances_world):
        assert np.linalg.eigvalsh(wider - narrower).min() > -1e-12 and np.trace(wider - narrower) > 0


def test_the_detectors_error_through_the_fit_is_what_a_least_squares_solution_passes_on():
    """detector_shape_covariance on a linear least-squares problem (pose 6 + shape 36 unknowns, a prior on the shape,
    two cameras' rows): its ``sum_c sigma_c^2 G_c G_c^T`` equals the covariance of the solutions that re-solving
    with each camera's right-hand side moved by ``A_c,s d_c`` gives, ``G_c`` built column by column from re-solves."""
    rng = np.random.default_rng(4)
    A = rng.normal(size=(40, 42))
    camera_index = np.repeat([0, 1], 10)  # 20 observations, two rows each
    prior = np.diag(np.r_[np.zeros(6), np.full(36, 4.0)])
    H = A.T @ A + prior
    b = rng.normal(size=40)
    solve = lambda rhs: np.linalg.solve(H, A.T @ rhs)  # noqa: E731
    cameras = tuple(dataclasses.replace(next(iter(load_scenario("intersection_2cam").cameras.values())), name=n)
                    for n in "ab")
    obs = KeypointObservations(cameras, camera_index, np.arange(20) % 12, np.zeros((20, 2)),
                               np.tile(np.eye(2), (20, 1, 1)))
    sigmas = {"a": 0.05, "b": 0.02}
    expected = np.zeros((42, 42))
    rows = np.repeat(camera_index, 2)
    for c, name in enumerate("ab"):
        G = np.empty((42, 36))
        for j in range(36):
            moved = b.copy()
            moved[rows == c] += A[rows == c, 6 + j]  # the camera's rows as if its keypoints moved by e_j
            G[:, j] = solve(moved) - solve(b)
        expected += sigmas[name] ** 2 * G @ G.T
    np.testing.assert_allclose(detector_shape_covariance(np.linalg.inv(H), A, obs, sigmas), expected,
                               rtol=1e-9, atol=1e-14)
    assert np.allclose(detector_shape_covariance(np.linalg.inv(H), A, obs, {}), 0.0)
    with pytest.raises(ValueError, match="shape_error_through_fit"):
        GraphConfig(shape_error_through_fit=-1.0)


def test_a_detector_shape_error_is_taken_at_the_vehicles_size():
    """shape_sigma_at_size: as given at the reference volume of the keypoints' box or with exponent 0, times
    (V / V0) ** exponent otherwise; a degenerate shape is held to a quarter .. four times V0."""
    box = np.array([[x, y, z] for x in (0.0, 4.5) for y in (0.0, 1.6) for z in (0.0, 1.25)] * 2)[:12]
    assert np.prod(np.ptp(box, axis=0)) == pytest.approx(SHAPE_SIGMA_REFERENCE_VOLUME)
    assert shape_sigma_at_size(0.05, box, 1.5) == pytest.approx(0.05)
    assert shape_sigma_at_size(0.05, box * 2.0, 0.0) == 0.05
    assert shape_sigma_at_size(0.05, box * 1.5, 1.5) == pytest.approx(0.05 * 3.375 ** 1.5)
    assert shape_sigma_at_size(0.05, box * [1.0, 1.0, 0.5], 1.0) == pytest.approx(0.025)
    assert shape_sigma_at_size(0.05, np.zeros((12, 3)), 1.5) == pytest.approx(0.05 * 0.25 ** 1.5)
    assert shape_sigma_at_size(0.05, box * 3.0, 1.5) == pytest.approx(0.05 * 4.0 ** 1.5)
    assert shape_sigma_at_size(0.05, np.full((12, 3), np.nan), 1.5) == pytest.approx(0.05)
    # the tracks' offset prior takes its sigma at the size too: a car 1.5 times as large in every direction has the
    # translation information of a sigma 3.375 ** 1.5 times larger
    small, large = (detector_offset_prior(1, 0.05, p, size_exponent=1.5) for p in (box, box * 1.5))
    info = lambda f: np.linalg.inv(f.noiseModel().covariance())  # noqa: E731
    assert info(small)[3, 3] == pytest.approx(3.375 ** 3 * info(large)[3, 3])
    with pytest.raises(ValueError, match="shape_sigma_size_exponent"):
        GraphConfig(shape_sigma_size_exponent=-1.0)


def test_each_keypoint_takes_its_own_covariance_or_the_confidence_sigma():
    """observations_from_detections, keypoint by keypoint: a finite 2x2 covariance gives its own square-root
    information (and the detection's calibration flag), a NaN one the confidence-weighted sigma of the box."""
    sim, f, vid = _vehicles(frames=1)[0]
    a, b = sim.scene.frames[f].detections_of(vid)[:2]
    rng = np.random.default_rng(3)
    A = rng.normal(0.0, 2.0, (12, 2, 2))
    cov = A @ np.swapaxes(A, 1, 2) + np.eye(2)
    cov[[1, 5, 6]] = np.nan  # keypoints without a covariance of their own
    dets = [dataclasses.replace(a, covariance=cov, covariance_calibrated=True), b]
    config = SolveOptions().graph
    obs = observations_from_detections(dets, sim.scene.cameras, config)
    for det in dets:
        seen = np.flatnonzero(det.confidence > 0)
        rows = obs.camera_index == list(sim.scene.cameras).index(det.camera)
        np.testing.assert_array_equal(obs.keypoint_index[rows], seen)
        np.testing.assert_array_equal(obs.uv[rows], det.keypoints[seen])
        base = max(config.min_pixel_sigma, config.relative_pixel_sigma * det.box_diagonal())
        for L, k, calibrated in zip(obs.sqrt_information[rows], seen, obs.calibrated[rows]):
            own = det.covariance is not None and np.isfinite(det.covariance[k]).all()
            expected = np.linalg.cholesky(np.linalg.inv(det.covariance[k])).T if own else \
                np.eye(2) * (det.confidence[k] / base)
            np.testing.assert_array_equal(L, expected)
            assert calibrated == own


def test_calibrated_keypoints_of_a_vehicle_only_cut_views_show_are_taken_wider():
    """GraphConfig.cut_view_sigma_factor: where every detection's box reaches beyond its image, the calibrated
    keypoints' square-root information is divided by the factor; a whole view among them, keypoints without a
    calibrated covariance or a factor of 1 leave every sigma as it is."""
    sim, f, vid = _vehicles(frames=1)[0]
    dets = sim.scene.frames[f].detections_of(vid)
    assert len(dets) == 2
    beyond = [-40.0, 10.0, 300.0, 200.0]  # reaches beyond the left edge of every camera's image
    inside = [20.0, 10.0, 300.0, 200.0]

    def observed(rois, calibrated=True, factor=None):
        config = SolveOptions().graph if factor is None else dataclasses.replace(SolveOptions().graph,
                                                                               cut_view_sigma_factor=factor)
        given = [dataclasses.replace(d, covariance=np.tile(np.eye(2) * 4.0, (12, 1, 1)), roi=roi,
                                     covariance_calibrated=calibrated) for d, roi in zip(dets, rois)]
        return observations_from_detections(given, sim.scene.cameras, config).sqrt_information

    whole = observed([inside, inside])
    factor = SolveOptions().graph.cut_view_sigma_factor
    assert factor > 1.0
    np.testing.assert_allclose(observed([beyond, beyond]), whole / factor)
    np.testing.assert_allclose(observed([beyond, inside]), whole)  # a whole view anchors the vehicle
    np.testing.assert_allclose(observed([beyond, beyond], calibrated=False), whole)
    np.testing.assert_allclose(observed([beyond, beyond], factor=1.0), whole)
    np.testing.assert_allclose(observed([beyond, beyond], factor=2.0), whole / 2.0)
    with pytest.raises(ValueError, match="cut_view_sigma_factor"):
        GraphConfig(cut_view_sigma_factor=0.0)
