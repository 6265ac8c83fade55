"""Bodies that roll and pitch on their suspension (``body_motion``): the keypoints the cameras see, the scenario
field, the truth file."""

from __future__ import annotations

import dataclasses
import math

import gtsam
import numpy as np
import pytest

from vfactor.errors import ScenarioError
from vfactor.sim import BodyMotion, load_scenario, scenario_from_dict, simulate
from vfactor.sim.simulate import VehicleTruth
from vfactor.sim.truth import truth_from_dict, truth_to_dict
from vfactor.wireframe import PRESETS


def _truth(**motion) -> VehicleTruth:
    return VehicleTruth(gtsam.Pose3(gtsam.Rot3.Yaw(0.3), np.array([2.0, 1.0, 0.34])), PRESETS["lincoln_mkz"].wireframe(),
                        "lincoln_mkz", 0.34, **motion)


def test_a_body_rolls_out_of_a_turn_and_pitches_nose_down_when_braking_its_hubs_on_the_road():
    motion = BodyMotion(roll_deg_per_g=5.0, pitch_deg_per_g=2.0)
    left_turn = motion.applied(_truth(speed=8.0, yaw_rate=0.6, acceleration=0.0))  # 4.8 m/s^2 to the left
    assert left_turn.body_roll == pytest.approx(math.radians(5.0) * 8.0 * 0.6 / 9.81)
    assert left_turn.body_pitch == 0.0
    body = left_turn.world_T_vehicle.transformTo(left_turn.seen_keypoints_world.T).T  # back in the hubs' frame
    rigid = np.asarray(left_turn.wireframe.vehicle_p_keypoints)
    np.testing.assert_allclose(body[:4], rigid[:4], atol=1e-12)  # the hubs do not move
    right = rigid[4:, 1] < 0
    assert np.all(body[4:][right, 2] < rigid[4:][right, 2])  # the right (outer) side goes down
    assert np.all(body[4:][~right, 2] > rigid[4:][~right, 2])
    braking = motion.applied(_truth(speed=5.0, yaw_rate=0.0, acceleration=-3.0))
    assert braking.body_pitch > 0 and braking.body_roll == 0.0
    body = braking.world_T_vehicle.transformTo(braking.seen_keypoints_world.T).T
    front = rigid[4:, 0] > 0
    assert np.all(body[4:][front, 2] < rigid[4:][front, 2])  # the nose dives
    rigid_truth = _truth(speed=5.0, yaw_rate=0.5, acceleration=-3.0)  # no body_motion: rigid
    np.testing.assert_array_equal(rigid_truth.seen_keypoints_world, rigid_truth.keypoints_world)
    still = _truth()
    assert motion.applied(still) is still  # independent frames: no accelerations, nothing to roll


def test_body_motion_moves_what_the_cameras_see_not_the_truth_and_round_trips_in_the_truth_file():
    scenario = load_scenario("tracks_3veh")
    rigid = simulate(scenario, seed=3, num_frames=12)
    rolling = simulate(dataclasses.replace(scenario, body_motion=BodyMotion(5.0, 2.0)), seed=3, num_frames=12)
    for a, b in zip(rigid.truth, rolling.truth):
        for vid in a:
            np.testing.assert_array_equal(a[vid].keypoints_world, b[vid].keypoints_world)  # scored against: rigid
    turned = [v for frame in rolling.truth for v in frame.values() if abs(v.body_roll) > math.radians(0.5)]
    assert turned  # some vehicle turns in these frames
    moved = max(np.abs(v.seen_keypoints_world - v.keypoints_world).max() for v in turned)
    assert moved > 0.01
    assert any(not np.allclose(d1.keypoints, d2.keypoints, equal_nan=True)
               for f1, f2 in zip(rigid.scene.frames, rolling.scene.frames) for d1, d2 in zip(f1.detections, f2.detections))
    back = truth_from_dict(truth_to_dict(rolling))
    for frame, again in zip(rolling.truth, back):
        for vid, v in frame.items():
            assert again[vid].body_roll == pytest.approx(v.body_roll) and again[vid].body_pitch == pytest.approx(v.body_pitch)
    assert "body_roll" not in truth_to_dict(rigid)["frames"][0]["vehicles"][0]


def test_the_body_motion_field_is_checked():
    base = {"cameras": [{"name": "cam0", "pole": [-14.0, -11.0], "height": 7.5, "look_at": [0.0, 0.0, 0.0],
                         "hfov_deg": 45.0, "image_size": [1280, 720]}],
            "vehicles": ["lincoln_mkz"], "motion": {"speed": [5, 6]}}
    scenario = scenario_from_dict({**base, "body_motion": {"roll_deg_per_g": 4.0}})
    assert scenario.body_motion == BodyMotion(4.0, 0.0)
    assert scenario_from_dict(base).body_motion is None
    with pytest.raises(ScenarioError, match="body_motion: needs motion"):
        scenario_from_dict({**{k: v for k, v in base.items() if k != "motion"}, "body_motion": {"roll_deg_per_g": 4}})
    with pytest.raises(ScenarioError, match="body_motion.pitch_deg_per_g"):
        scenario_from_dict({**base, "body_motion": {"pitch_deg_per_g": -1}})
    with pytest.raises(ScenarioError, match="body_motion"):
        scenario_from_dict({**base, "body_motion": {"yaw_deg_per_g": 1}})


def test_turn_lateral_accel_slows_a_turning_vehicle_to_it():
    """``motion.turn_lateral_accel``: traffic slows for a turn; the default routes turn at cruise speed (1.2-1.4 g on
    ``library_tracks``)."""
    base = load_scenario("library_tracks")
    for cap, most in ((None, 9.81), (3.5, 3.5 + 1e-9)):
        scenario = dataclasses.replace(base, motion=dataclasses.replace(base.motion, turn_lateral_accel=cap))
        lateral = [abs(v.speed * v.yaw_rate) for seed in (210, 211, 212)
                   for frame in simulate(scenario, seed=seed).truth for v in frame.values()]
        if cap is None:
            assert max(lateral) > most  # more than 1 g somewhere
        else:
            assert max(lateral) <= most
    traffic = load_scenario("library_tracks_traffic")
    assert traffic.motion.turn_lateral_accel == 3.5 and traffic.body_motion == BodyMotion(4.5, 2.0)
    with pytest.raises(ScenarioError, match="motion.turn_lateral_accel"):
        scenario_from_dict({"cameras": [{"name": "cam0", "pole": [-14.0, -11.0], "height": 7.5,
                                         "look_at": [0.0, 0.0, 0.0], "hfov_deg": 45.0, "image_size": [1280, 720]}],
                            "vehicles": ["van"], "motion": {"kind": "route", "turn_lateral_accel": 0}})
