"""Scenario files: packaged scenarios, name resolution and field-by-field validation."""

from __future__ import annotations

import copy
import dataclasses
import json
import math

import numpy as np
import pytest

from vfactor.errors import ScenarioError
from vfactor.sim import (
    Motion,
    NoiseModel,
    Scenario,
    list_scenarios,
    load_scenario,
    scenario_from_dict,
    scenario_path,
)


@pytest.fixture
def base() -> dict:
    return json.loads(scenario_path("intersection_2cam").read_text())


def test_the_packaged_scenarios_load():
    names = list_scenarios()
    assert {"intersection_2cam", "intersection_3cam"} <= set(names)
    for name in names:
        scenario = load_scenario(name)
        assert isinstance(scenario, Scenario) and scenario.name == name
        assert load_scenario(scenario) is scenario  # one built in code (or loaded) is taken as it is
        assert len(scenario.cameras) >= (1 if name.startswith("rig_one_cam") else 2)  # the single-camera rigs


def test_intersection_2cam_is_two_pole_cameras_on_opposite_sides():
    scenario = load_scenario("intersection_2cam")
    assert list(scenario.cameras) == ["cam0", "cam1"]
    c0, c1 = (c.center for c in scenario.cameras.values())
    for c in (c0, c1):
        assert 5.0 <= c[2] <= 10.0 and 15.0 <= np.hypot(c[0], c[1]) <= 25.0
    assert np.dot(c0[:2], c1[:2]) < 0  # opposite sides of the intersection
    assert scenario.noise == NoiseModel()
    assert scenario.visible_in == ("cam0", "cam1")


def test_scenario_path_accepts_names_files_and_rejects_unknown(tmp_path, base):
    assert scenario_path("intersection_2cam") == scenario_path("intersection_2cam.json")
    path = tmp_path / "mine.json"
    path.write_text(json.dumps(base))
    assert scenario_path(path) == path
    assert load_scenario(str(path)).name == "intersection_2cam"
    with pytest.raises(ScenarioError, match="no such file or packaged scenario"):
        scenario_path("no_such_scenario")


def test_invalid_json_is_reported(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text("{ not json")
    with pytest.raises(ScenarioError, match="not valid JSON"):
        load_scenario(path)


def test_defaults_and_conversions(base):
    data = {"cameras": base["cameras"], "vehicles": ["random"], "yaw_deg": [-90, 90], "noise": "noiseless"}
    scenario = scenario_from_dict(data)
    assert scenario.vehicles_per_frame == 1 and scenario.num_frames == 10 and scenario.seed == 0
    assert scenario.yaw_range == pytest.approx((-math.pi / 2, math.pi / 2))
    assert scenario.noise == NoiseModel.noiseless()
    assert scenario.motion is None
    data["motion"] = {"speed": [1, 2], "yaw_rate_deg": [-180, 0]}
    assert scenario_from_dict(data).motion == Motion(speed=(1.0, 2.0), yaw_rate=(-math.pi, 0.0))


def test_a_camera_may_be_given_by_K_and_world_T_camera(base):
    cam = load_scenario("intersection_2cam").cameras["cam0"]
    base["cameras"][0] = {"name": "cam0", "K": cam.K.tolist(), "world_T_camera": cam.world_T_camera.tolist(),
                          "image_size": [1280, 720], "dist": [0.01, 0, 0, 0]}
    again = scenario_from_dict(base).cameras["cam0"]
    np.testing.assert_allclose(again.K, cam.K)
    np.testing.assert_allclose(again.world_T_camera, cam.world_T_camera)
    np.testing.assert_allclose(again.dist, [0.01, 0, 0, 0, 0])


def _set(path, value):
    """A mutation that sets ``data[path...] = value`` (or deletes it when value is ...)."""

    def apply(data):
        *head, last = path
        for key in head:
            data = data[key]
        if value is ...:
            del data[last]
        else:
            data[last] = value

    return apply


CASES = [
    (_set(["colour"], "red"), "colour", "unknown key"),
    (_set(["cameras"], ...), "cameras", "missing"),
    (_set(["cameras"], []), "cameras", "non-empty"),
    (_set(["cameras", 0, "height"], -2.0), "cameras[0].height", "> 0"),
    (_set(["cameras", 0, "height"], "high"), "cameras[0].height", "expected a number"),
    (_set(["cameras", 1, "hfov_deg"], 200.0), "cameras[1].hfov_deg", "< 180"),
    (_set(["cameras", 1, "K"], [[800, 0, 640], [0, 800, 360], [0, 0, 1]]), "cameras[1]", "exactly one of"),
    (_set(["cameras", 0, "pole"], [1.0]), "cameras[0].pole", "list of 2 numbers"),
    (_set(["cameras", 0, "pole"], ...), "cameras[0].pole", "missing"),
    (_set(["cameras", 0, "look_at"], [-14.0, -11.0, 0.0]), "cameras[0].look_at", "parallel"),
    (_set(["cameras", 0, "image_size"], [1280, -720]), "cameras[0].image_size", "positive integers"),
    (_set(["cameras", 0, "dist"], [0.1, 0.2]), "cameras[0].dist", "4 or 5"),
    (_set(["cameras", 0, "zoom"], 2), "cameras[0].zoom", "unknown key"),
    (_set(["cameras", 1, "name"], "cam0"), "cameras[1].name", "duplicate"),
    (_set(["vehicles"], ["lincoln_mkz", "tractor"]), "vehicles[1]", "unknown name 'tractor'"),
    (_set(["vehicles"], "lincoln_mkz"), "vehicles", "non-empty list"),
    (_set(["vehicle_order"], "shuffle"), "vehicle_order", "expected one of"),
    (_set(["vehicles_per_frame"], 0), "vehicles_per_frame", ">= 1"),
    (_set(["vehicles_per_frame"], 1.5), "vehicles_per_frame", "integer"),
    (_set(["random_shape", "wheelbase"], [3.0, 2.5]), "random_shape.wheelbase", "min <= max"),
    (_set(["random_shape", "size"], 1), "random_shape.size", "unknown key"),
    (_set(["region", "x"], [3.0, -3.0]), "region.x", "min <= max"),
    (_set(["region", "y"], ...), "region.y", "missing"),
    (_set(["yaw_deg"], [0, 720]), "yaw_deg", "at most 360"),
    (_set(["visible_in"], ["cam0", "cam7"]), "visible_in[1]", "expected one of"),
    (_set(["margin_px"], -1), "margin_px", ">= 0"),
    (_set(["noise", "outlier_rate"], 1.5), "noise.outlier_rate", "<= 1"),
    (_set(["noise", "relative_sigma"], True), "noise.relative_sigma", "expected a number"),
    (_set(["noise", "confidence_visible"], [0.0, 1.0]), "noise.confidence_visible", "> 0"),
    (_set(["noise", "confidence_occluded"], [0.6, 0.3]), "noise.confidence_occluded", "min <= max"),
    (_set(["noise", "blur"], 1), "noise.blur", "unknown key"),
    (_set(["noise"], "loud"), "noise", "expected one of"),
    (_set(["num_frames"], 0), "num_frames", ">= 1"),
    (_set(["dt"], 0.0), "dt", "> 0"),
    (_set(["seed"], -1), "seed", ">= 0"),
    (_set(["seed"], "abc"), "seed", "integer"),
    (_set(["motion"], {"speed": [-1, 2]}), "motion.speed", "within"),
    (_set(["motion"], {"accel": 1}), "motion.accel", "unknown key"),
]


@pytest.mark.parametrize("mutate, field, problem", CASES, ids=[c[1] + ":" + c[2] for c in CASES])
def test_validation_errors_name_the_field(base, mutate, field, problem):
    data = copy.deepcopy(base)
    mutate(data)
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(data)
    assert info.value.field == field
    assert problem in info.value.problem
    assert isinstance(info.value, ValueError)


def test_a_bad_K_is_reported_under_the_camera(base):
    base["cameras"][0] = {"name": "cam0", "K": [[-5, 0, 640], [0, 800, 360], [0, 0, 1]], "pole": [-14, -11],
                          "height": 7.5}
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(base)
    assert info.value.field == "cameras[0].K"


def test_a_scenario_moves_onto_given_cameras_where_they_look():
    """``scenario_on_cameras``: the given rig moved along the road so that where it looks (the median of its optical
    axes' points on z = 0) is the world origin, around which the base scenario puts its vehicles, each whole in at
    least one view; a scenario with tracks keeps its own; cameras that look at no road are a named error."""
    from vfactor.sim import pole_camera, scenario_on_cameras, simulate

    cameras = {c.name: c for c in (pole_camera("a", (20.0, -5.0), 8.0, target=(40.0, 10.0, 0.0)),
                                   pole_camera("b", (55.0, 28.0), 6.0, target=(40.0, 10.0, 0.0)))}
    base = load_scenario("library_2cam")
    moved = scenario_on_cameras(base, cameras)
    for name, camera in moved.cameras.items():  # the same rig, 40 m and 10 m nearer the origin, turned by nothing
        shift = cameras[name].world_T_camera - camera.world_T_camera
        assert np.allclose(shift[:2, 3], [40.0, 10.0]) and np.allclose(np.delete(shift, 3, axis=1), 0.0)
        assert np.array_equal(camera.K, cameras[name].K)
    assert moved.region == base.region and moved.noise == base.noise
    assert moved.require_visible == "any" and moved.visible_in == ("a", "b")
    sim = simulate(moved, seed=3, num_frames=4)
    for frame in sim.scene.frames:  # every vehicle whole in at least one view
        assert {d.camera for d in frame.detections if d.seen.all()}
    tracks = scenario_on_cameras(load_scenario("tracks_3veh"), cameras)
    assert tracks.motion == load_scenario("tracks_3veh").motion and tracks.require_visible == "none"
    assert len(simulate(tracks, seed=1).scene.frames) == 30
    from vfactor.camera import extrinsic_sigma

    surveyed = {name: dataclasses.replace(c, extrinsic_sigma=extrinsic_sigma(0.3, 0.05)) for name, c in cameras.items()}
    assert all(c.extrinsic_sigma is None for c in scenario_on_cameras(base, surveyed).cameras.values())  # the truth's
    up = pole_camera("up", (0.0, 0.0), 5.0, target=(10.0, 0.0, 9.0))  # looking above the horizon
    with pytest.raises(ScenarioError) as info:
        scenario_on_cameras(base, {"up": up})
    assert info.value.field == "cameras"
