"""The cameras' extrinsic uncertainty: its Jacobian, the covariance it adds, the scene and scenario fields."""

from __future__ import annotations

import dataclasses
import json

import gtsam
import numpy as np
import pytest

from vfactor.camera import Camera, extrinsic_sigma
from vfactor.errors import CalibrationError, ScenarioError, SceneError
from vfactor.evaluation import NOISE_LEVELS, compare_methods, noise_variant
from vfactor.extrinsics import extrinsic_covariance, extrinsic_jacobian
from vfactor.factors.projection import whitened_pose_jacobian, whitened_residuals
from vfactor.graph import GraphConfig, observations_from_detections
from vfactor.metrics import CHI2_95
from vfactor.scene import load_scene, save_scene, scene_from_dict, scene_to_dict
from vfactor.schema import validate
from vfactor.sim import ExtrinsicError, load_scenario, scenario_from_dict, simulate
from vfactor.solve import SolveOptions, solve_frame

SURVEY = extrinsic_sigma(0.3, 0.05)  # a survey's accuracy: 0.3 degrees and 5 cm per camera axis


def _one_vehicle(seed: int = 3):
    sim = simulate("library_2cam", seed=seed, num_frames=1)
    frame = sim.scene.frames[0]
    vid = frame.vehicle_ids()[0]
    return sim, frame, vid


def test_extrinsic_jacobian_is_the_derivative_of_the_residuals_by_the_cameras_pose():
    """The camera's error acts on its residuals as a change of the vehicle's pose: against central differences of
    the compiled residuals with the camera moved by ``Exp(xi)`` (a lens with distortion, rotation and translation)."""
    sim, frame, vid = _one_vehicle()
    truth = sim.truth[0][vid]
    obs = observations_from_detections(frame.detections_of(vid), sim.scene.cameras, GraphConfig())
    points = truth.wireframe.vehicle_p_keypoints
    _, pose_jacobian = whitened_pose_jacobian(obs, truth.world_T_vehicle, points)
    for c in np.unique(obs.camera_index):
        rows = obs.camera_index == c
        camera = obs.cameras[c]
        B = extrinsic_jacobian(pose_jacobian[rows].reshape(-1, 6), truth.world_T_vehicle, camera.pose)
        numeric, h = np.zeros_like(B), 1e-6
        for k in range(6):
            moved = []
            for sign in (1.0, -1.0):
                xi = np.zeros(6)
                xi[k] = sign * h
                camera_moved = dataclasses.replace(
                    camera, world_T_camera=camera.world_T_camera @ gtsam.Pose3.Expmap(xi).matrix())
                cameras = tuple(camera_moved if i == c else other for i, other in enumerate(obs.cameras))
                moved.append(whitened_residuals(dataclasses.replace(obs, cameras=cameras), truth.world_T_vehicle,
                                                points)[rows].ravel())
            numeric[:, k] = (moved[0] - moved[1]) / (2 * h)
        np.testing.assert_allclose(B, numeric, rtol=0, atol=1e-6 * np.abs(numeric).max())


def test_extrinsic_covariance_is_the_linear_propagation_of_the_cameras_errors():
    """``sum_c P A_c^T B_c S_c B_c^T A_c P`` against the least-squares step of each drawn error, and nothing for
    cameras without a sigma."""
    sim, frame, vid = _one_vehicle()
    truth = sim.truth[0][vid]
    cameras = {name: dataclasses.replace(cam, extrinsic_sigma=SURVEY) for name, cam in sim.scene.cameras.items()}
    obs = observations_from_detections(frame.detections_of(vid), cameras, GraphConfig())
    _, pose_jacobian = whitened_pose_jacobian(obs, truth.world_T_vehicle, truth.wireframe.vehicle_p_keypoints)
    A = pose_jacobian.reshape(-1, 6)  # the pose alone: P = (A^T A)^-1
    P = np.linalg.inv(A.T @ A)
    C = extrinsic_covariance(P, A, obs, truth.world_T_vehicle)
    rng = np.random.default_rng(0)
    rows = np.repeat(obs.camera_index, 2)
    steps = []
    for _ in range(4000):  # each camera's error moves its residuals; the least-squares step follows
        shift = np.zeros(len(A))
        for c in np.unique(obs.camera_index):
            B = extrinsic_jacobian(A[rows == c], truth.world_T_vehicle, obs.cameras[c].pose)
            shift[rows == c] = B @ (rng.normal(size=6) * SURVEY)
        steps.append(-P @ A.T @ shift)
    empirical = np.cov(np.array(steps).T)
    np.testing.assert_allclose(np.sqrt(np.diag(empirical)), np.sqrt(np.diag(C)), rtol=0.05)
    assert np.all(np.linalg.eigvalsh(C) > -1e-12 * np.abs(C).max())
    exact = observations_from_detections(frame.detections_of(vid), sim.scene.cameras, GraphConfig())
    np.testing.assert_array_equal(extrinsic_covariance(P, A, exact, truth.world_T_vehicle), 0.0)


def test_with_extrinsics_adds_each_cameras_error_as_variables_under_its_prior():
    """The augmented system: ``[A, B]`` as the projection's Jacobian, the graph's Hessian and the prior ``S^-1`` on
    the errors' nonzero components (a camera declaring rotation alone adds three variables, one without a sigma
    none)."""
    from vfactor.extrinsics import with_extrinsics
    from vfactor.shape_evidence import Linearisation

    sim, frame, vid = _one_vehicle()
    truth = sim.truth[0][vid]
    names = list(sim.scene.cameras)
    cameras = dict(sim.scene.cameras)
    cameras[names[0]] = dataclasses.replace(cameras[names[0]], extrinsic_sigma=extrinsic_sigma(0.3, 0.0))
    obs = observations_from_detections(frame.detections_of(vid), cameras, GraphConfig())
    _, pose_jacobian = whitened_pose_jacobian(obs, truth.world_T_vehicle, truth.wireframe.vehicle_p_keypoints)
    A = pose_jacobian.reshape(-1, 6)
    rng = np.random.default_rng(1)
    b = rng.normal(size=len(A))
    H = A.T @ A + np.eye(6)  # the projection plus some prior
    lin = Linearisation(H, A.T @ b + 1.0, A.T @ A, A.T @ b, np.zeros((6, 6)), np.zeros(6), np.zeros(36), A, b)
    out = with_extrinsics(lin, obs, truth.world_T_vehicle)
    first = obs.camera_index == obs.camera_index[np.flatnonzero(
        [obs.cameras[c].name == names[0] for c in obs.camera_index])[0]]
    B = np.zeros((len(A), 3))
    B[np.repeat(first, 2)] = extrinsic_jacobian(A[np.repeat(first, 2)], truth.world_T_vehicle,
                                                cameras[names[0]].pose)[:, :3]
    AB = np.hstack([A, B])
    np.testing.assert_allclose(out.jacobian, AB, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out.projection, AB.T @ AB, rtol=1e-12)
    np.testing.assert_allclose(out.total[:6, :6], H, rtol=1e-12)
    np.testing.assert_allclose(out.total[6:, 6:], B.T @ B + np.eye(3) / np.radians(0.3) ** 2, rtol=1e-12)
    np.testing.assert_allclose(out.total_eta, np.r_[lin.total_eta, B.T @ b], rtol=1e-12)
    np.testing.assert_allclose(out.projection_eta, AB.T @ b, rtol=1e-12)
    exact = observations_from_detections(frame.detections_of(vid), sim.scene.cameras, GraphConfig())
    assert with_extrinsics(lin, exact, truth.world_T_vehicle) is lin


def test_the_solve_adds_the_extrinsic_covariance_and_keeps_the_estimate():
    """The same frame with and without the cameras' sigmas: the same poses and shapes, wider covariances (pose,
    keypoints and box; the keypoints' own noise is then read off with the cameras' errors explained, so no
    direction need be wider), and with sigmas of zero the covariances as without any."""
    sim, frame, _ = _one_vehicle(5)
    uncertain = {name: dataclasses.replace(cam, extrinsic_sigma=SURVEY) for name, cam in sim.scene.cameras.items()}
    zero = {name: dataclasses.replace(cam, extrinsic_sigma=np.zeros(6)) for name, cam in sim.scene.cameras.items()}
    exact, wider, zeroed = (solve_frame(frame, cams, SolveOptions())
                            for cams in (sim.scene.cameras, uncertain, zero))
    for a, b, z in zip(exact.vehicles, wider.vehicles, zeroed.vehicles):
        assert a.ok and b.ok
        np.testing.assert_array_equal(a.world_T_vehicle.matrix(), b.world_T_vehicle.matrix())
        np.testing.assert_array_equal(a.pose_covariance, z.pose_covariance)
        assert np.trace(b.pose_covariance[3:, 3:]) > 1.5 * np.trace(a.pose_covariance[3:, 3:])  # 0.3 deg at 25 m
        assert np.trace(b.pose_covariance[:3, :3]) > np.trace(a.pose_covariance[:3, :3])
        assert np.all(np.trace(b.keypoint_covariances_world, axis1=1, axis2=2)
                      > np.trace(a.keypoint_covariances_world, axis1=1, axis2=2))
        assert np.all(b.box.centre_sigma > a.box.centre_sigma)


@pytest.mark.parametrize("declared", [True, False])
def test_declared_extrinsic_sigmas_make_the_pose_covariances_consistent(declared):
    """Cameras off by draws of 0.3 degrees and 5 cm (a survey's error), a sharp detector (1 % of the box): with
    their sigmas declared the pose NEES averages about 6; without, the covariances claim several times more than
    the poses are worth. Ten scenes, each its own draw of the cameras' errors (which a scene's vehicles share);
    seeds 1300-1309 of library_2cam, not among those the feature was looked at on."""
    scenario = dataclasses.replace(noise_variant(load_scenario("library_2cam"), **NOISE_LEVELS["sharp"]),
                                   extrinsic_error=ExtrinsicError(0.3, 0.05, declared))
    nees = []
    for seed in range(1300, 1310):
        rows = compare_methods(simulate(scenario, seed=seed, num_frames=6), SolveOptions(),
                               methods=("factor_graph",))["factor_graph"]
        nees += [r["pose_nees"] for r in rows]
    nees = np.array(nees)
    assert len(nees) >= 60
    if declared:
        assert 0.6 <= nees.mean() / 6 <= 1.4 and np.mean(nees < CHI2_95[6]) >= 0.85, (nees.mean() / 6,)
    else:
        assert nees.mean() / 6 > 4.0 and np.mean(nees < CHI2_95[6]) < 0.5, (nees.mean() / 6,)


def test_scene_files_carry_extrinsic_sigma(tmp_path):
    sim, _, _ = _one_vehicle()
    data = scene_to_dict(sim.scene)
    data["cameras"][0]["extrinsic_sigma"] = {"rotation_deg": 0.2, "translation_m": [0.02, 0.02, 0.05]}
    assert validate(data, "scene") == []
    scene = scene_from_dict(data)
    name = data["cameras"][0]["name"]
    expected = np.r_[np.full(3, np.radians(0.2)), 0.02, 0.02, 0.05]
    np.testing.assert_allclose(scene.cameras[name].extrinsic_sigma, expected, rtol=1e-15)
    assert scene.cameras[data["cameras"][1]["name"]].extrinsic_sigma is None
    path = tmp_path / "scene.json"
    save_scene(scene, path)
    written = json.loads(path.read_text())
    assert validate(written, "scene") == []
    np.testing.assert_allclose(load_scene(path).cameras[name].extrinsic_sigma, expected, rtol=1e-12)


@pytest.mark.parametrize("value, field", [
    ({"rotation_deg": -0.1, "translation_m": 0.02}, "cameras[0].extrinsic_sigma.rotation_deg"),
    ({"rotation_deg": 0.1}, "cameras[0].extrinsic_sigma.translation_m"),
    ({"rotation_deg": [0.1, 0.2], "translation_m": 0.02}, "cameras[0].extrinsic_sigma.rotation_deg"),
    ({"rotation_deg": 0.1, "translation_m": "5 cm"}, "cameras[0].extrinsic_sigma.translation_m"),
    ({"rotation_deg": 0.1, "translation_m": 0.02, "yaw_deg": 1}, "cameras[0].extrinsic_sigma.yaw_deg"),
    (0.3, "cameras[0].extrinsic_sigma"),
])
def test_a_bad_extrinsic_sigma_names_its_field(value, field):
    sim, _, _ = _one_vehicle()
    data = scene_to_dict(sim.scene)
    data["cameras"][0]["extrinsic_sigma"] = value
    with pytest.raises(SceneError) as info:
        scene_from_dict(data)
    assert info.value.field == field
    assert validate(data, "scene") != []  # the schema refuses it too


def test_a_camera_refuses_a_bad_extrinsic_sigma():
    camera = next(iter(simulate("library_2cam", seed=3, num_frames=1).scene.cameras.values()))
    for bad in ([0.1] * 5, [0.1, 0.1, 0.1, 0.1, 0.1, -0.1], [np.nan] * 6, "small"):
        with pytest.raises(CalibrationError, match="extrinsic_sigma"):
            dataclasses.replace(camera, extrinsic_sigma=bad)
    assert isinstance(camera, Camera)


def test_the_simulator_moves_the_scenes_cameras_not_the_detections():
    """With an extrinsic error the detections are the true cameras' (the same pixels as without), the scene's
    cameras are moved by about the error's size and carry it as declared."""
    base = load_scenario("library_2cam")
    plain = simulate(base, seed=7, num_frames=2)
    for declared in (True, False):
        off = simulate(dataclasses.replace(base, extrinsic_error=ExtrinsicError(0.3, 0.05, declared)), seed=7,
                       num_frames=2)
        for f0, f1 in zip(plain.scene.frames, off.scene.frames):
            for d0, d1 in zip(f0.detections, f1.detections):
                np.testing.assert_array_equal(d0.keypoints, d1.keypoints)
        for name, camera in plain.scene.cameras.items():
            moved = off.scene.cameras[name]
            xi = gtsam.Pose3.Logmap(camera.pose.between(moved.pose))
            assert 0 < np.linalg.norm(xi[:3]) < np.radians(2.0) and 0 < np.linalg.norm(xi[3:]) < 0.5
            assert (moved.extrinsic_sigma is not None) == declared
        assert all(np.array_equal(off.scenario.cameras[n].world_T_camera, c.world_T_camera)
                   for n, c in base.cameras.items())  # the truth's cameras are the true ones


def test_scenario_files_take_an_extrinsic_error():
    data = json.loads(json.dumps({"cameras": [{"name": "c0", "pole": [20, 0], "height": 6, "hfov_deg": 60}],
                                  "vehicles": ["library"]}))
    scenario = scenario_from_dict(dict(data, extrinsic_error={"rotation_deg": 0.2, "translation_m": 0.03}))
    assert scenario.extrinsic_error == ExtrinsicError(0.2, 0.03, True)
    for bad, field in (({"rotation_deg": -1}, "extrinsic_error.rotation_deg"),
                       ({"translation_m": 50}, "extrinsic_error.translation_m"),
                       ({"declared": "yes"}, "extrinsic_error.declared"),
                       ({"pitch": 1}, "extrinsic_error.pitch")):
        with pytest.raises(ScenarioError) as info:
            scenario_from_dict(dict(data, extrinsic_error=bad))
        assert info.value.field == field


def test_eval_takes_an_extrinsic_error(capsys):
    """``vfactor eval --extrinsic-error DEG,M`` says so in its tables' titles and its command; bad values, the
    switch without it and other experiments are one-line errors (exit 2)."""
    from vfactor.cli import main

    assert main(["eval", "--frames", "2", "--levels", "paper", "--extrinsic-error", "0.3,0.05"]) == 0
    out = capsys.readouterr().out
    assert "each camera off by draws of 0.3 deg and 0.05 m per axis (its extrinsic_sigma)" in out
    assert "--extrinsic-error 0.3,0.05" in out
    assert main(["eval", "--frames", "2", "--levels", "paper", "--extrinsic-error", "0.3,0.05",
                 "--undeclared-extrinsics"]) == 0
    assert "(no extrinsic_sigma)" in capsys.readouterr().out
    for argv in (["eval", "--extrinsic-error", "0.3"], ["eval", "--extrinsic-error=-1,0.05"],
                 ["eval", "--extrinsic-error", "0.3,9"], ["eval", "--undeclared-extrinsics"],
                 ["eval", "paper", "--extrinsic-error", "0.3,0.05"]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert "extrinsic" in err and len(err.splitlines()) == 1, err


def test_a_camera_off_by_its_declared_error_is_not_at_odds_but_a_wrong_one_is():
    """Far poles (40 m), a sharp detector, cameras off by draws of 0.3 degrees and 5 cm: without their sigmas the
    check of cameras at odds fails three of twelve vehicles of this scene (their keypoints do disagree by 20-30 cm);
    with them it fails none, and a camera turned by 3 degrees more is still named."""
    base = noise_variant(load_scenario("rig_far_2cam"), **NOISE_LEVELS["sharp"])
    frames = (0, 8, 10)
    runs = {}
    for declared in (False, True):
        sim = simulate(dataclasses.replace(base, extrinsic_error=ExtrinsicError(0.3, 0.05, declared)), seed=1104,
                       num_frames=11)
        runs[declared] = sim
        for f in frames:
            v = solve_frame(sim.scene.frames[f], sim.scene.cameras).vehicles[0]
            assert v.ok == declared, (declared, f, v.status, v.message)
            if not declared:
                assert "disagree" in v.message
    sim = runs[True]
    turned = dict(sim.scene.cameras)
    cam0 = turned["cam0"]
    turned["cam0"] = dataclasses.replace(
        cam0, world_T_camera=cam0.world_T_camera @ gtsam.Pose3(gtsam.Rot3.Ry(np.radians(3.0)), np.zeros(3)).matrix())
    for f in frames:
        v = solve_frame(sim.scene.frames[f], turned).vehicles[0]
        assert not v.ok and "disagree" in v.message, (f, v.status, v.message)


def test_the_keypoints_noise_is_read_with_the_cameras_errors_explained():
    """The cameras' disagreement is not taken for pixel noise where their errors are declared: the covariances'
    noise scale comes out as with exact cameras (far poles, sharp detector), where undeclared it is far larger."""
    base = noise_variant(load_scenario("rig_far_2cam"), **NOISE_LEVELS["sharp"])
    scales = {}
    for name, off in (("exact", None), ("declared", ExtrinsicError(0.3, 0.05, True)),
                      ("undeclared", ExtrinsicError(0.3, 0.05, False))):
        sim = simulate(dataclasses.replace(base, extrinsic_error=off), seed=1105, num_frames=10)
        scales[name] = np.median([v.extras["covariance_noise_scale"] for frame in sim.scene.frames
                                  for v in solve_frame(frame, sim.scene.cameras).vehicles])
    assert abs(scales["declared"] / scales["exact"] - 1) < 0.25, scales
    assert scales["undeclared"] > 1.3 * scales["exact"], scales


@pytest.mark.parametrize("declared", [True, False])
def test_tracks_carry_the_declared_extrinsic_errors(declared):
    """Two cameras off by draws of 0.3 degrees and 5 cm, a track of each of three vehicles: a camera's error is the
    same in every frame, so the tracks' poses are as far off as one frame's, and without the sigmas declared their
    covariances claim many times more (the pixel noise averages away over the frames, the cameras' errors do not);
    with them, smoothed and online, about consistent. Seeds 1300-1301 of library_tracks_2cam, not looked at."""
    from vfactor.metrics import pose_nees
    from vfactor.track import TrackOptions, track_scene

    scenario = dataclasses.replace(load_scenario("library_tracks_2cam"),
                                   extrinsic_error=ExtrinsicError(0.3, 0.05, declared))
    nees = {"smoothed": [], "online": []}
    for seed in (1300, 1301):
        sim = simulate(scenario, seed=seed, num_frames=16)
        run = track_scene(sim.scene, TrackOptions())
        for kind, frames in (("smoothed", run.frames), ("online", run.online)):
            for f, frame in enumerate(frames):
                for v in frame.vehicles:
                    if v.ok and v.pose_covariance is not None and v.id in sim.truth[f]:
                        nees[kind].append(pose_nees(v.world_T_vehicle, v.pose_covariance,
                                                    sim.truth[f][v.id].world_T_vehicle))
    for kind, values in nees.items():
        mean = np.mean(values) / 6
        assert len(values) >= 40, (kind, len(values))
        if declared:
            assert 0.5 <= mean <= 2.0, (kind, mean)
        else:
            assert mean > 4.0, (kind, mean)
