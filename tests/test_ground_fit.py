"""The road plane fitted to the traffic (vfactor.ground_fit, ``vfactor fit-ground``)."""

from __future__ import annotations

import json

import gtsam
import numpy as np
import pytest

from vfactor.cli import main
from vfactor.errors import InputError
from vfactor.factors.ground_plane import GroundPlane
from vfactor.ground_fit import MIN_GROUND_POINTS, fit_ground_plane, plane_heights, plane_note
from vfactor.result import FrameResult, Status, VehicleResult
from vfactor.scene import load_scene
from vfactor.wireframe import PRESETS

HUB_HEIGHT = 0.34


def _on_plane(normal, offset, positions, rng, noise=0.02, yaw=None):
    """Frames of one solved vehicle each, standing on the plane n . x = offset at the given (x, y) positions
    (hubs HUB_HEIGHT above it, give or take ``noise`` metres), turned so that its z is the plane's normal."""
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    x_axis = np.cross([0.0, 1.0, 0.0], n)
    x_axis /= np.linalg.norm(x_axis)
    R = np.column_stack([x_axis, np.cross(n, x_axis), n])
    shape = PRESETS["toyota_prius"].wireframe()
    frames = []
    for i, (x, y) in enumerate(positions):
        z = (offset - n[0] * x - n[1] * y) / n[2]  # on the road
        hub = np.array([x, y, z]) + (HUB_HEIGHT + rng.normal(0.0, noise)) * n
        turn = gtsam.Rot3(R).compose(gtsam.Rot3.Rz(rng.uniform(-np.pi, np.pi) if yaw is None else yaw))
        pose = gtsam.Pose3(turn, hub)  # the body origin is the hub centroid
        frames.append(FrameResult(0.1 * i, [VehicleResult(f"v{i}", Status.CONVERGED, pose, shape)]))
    return frames


def _tilt_deg(a, b) -> float:
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0))))


def test_the_plane_under_the_hubs_comes_back_despite_vehicles_metres_off():
    rng = np.random.default_rng(3)
    normal, offset = np.array([0.03, -0.05, 1.0]) / np.linalg.norm([0.03, -0.05, 1.0]), 1.7
    positions = rng.uniform(-20.0, 20.0, (60, 2))
    frames = _on_plane(normal, offset, positions, rng)
    for frame in frames[:8]:  # a vehicle taken for the wrong type is metres off along a camera's ray
        v = frame.vehicles[0]
        v.world_T_vehicle = gtsam.Pose3(v.world_T_vehicle.rotation(), v.world_T_vehicle.translation()
                                        + rng.normal(0.0, 2.0, 3))
    frames.append(FrameResult(9.0, [VehicleResult("gone", Status.FAILED, message="not solved")]))  # skipped
    fit = fit_ground_plane(frames, HUB_HEIGHT)
    assert fit.points == 60
    assert _tilt_deg(fit.plane.normal, normal) < 0.2
    assert fit.plane.offset == pytest.approx(offset, abs=0.02)
    assert fit.inliers <= 54 and fit.scale < 0.05
    hubs = np.array([f.vehicles[0].world_T_vehicle.translation() for f in frames[:60]])
    plain = np.linalg.svd(hubs - hubs.mean(axis=0))[2][-1]  # the plane of least squares through them all
    assert _tilt_deg(np.sign(plain[2]) * plain, normal) > 3 * _tilt_deg(fit.plane.normal, normal)


def test_each_vehicle_s_hubs_are_moved_down_by_its_body_type_s_wheel_radius():
    """Traffic of buses (hubs 0.48 m up) and hatchbacks (0.32 m) on a tilted road: the plane fitted with one hub
    height for all (0.34 m) sat 6 cm above the road; with each vehicle's body type's it is on it."""
    from vfactor.shape_model import default_shape_model

    types = default_shape_model().types
    rng = np.random.default_rng(5)
    normal, offset = np.array([0.02, 0.04, 1.0]) / np.linalg.norm([0.02, 0.04, 1.0]), -0.8
    frames = []
    for i, body_type in enumerate(["bus", "hatchback"] * 20):
        frame, = _on_plane(normal, offset, rng.uniform(-20.0, 20.0, (1, 2)), rng, noise=0.005)
        v = frame.vehicles[0]
        lift = types[body_type].hub_height - HUB_HEIGHT  # _on_plane put the hubs HUB_HEIGHT up
        v.world_T_vehicle = gtsam.Pose3(v.world_T_vehicle.rotation(), v.world_T_vehicle.translation() + lift * normal)
        v.body_type = body_type
        frames.append(frame)
    fit = fit_ground_plane(frames)
    assert _tilt_deg(fit.plane.normal, normal) < 0.1 and fit.plane.offset == pytest.approx(offset, abs=0.01)
    assert fit.hub_height == pytest.approx(np.mean([types[t].hub_height for t in ("bus", "hatchback")]), abs=0.01)
    one = fit_ground_plane(frames, HUB_HEIGHT)
    assert one.plane.offset - offset > 0.05 and one.hub_height == pytest.approx(HUB_HEIGHT)


def test_too_few_poses_or_traffic_along_one_line_is_refused():
    rng = np.random.default_rng(4)
    with pytest.raises(InputError, match="at least"):
        fit_ground_plane(_on_plane([0, 0, 1], 0.0, rng.uniform(-10, 10, (MIN_GROUND_POINTS - 1, 2)), rng))
    line = np.c_[np.linspace(-20.0, 20.0, 30), 0.2 * rng.normal(size=30)]
    with pytest.raises(InputError, match="one line"):
        fit_ground_plane(_on_plane([0, 0, 1], 0.0, line, rng))


def test_fit_ground_writes_the_scene_with_the_road_under_the_tracks(tmp_path, capsys):
    """The command tracks a simulated two-camera scene (no plane given) and writes it back with a plane within
    half a degree and 10 cm of the simulator's road (z = 0; the hubs of its vehicles are 0.30-0.40 m high)."""
    scene = tmp_path / "scene.json"
    assert main(["simulate", "library_tracks_2cam", "--seed", "20", "--out", str(scene)]) == 0
    out = tmp_path / "with_plane.json"
    _fit_ground_keeps_the_scene(scene, out, capsys, "each at its body type's wheel radius", max_tilt_deg=0.5)

    assert main(["fit-ground", str(out), "--out", str(tmp_path / "again.json")]) == 2  # a plane is given already
    assert "ground_plane" in capsys.readouterr().err
    assert not (tmp_path / "again.json").exists()


def test_fit_ground_associates_detections_that_name_no_vehicle(tmp_path, capsys):
    """A rig without a surveyed road and without vehicle ids (each camera numbering its own boxes): the command
    refused the scene ("associate them first"); it now associates it, as ``vfactor track`` does, and writes the
    scene as given with the plane."""
    import dataclasses

    from vfactor.observations import UNASSIGNED, Frame
    from vfactor.scene import save_scene
    from vfactor.sim import load_scenario, simulate

    sim = simulate(load_scenario("library_tracks_2cam"), seed=20, num_frames=15)
    frames = [Frame(f.t, [dataclasses.replace(d, vehicle=UNASSIGNED, track=f"{d.camera}-{d.vehicle}")
                          for d in f.detections]) for f in sim.scene.frames]
    scene = tmp_path / "no_ids.json"
    save_scene(dataclasses.replace(sim.scene, frames=frames), scene)
    _fit_ground_keeps_the_scene(scene, tmp_path / "with_plane.json", capsys, "associated", max_tilt_deg=1.0)


def _fit_ground_keeps_the_scene(scene, out, capsys, said: str, max_tilt_deg: float) -> None:
    """``vfactor fit-ground scene --out out`` says ``said``, fits a plane within ``max_tilt_deg`` and 10 cm of the
    simulator's road and writes the scene as given plus the plane (nothing else changed)."""
    assert main(["fit-ground", str(scene), "--out", str(out)]) == 0
    assert said in capsys.readouterr().out
    plane = load_scene(out).ground_plane
    assert plane is not None and _tilt_deg(plane.normal, [0.0, 0.0, 1.0]) < max_tilt_deg and abs(plane.offset) < 0.1
    written = json.loads(out.read_text())
    assert written.pop("ground_plane") and written == json.loads(scene.read_text())


def test_fit_ground_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    scene = tmp_path / "short.json"
    assert main(["simulate", "intersection_2cam", "--out", str(scene)]) == 0  # 8 frames of one vehicle each
    capsys.readouterr()
    out = tmp_path / "out.json"
    for argv, field in ((["fit-ground", str(scene), "--out", str(out)], "short.json: 8 solved vehicle poses"),
                        (["fit-ground", str(scene), "--out", str(out), "--hub-height", "-1"], "--hub-height"),
                        (["fit-ground", str(tmp_path / "none.json"), "--out", str(out)], "none.json")):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert field in err and len(err.strip().splitlines()) == 1
        assert not out.exists()


def test_fit_ground_pools_the_traffic_of_one_rig(tmp_path, capsys):
    """``--traffic`` adds other scenes of the same cameras to the fit (here too little traffic alone makes one);
    a scene of another rig is refused, naming the option."""
    short, other, elsewhere = tmp_path / "short.json", tmp_path / "other.json", tmp_path / "multi.json"
    assert main(["simulate", "intersection_2cam", "--out", str(short)]) == 0  # 8 poses: too few on their own
    assert main(["simulate", "tracks_3veh", "--seed", "20", "--out", str(other)]) == 0  # the same two cameras
    assert main(["simulate", "intersection_multi", "--out", str(elsewhere)]) == 0
    out = tmp_path / "with_plane.json"
    capsys.readouterr()
    assert main(["fit-ground", str(short), "--traffic", str(other), "--out", str(out)]) == 0
    assert "of 2 scene(s)" in capsys.readouterr().out
    plane = load_scene(out).ground_plane
    assert _tilt_deg(plane.normal, [0.0, 0.0, 1.0]) < 0.5 and len(load_scene(out).frames) == 8
    assert main(["fit-ground", str(short), "--traffic", str(elsewhere), "--out", str(tmp_path / "no.json")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("vfactor fit-ground: error: --traffic:") and not (tmp_path / "no.json").exists()



def test_a_wrong_road_plane_is_said_and_a_right_one_is_not(tmp_path, capsys):
    """A scene's ground_plane 30 cm off (a survey in another datum, a plane fitted elsewhere) pulled every vehicle
    towards it without a word; the solved hubs still sit a median 16 cm from it, and the commands say so."""
    rng = np.random.default_rng(6)
    frames = _on_plane([0, 0, 1], 0.0, rng.uniform(-15.0, 15.0, (12, 2)), rng, noise=0.02)
    assert np.abs(plane_heights(frames, GroundPlane((0, 0, 1), 0.0), HUB_HEIGHT)).max() < 0.1
    assert plane_note(frames, GroundPlane((0, 0, 1), 0.0), HUB_HEIGHT) is None
    assert "below" in plane_note(frames, GroundPlane((0, 0, 1), 0.3), HUB_HEIGHT)
    assert plane_note(frames[:MIN_GROUND_POINTS - 1], GroundPlane((0, 0, 1), 0.3), HUB_HEIGHT) is None  # too few
    tilted = GroundPlane((np.sin(0.05), 0.0, np.cos(0.05)), 0.0)  # 2.9 deg: the vehicles 0.75 m off at 15 m
    assert "plane tilted 2." in plane_note(frames, tilted, HUB_HEIGHT)

    import dataclasses

    from vfactor.scene import save_scene
    from vfactor.sim import load_scenario, simulate

    sim = simulate(load_scenario("library_2cam"), seed=700, num_frames=12)
    for offset, said in ((0.0, False), (0.3, True)):
        scene = tmp_path / f"plane_{offset}.json"
        save_scene(dataclasses.replace(sim.scene, ground_plane=GroundPlane((0, 0, 1), offset)), scene)
        assert main(["solve", str(scene), "--out", str(tmp_path / "result.json"), "--no-covariance"]) == 0
        assert ("is the plane right?" in capsys.readouterr().err) == said
