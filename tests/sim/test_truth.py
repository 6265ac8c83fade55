"""Ground-truth files: JSON round trip, validation, writing a whole simulation."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vfactor.errors import SceneError
from vfactor.sim import load_scenario, load_truth, save_truth, simulate, truth_to_dict, write_simulation


@pytest.fixture(scope="module")
def sim():
    return simulate(load_scenario("intersection_multi"), num_frames=3)


def test_truth_round_trips_through_json(sim, tmp_path):
    path = tmp_path / "truth.json"
    save_truth(sim, path)
    loaded = load_truth(path)
    assert len(loaded) == len(sim.truth)
    for a, b in zip(sim.truth, loaded):
        assert list(a) == list(b)
        for vid in a:
            assert b[vid].preset == a[vid].preset and b[vid].wheel_radius == a[vid].wheel_radius
            assert b[vid].wireframe == a[vid].wireframe
            np.testing.assert_allclose(b[vid].world_T_vehicle.matrix(), a[vid].world_T_vehicle.matrix(), atol=1e-12)
            np.testing.assert_allclose(b[vid].keypoints_world, a[vid].keypoints_world, atol=1e-12)
    data = json.loads(path.read_text())
    assert data["scenario"] == "intersection_multi" and data["seed"] == sim.seed
    entry = data["frames"][0]["vehicles"][0]
    assert set(entry) == {"id", "preset", "wheel_radius", "world_T_vehicle", "keypoints_world", "keypoints_vehicle"}
    assert np.array(entry["keypoints_world"]).shape == (12, 3)


@pytest.mark.parametrize(
    "mutate, field",
    [
        (lambda d: d["frames"][1]["vehicles"][0].pop("world_T_vehicle"), "frames[1].vehicles[0].world_T_vehicle"),
        (lambda d: d["frames"][0]["vehicles"][1].__setitem__("keypoints_vehicle", [[0, 0, 0]]),
         "frames[0].vehicles[1].keypoints_vehicle"),
        (lambda d: d["frames"][0]["vehicles"][0]["world_T_vehicle"][0].__setitem__(0, 2.0),
         "frames[0].vehicles[0].world_T_vehicle"),
        (lambda d: d["frames"][2]["vehicles"][1].__setitem__("id", "v1"), "frames[2].vehicles[1].id"),
        (lambda d: d["frames"][0]["vehicles"][0].__setitem__("wheel_radius", -1), "frames[0].vehicles[0].wheel_radius"),
    ],
)
def test_malformed_truth_names_the_field(sim, tmp_path, mutate, field):
    data = truth_to_dict(sim)
    mutate(data)
    path = tmp_path / "truth.json"
    path.write_text(json.dumps(data))
    with pytest.raises(SceneError) as info:
        load_truth(path)
    assert info.value.field == field


def test_missing_truth_file(tmp_path):
    with pytest.raises(SceneError, match="file not found"):
        load_truth(tmp_path / "nothing.json")


def test_write_simulation_writes_a_loadable_scene_and_truth(sim, tmp_path):
    scene_module = pytest.importorskip("vfactor.scene")
    write_simulation(sim, tmp_path / "scene.json", tmp_path / "truth.json")
    scene = scene_module.load_scene(tmp_path / "scene.json")
    assert list(scene.cameras) == list(sim.scene.cameras)
    assert len(scene.frames) == len(sim.scene.frames) == len(load_truth(tmp_path / "truth.json"))
    for a, b in zip(sim.scene.frames, scene.frames):
        assert a.t == b.t and len(a.detections) == len(b.detections)
        for da, db in zip(a.detections, b.detections):
            assert (da.camera, da.vehicle) == (db.camera, db.vehicle)
            np.testing.assert_array_equal(da.confidence, db.confidence)
            seen = da.confidence > 0
            np.testing.assert_allclose(db.keypoints[seen], da.keypoints[seen], atol=1e-9)
