"""Synthetic scenes: camera rigs, vehicles on the road, self-occlusion, detector noise, scenarios.

Typical use::

    from vfactor.sim import load_scenario, simulate, write_simulation

    sim = simulate(load_scenario("intersection_2cam"), seed=1)
    sim.scene        # a vfactor.observations.Scene: cameras and noisy detections
    sim.truth[0]     # frame 0: vehicle id -> VehicleTruth(world_T_vehicle, wireframe, preset, ..., speed, yaw_rate)
    write_simulation(sim, "scene.json", "scene_truth.json")

Tracks (vehicles driving routes through the intersection, entering and leaving the views)::

    sim = simulate("tracks_3veh")
    sim.truth[f]["v2"].speed, sim.truth[f]["v2"].yaw_rate     # per-frame true motion state
    sim.trajectories["v2"].states(times)                      # continuous-time truth

Association (no vehicle ids; per-camera tracks, misses, false detections)::

    anon = anonymise(simulate("association_4cam"), seed=0, track_switch_rate=0.02, false_rate=0.1, miss_rate=0.05)
    anon.scene       # every detection's vehicle is vfactor.observations.UNASSIGNED
    anon.truth_ids   # per frame, per detection: the true vehicle id (None: a false detection)
"""

from vfactor.sim.noise import NoiseModel, NoisyKeypoints, box_diagonal, corrupt_keypoints
from vfactor.sim.rig import intersection_rig, intrinsics_from_hfov, look_at, pole_camera
from vfactor.sim.routes import (
    ARMS,
    TURNS,
    IntersectionRoute,
    Path,
    SpeedProfile,
    Trajectory,
    TrajectoryStates,
    drive_profile,
    intersection_path,
)
from vfactor.sim.scenario import (
    CAMERA_FIELDS,
    MOTION_FIELDS,
    REQUIRE_VISIBLE,
    ROUTE_FIELDS,
    ROUTE_MOTION_FIELDS,
    SCENARIO_FIELDS,
    BodyMotion,
    ExtrinsicError,
    Motion,
    RouteMotion,
    RouteSpec,
    Scenario,
    list_scenarios,
    load_scenario,
    noise_from_value,
    scenario_from_dict,
    scenario_on_cameras,
    scenario_path,
)
from vfactor.sim.simulate import (
    DetectionTruth,
    Simulation,
    VehicleTruth,
    keypoints_in_view,
    redraw_noise,
    simulate,
    vehicle_ids,
)
from vfactor.sim.truth import load_truth, save_truth, truth_from_dict, truth_to_dict, write_simulation
from vfactor.sim.vehicles import (
    LIBRARY,
    RANDOM,
    RandomShape,
    footprint,
    footprints_overlap,
    random_wireframe,
    road_pose,
    symmetrised,
    vehicle_shape,
    draw_vehicle,
    check_vehicle_name,
    vehicle_names,
    within_hwc_bounds,
)
from vfactor.sim.visibility import HUB_PUSH, VehicleBody, occluded_keypoints, self_occluded
from vfactor.sim.anonymise import AnonymousScene, TrackSwitch, anonymise, load_truth_ids, write_anonymised

__all__ = [
    # rig
    "look_at",
    "intrinsics_from_hfov",
    "pole_camera",
    "intersection_rig",
    # vehicles
    "RANDOM",
    "LIBRARY",
    "RandomShape",
    "random_wireframe",
    "symmetrised",
    "vehicle_shape",
    "draw_vehicle",
    "check_vehicle_name",
    "vehicle_names",
    "within_hwc_bounds",
    "road_pose",
    "footprint",
    "footprints_overlap",
    # visibility
    "HUB_PUSH",
    "VehicleBody",
    "occluded_keypoints",
    "self_occluded",
    # noise
    "NoiseModel",
    "NoisyKeypoints",
    "corrupt_keypoints",
    "box_diagonal",
    # routes
    "ARMS",
    "TURNS",
    "Path",
    "SpeedProfile",
    "drive_profile",
    "Trajectory",
    "TrajectoryStates",
    "IntersectionRoute",
    "intersection_path",
    # scenarios
    "Scenario",
    "BodyMotion",
    "ExtrinsicError",
    "Motion",
    "RouteMotion",
    "RouteSpec",
    "SCENARIO_FIELDS",
    "CAMERA_FIELDS",
    "MOTION_FIELDS",
    "ROUTE_MOTION_FIELDS",
    "ROUTE_FIELDS",
    "REQUIRE_VISIBLE",
    "load_scenario",
    "scenario_from_dict",
    "scenario_on_cameras",
    "scenario_path",
    "list_scenarios",
    "noise_from_value",
    # simulation and truth
    "simulate",
    "redraw_noise",
    "Simulation",
    "VehicleTruth",
    "DetectionTruth",
    "vehicle_ids",
    "keypoints_in_view",
    "save_truth",
    "load_truth",
    "truth_to_dict",
    "truth_from_dict",
    "write_simulation",
    # association test scenes
    "anonymise",
    "AnonymousScene",
    "TrackSwitch",
    "write_anonymised",
    "load_truth_ids",
]
