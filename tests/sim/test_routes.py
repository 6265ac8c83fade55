"""Routes: paths, speed profiles with stops, route scenarios, vehicles leaving the views, long tracks."""

from __future__ import annotations

import copy
import dataclasses
import json
import math
import time

import numpy as np
import pytest

from vfactor.errors import ScenarioError
from vfactor.sim import (
    Path,
    RouteMotion,
    RouteSpec,
    drive_profile,
    footprint,
    footprints_overlap,
    intersection_path,
    load_scenario,
    load_truth,
    save_truth,
    scenario_from_dict,
    scenario_path,
    simulate,
)
from vfactor.sim.simulate import keypoints_in_view

FINE_DT = 0.005


# --- paths -------------------------------------------------------------------------------------------------------


def test_a_path_of_straights_and_arcs_is_continuous_and_turns_by_its_curvature():
    path = Path((1.0, 2.0, 0.3), ((4.0, 0.0), (math.pi * 5.0, 0.2), (3.0, 0.0), (2.0, -0.5)))
    assert path.length == pytest.approx(9.0 + math.pi * 5.0)
    s = np.linspace(-3.0, path.length + 3.0, 4001)
    x, y, yaw, curvature = path.at(s)
    step = np.hypot(np.diff(x), np.diff(y))
    np.testing.assert_allclose(step, np.diff(s), rtol=1e-3)  # arc length: no jumps
    heading = np.arctan2(np.diff(y), np.diff(x))  # the path's tangent is its yaw
    mid_yaw = yaw[:-1] + 0.5 * np.angle(np.exp(1j * (yaw[1:] - yaw[:-1])))
    assert np.abs(np.angle(np.exp(1j * (heading - mid_yaw)))).max() < 1e-3
    end = path.end()
    assert end[2] == pytest.approx(0.3 + math.pi - 1.0)
    assert set(np.round(curvature, 6)) == {0.0, 0.2, -0.5}


def test_a_loop_repeats_and_must_close():
    lap = Path((0.0, -5.0, 0.0), ((10.0, 0.0), (math.pi * 5.0, 0.2), (10.0, 0.0), (math.pi * 5.0, 0.2)), loop=True)
    s = np.array([1.0, 17.0, 33.0])
    for a, b in zip(lap.at(s), lap.at(s + 3 * lap.length)):
        np.testing.assert_allclose(a, b, atol=1e-9)
    with pytest.raises(ValueError, match="does not close"):
        Path((0.0, 0.0, 0.0), ((10.0, 0.0), (math.pi * 5.0, 0.2)), loop=True)


@pytest.mark.parametrize("arm", ["west", "south", "east", "north"])
@pytest.mark.parametrize("turn, radius", [("straight", 8.0), ("left", 12.0), ("right", 7.0)])
def test_intersection_routes_drive_on_the_right_and_turn_by_a_quarter(arm, turn, radius):
    route = intersection_path(arm, turn, radius, lane_offset=1.75, stop_at=7.0)
    heading = math.radians({"west": 0, "south": 90, "east": 180, "north": 270}[arm])
    x, y, yaw, _ = route.path.at(np.array([-30.0 - route.offset, 40.0]))
    # Approach: right-hand lane, heading into the intersection.
    right = np.array([math.sin(heading), -math.cos(heading)])
    assert np.dot([x[0], y[0]], right) == pytest.approx(1.75)
    assert math.cos(yaw[0] - heading) == pytest.approx(1.0)
    # Exit: turned by 0 or +-90 degrees, again in the right-hand lane of the new road.
    exit_heading = heading + math.radians({"straight": 0, "left": 90, "right": -90}[turn])
    assert math.cos(yaw[1] - exit_heading) == pytest.approx(1.0)
    exit_right = np.array([math.sin(exit_heading), -math.cos(exit_heading)])
    assert np.dot([x[1], y[1]], exit_right) == pytest.approx(1.75)
    assert route.stop_s <= -7.0 + 1e-12


# --- speed profiles -----------------------------------------------------------------------------------------------


def _sampled(profile, t0, t1):
    t = np.arange(t0, t1, FINE_DT)
    s, v, a = profile.state(t)
    return t, s, v, a


def test_a_stop_is_reached_at_rest_and_held_for_the_wait_within_the_acceleration_bounds():
    profile = drive_profile(cruise=10.0, accel=2.0, decel=3.0, stops=[(60.0, 2.5), (70.0, 1.0)], s0=0.0)
    t, s, v, a = _sampled(profile, -2.0, 30.0)
    assert v.max() <= 10.0 + 1e-9 and v.min() >= 0.0
    dv = np.diff(v) / FINE_DT
    assert dv.max() <= 2.0 + 1e-6 and dv.min() >= -3.0 - 1e-6
    np.testing.assert_allclose(np.diff(s) / FINE_DT, 0.5 * (v[1:] + v[:-1]), atol=0.01)  # s is the integral of v
    for stop, wait in ((60.0, 2.5), (70.0, 1.0)):
        arrive = profile.time_at(stop)
        rest = (t >= arrive) & (t < arrive + wait)
        assert np.all(v[rest] == 0.0) and np.allclose(s[rest], stop)
        assert rest.sum() == pytest.approx(wait / FINE_DT, abs=1)
    # The two stops are 10 m apart: the vehicle cannot reach its cruise speed between them.
    between = (s > 60.0) & (s < 70.0)
    assert 0.0 < v[between].max() < 10.0
    assert v[-1] == pytest.approx(10.0) and a[-1] == 0.0


def test_a_vehicle_too_fast_to_stop_enters_already_braking():
    profile = drive_profile(cruise=12.0, accel=2.0, decel=3.0, stops=[(5.0, 1.0)], s0=0.0)
    assert profile.v[0] == pytest.approx(math.sqrt(2 * 3.0 * 5.0)) and profile.a[0] == -3.0


def test_a_vehicle_may_start_at_rest():
    profile = drive_profile(cruise=4.0, accel=1.5, decel=2.0, s0=0.0, t0=1.0, v0=0.0)
    s, v, a = profile.state(np.array([1.0, 2.0, 10.0]))
    np.testing.assert_allclose(v, [0.0, 1.5, 4.0])
    np.testing.assert_allclose(a, [1.5, 1.5, 0.0])


# --- route scenarios ----------------------------------------------------------------------------------------------


def _random_routes(num_vehicles=4, **motion):
    """A scenario of vehicles on random routes through the intersection, no visibility requirement."""
    base = load_scenario("tracks_3veh")
    return dataclasses.replace(
        base, vehicles=("lincoln_mkz", "suv", "van", "random"), vehicles_per_frame=num_vehicles,
        motion=RouteMotion(**{"stop_probability": 0.5, "scene_radius": None, **motion}), num_frames=40,
    )


@pytest.fixture(scope="module")
def routes_sim():
    return simulate(_random_routes(), seed=3)


def test_route_kinematics_respect_the_bounds_and_are_non_holonomic(routes_sim):
    motion = routes_sim.scenario.motion
    for vid, trajectory in routes_sim.trajectories.items():
        info = trajectory.info
        assert motion.speed[0] <= info["speed"] <= motion.speed[1]
        assert motion.decel[0] <= info["decel"] <= motion.decel[1]
        assert motion.accel[0] <= info["accel"] <= motion.accel[1]
        st = trajectory.states(np.arange(-1.0, 5.0, FINE_DT))
        assert st.speed.max() <= info["speed"] + 1e-9 and st.speed.min() >= 0.0
        dv = np.diff(st.speed) / FINE_DT
        assert dv.max() <= info["accel"] + 1e-6 and dv.min() >= -info["decel"] - 1e-6
        # Velocity (central differences of the positions) is along the heading: no sideways slip.
        vx = (st.x[2:] - st.x[:-2]) / (2 * FINE_DT)
        vy = (st.y[2:] - st.y[:-2]) / (2 * FINE_DT)
        yaw = st.yaw[1:-1]
        lateral = -np.sin(yaw) * vx + np.cos(yaw) * vy
        forward = np.cos(yaw) * vx + np.sin(yaw) * vy
        assert np.abs(lateral).max() < 0.01
        np.testing.assert_allclose(forward, st.speed[1:-1], atol=0.02)
        # Yaw rate = speed * curvature = the heading's rate of change.
        yaw_rate = np.angle(np.exp(1j * (st.yaw[2:] - st.yaw[:-2]))) / (2 * FINE_DT)
        smooth = np.abs(np.diff(st.curvature))[1:] + np.abs(np.diff(st.curvature))[:-1] == 0
        np.testing.assert_allclose(yaw_rate[smooth], st.yaw_rate[1:-1][smooth], atol=1e-3)


def test_per_frame_truth_carries_speed_yaw_rate_and_acceleration_and_stands_on_the_road(routes_sim):
    for f, truth in enumerate(routes_sim.truth):
        for vid, v in truth.items():
            st = routes_sim.trajectories[vid].states([f * routes_sim.scenario.dt])
            assert v.speed == pytest.approx(st.speed[0]) and v.yaw_rate == pytest.approx(st.yaw_rate[0])
            assert v.acceleration == pytest.approx(st.acceleration[0])
            T = v.world_T_vehicle
            roll, pitch, yaw = T.rotation().rpy()
            assert abs(roll) < 1e-12 and abs(pitch) < 1e-12 and T.z() == pytest.approx(v.wheel_radius)
            assert math.cos(yaw - st.yaw[0]) == pytest.approx(1.0)


def test_a_turn_follows_a_circle_of_the_given_radius():
    scenario = _random_routes(1, turns=("left",), radius=(9.0, 9.0))
    scenario = dataclasses.replace(scenario, motion=dataclasses.replace(
        scenario.motion, routes=(RouteSpec(turn="left", radius=9.0, stop=False),)
    ))
    trajectory = simulate(scenario, seed=1).trajectories["v1"]
    st = trajectory.states(np.arange(-10.0, 10.0, 0.01))
    on_arc = st.curvature != 0
    assert on_arc.sum() > 50
    np.testing.assert_allclose(st.curvature[on_arc], 1.0 / 9.0)
    np.testing.assert_allclose(st.speed[on_arc] / st.yaw_rate[on_arc], 9.0)
    # The positions on the arc lie on one circle of radius 9 (to the left of the heading).
    cx = st.x[on_arc] - 9.0 * np.sin(st.yaw[on_arc])
    cy = st.y[on_arc] + 9.0 * np.cos(st.yaw[on_arc])
    assert np.ptp(cx) < 1e-9 and np.ptp(cy) < 1e-9
    assert np.hypot(st.x[on_arc] - cx[0], st.y[on_arc] - cy[0]) == pytest.approx(9.0)
    total_turn = np.angle(np.exp(1j * (st.yaw[-1] - st.yaw[0])))
    assert total_turn == pytest.approx(math.pi / 2)


def test_a_stopping_vehicle_reaches_rest_at_its_stop_time_and_waits():
    scenario = _random_routes(1)
    scenario = dataclasses.replace(scenario, motion=dataclasses.replace(
        scenario.motion, routes=(RouteSpec(arm="north", turn="straight", stop_time=1.5, wait=1.2),)
    ))
    sim = simulate(scenario, seed=2)
    info = sim.trajectories["v1"].info
    assert info["stop"] and info["stop_time"] == pytest.approx(1.5) and info["wait"] == 1.2
    speeds = np.array([t["v1"].speed for t in sim.truth])
    at_rest = np.flatnonzero(speeds == 0.0)
    np.testing.assert_array_equal(at_rest, np.arange(15, 27))  # 1.5 s to 2.7 s (1.2 s at rest), every frame
    positions = np.array([t["v1"].world_T_vehicle.translation() for t in sim.truth])
    assert np.ptp(positions[at_rest], axis=0).max() < 1e-9
    np.testing.assert_allclose(positions[15, :2], info["stop_point"])
    assert np.hypot(*positions[15, :2]) == pytest.approx(math.hypot(7.0, 1.75))  # stop_at 7 m before the centre
    assert np.all(np.diff(speeds[:15]) < 0) and np.all(np.diff(speeds[27:]) > 0)  # braking, then setting off


def test_vehicles_keep_their_ids_and_shapes_and_never_come_too_close(routes_sim):
    scenario = routes_sim.scenario
    ids = ["v1", "v2", "v3", "v4"]
    assert sorted(routes_sim.trajectories) == ids
    for vid in ids:
        frames = routes_sim.vehicle_frames(vid)
        assert frames and len({routes_sim.truth[f][vid].wireframe for f in frames}) == 1
    for frame, truth in zip(routes_sim.scene.frames, routes_sim.truth):
        assert set(frame.vehicle_ids()) <= set(truth) <= set(ids)
        prints = [footprint(v.wireframe, v.world_T_vehicle) for v in truth.values()]
        for i in range(len(prints)):
            for j in range(i + 1, len(prints)):
                assert not footprints_overlap(prints[i], prints[j], scenario.min_gap)


def test_vehicles_exist_only_within_the_scene_radius():
    scenario = _random_routes(3, scene_radius=15.0, centre_time=(1.0, 3.0))
    sim = simulate(scenario, seed=4)
    present = {vid: sim.vehicle_frames(vid) for vid in sim.trajectories}
    for vid, frames in present.items():
        assert frames == list(range(frames[0], frames[-1] + 1))  # enters once, leaves once
        for f, truth in enumerate(sim.truth):
            st = sim.trajectories[vid].states([f * scenario.dt])
            assert (vid in truth) == bool(np.hypot(st.x[0], st.y[0]) <= 15.0)
            if vid not in truth:
                assert vid not in sim.scene.frames[f].vehicle_ids()
    assert any(len(frames) < scenario.num_frames for frames in present.values())


def test_route_simulations_are_deterministic(routes_sim):
    again = simulate(routes_sim.scenario, seed=3)
    other = simulate(routes_sim.scenario, seed=4)
    for f, (a, b) in enumerate(zip(routes_sim.truth, again.truth)):
        assert list(a) == list(b)
        for vid in a:
            np.testing.assert_array_equal(a[vid].world_T_vehicle.matrix(), b[vid].world_T_vehicle.matrix())
        da, db = routes_sim.scene.frames[f].detections, again.scene.frames[f].detections
        assert [(d.camera, d.vehicle) for d in da] == [(d.camera, d.vehicle) for d in db]
        for x, y in zip(da, db):
            np.testing.assert_array_equal(x.keypoints, y.keypoints)
    assert routes_sim.trajectories["v1"].info != other.trajectories["v1"].info


def test_explicit_colliding_routes_are_reported_under_the_route():
    scenario = _random_routes(2)
    same = RouteSpec(arm="west", turn="straight", speed=8.0, stop=False, centre_time=1.0)
    scenario = dataclasses.replace(scenario, motion=dataclasses.replace(scenario.motion, routes=(same, same)))
    with pytest.raises(ScenarioError) as info:
        simulate(scenario)
    assert info.value.field == "motion.routes[1]" and "min_gap" in info.value.problem


def test_require_visible_any_keeps_each_vehicle_whole_in_one_camera():
    scenario = dataclasses.replace(_random_routes(2, speed=(3.0, 5.0), radius=(6.0, 8.0)), require_visible="any",
                                   num_frames=12)
    sim = simulate(scenario, seed=0)
    cameras = list(sim.scene.cameras.values())
    for truth in sim.truth:
        for v in truth.values():
            assert any(keypoints_in_view(v.keypoints_world, [c], scenario.margin_px) for c in cameras)
    with pytest.raises(ScenarioError) as info:  # the whole vehicle in both small-overlap views: rarely possible
        simulate(dataclasses.replace(scenario, require_visible="all", num_frames=40), seed=0)
    assert info.value.field == "motion" and "require_visible" in info.value.problem


# --- the packaged track scenarios ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tracks():
    return simulate("tracks_3veh")


def test_tracks_3veh_has_three_body_types_a_straight_a_turn_and_a_stop(tracks):
    assert len(tracks.scene.frames) == 30 and len(tracks.scene.cameras) == 2
    info = {vid: t.info for vid, t in tracks.trajectories.items()}
    assert [info[v]["vehicle"] for v in ("v1", "v2", "v3")] == ["lincoln_mkz", "suv", "van"]
    assert info["v1"]["turn"] == "straight" and not info["v1"]["stop"]
    assert info["v2"]["turn"] in ("left", "right") and 6.0 <= info["v2"]["radius"] <= 15.0
    assert info["v3"]["stop"] and 0.0 < info["v3"]["stop_time"] < 2.9
    for vid in ("v1", "v2", "v3"):
        frames = tracks.vehicle_frames(vid)
        seen = [f for f in frames if vid in tracks.scene.frames[f].vehicle_ids()]
        assert len(seen) >= 0.7 * 30, vid  # seen by at least one camera in most frames
    stopped = [f for f in tracks.vehicle_frames("v3") if tracks.truth[f]["v3"].speed == 0.0]
    assert len(stopped) >= 4
    speeds = [t[v].speed for t in tracks.truth for v in t]
    assert max(speeds) <= 12.0


def test_a_vehicle_leaving_a_view_loses_detections_there_but_keeps_its_truth(tracks):
    left = set()
    for f in range(len(tracks.truth) - 1):
        for (camera, vid), labels in tracks.detection_truth[f].items():
            cam = tracks.scene.cameras[camera]
            outside = ~cam.in_image(np.nan_to_num(labels.uv_true, nan=-1e6))
            # Keypoints outside the image are missing, whatever the noise did.
            assert np.all(labels.missing[outside & ~labels.swapped])
            det = next(d for d in tracks.scene.frames[f].detections if (d.camera, d.vehicle) == (camera, vid))
            assert np.all(det.confidence[outside & ~labels.swapped] == 0.0)
            if vid in tracks.truth[f + 1] and (camera, vid) not in tracks.detection_truth[f + 1]:
                left.add((camera, vid))
                uv, depth = cam.project(tracks.truth[f + 1][vid].keypoints_world)
                assert not np.any(cam.in_image(uv) & (depth > 0))  # nothing of it left in that image
    assert ("cam0", "v2") in left  # v2 turns out of cam0's view while cam1 still sees it
    assert "v1" not in {d.vehicle for d in tracks.scene.frames[8].detections if d.camera == "cam0"}
    assert "v1" in tracks.truth[8] and "v1" in tracks.scene.frames[8].vehicle_ids()


def test_a_vehicle_partly_in_an_image_is_detected_with_the_keypoints_inside(tracks):
    partial = 0
    for labels_of_frame in tracks.detection_truth:
        for (camera, vid), labels in labels_of_frame.items():
            cam = tracks.scene.cameras[camera]
            inside = cam.in_image(np.nan_to_num(labels.uv_true, nan=-1e6))
            if 0 < inside.sum() < 12:
                partial += 1
    assert partial >= 5


def test_tracks_3cam_is_tracks_3veh_with_a_third_camera(tracks):
    sim3 = simulate("tracks_3cam")
    assert list(sim3.scene.cameras) == ["cam0", "cam1", "cam2"]
    for vid in ("v1", "v2", "v3"):
        assert sim3.trajectories[vid].info == tracks.trajectories[vid].info
    assert sim3.vehicle_frames("v2") == tracks.vehicle_frames("v2")


def test_long_track_has_500_frames_each_vehicle_seen_in_every_frame_and_simulates_fast():
    start = time.perf_counter()
    sim = simulate("long_track")
    elapsed = time.perf_counter() - start
    assert elapsed < 10.0
    assert len(sim.scene.frames) == len(sim.truth) == 500
    assert sim.scene.frames[-1].t == pytest.approx(49.9)
    ids = sorted(sim.trajectories)
    assert ids[0] == "v1"
    for frame, truth in zip(sim.scene.frames, sim.truth):
        assert sorted(truth) == ids
        assert set(frame.vehicle_ids()) == set(ids)  # each vehicle seen by at least one camera
    speeds = np.array([t["v1"].speed for t in sim.truth])
    assert (speeds == 0).sum() > 20 and speeds.max() == pytest.approx(4.0)  # stop-and-go
    yaw_rates = np.array([t["v1"].yaw_rate for t in sim.truth])
    assert yaw_rates.max() == pytest.approx(4.0 / 5.0)  # 4 m/s on the 5 m half-circles
    lap = sim.trajectories["v1"].path.length
    assert sim.trajectories["v1"].states([49.9]).s[0] > 2 * lap


def test_truth_files_keep_speed_yaw_rate_and_acceleration(tracks, tmp_path):
    save_truth(tracks, tmp_path / "truth.json")
    data = json.loads((tmp_path / "truth.json").read_text())
    assert [len(f["vehicles"]) for f in data["frames"]] == [len(t) for t in tracks.truth]
    loaded = load_truth(tmp_path / "truth.json")
    for a, b in zip(tracks.truth, loaded):
        assert list(a) == list(b)
        for vid in a:
            assert (b[vid].speed, b[vid].yaw_rate, b[vid].acceleration) == pytest.approx(
                (a[vid].speed, a[vid].yaw_rate, a[vid].acceleration)
            )


# --- route scenario validation -------------------------------------------------------------------------------------


@pytest.fixture
def route_data() -> dict:
    return json.loads(scenario_path("tracks_3veh").read_text())


def test_route_scenarios_load_with_their_defaults(route_data):
    scenario = scenario_from_dict(route_data)
    assert scenario.vehicles_per_frame == 3 and scenario.require_visible == "none"
    assert isinstance(scenario.motion, RouteMotion)
    assert scenario.motion.routes[2] == RouteSpec(arm="east", turn="straight", stop=True, stop_time=1.2)
    data = {"cameras": route_data["cameras"], "vehicles": ["random"], "require_visible": "none",
            "motion": {"kind": "route"}}
    scenario = scenario_from_dict(data)
    assert scenario.motion == RouteMotion() and scenario.vehicles_per_frame == 1
    assert RouteMotion().speed == (5.0, 12.0) and RouteMotion().radius == (6.0, 15.0)
    data["motion"]["speed"] = 7  # a single number is a fixed value
    assert scenario_from_dict(data).motion.speed == (7.0, 7.0)
    data["vehicles_per_frame"] = 5  # more vehicles than routes: the rest are drawn
    data["motion"]["routes"] = [{"from": "west"}]
    assert scenario_from_dict(data).vehicles_per_frame == 5
    sim = simulate(scenario_from_dict(data), num_frames=5)
    assert sorted(sim.trajectories) == ["v1", "v2", "v3", "v4", "v5"]
    assert sim.trajectories["v1"].info["from"] == "west"


def _route_set(path, value):
    def apply(data):
        target = data
        for key in path[:-1]:
            target = target[key]
        if value is ...:
            del target[path[-1]]
        else:
            target[path[-1]] = value

    return apply


R0 = ["motion", "routes", 0]
ROUTE_CASES = [
    (_route_set(["require_visible"], "some"), "require_visible", "expected one of"),
    (_route_set(["motion", "kind"], "teleport"), "motion.kind", "expected one of"),
    (_route_set(["motion", "kind"], "constant"), "motion.radius", 'needs "kind": "route"'),
    (_route_set(["motion", "speed"], [0.0, 5.0]), "motion.speed", "> 0"),
    (_route_set(["motion", "radius"], [12.0, 6.0]), "motion.radius", "min <= max"),
    (_route_set(["motion", "from"], ["west", "up"]), "motion.from[1]", "expected one of"),
    (_route_set(["motion", "turn"], []), "motion.turn", "non-empty list"),
    (_route_set(["motion", "stop_probability"], 1.5), "motion.stop_probability", "<= 1"),
    (_route_set(["motion", "scene_radius"], 0), "motion.scene_radius", "> 0"),
    (_route_set(["motion", "routes"], {"from": "west"}), "motion.routes", "list of routes"),
    (_route_set(["motion", "teleport"], 1), "motion.teleport", "unknown key"),
    (_route_set(R0 + ["from"], "sky"), "motion.routes[0].from", "expected one of"),
    (_route_set(R0 + ["turn"], "u-turn"), "motion.routes[0].turn", "expected one of"),
    (_route_set(R0 + ["radius"], 0.5), "motion.routes[0].radius", ">= 2"),
    (_route_set(R0 + ["speed"], 0.0), "motion.routes[0].speed", "> 0"),
    (_route_set(R0 + ["stop"], "yes"), "motion.routes[0].stop", "true or false"),
    (_route_set(R0 + ["stop_time"], 1.0), "motion.routes[0].stop_time", "at most one"),
    (_route_set(["motion", "routes", 2, "stop"], False), "motion.routes[2].stop_time", "stop: false"),
    (_route_set(R0 + ["decel"], -2.0), "motion.routes[0].decel", "> 0"),
    (_route_set(R0 + ["vehicle"], "tractor"), "motion.routes[0].vehicle", "unknown name 'tractor'"),
    (_route_set(R0 + ["stops"], []), "motion.routes[0].stops", 'only with "path"'),
    (_route_set(R0 + ["wings"], 2), "motion.routes[0].wings", "unknown key"),
    (_route_set(R0 + ["path"], {"start": [0, 0, 0], "segments": [{"straight": 5}]}), "motion.routes[0].from",
     'not with "path"'),
    (_route_set(["vehicles_per_frame"], 2), "motion.routes", "at most one route per vehicle"),
]
PATH = {"start": [0.0, -5.0, 0.0], "segments": [{"straight": 10.0}, {"arc_deg": 180.0, "radius": 5.0},
                                                  {"straight": 10.0}, {"arc_deg": 180.0, "radius": 5.0}], "loop": True}
PATH_CASES = [
    ({"path": {**PATH, "loop": "yes"}}, "motion.routes[0].path.loop", "true or false"),
    ({"path": {**PATH, "segments": []}}, "motion.routes[0].path.segments", "non-empty"),
    ({"path": {**PATH, "segments": PATH["segments"][:2]}}, "motion.routes[0].path", "does not close"),
    ({"path": {**PATH, "segments": [{"straight": -1.0}]}}, "motion.routes[0].path.segments[0].straight", "> 0"),
    ({"path": {**PATH, "segments": [{"arc_deg": 0.0, "radius": 5.0}]}}, "motion.routes[0].path.segments[0].arc_deg",
     "non-zero"),
    ({"path": {**PATH, "segments": [{"arc_deg": 90.0}]}}, "motion.routes[0].path.segments[0].radius", "missing"),
    ({"path": {**PATH, "start": [0, 0]}}, "motion.routes[0].path.start", "list of 3 numbers"),
    ({"path": PATH, "stops": [{"at": 5.0}, {"at": 4.0}]}, "motion.routes[0].stops[1].at", "increasing"),
    ({"path": PATH, "stops": [{"at": 5.0, "wait": -1}]}, "motion.routes[0].stops[0].wait", ">= 0"),
    ({"path": PATH, "speed": 4.0, "start_speed": 5.0}, "motion.routes[0].start_speed", "at most the cruise speed"),
    ({"path": PATH, "turn": "left"}, "motion.routes[0].turn", 'not with "path"'),
]


@pytest.mark.parametrize("mutate, field, problem", ROUTE_CASES, ids=[c[1] + ":" + c[2] for c in ROUTE_CASES])
def test_route_validation_errors_name_the_field(route_data, mutate, field, problem):
    data = copy.deepcopy(route_data)
    mutate(data)
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(data)
    assert info.value.field == field
    assert problem in info.value.problem


@pytest.mark.parametrize("route, field, problem", PATH_CASES, ids=[c[1] + ":" + c[2] for c in PATH_CASES])
def test_path_validation_errors_name_the_field(route_data, route, field, problem):
    data = copy.deepcopy(route_data)
    data["motion"]["routes"][0] = route
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(data)
    assert info.value.field == field
    assert problem in info.value.problem


def test_constant_motion_truth_has_speed_and_yaw_rate():
    sim = simulate("intersection_2cam_track", num_frames=4)
    v = sim.truth[0]["v1"]
    assert v.speed is not None and 3.0 <= v.speed <= 8.0 and abs(v.yaw_rate) <= math.radians(10.0)
    assert v.acceleration == 0.0 and sim.trajectories == {}
    assert simulate("intersection_2cam", num_frames=1).truth[0]["v1"].speed is None


def test_a_shorter_route_run_is_a_prefix_of_a_longer_one(tracks):
    short = simulate("tracks_3veh", num_frames=12)
    for f in range(12):
        assert list(short.truth[f]) == list(tracks.truth[f])
        for vid, v in short.truth[f].items():
            np.testing.assert_array_equal(v.world_T_vehicle.matrix(), tracks.truth[f][vid].world_T_vehicle.matrix())
        for a, b in zip(short.scene.frames[f].detections, tracks.scene.frames[f].detections, strict=True):
            np.testing.assert_array_equal(a.keypoints, b.keypoints)
