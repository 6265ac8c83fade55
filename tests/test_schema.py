"""The shipped JSON Schemas: valid schemas, every file vfactor writes validates, structural errors fail them."""

from __future__ import annotations

import json

import jsonschema
import pytest

from tests.test_scene import BAD_CASES, base_scene
from vfactor.cli import main
from vfactor.scene import results_to_dict, save_scene, scene_to_dict
from vfactor.schema import SCHEMAS, load_schema, schema_text, validate
from vfactor.sim import list_scenarios, load_scenario, simulate
from vfactor.solve import solve_scene

#: BAD_CASES of tests/test_scene.py that are about the structure of the file, which a schema can say (the
#: others are about values: a rotation that is not one, duplicate names, NaN, unknown cameras, ...).
STRUCTURAL = {
    "top_empty", "cameras_missing", "cameras_empty", "frames_not_list", "unknown_top_key", "unknown_camera_key",
    "camera_name_missing", "camera_name_not_string", "K_shape", "K_string", "pose_missing", "dist_three",
    "image_size_negative", "image_size_float", "frame_not_object", "t_missing", "t_string", "detections_missing",
    "unknown_frame_key", "detection_not_object", "unknown_detection_key", "camera_missing", "keypoints_not_list",
    "keypoints_eleven", "keypoint_row_short", "keypoint_row_not_list", "confidence_negative", "confidence_string",
    "confidence_null", "images_not_object", "images_not_string", "neither_keypoints_nor_heatmaps",
}


@pytest.mark.parametrize("which", sorted(SCHEMAS))
def test_schemas_are_valid_draft_2020_12(which):
    jsonschema.Draft202012Validator.check_schema(load_schema(which))
    assert load_schema(which)["$schema"] == "https://json-schema.org/draft/2020-12/schema"


def test_schema_command_prints_and_writes_the_schema(tmp_path, capsys):
    assert main(["schema"]) == 0
    assert json.loads(capsys.readouterr().out) == load_schema("scene")
    assert main(["schema", "result", "--out", str(tmp_path / "result.schema.json")]) == 0
    assert (tmp_path / "result.schema.json").read_text() == schema_text("result")


#: Frames of each packaged scenario validated: all of them for most; city_intersection's 2000 (the scale benchmark's
#: scene, the same cameras and vehicle mix throughout) took 181 s, 42 % of the default suite, where 60 take 6 s.
SCHEMA_FRAMES = 60


@pytest.mark.parametrize("scenario", list_scenarios())
def test_every_packaged_scenario_makes_scenes_that_validate(scenario):
    config = load_scenario(scenario)
    sim = simulate(config, seed=1, num_frames=min(config.num_frames, SCHEMA_FRAMES))
    assert len(sim.scene.frames) == min(config.num_frames, SCHEMA_FRAMES)
    assert validate(scene_to_dict(sim.scene)) == []


def test_results_of_solve_and_track_validate(tmp_path):
    sim = simulate(load_scenario("intersection_2cam_track"), seed=3, num_frames=4)
    assert validate(results_to_dict(solve_scene(sim.scene)), "result") == []
    scene, out = tmp_path / "scene.json", tmp_path / "result.json"
    save_scene(sim.scene, scene)
    assert main(["track", str(scene), "--out", str(out), "-q"]) == 0
    data = json.loads(out.read_text())
    assert any("pose_covariance_kind" in v for f in data["frames"] for v in f["vehicles"])
    assert validate(data, "result") == []
    data["frames"][0]["vehicles"][0]["status"] = "failed"  # a failed vehicle must have no pose
    assert any("frames[0].vehicles[0].world_T_vehicle" in p for p in validate(data, "result"))


def test_scene_loader_examples_validate(tmp_path):
    assert validate(base_scene(tmp_path)) == []


@pytest.mark.parametrize("name, edit", [(c[0], c[1]) for c in BAD_CASES if c[0] in STRUCTURAL])
def test_structural_errors_fail_the_schema_too(tmp_path, name, edit):
    data = base_scene(tmp_path)
    edit(data)
    problems = validate(data)
    assert problems, f"{name}: the schema accepts what the loader refuses"


def test_every_structural_case_is_known():
    assert STRUCTURAL <= {c[0] for c in BAD_CASES}


def test_a_problem_names_the_row_at_fault_in_one_short_line():
    """A short keypoint row was reported as the whole 12-row list, its numbers in the message."""
    data = scene_to_dict(simulate("intersection_2cam", seed=0, num_frames=1).scene)
    data["frames"][0]["detections"][0]["keypoints"][3] = [1.0, 2.0]
    (problem,) = validate(data)
    assert problem == "frames[0].detections[0].keypoints[3]: [1.0, 2.0] is too short"
    data["frames"][0]["detections"][0]["keypoints"] = [[1.0, 2.0, 0.5]] * 400
    assert all(len(p) < 300 for p in validate(data))
