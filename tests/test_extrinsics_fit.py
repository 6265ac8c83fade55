"""The cameras' extrinsic errors fitted to their traffic (vfactor.extrinsics_fit, vfactor fit-extrinsics)."""

from __future__ import annotations

import dataclasses
import itertools

import gtsam
import numpy as np
import pytest

from vfactor.cli import main
from vfactor.errors import InputError
from vfactor.extrinsics_fit import MIN_VEHICLES, fit_extrinsics
from vfactor.scene import load_scene, save_scene
from vfactor.sim import load_scenario, simulate
from vfactor.sim.scenario import ExtrinsicError
from vfactor.solve import SolveOptions, solve_scene
from vfactor.stats import chi2_quantile

#: library_tracks (three cameras, the road plane) with a survey off by 0.5 degrees and 8 cm per axis, declared. Its
#: seeds 1310-1312 are this file's (not held out for docs/results.md).
SCENARIO = dataclasses.replace(load_scenario("library_tracks"), extrinsic_error=ExtrinsicError(0.5, 0.08, True))


@pytest.fixture(scope="module")
def surveyed():
    return simulate(SCENARIO, seed=1310)


@pytest.fixture(scope="module")
def fitted(surveyed):
    """The cameras fitted to two scenes of the rig's traffic (the second recorded with the first one's cameras)."""
    more = simulate(SCENARIO, seed=1312).scene
    return fit_extrinsics([surveyed.scene, dataclasses.replace(more, cameras=surveyed.scene.cameras)])


def _relative_rotation_error_deg(cameras: dict) -> float:
    """Mean over camera pairs of the angle (degrees) by which their relative orientation differs from the true
    rig's: what vehicles seen by two cameras show."""
    true = SCENARIO.cameras
    angles = []
    for a, b in itertools.combinations(sorted(true), 2):
        given = cameras[a].pose.rotation().between(cameras[b].pose.rotation())
        actual = true[a].pose.rotation().between(true[b].pose.rotation())
        angles.append(np.degrees(np.linalg.norm(gtsam.Rot3.Logmap(given.between(actual)))))
    return float(np.mean(angles))


def _translation_error_cm(sim, cameras) -> float:
    """Mean translation error (cm) of the one-frame solves of ``sim``'s vehicles with ``cameras``."""
    results = solve_scene(dataclasses.replace(sim.scene, cameras=cameras), SolveOptions(covariance=False))
    errors = [np.linalg.norm(v.keypoints_world.mean(0) - sim.truth[f][v.id].keypoints_world.mean(0))
              for f, frame in enumerate(results) for v in frame.vehicles if v.ok]
    return 100.0 * float(np.mean(errors))


def test_the_fit_finds_how_the_cameras_sit_against_each_other(surveyed, fitted):
    before = _relative_rotation_error_deg(surveyed.scene.cameras)
    after = _relative_rotation_error_deg(fitted.cameras)
    assert before > 0.5
    assert after < 0.5 * before
    assert fitted.poses >= 2 * MIN_VEHICLES and set(fitted.corrections) == set(SCENARIO.cameras)
    bound = chi2_quantile(6, 0.999)
    for name, camera in fitted.cameras.items():
        given = surveyed.scene.cameras[name]
        assert np.all(camera.extrinsic_sigma < given.extrinsic_sigma)  # the fit's sigma, narrower than the survey's
        np.testing.assert_allclose(camera.extrinsic_sigma, np.sqrt(np.diag(fitted.covariances[name])))
        moved = given.pose.compose(gtsam.Pose3.Expmap(fitted.corrections[name]))
        np.testing.assert_allclose(camera.world_T_camera, moved.matrix(), atol=1e-9)
        left = gtsam.Pose3.Logmap(camera.pose.inverse().compose(SCENARIO.cameras[name].pose))  # the error left
        assert left @ np.linalg.solve(fitted.covariances[name], left) < bound  # ... within the fit's sigma


def test_other_traffic_of_the_rig_is_solved_closer_with_the_fitted_cameras(surveyed, fitted):
    later = simulate(SCENARIO, seed=1311)  # other vehicles, the same rig; its own survey draw is not used
    with_survey = _translation_error_cm(later, surveyed.scene.cameras)
    with_fit = _translation_error_cm(later, fitted.cameras)
    exact = _translation_error_cm(later, dict(SCENARIO.cameras))
    assert with_fit - exact < 0.6 * (with_survey - exact)


def test_a_camera_without_a_sigma_is_held_where_it_is(surveyed):
    cameras = dict(surveyed.scene.cameras)
    cameras["cam0"] = dataclasses.replace(cameras["cam0"], extrinsic_sigma=None)
    fit = fit_extrinsics(dataclasses.replace(surveyed.scene, cameras=cameras, frames=surveyed.scene.frames[:12]),
                         rounds=1)
    assert "cam0" not in fit.corrections and set(fit.corrections) == {"cam1", "cam2"}
    np.testing.assert_array_equal(fit.cameras["cam0"].world_T_camera, cameras["cam0"].world_T_camera)
    assert fit.cameras["cam0"].extrinsic_sigma is None


def test_the_vehicles_solved_on_an_engine_with_a_model_given_give_the_same_fit(surveyed):
    from vfactor.parallel import InProcess
    from vfactor.shape_model import default_shape_model

    short = dataclasses.replace(surveyed.scene, frames=surveyed.scene.frames[:12])
    here = fit_extrinsics(short, rounds=1)
    there = fit_extrinsics(short, rounds=1, engine=InProcess(), model=default_shape_model())
    for name in here.corrections:
        np.testing.assert_array_equal(here.corrections[name], there.corrections[name])


def test_bad_input_is_refused_naming_the_field(surveyed):
    plain = dataclasses.replace(surveyed.scene, cameras={name: dataclasses.replace(c, extrinsic_sigma=None)
                                                         for name, c in surveyed.scene.cameras.items()})
    with pytest.raises(InputError, match="no camera declares") as caught:
        fit_extrinsics(plain)
    assert caught.value.field == "extrinsic_sigma"
    with pytest.raises(InputError) as caught:
        fit_extrinsics(plain, default_sigma=[0.01, 0.01])
    assert caught.value.field == "default_sigma"
    few = dataclasses.replace(surveyed.scene, frames=surveyed.scene.frames[:3])
    with pytest.raises(InputError, match=f"at least {MIN_VEHICLES}"):
        fit_extrinsics(few)
    moved = {name: dataclasses.replace(c, world_T_camera=c.pose.compose(gtsam.Pose3(gtsam.Rot3(), [0.5, 0, 0]))
                                       .matrix()) for name, c in surveyed.scene.cameras.items()}
    with pytest.raises(InputError, match="one rig") as caught:
        fit_extrinsics([surveyed.scene, dataclasses.replace(surveyed.scene, cameras=moved)])
    assert caught.value.field.startswith("scenes[1].cameras.")
    with pytest.raises(InputError, match="one list of frame results per scene"):
        fit_extrinsics(surveyed.scene, results=[])


def test_fit_extrinsics_writes_the_scene_with_the_fitted_cameras(tmp_path, capsys, surveyed):
    scene, out = tmp_path / "scene.json", tmp_path / "fitted.json"
    given = dataclasses.replace(surveyed.scene, frames=surveyed.scene.frames[:12])  # enough poses, and quick
    save_scene(given, scene)
    assert main(["fit-extrinsics", str(scene), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "camera cam0: turned" in printed and f"wrote {out}" in printed
    written = load_scene(out)
    assert len(written.frames) == len(given.frames)  # the scene as it was, its cameras fitted
    for name, camera in written.cameras.items():
        before = given.cameras[name]
        assert np.abs(camera.world_T_camera - before.world_T_camera).max() > 1e-5
        assert np.all(camera.extrinsic_sigma <= before.extrinsic_sigma + 1e-12)


def test_fit_extrinsics_bad_input_is_one_line_and_exit_2(tmp_path, capsys, surveyed):
    plain = dataclasses.replace(surveyed.scene, frames=surveyed.scene.frames[:12],  # enough poses, and quick
                                cameras={name: dataclasses.replace(c, extrinsic_sigma=None)
                                         for name, c in surveyed.scene.cameras.items()})
    scene, other = tmp_path / "plain.json", tmp_path / "other.json"
    save_scene(plain, scene)
    save_scene(simulate(SCENARIO, seed=1311).scene, other)  # another survey's cameras
    for argv, field in (([str(scene)], "extrinsic_sigma"),
                        ([str(scene), "--extrinsic-sigma", "0.3"], "--extrinsic-sigma"),
                        ([str(scene), "--extrinsic-sigma", "0.3,-1"], "--extrinsic-sigma"),
                        ([str(scene), "--extrinsic-sigma", "0.3,0.05", "--traffic", str(other)], "--traffic"),
                        ([str(scene), "--extrinsic-sigma", "0.3,0.05", "--workers", "0"], "--workers"),
                        ([str(scene), "--workers", "2", "--scheduler", "tcp://h:8786"], "--workers")):
        assert main(["fit-extrinsics", *argv, "--out", str(tmp_path / "out.json")]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"vfactor fit-extrinsics: error: {field}") and "\n" not in err
    assert not (tmp_path / "out.json").exists()
    out = tmp_path / "out.json"
    assert main(["fit-extrinsics", str(scene), "--extrinsic-sigma", "0.3,0.05", "--shape-per-frame",
                 "--out", str(out)]) == 0
    assert all(camera.extrinsic_sigma is not None for camera in load_scene(out).cameras.values())
