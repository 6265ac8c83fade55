"""The public API surface: a test that fails when a public name disappears, and torch stays out of the core."""

from __future__ import annotations

import subprocess
import sys

import vfactor

PUBLIC = {
    "Camera", "CalibrationError", "Detection", "Frame", "FrameResult", "GraphConfig", "InputError", "KEYPOINT_NAMES",
    "KeyScheme", "LAYERS", "LEFT_RIGHT_PAIRS", "NUM_KEYPOINTS", "PRESETS", "RobustLoss", "Scene", "SceneError",
    "ScenarioError", "ShapePrior", "SolveOptions", "Status", "VehicleResult", "Wireframe", "add_observation_factor",
    "add_shape_factors", "build_vehicle_graph", "default_hwc_bounds", "default_shape_prior", "hwc_factor",
    "insert_vehicle_values", "load_results", "load_scene", "observations_from_detections", "save_results",
    "save_scene", "solve_frame", "solve_observations", "solve_scene", "solve_vehicle", "GroundPlane", "MotionModel",
    "TrackOptions", "TrackRun", "Tracker", "smooth_scene", "track_scene", "BODY_TYPES", "ShapeModel", "TrackShape",
    "default_shape_model", "track_shape", "load_calibration", "Association", "AssociationOptions", "associate_scene",
    "GroundFit", "fit_ground_plane", "class_hints",
}


def test_public_names_are_exported():
    assert PUBLIC <= set(vfactor.__all__)
    for name in vfactor.__all__:
        assert hasattr(vfactor, name), name


def test_core_import_does_not_load_torch_or_matplotlib():
    code = "import sys, vfactor, vfactor.cli, vfactor.sim; print('torch' in sys.modules, 'matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]
