"""The public surface of vfactor.sim and vfactor.metrics: a test that fails when a name disappears."""

from __future__ import annotations

import vfactor.metrics
import vfactor.sim

SIM_NAMES = {
    "look_at", "intrinsics_from_hfov", "pole_camera", "intersection_rig",
    "RANDOM", "RandomShape", "random_wireframe", "symmetrised", "vehicle_shape", "within_hwc_bounds",
    "road_pose", "footprint", "footprints_overlap",
    "HUB_PUSH", "VehicleBody", "occluded_keypoints", "self_occluded",
    "NoiseModel", "NoisyKeypoints", "corrupt_keypoints", "box_diagonal",
    "Scenario", "Motion", "SCENARIO_FIELDS", "CAMERA_FIELDS", "load_scenario", "scenario_from_dict",
    "scenario_path", "list_scenarios", "noise_from_value",
    "simulate", "Simulation", "VehicleTruth", "DetectionTruth", "vehicle_ids", "keypoints_in_view",
    "RouteMotion", "RouteSpec", "MOTION_FIELDS", "ROUTE_MOTION_FIELDS", "ROUTE_FIELDS", "REQUIRE_VISIBLE",
    "ARMS", "TURNS", "Path", "SpeedProfile", "drive_profile", "Trajectory", "TrajectoryStates", "IntersectionRoute",
    "intersection_path",
    "save_truth", "load_truth", "truth_to_dict", "truth_from_dict", "write_simulation",
    "anonymise", "AnonymousScene", "TrackSwitch", "write_anonymised", "load_truth_ids",
}
METRICS_NAMES = {
    "rotation_error_deg", "translation_error_cm", "keypoint_errors_cm", "pose_errors", "summarise", "evaluate",
}


def test_public_names_exist_and_are_exported():
    for module, names in ((vfactor.sim, SIM_NAMES), (vfactor.metrics, METRICS_NAMES)):
        assert names <= set(module.__all__), names - set(module.__all__)
        for name in module.__all__:
            assert hasattr(module, name), name
