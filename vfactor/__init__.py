"""vfactor: vehicle pose and shape from several fixed monocular cameras, as a GTSAM factor graph.

Quick start::

    import vfactor
    scene = vfactor.load_scene("scene.json")
    results = vfactor.solve_scene(scene)
    for frame in results:
        for v in frame.vehicles:
            print(v.id, v.status.value, v.world_T_vehicle, v.pose_covariance)

Conventions (frames, units, keypoint order) are in ``docs/conventions.md``.
PyTorch is never imported by the core; only a keypoint network will need it.
"""

from vfactor._version import __version__
from vfactor.association import Association, AssociationOptions, associate_scene
from vfactor.box import Box, BoxModel, default_box_model, vehicle_box
from vfactor.calibration import load_calibration
from vfactor.camera import Camera
from vfactor.errors import CalibrationError, InputError, ScenarioError, SceneError
from vfactor.factors.ground_plane import GroundPlane
from vfactor.factors.motion import MotionModel
from vfactor.factors.robust import RobustLoss
from vfactor.graph import (
    GraphConfig,
    add_observation_factor,
    add_shape_factors,
    build_vehicle_graph,
    hwc_factor,
    insert_vehicle_values,
    observations_from_detections,
)
from vfactor.extrinsics_fit import ExtrinsicsFit, fit_extrinsics
from vfactor.ground_fit import GroundFit, fit_ground_plane
from vfactor.keypoints import KEYPOINT_NAMES, LAYERS, LEFT_RIGHT_PAIRS, NUM_KEYPOINTS
from vfactor.keys import KeyScheme
from vfactor.observations import Detection, Frame, Scene, class_hints
from vfactor.result import FrameResult, Status, VehicleResult
from vfactor.scene import load_results, load_scene, save_results, save_scene
from vfactor.shape_evidence import TrackShape, track_shape
from vfactor.shape_model import ShapeModel, ShapePrior, default_hwc_bounds, default_shape_model, default_shape_prior
from vfactor.solve import SolveOptions, solve_frame, solve_observations, solve_scene, solve_vehicle
from vfactor.track import Tracker, TrackOptions, TrackRun, smooth_scene, track_scene
from vfactor.vehicle_library import BODY_TYPES
from vfactor.wireframe import PRESETS, Wireframe

__all__ = [
    "Box",
    "BoxModel",
    "Camera",
    "CalibrationError",
    "Detection",
    "Frame",
    "FrameResult",
    "GraphConfig",
    "GroundFit",
    "GroundPlane",
    "InputError",
    "KEYPOINT_NAMES",
    "KeyScheme",
    "LAYERS",
    "LEFT_RIGHT_PAIRS",
    "MotionModel",
    "NUM_KEYPOINTS",
    "PRESETS",
    "RobustLoss",
    "Scene",
    "SceneError",
    "ScenarioError",
    "ShapeModel",
    "ShapePrior",
    "SolveOptions",
    "Status",
    "TrackOptions",
    "TrackRun",
    "TrackShape",
    "Tracker",
    "VehicleResult",
    "Wireframe",
    "add_observation_factor",
    "add_shape_factors",
    "build_vehicle_graph",
    "default_box_model",
    "BODY_TYPES",
    "default_hwc_bounds",
    "default_shape_model",
    "default_shape_prior",
    "fit_ground_plane",
    "fit_extrinsics",
    "ExtrinsicsFit",
    "hwc_factor",
    "insert_vehicle_values",
    "load_calibration",
    "Association",
    "AssociationOptions",
    "associate_scene",
    "load_results",
    "load_scene",
    "observations_from_detections",
    "save_results",
    "save_scene",
    "solve_frame",
    "solve_observations",
    "solve_scene",
    "solve_vehicle",
    "smooth_scene",
    "track_scene",
    "track_shape",
    "vehicle_box",
    "class_hints",
]
