"""The association test scenes (graphs/association_*.json) and the anonymiser (vfactor.sim.anonymise)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from vfactor.association_metrics import clear_mot, cross_camera_pairs, truth_positions
from vfactor.evaluation import body_type_of
from vfactor.observations import UNASSIGNED
from vfactor.scene import load_scene
from vfactor.sim import anonymise, load_scenario, load_truth_ids, self_occluded, simulate, write_anonymised

# The files of this checkout (an installed vfactor.graphs may be another checkout's).
GRAPHS = Path(__file__).resolve().parents[2] / "graphs"


@pytest.fixture(scope="module")
def sim4():
    return simulate(load_scenario(GRAPHS / "association_4cam.json"))


@pytest.fixture(scope="module")
def sim3():
    return simulate(load_scenario(GRAPHS / "association_3cam.json"))


def seen_per_frame(sim) -> list[set[str]]:
    """Per frame, the vehicles with at least one detection."""
    return [{d.vehicle for d in frame.detections} for frame in sim.scene.frames]


def longest_run(flags) -> int:
    best = run = 0
    for flag in flags:
        run = run + 1 if flag else 0
        best = max(best, run)
    return best


def in_camera(sim, camera: str) -> list[set[str]]:
    return [{d.vehicle for d in frame.detections if d.camera == camera} for frame in sim.scene.frames]


def binomial_ok(count: int, n: int, p: float, sigmas: float = 4.0) -> bool:
    return abs(count - n * p) <= sigmas * math.sqrt(n * p * (1 - p)) + 1


# --- the scenarios ---------------------------------------------------------------------------------------------

def test_association_4cam_is_a_busy_intersection_seen_from_four_corners(sim4):
    cams = sim4.scene.cameras
    assert len(cams) == 4 and all(c.image_size == (1280, 720) for c in cams.values())
    corners = {(np.sign(c.center[0]), np.sign(c.center[1])) for c in cams.values()}
    assert corners == {(-1, -1), (1, -1), (1, 1), (-1, 1)}
    seen = seen_per_frame(sim4)
    assert 40 <= len(seen) <= 60
    counts = [len(s) for s in seen]
    assert max(counts) <= 12 and longest_run([c >= 8 for c in counts]) == len(counts)
    last = len(seen) - 1
    first_seen = {v: min(f for f, s in enumerate(seen) if v in s) for v in set().union(*seen)}
    last_seen = {v: max(f for f, s in enumerate(seen) if v in s) for v in set().union(*seen)}
    assert sum(f > 0 for f in first_seen.values()) >= 4  # entering
    assert sum(f < last for f in last_seen.values()) >= 4  # leaving
    types = {body_type_of(v.preset) for frame in sim4.truth for v in frame.values()}
    assert {"sedan", "hatchback", "suv", "pickup", "van"} <= types


def test_association_4cam_has_parallel_lanes_close_following_and_turns(sim4):
    states = {vid: tr.states(np.arange(len(sim4.truth)) * sim4.scenario.dt) for vid, tr in sim4.trajectories.items()}
    eastbound = [v for v, st in states.items() if np.all(np.abs(np.cos(st.yaw) - 1) < 1e-6)]
    lanes = {round(float(states[v].y[0]), 2) for v in eastbound}
    assert {-1.75, -5.25} <= lanes  # two eastbound lanes 3.5 m apart
    # close following: in the inner lane, consecutive vehicles 1.5 to 2 s apart (the first gap 2.1 s)
    inner = sorted((sim4.trajectories[v].info["centre_time"], v) for v in eastbound
                   if sim4.trajectories[v].info.get("kind") == "intersection")
    gaps = np.diff([t for t, _ in inner])
    assert np.sum((gaps >= 1.5) & (gaps <= 2.0)) >= 2 and np.all(gaps <= 2.2)
    turns = [v for v, tr in sim4.trajectories.items() if tr.info.get("turn") in ("left", "right")
             or len(tr.path.segments) > 1]
    assert len(turns) >= 3
    assert any(np.all(st.speed[st.exists] < 1e-6) for st in states.values())  # at rest in a queue


def test_association_4cam_vehicles_hide_each_other(sim4):
    cams = sim4.scene.cameras
    hidden_by_others = 0
    for f in range(0, len(sim4.truth), 10):
        for (camera, vid), label in sim4.detection_truth[f].items():
            v = sim4.truth[f][vid]
            own = self_occluded(cams[camera], v.wireframe, v.world_T_vehicle, v.wheel_radius)
            hidden_by_others += int(np.sum(label.occluded & ~own))
    assert hidden_by_others > 20


def test_association_3cam_queues_side_by_side(sim3):
    assert len(sim3.scene.cameras) == 3
    seen = seen_per_frame(sim3)
    assert len(set().union(*seen)) >= 8
    assert longest_run([len(s) >= 8 for s in seen]) >= 30
    f = len(sim3.truth) - 1
    at_rest = [v for v in sim3.truth[f].values() if v.speed < 1e-6]
    pos = np.array([v.world_T_vehicle.translation()[:2] for v in at_rest])
    side_by_side = [(i, j) for i in range(len(pos)) for j in range(i + 1, len(pos))
                    if abs(pos[i, 0] - pos[j, 0]) < 1.0 and abs(abs(pos[i, 1] - pos[j, 1]) - 3.5) < 0.1]
    assert len(at_rest) >= 5 and side_by_side


# --- the anonymiser --------------------------------------------------------------------------------------------

def test_anonymise_removes_the_ids_and_keeps_the_answer(sim4):
    anon = anonymise(sim4, seed=1)
    assert len(anon.scene.frames) == len(sim4.scene.frames) and len(anon.truth_ids) == len(anon.scene.frames)
    assert len(anon.scene.unassigned()) == sum(len(f.detections) for f in sim4.scene.frames)
    for frame, ids, original in zip(anon.scene.frames, anon.truth_ids, sim4.scene.frames):
        assert len(ids) == len(frame.detections) == len(original.detections)
        by_key = {(d.camera, d.vehicle): d for d in original.detections}
        for det, vid in zip(frame.detections, ids):
            assert det.vehicle == UNASSIGNED and det.track is not None
            source = by_key.pop((det.camera, vid))
            np.testing.assert_array_equal(det.keypoints, source.keypoints)
            np.testing.assert_array_equal(det.confidence, source.confidence)
        assert not by_key
    assert sim4.scene.frames[0].detections[0].vehicle != UNASSIGNED  # the simulation is left alone
    # the order says nothing: no frame keeps the simulation's order of cameras
    same = [[d.camera for d in a.detections] == [d.camera for d in o.detections]
            for a, o in zip(anon.scene.frames, sim4.scene.frames)]
    assert not any(same)


def test_tracks_are_stable_per_camera_and_vehicle(sim4):
    anon = anonymise(sim4, seed=2)
    for camera in sim4.scene.cameras:
        owner: dict[str, str] = {}  # track -> vehicle
        last: dict[str, str] = {}  # vehicle -> its track in the previous frame
        for frame, ids in zip(anon.scene.frames, anon.truth_ids):
            now = {vid: d.track for d, vid in zip(frame.detections, ids) if d.camera == camera}
            assert len(set(now.values())) == len(now)
            for vid, track in now.items():
                assert owner.setdefault(track, vid) == vid  # a track never passes to another vehicle
                if vid in last:
                    assert last[vid] == track
            last = now


def test_a_vehicle_that_leaves_a_view_and_comes_back_gets_a_new_track(sim4):
    # Take v2 out of cam0's view for frames 10-12 (as if it drove behind a building).
    frames = [dataclasses.replace(fr, detections=[d for d in fr.detections
                                                  if not (d.camera == "cam0" and d.vehicle == "v2" and 10 <= f <= 12)])
              for f, fr in enumerate(sim4.scene.frames)]
    assert any(d.camera == "cam0" and d.vehicle == "v2" for d in frames[9].detections + frames[13].detections)
    sim = dataclasses.replace(sim4, scene=dataclasses.replace(sim4.scene, frames=frames))
    anon = anonymise(sim, seed=0)

    def track(f):
        return next(d.track for d, v in zip(anon.scene.frames[f].detections, anon.truth_ids[f])
                    if d.camera == "cam0" and v == "v2")

    assert track(8) == track(9) and track(13) == track(14) and track(9) != track(13)
    earlier = {d.track for fr in anon.scene.frames[:13] for d in fr.detections if d.camera == "cam0"}
    assert track(13) not in earlier  # a fresh number, never used before in that camera


def test_missed_detections_keep_their_track(sim4):
    anon = anonymise(sim4, seed=3, miss_rate=0.3)
    n = sum(len(f.detections) for f in sim4.scene.frames)
    assert binomial_ok(len(anon.missed), n, 0.3)
    assert sum(len(f.detections) for f in anon.scene.frames) == n - len(anon.missed)
    dropped = set(anon.missed)
    for f, ids in enumerate(anon.truth_ids):
        kept = {(d.camera, v) for d, v in zip(anon.scene.frames[f].detections, ids)}
        assert not kept & {(c, v) for g, c, v in dropped if g == f}
    # the tracker coasts: with or without misses, a kept detection has the same track
    full = anonymise(sim4, seed=3)
    for a, b, ia, ib in zip(anon.scene.frames, full.scene.frames, anon.truth_ids, full.truth_ids):
        tracks = {(d.camera, v): d.track for d, v in zip(b.detections, ib)}
        assert all(tracks[(d.camera, v)] == d.track for d, v in zip(a.detections, ia))


def test_track_switches_happen_at_their_rate_and_swap_two_tracks(sim4):
    rate = 0.1
    anon = anonymise(sim4, seed=4, track_switch_rate=rate)
    eligible = sum(len(in_camera(sim4, c)[f] & in_camera(sim4, c)[f - 1]) >= 2
                   for c in sim4.scene.cameras for f in range(1, len(sim4.scene.frames)))
    assert anon.switches and binomial_ok(len(anon.switches), eligible, rate)
    plain = anonymise(sim4, seed=4)
    assert not plain.switches

    def tracks(a, f, camera):
        return {v: d.track for d, v in zip(a.scene.frames[f].detections, a.truth_ids[f]) if d.camera == camera}

    for s in anon.switches:
        a, b = s.vehicles
        before, after = tracks(anon, s.frame - 1, s.camera), tracks(anon, s.frame, s.camera)
        assert after[a] == before[b] and after[b] == before[a]
    # a switch between v_a and v_b: the two share the camera's view in consecutive frames
    assert all(set(s.vehicles) <= in_camera(sim4, s.camera)[s.frame - 1] for s in anon.switches)


def test_false_detections_at_their_rate_look_like_vehicles(sim4):
    rate = 0.5
    anon = anonymise(sim4, seed=5, false_rate=rate)
    frames = len(sim4.scene.frames)
    tracks_seen: dict[tuple[str, str], int] = {}
    for camera, cam in sim4.scene.cameras.items():
        false = [(f, d) for f, (fr, ids) in enumerate(zip(anon.scene.frames, anon.truth_ids))
                 for d, v in zip(fr.detections, ids) if v is None and d.camera == camera]
        assert abs(len(false) - rate * frames) <= 4 * math.sqrt(rate * frames)  # Poisson
        for f, det in false:
            seen = det.seen
            assert seen.sum() >= 6 and np.all(cam.in_image(det.keypoints[seen]))
            assert 20.0 < det.box_diagonal() < 1000.0
            tracks_seen[(camera, det.track)] = tracks_seen.get((camera, det.track), 0) + 1
    assert tracks_seen and set(tracks_seen.values()) == {1}  # a track of one detection
    real = {(d.camera, d.track) for fr, ids in zip(anon.scene.frames, anon.truth_ids)
            for d, v in zip(fr.detections, ids) if v is not None}
    assert not real & set(tracks_seen)


def test_without_tracks_and_deterministic(sim4):
    bare = anonymise(sim4, seed=6, false_rate=0.2, keep_tracks=False)
    assert all(d.track is None for fr in bare.scene.frames for d in fr.detections)
    kwargs = dict(seed=7, track_switch_rate=0.05, false_rate=0.2, miss_rate=0.1)
    one, two = anonymise(sim4, **kwargs), anonymise(sim4, **kwargs)
    assert one.truth_ids == two.truth_ids and one.switches == two.switches and one.missed == two.missed
    for a, b in zip(one.scene.frames, two.scene.frames):
        assert [(d.camera, d.track) for d in a.detections] == [(d.camera, d.track) for d in b.detections]
        for da, db in zip(a.detections, b.detections):
            np.testing.assert_array_equal(da.keypoints, db.keypoints)
    other = anonymise(sim4, **{**kwargs, "seed": 8})
    assert other.truth_ids != one.truth_ids
    with pytest.raises(ValueError, match="miss_rate"):
        anonymise(sim4, miss_rate=1.5)


def test_written_anonymised_scenes_load_as_unassigned(sim4, tmp_path):
    anon = anonymise(sim4, seed=9, false_rate=0.2, miss_rate=0.05)
    scene_path, ids_path = tmp_path / "scene.json", tmp_path / "scene_ids.json"
    write_anonymised(anon, scene_path, ids_path)
    scene = load_scene(scene_path)
    assert len(scene.unassigned()) == sum(len(f.detections) for f in anon.scene.frames)
    assert [[d.track for d in f.detections] for f in scene.frames] == \
        [[d.track for d in f.detections] for f in anon.scene.frames]
    assert load_truth_ids(ids_path) == anon.truth_ids


def test_the_truth_scores_perfectly(sim3):
    anon = anonymise(sim3, seed=0, false_rate=0.2)
    cameras = [[d.camera for d in f.detections] for f in anon.scene.frames]
    assigned = [[v for v in ids] for ids in anon.truth_ids]  # false detections left unassigned
    pairs = cross_camera_pairs(anon.truth_ids, assigned, cameras)
    assert pairs.precision == pairs.recall == 1.0 and pairs.true > 500 and pairs.false_attached == 0
    truth = truth_positions(sim3.truth)
    mot = clear_mot(truth, truth)
    assert mot["mota"] == mot["idf1"] == 1.0 and mot["num_switches"] == 0
