"""Association without shared ids: detections grouped into vehicles across cameras, linked across frames."""

from __future__ import annotations

import dataclasses
import itertools
import json

import numpy as np
import pytest

from vfactor.association import AssociationOptions, TrackLinker, associate_frame, associate_scene
from vfactor.association.linking import constant_velocity
from vfactor.association.linking import ray_distance
from vfactor.cli import main
from vfactor.errors import InputError
from vfactor.observations import UNASSIGNED, Detection, Frame
from vfactor.scene import load_results, save_scene
from vfactor.sim import load_scenario, simulate


def anonymous(scene):
    """The scene with every detection's vehicle unknown, and the true ids aside."""
    truth = [[d.vehicle for d in f.detections] for f in scene.frames]
    frames = [Frame(f.t, [dataclasses.replace(d, vehicle=UNASSIGNED) for d in f.detections], f.images)
              for f in scene.frames]
    return dataclasses.replace(scene, frames=frames), truth


def pair_counts(frames, truth):
    """(correct pairs, wrong pairs, missed pairs) over pairs of detections of different cameras."""
    tp = fp = fn = 0
    for frame, ids in zip(frames, truth):
        got = [d.vehicle for d in frame.detections]
        for i, j in itertools.combinations(range(len(ids)), 2):
            if frame.detections[i].camera == frame.detections[j].camera:
                continue
            tp += ids[i] == ids[j] and got[i] == got[j]
            fp += ids[i] != ids[j] and got[i] == got[j]
            fn += ids[i] == ids[j] and got[i] != got[j]
    return tp, fp, fn


@pytest.fixture(scope="module")
def multi():
    return simulate(load_scenario("intersection_multi"), seed=2, num_frames=3)


def test_three_vehicles_three_cameras_are_grouped_as_they_are(multi):
    scene, truth = anonymous(multi.scene)
    found = associate_scene(scene)
    tp, fp, fn = pair_counts(found.scene.frames, truth)
    assert fp == 0 and fn == 0 and tp == 27
    assert not found.scene.unassigned()
    for f, groups in enumerate(found.groups):
        assert sorted(j for g in groups.values() for j in g) == list(range(len(scene.frames[f].detections)))
        for vid, g in groups.items():
            assert len({truth[f][j] for j in g}) == 1 and len({scene.frames[f].detections[j].camera for j in g}) == len(g)


def test_a_vehicle_seen_by_one_camera_is_its_own_vehicle_and_a_far_detection_joins_nothing(multi):
    frame = multi.scene.frames[0]
    kept = [d for d in frame.detections if not (d.vehicle == "v2" and d.camera != "cam0")]
    groups = associate_frame(Frame(frame.t, kept), multi.scene.cameras)
    by_truth = sorted(sorted(kept[j].vehicle for j in g) for g in groups.groups)
    assert by_truth == [["v1"] * 3, ["v2"], ["v3"] * 3]
    alone = groups.groups[[kept[g[0]].vehicle for g in groups.groups].index("v2")]
    assert groups.results[groups.groups.index(alone)].ok  # a single view is still solved


def test_a_weak_view_joins_a_vehicle_seen_alone_and_every_detection_is_in_one_group(multi):
    """v2 seen well by cam0 only and by three keypoints in cam1: the weak view joins it, and cam0's detection is
    in that one group (it was also left as a vehicle of its own, which dropped it)."""
    frame = multi.scene.frames[0]
    strong = next(d for d in frame.detections if d.vehicle == "v2" and d.camera == "cam0")
    partial = next(d for d in frame.detections if d.vehicle == "v2" and d.camera == "cam1")
    keep = np.flatnonzero(partial.seen)[:3]
    seen = np.zeros(len(partial.seen), bool)
    seen[keep] = True
    weak = dataclasses.replace(partial, keypoints=np.where(seen[:, None], partial.keypoints, np.nan),
                               confidence=np.where(seen, partial.confidence, 0.0))
    dets = [weak] + [d for d in frame.detections if d.vehicle != "v2"] + [strong]
    groups = associate_frame(Frame(frame.t, dets), multi.scene.cameras)
    assert sorted(j for g in groups.groups for j in g) == list(range(len(dets)))
    assert [0, len(dets) - 1] in groups.groups
    assert all(r.ok for r in groups.results)


def test_a_false_detection_is_not_merged_into_a_vehicle(multi):
    """A library van's keypoints where no vehicle is, in cam1: it stays apart."""
    import gtsam

    from vfactor.vehicle_library import library_ids, library_vehicle

    frame = multi.scene.frames[1]
    camera = multi.scene.cameras["cam1"]
    van = library_vehicle(library_ids("van")[0])
    pose = gtsam.Pose3(gtsam.Rot3.Yaw(0.7), np.array([2.5, -3.0, van.wheel_radius]))
    uv, depth = camera.project(van.wireframe.in_world(pose))
    seen = (depth > 0) & camera.in_image(uv)
    ghost = Detection("cam1", UNASSIGNED, np.where(seen[:, None], uv, np.nan), np.where(seen, 0.9, 0.0))
    dets = frame.detections + [ghost]
    groups = associate_frame(Frame(frame.t, dets), multi.scene.cameras)
    assert [len(dets) - 1] in groups.groups
    assert sorted(sorted(dets[j].vehicle for j in g) for g in groups.groups if len(dets) - 1 not in g) == [
        ["v1"] * 3, ["v2"] * 3, ["v3"] * 3]


def test_linking_keeps_ids_through_a_miss_and_uses_camera_tracks():
    linker = TrackLinker(AssociationOptions())
    lanes = [np.array([0.0, 0.0]), np.array([0.0, 3.5])]
    ids0 = linker.link(0.0, lanes, [{("cam0", "7")}, {("cam0", "8")}])
    ids1 = linker.link(0.1, [lanes[1] + [1.0, 0], lanes[0] + [1.0, 0]], [set(), set()])
    assert ids1 == ids0[::-1]
    ids2 = linker.link(0.2, [lanes[0] + [2.0, 0]], [set()])  # lane 1 missed for a frame
    ids3 = linker.link(0.3, [lanes[0] + [3.0, 0], lanes[1] + [3.0, 0]], [set(), set()])
    assert ids2 == [ids0[0]] and ids3 == ids0
    far = linker.link(5.0, [np.array([100.0, 0.0])], [set()])  # after max_missed: a new track
    assert far[0] not in ids0
    # a camera track id helps where the geometry alone is ambiguous
    both = TrackLinker(AssociationOptions())
    a = both.link(0.0, [np.array([0.0, 0.0])], [{("cam1", "3")}])
    b = both.link(0.1, [np.array([1.8, 0.0]), np.array([-1.7, 0.0])], [set(), {("cam1", "3")}])
    assert b[1] == a[0]


def test_a_single_view_metres_off_along_its_ray_continues_the_track():
    """A vehicle seen by two cameras, then for a frame by one alone, its single-view position 6 m on in 0.1 s:
    along that camera's ray (a single view's depth is metres off), with the camera's track id, it continues the
    track; the same offset across the ray, without the camera's track id, or seen by two cameras, starts a new
    one."""
    options = AssociationOptions()
    gate = options.link_distance + options.max_speed * 0.1  # a track of one position: its speed unknown
    assert gate + options.track_bonus < 6.0

    def second_frame(viewpoint, tracks=frozenset({("cam0", "7")})):
        linker = TrackLinker(options)
        first = linker.link(0.0, [np.array([0.0, 0.0])], [{("cam0", "7"), ("cam1", "2")}])
        return linker.link(0.1, [np.array([6.0, 0.0])], [set(tracks)], [viewpoint])[0] == first[0]

    assert second_frame(np.array([30.0, 0.0]))  # cam0 looks along x: the 6 m are depth
    assert not second_frame(np.array([30.0, 0.0]), tracks=set())  # a detection cam0's tracker does not tie to it
    assert not second_frame(np.array([6.0, 30.0]))  # cam0 looks along y: the 6 m are across its ray
    assert not second_frame(None)  # seen by several cameras: 6 m is 6 m


def test_a_track_that_may_be_a_false_detection_s_continues_only_with_its_camera_track():
    """A vehicle seen by one camera only (to the linker, maybe a false detection) and 0.3 s later a vehicle of two
    cameras 5 m from it, inside a one-position track's wide gate: whose camera track ids are all others' it starts
    a track of its own (association_4cam seed 7: a false detection's track took over a van entering the view);
    with the view's camera track id, without camera track ids on either side, or where the first position was
    seen by two cameras, it continues the track."""
    options = AssociationOptions()
    assert 5.0 < options.link_distance + options.max_speed * 0.3

    def continued(first_tracks, later_tracks, first_viewpoint=np.array([-30.0, 0.0])):
        linker = TrackLinker(options)
        (first,) = linker.link(0.0, [np.array([0.0, 0.0])], [set(first_tracks)], [first_viewpoint])
        (later,) = linker.link(0.3, [np.array([0.0, -5.0])], [set(later_tracks)])
        return later == first

    assert not continued({("cam1", "18")}, {("cam1", "21"), ("cam2", "23")})
    assert not continued({("cam1", "18")}, {("cam2", "23")})
    assert continued({("cam1", "18")}, {("cam1", "18"), ("cam2", "23")})
    assert continued(set(), set())
    assert continued({("cam1", "18")}, {("cam1", "21"), ("cam2", "23")}, first_viewpoint=None)


def test_ray_distance_shortens_the_offset_along_the_ray_only():
    options = AssociationOptions(link_distance=2.0, single_view_depth=0.1)
    position, viewpoint = np.array([0.0, 20.0]), np.array([0.0, 0.0])  # 20 m from the camera: along-ray x 0.5
    assert ray_distance(np.array([0.0, 3.0]), position, viewpoint, options) == pytest.approx(1.5)
    assert ray_distance(np.array([3.0, 0.0]), position, viewpoint, options) == pytest.approx(3.0)
    assert ray_distance(np.array([3.0, 4.0]), position, viewpoint, options) == pytest.approx(np.hypot(3.0, 2.0))
    assert ray_distance(np.array([3.0, 4.0]), position, None, options) == pytest.approx(5.0)


def test_ids_made_never_clash_with_the_scene_s(multi):
    linker = TrackLinker(AssociationOptions(), taken={"t1", "t2"})
    assert linker.link(0.0, [np.zeros(2), np.ones(2) * 10], [set(), set()]) == ["t3", "t4"]


def test_bad_options_are_named():
    with pytest.raises(InputError) as info:
        AssociationOptions(gate_cost=-1.0)
    assert info.value.field == "AssociationOptions.gate_cost"
    with pytest.raises(InputError) as info:
        AssociationOptions(quick_gate=float("nan"))
    assert info.value.field == "AssociationOptions.quick_gate"
    with pytest.raises(InputError) as info:
        AssociationOptions(slide_gate=-1.0)
    assert info.value.field == "AssociationOptions.slide_gate"


def test_a_pair_the_quick_solve_refuses_is_the_full_test_s_refusal_too(multi, monkeypatch):
    """The quick solve (``quick_gate``) refuses pairs of different vehicles without their full joint solve, and
    refuses none that the full test finds compatible: the same groups as testing every pair in full."""
    import vfactor.association.cross_camera as cross_camera

    solved = []
    solve = cross_camera.solve_observations
    monkeypatch.setattr(cross_camera, "solve_observations",
                        lambda obs, options, name, *args, **kwargs: solved.append(name) or
                        solve(obs, options, name, *args, **kwargs))
    frame, truth = multi.scene.frames[0], [d.vehicle for d in multi.scene.frames[0].detections]
    anonymous_frame = Frame(frame.t, [dataclasses.replace(d, vehicle=UNASSIGNED) for d in frame.detections])
    full = associate_frame(anonymous_frame, multi.scene.cameras, AssociationOptions(quick_gate=0.0, slide_gate=0.0))
    solved.clear()
    quick = associate_frame(anonymous_frame, multi.scene.cameras, AssociationOptions(slide_gate=0.0))
    assert quick.groups == full.groups and set(quick.pairs) == set(full.pairs)
    refused = [(i, j) for i, j in quick.pairs if f"d{i}+d{j}" not in solved]  # the quick solve's refusals
    assert refused and solved.count("quick") == len(quick.pairs)
    assert all(not quick.pairs[pair][0] and quick.pairs[pair][1] > 3.0 for pair in refused)
    assert all(truth[i] != truth[j] and not full.pairs[(i, j)][0] for i, j in refused)
    assert all(quick.pairs[pair] == full.pairs[pair] for pair in quick.pairs if pair not in refused)


def test_a_pair_the_slid_views_refuse_is_the_quick_test_s_refusal_too(monkeypatch):
    """The single views slid along their rays (``slide_gate``) refuse pairs of different vehicles without a quick
    solve, and none that the quick and full tests find compatible: ten vehicles in a frame give the same groups
    and the same compatible pairs with them as without them."""
    import vfactor.association.cross_camera as cross_camera

    base = load_scenario("intersection_multi")
    dense = dataclasses.replace(base, vehicles_per_frame=10, region=((-8.7, 8.7), (-8.7, 8.7)), require_visible="any",
                                min_gap=0.5)
    sim = simulate(dense, seed=3, num_frames=1)
    frame, truth = sim.scene.frames[0], [d.vehicle for d in sim.scene.frames[0].detections]
    anonymous_frame = Frame(frame.t, [dataclasses.replace(d, vehicle=UNASSIGNED) for d in frame.detections])
    solved = []
    solve = cross_camera.solve_observations
    monkeypatch.setattr(cross_camera, "solve_observations",
                        lambda obs, options, name, *args, **kwargs: solved.append(name) or
                        solve(obs, options, name, *args, **kwargs))
    without = associate_frame(anonymous_frame, sim.scene.cameras, AssociationOptions(slide_gate=0.0))
    quick_without = solved.count("quick")
    solved.clear()
    slid = associate_frame(anonymous_frame, sim.scene.cameras, AssociationOptions())
    assert slid.groups == without.groups and set(slid.pairs) == set(without.pairs)
    refused = [pair for pair in slid.pairs if slid.pairs[pair] != without.pairs[pair]]  # the slid views' refusals
    assert refused and solved.count("quick") == quick_without - len(refused)
    assert all(not slid.pairs[pair][0] and slid.pairs[pair][1] > 10.0 for pair in refused)
    assert all(truth[i] != truth[j] and not without.pairs[(i, j)][0] for i, j in refused)
    assert sorted(map(sorted, slid.groups)) == sorted(
        sorted(i for i, v in enumerate(truth) if v == vehicle) for vehicle in set(truth) if vehicle is not None)


def test_slid_single_views_score_a_pair_cheaply(multi):
    """``_slid_rise``: one vehicle's two views slide to a small rise, two vehicles' far apart to one beyond the slide
    gate, and a cost that is not a number leaves the pair to the quick solve (-inf: never refused)."""
    import math

    import vfactor.association.cross_camera as cross_camera

    frame, cameras, options = multi.scene.frames[0], multi.scene.cameras, AssociationOptions()
    det = frame.detections
    seen = {k: int(d.seen.sum()) for k, d in enumerate(det)}
    alone = {k: cross_camera._solve([d], cameras, options, f"d{k}") for k, d in enumerate(det)}
    own = {k: cross_camera._observations(d, cameras, options) for k, d in enumerate(det)}
    baseline = {k: cross_camera._cost(own[k], alone[k], options) for k in alone}
    pairs = [(i, j) for i, j in itertools.combinations(range(len(det)), 2) if det[i].camera != det[j].camera]
    same = [p for p in pairs if det[p[0]].vehicle == det[p[1]].vehicle]
    other = [p for p in pairs if det[p[0]].vehicle != det[p[1]].vehicle]
    gate = {(i, j): options.gate_cost if min(seen[i], seen[j]) >= options.strong_keypoints else options.gate_cost_weak
            for i, j in pairs}
    score = {p: cross_camera._slid_rise(p, det, cameras, alone, own, baseline, seen, options) / gate[p] for p in pairs}
    assert same and other and all(alone[k].ok for k in alone)
    assert max(score[p] for p in same) < 0.5 * options.slide_gate  # one vehicle: a slide fits both views
    assert max(score[p] for p in other) > options.slide_gate  # another vehicle far off: none does
    i, j = same[0]
    own[j] = own[j]._with(uv=np.full_like(own[j].uv, np.nan))
    assert cross_camera._slid_rise((i, j), det, cameras, alone, own, baseline, seen, options) == -math.inf


def test_solve_and_track_associate_scenes_without_ids(tmp_path, multi, capsys):
    scene, truth = anonymous(multi.scene)
    for frame in scene.frames:  # the cameras' own track ids, as a 2D tracker would give them
        for d in frame.detections:
            d.track = None
    path = tmp_path / "scene.json"
    save_scene(scene, path)
    data = json.loads(path.read_text())
    assert all("vehicle" not in d for f in data["frames"] for d in f["detections"])
    for command in ("solve", "track"):
        out = tmp_path / f"{command}.json"
        assert main([command, str(path), "--out", str(out), "--no-covariance"]) == 0
        assert "associated 27 detections into 9 vehicles" in capsys.readouterr().out
        results = load_results(out)
        for f, frame in enumerate(results):
            for v in frame.vehicles:
                assert v.ok and len({truth[f][j] for j in v.extras["detections"]}) == 1
        json.loads(out.read_text())  # written


def test_associate_option_checks_given_ids(tmp_path, capsys):
    """intersection_multi re-draws its vehicles each frame under v1-v3: with --associate the ids are made anew."""
    sim = simulate(load_scenario("intersection_multi"), seed=0, num_frames=3)
    path = tmp_path / "scene.json"
    save_scene(sim.scene, path)
    assert main(["track", str(path), "--out", str(tmp_path / "r.json"), "--associate", "--no-covariance", "-q"]) == 0
    results = load_results(tmp_path / "r.json")
    ids = {v.id for f in results for v in f.vehicles}
    assert ids.isdisjoint({"v1", "v2", "v3"}) and len(ids) >= 3
    for f, frame in enumerate(results):
        for v in frame.vehicles:
            assert len({sim.scene.frames[f].detections[j].vehicle for j in v.extras["detections"]}) == 1


def test_associate_never_makes_an_id_the_scene_gives(tmp_path, capsys):
    """With --associate the scene's ids are ignored, not freed: a made id that a given one also names would mean two
    vehicles to a reader (the scene's own t1-t3 came out on other vehicles)."""
    sim = simulate(load_scenario("intersection_multi"), seed=0, num_frames=3)
    renamed = {"v1": "t3", "v2": "t1", "v3": "t2"}
    frames = [dataclasses.replace(f, detections=[dataclasses.replace(d, vehicle=renamed[d.vehicle])
                                                 for d in f.detections]) for f in sim.scene.frames]
    path = tmp_path / "scene.json"
    save_scene(dataclasses.replace(sim.scene, frames=frames), path)
    assert main(["track", str(path), "--out", str(tmp_path / "r.json"), "--associate", "--no-covariance", "-q"]) == 0
    ids = {v.id for f in load_results(tmp_path / "r.json") for v in f.vehicles}
    assert ids.isdisjoint(renamed.values()) and len(ids) >= 3, ids


def test_a_flicker_is_left_out_and_said_so_and_results_point_at_the_detections_given(multi):
    """A van's keypoints in one camera for one frame only (a false detection): left out, not a vehicle."""
    import gtsam

    from vfactor.solve import SolveOptions, solve_scene
    from vfactor.vehicle_library import library_ids, library_vehicle

    scene, truth = anonymous(multi.scene)
    camera = scene.cameras["cam1"]
    van = library_vehicle(library_ids("van")[0])
    pose = gtsam.Pose3(gtsam.Rot3.Yaw(0.7), np.array([2.5, -3.0, van.wheel_radius]))
    uv, depth = camera.project(van.wireframe.in_world(pose))
    seen = (depth > 0) & camera.in_image(uv)
    ghost = Detection("cam1", UNASSIGNED, np.where(seen[:, None], uv, np.nan), np.where(seen, 0.9, 0.0))
    scene.frames[1].detections.insert(0, ghost)
    truth[1].insert(0, None)
    found = associate_scene(scene)
    assert [(f, j) for f, j, _ in found.left_out] == [(1, 0)]
    assert "a flicker of the detector" in found.left_out[0][2]
    assert len(found.scene.frames[1].detections) == len(scene.frames[1].detections) - 1
    results = solve_scene(found.scene, SolveOptions(covariance=False))
    found.restore_indices(results)
    for f, frame in enumerate(results):
        for v in frame.vehicles:
            assert None not in {truth[f][j] for j in v.extras["detections"]}
            assert len({truth[f][j] for j in v.extras["detections"]}) == 1


def test_a_single_view_position_weighs_little_in_a_track_s_velocity():
    """A track seen by two cameras moving at 10 m/s along x; one frame seen by one camera, 1.8 m off in depth:
    the next prediction stays near the true line (a two-point velocity would put it 3.5 m astray)."""
    linker = TrackLinker(AssociationOptions())
    for k in range(4):
        (vid,) = linker.link(0.1 * k, [np.array([1.0 * k, 0.0])], [set()])
    camera = np.array([4.0 + 1.2 * 10, 1.35 * 10])  # its single view's depth is 1.8 m off, along this camera's ray
    assert linker.link(0.4, [np.array([4.0 + 1.2, 1.35])], [set()], [camera]) == [vid]  # within the gate
    predicted = linker.tracks[0].predict(0.5)
    assert np.linalg.norm(predicted - [5.0, 0.0]) < 1.0, predicted


def test_a_track_of_a_two_camera_position_and_a_single_view_takes_no_velocity_from_the_single_view():
    """Two positions define a velocity exactly, whatever their weights: a vehicle seen by two cameras, then by one
    whose position is 7.6 m on along its ray, predicted a 73 m/s vehicle (association_3cam at hard noise, seed 6),
    and the next, accurate two-camera position fell outside the track's gate. The single view waits for more
    positions; until then the track's speed is unknown, its gate that of a track of one position."""
    options = AssociationOptions()
    linker = TrackLinker(options)
    camera = np.array([-1.76 + 3.63 * 10, 17.08 + 6.67 * 10])  # the single view's error lies along this camera's ray
    tracks = {("cam0", "3"), ("cam1", "5")}
    (vid,) = linker.link(0.1, [np.array([-1.76, 17.08])], [tracks])
    assert linker.link(0.2, [np.array([1.87, 23.75])], [{("cam1", "5")}], [camera]) == [vid]
    track = linker.tracks[0]
    np.testing.assert_allclose(track.predict(0.3), [-1.76, 17.08])  # was (9.14, 37.1)
    assert track.gate(0.3, options) == pytest.approx(options.link_distance + options.max_speed * 0.2)
    assert linker.link(0.3, [np.array([-1.75, 14.97])], [tracks]) == [vid]  # 2.1 m in 0.2 s: the same vehicle
    # with a third position the weights decide: the single view weighs single_view_weight
    position, velocity = constant_velocity(np.array(track.times), np.array(track.positions), np.array(track.weights))
    np.testing.assert_allclose(track.predict(0.4), position + 0.1 * velocity)  # all three in the fit, weighted


def test_a_wrong_best_pair_gives_its_views_back_to_the_vehicles_they_agree_with():
    """Two vehicles side by side: the best-scoring pair (7, 12) is wrong and the greedy merging took it first,
    keeping 12 out of the vehicle of 10 and 16 (both agree with it) and 7 away from 1. The moves put them back."""
    from vfactor.association.cross_camera import _improve

    camera = {1: "cam0", 7: "cam2", 10: "cam0", 12: "cam1", 16: "cam2"}
    pairs = {(7, 12): (True, 0.10), (10, 16): (True, 0.30), (10, 12): (True, 0.33), (12, 16): (True, 0.18),
             (1, 7): (True, 0.33), (1, 12): (False, 3.0), (7, 10): (False, 2.0), (1, 16): (False, 4.0)}
    members = {7: [7, 12], 10: [10, 16], 1: [1]}
    group_of = {k: g for g, group in members.items() for k in group}
    _improve(members, group_of, pairs, camera)
    assert sorted(members.values()) == [[1, 7], [10, 12, 16]]
    assert all(k in members[group_of[k]] for k in camera)



def test_a_view_entering_a_camera_joins_the_vehicle_its_camera_track_joins_later():
    """tracks_3cam, frames 13-16: in frame 13 cam0's first view of v1 is two keypoints, 20 sigmas off (a
    vehicle entering the view, which the second pass alone refuses); from frame 14 cam0's tracker follows it
    under the same track id, seen well, and that view joins v1. The first view then joins v1 too, through its
    camera track (associated in time order, frame 13 had no earlier track to go by); without track ids it is
    left out."""
    sim = simulate(load_scenario("tracks_3cam"), seed=0, num_frames=30)
    first = next(j for j, d in enumerate(sim.scene.frames[13].detections) if d.vehicle == "v1" and d.camera == "cam0")

    def scene_with(tracked: bool):
        frames = []
        for f in range(13, 17):
            dets = list(sim.scene.frames[f].detections)
            if f == 13:
                d = dets[first]
                seen = np.zeros(len(d.seen), bool)
                seen[np.flatnonzero(d.seen)[[0, -1]]] = True
                sigma = 0.03 * float(np.linalg.norm(np.ptp(d.keypoints[seen], axis=0)))
                dets[first] = dataclasses.replace(d, keypoints=np.where(seen[:, None], d.keypoints + 20 * sigma, np.nan),
                                                  confidence=np.where(seen, 1.0, 0.0))
            dets = [dataclasses.replace(d, vehicle=UNASSIGNED, track=f"{d.camera}:{d.vehicle}" if tracked else None)
                    for d in dets]
            frames.append(Frame(sim.scene.frames[f].t, dets, sim.scene.frames[f].images))
        return dataclasses.replace(sim.scene, frames=frames)

    truth = [[d.vehicle for d in sim.scene.frames[f].detections] for f in range(13, 17)]
    tracked = associate_scene(scene_with(True))
    assert pair_counts(tracked.scene.frames[:1], [[v for k, v in enumerate(truth[0]) if k in tracked.kept[0]]]) == (9, 0, 0)
    assert [sorted(truth[0][j] for j in g) for g in tracked.groups[0].values() if first in g] == [["v1"] * 3]
    without = associate_scene(scene_with(False))
    assert (0, first, "too few keypoints to associate or to solve alone") in without.left_out


def test_camera_tracks_favour_their_pairs_but_never_make_a_pair_the_geometry_refuses():
    """tracks_3cam frame 14 (three vehicles, three cameras). Hints from the cameras' tracks take ``hint_bonus``
    off the scores of the pairs they support and leave the others; hints that cross two vehicles (v1's cam0
    view and v2's cam1 view said to be one) change no group: the crossed pair fails its gate."""
    sim = simulate(load_scenario("tracks_3cam"), seed=0, num_frames=30)
    frame = sim.scene.frames[14]
    truth = [d.vehicle for d in frame.detections]
    plain = associate_frame(frame, sim.scene.cameras)
    right = associate_frame(frame, sim.scene.cameras, hints={j: v for j, v in enumerate(truth)})
    bonus = AssociationOptions().hint_bonus
    assert right.pairs.keys() == plain.pairs.keys() and len(plain.pairs) > 0
    for (i, j), (ok, score) in plain.pairs.items():
        assert right.pairs[(i, j)][0] == ok
        assert right.pairs[(i, j)][1] == pytest.approx(score - bonus if truth[i] == truth[j] else score)
    a = next(j for j, d in enumerate(frame.detections) if d.vehicle == "v1" and d.camera == "cam0")
    b = next(j for j, d in enumerate(frame.detections) if d.vehicle == "v2" and d.camera == "cam1")
    crossed = associate_frame(frame, sim.scene.cameras, hints={a: "x", b: "x"})
    assert not crossed.pairs.get((min(a, b), max(a, b)), (False, 0))[0]
    assert sorted(crossed.groups) == sorted(plain.groups)
    assert all(len({truth[j] for j in g}) == 1 for g in plain.groups + right.groups)


def test_a_vehicle_seen_in_two_halves_is_merged_and_two_vehicles_are_not():
    """association_4cam seed 6, frame 38: v12, seen by four cameras, given as two pairs of views (as the
    association left it in frames 37-39 before this step) is merged into one vehicle of four views; v12's half
    and another vehicle's pair are left apart even with the distance gate opened wide: the joint solve's
    rises refuse them."""
    from vfactor.association.cross_camera import _merge_split_vehicles, _observations, _solve

    sim = simulate(load_scenario("association_4cam"), seed=6, num_frames=60)
    frame = sim.scene.frames[38]
    det = frame.detections
    options = AssociationOptions()
    views = {d.camera: j for j, d in enumerate(det) if d.vehicle == "v12"}
    assert sorted(views) == ["cam0", "cam1", "cam2", "cam3"]
    halves = [sorted([views["cam1"], views["cam3"]]), sorted([views["cam0"], views["cam2"]])]
    own = {j: _observations(det[j], sim.scene.cameras, options) for j in range(len(det))}
    groups = [list(g) for g in halves]
    results = [_solve([det[m] for m in g], sim.scene.cameras, options, "half") for g in groups]
    assert all(r.ok for r in results)
    _merge_split_vehicles(det, own, groups, results, sim.scene.cameras, options)
    assert groups == [sorted(views.values())] and results[0].ok

    other = next(v for v in sorted({d.vehicle for d in det} - {"v12"})
                 if {"cam0", "cam2"} <= {d.camera for d in det if d.vehicle == v})
    pair = sorted(j for j, d in enumerate(det) if d.vehicle == other and d.camera in ("cam0", "cam2"))
    groups = [list(halves[0]), pair]
    results = [_solve([det[m] for m in g], sim.scene.cameras, options, "g") for g in groups]
    assert all(r.ok for r in results)
    _merge_split_vehicles(det, own, groups, results, sim.scene.cameras,
                          dataclasses.replace(options, link_distance=1000.0))
    assert groups == [halves[0], pair]


def test_every_detection_left_out_is_named_at_verbose():
    from vfactor.cli.estimate import left_out_lines

    lines = left_out_lines([(f, 0, "flicker") for f in range(7)] + [(3, 2, "crowd")])
    assert lines[0][0].endswith("frames[4].detections[0], ... (every one with -v)") and "frames[6]" in lines[0][1]
    assert lines[1] == ("left out 1 detections: crowd: frames[3].detections[2]", "")


def test_the_scene_s_road_plane_keeps_a_bus_seen_by_one_camera_on_its_track():
    """association_3cam_bus seed 0, frames 15-22, the two buses alone: the southbound bus (v10) leaves the other
    cameras' views in frame 18 and cam1 alone sees it; the northbound one (v9) comes into cam1's view alone. One
    camera's keypoints of a bus fit a van about 14 m nearer that camera and 2.7 m above the road as well, unless
    the solves hold it to the scene's road plane: then each bus keeps one id while cam1's tracker follows it."""
    sim = simulate(load_scenario("association_3cam_bus"), seed=0)
    frames = []
    for f in range(15, 23):
        dets = [dataclasses.replace(d, vehicle=UNASSIGNED, track=f"{d.camera}:{d.vehicle}")
                for d in sim.scene.frames[f].detections if d.vehicle in ("v9", "v10")]
        frames.append(Frame(sim.scene.frames[f].t, dets))
    scene = dataclasses.replace(sim.scene, frames=frames)
    assert scene.ground_plane is not None
    found = associate_scene(scene)
    for bus in ("v9", "v10"):
        ids = {found.scene.frames[n].detections[i].vehicle for n, kept in enumerate(found.kept)
               for i, j in enumerate(kept) if frames[n].detections[j].track.endswith(f":{bus}")}
        assert len(ids) == 1, (bus, ids)
    single = sum(len(g) == 1 for groups in found.groups for g in groups.values())
    assert single >= 8  # the buses were seen by one camera alone in many of these frames


def test_the_association_s_solves_weigh_the_detectors_classes(multi):
    """The association solved each group without the 2D detector's classes (``"class"``) that a one-frame solve
    weighs the body types by (a detector's ``bus`` was dropped there): each group's solve now has the posterior
    that ``solve_vehicle`` of the same detections has."""
    from vfactor.solve import SolveOptions, solve_vehicle

    frame = multi.scene.frames[0]
    classed = Frame(frame.t, [dataclasses.replace(d, vehicle=UNASSIGNED, vehicle_class="truck")
                              for d in frame.detections])
    found = associate_frame(classed, multi.scene.cameras)
    assert len(found.groups) == 3
    for group, result in zip(found.groups, found.results):
        alone = solve_vehicle([classed.detections[j] for j in group], multi.scene.cameras,
                              SolveOptions(covariance=False))
        assert result.body_type == alone.body_type
        assert result.body_type_probability == pytest.approx(alone.body_type_probability, abs=0.05)
    plain = associate_frame(Frame(frame.t, [dataclasses.replace(d, vehicle=UNASSIGNED) for d in frame.detections]),
                            multi.scene.cameras)
    def suggested(result):  # what a detector's "truck" suggests
        return result.extras["body_type_posterior"]["pickup"] + result.extras["body_type_posterior"]["van"]

    assert all(suggested(a) >= suggested(b) for a, b in zip(found.results, plain.results))
    assert max(suggested(a) - suggested(b) for a, b in zip(found.results, plain.results)) > 0.01
