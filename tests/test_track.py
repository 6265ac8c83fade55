"""Tracking over frames: iSAM2 against frame-by-frame and batch, fixed lag, and awkward input."""

from __future__ import annotations

import copy
import dataclasses

import gtsam
import numpy as np
import pytest

from vfactor.errors import InputError
from vfactor.graph import observations_from_detections
from vfactor.metrics import pose_errors
from vfactor.observations import Detection, Frame, Scene
from vfactor.result import Status
from vfactor.sim import load_scenario, simulate
from vfactor.sim.noise import NoiseModel
from vfactor.shape_model import default_shape_prior
from vfactor.solve import SolveOptions, solve_scene
from vfactor.track import TrackOptions, Tracker, smooth_scene, track_scene
from vfactor.vehicle_library import BODY_TYPES


@pytest.fixture(scope="module")
def sim():
    return simulate(load_scenario("intersection_2cam_track"), seed=1)


@pytest.fixture(scope="module")
def tracked(sim):
    return track_scene(sim.scene)


def mean_errors(sim, frames):
    rows = []
    for f, frame in enumerate(frames):
        for v in frame.vehicles:
            if v.ok:
                truth = sim.truth[f][v.id]
                e = pose_errors(v.world_T_vehicle, v.keypoints_world, truth.world_T_vehicle, truth.keypoints_world)
                rows.append((e["rotation_deg"], e["translation_cm"]))
    return np.mean(rows, axis=0), len(rows)


def test_tracking_halves_frame_by_frame_errors(sim, tracked):
    (rot_t, trans_t), n_t = mean_errors(sim, tracked.frames)
    (rot_f, trans_f), n_f = mean_errors(sim, solve_scene(sim.scene))
    assert n_t == n_f == len(sim.scene.frames)
    assert rot_t <= 0.5 * rot_f and trans_t <= 0.5 * trans_f


def test_shared_shape_converges(sim, tracked):
    last = tracked.frames[-1].vehicles[0]
    truth = sim.truth[-1][last.id]
    error_cm = 100 * np.linalg.norm(last.keypoints_vehicle - truth.keypoints_vehicle, axis=1).mean()
    assert error_cm <= 5.0
    shapes = {v.wireframe for f in tracked.frames for v in f.vehicles}
    assert len(shapes) == 1  # one shape for the whole track


#: One prior and the nominal sigmas for both solvers: then they minimise the same cost.
FIXED = dict(options=TrackOptions(solve=SolveOptions(estimate_noise=False)), prior=default_shape_prior())


def largest_difference(run_a, run_b):
    """Largest translation (m) and rotation (deg) difference of the first vehicle over the frames."""
    out = []
    for a, b in zip(run_a, run_b):
        va, vb = a.vehicles[0], b.vehicles[0]
        out.append((np.linalg.norm(va.world_T_vehicle.translation() - vb.world_T_vehicle.translation()),
                    np.degrees(np.linalg.norm(va.world_T_vehicle.rotation().logmap(vb.world_T_vehicle.rotation())))))
    return np.max(out, axis=0)


def test_isam2_agrees_with_batch(sim):
    """With one prior and fixed sigmas iSAM2 reaches batch smoothing's minimum."""
    cm, deg = largest_difference(track_scene(sim.scene, **FIXED).frames, smooth_scene(sim.scene, **FIXED))
    assert cm < 0.01 and deg < 0.5


def test_isam2_and_batch_choose_their_shape_from_different_frames(sim, tracked):
    """By default the tracker takes body type and noise scale from a young track's frames, batch from all frames."""
    batch = smooth_scene(sim.scene)
    cm, deg = largest_difference(tracked.frames, batch)
    assert cm < 0.03 and deg < 0.5
    assert tracked.frames[-1].vehicles[0].body_type in BODY_TYPES and batch[-1].vehicles[0].body_type in BODY_TYPES


def test_covariance_shrinks_as_frames_accumulate(tracked):
    """The last frame's position covariance is well under the first's (whose noise scale is that frame's alone)."""
    online = [f.vehicles[0].pose_covariance for f in tracked.online]
    assert np.trace(online[-1][3:, 3:]) < 0.6 * np.trace(online[0][3:, 3:])


def test_fixed_lag_keeps_a_bounded_window(sim):
    """Poses within the lag once the track is grown up; a young track (fewer than five frames seen by two cameras)
    keeps its poses until its last re-solve has been read (at most _YOUNG_HOLD_FRAMES of them)."""
    tracker = Tracker(sim.scene.cameras, TrackOptions(lag=0.35))
    for i, frame in enumerate(sim.scene.frames):
        result = tracker.add_frame(frame, i)
        assert result.vehicles[0].ok
        held = len(tracker.estimates())
        assert held <= (5 if i >= 8 else i + 1)  # poses within 0.35 s at 10 Hz once grown up
    run = track_scene(sim.scene, TrackOptions(lag=0.35))
    (rot, trans), _ = mean_errors(sim, run.frames)
    (rot_f, trans_f), _ = mean_errors(sim, solve_scene(sim.scene))
    assert rot < rot_f and trans < trans_f


def test_frames_out_of_order_are_tracked_in_time_order(sim, tracked):
    shuffled = copy.copy(sim.scene)
    order = [1, 0] + list(range(2, len(sim.scene.frames)))
    shuffled.frames = [sim.scene.frames[i] for i in order]
    run = track_scene(shuffled)
    assert any("not in time order" in m for m in run.messages)
    for pos, i in enumerate(order):  # results in the file's order, same estimates
        a, b = run.frames[pos].vehicles[0], tracked.frames[i].vehicles[0]
        assert np.allclose(a.world_T_vehicle.matrix(), b.world_T_vehicle.matrix(), atol=1e-6)


def test_duplicate_times_name_the_frame(sim):
    scene = copy.copy(sim.scene)
    scene.frames = list(sim.scene.frames)
    scene.frames[3] = Frame(scene.frames[2].t, scene.frames[3].detections)
    with pytest.raises(InputError) as info:
        track_scene(scene)
    assert info.value.field == "frames[3].t"


def test_gaps_single_frame_vehicles_and_bad_tracks(sim):
    scene = copy.copy(sim.scene)
    frames = []
    for i, frame in enumerate(sim.scene.frames):
        dets = [] if i in (5, 6, 7) else list(frame.detections)  # v1 unseen for 0.3 s
        if i == 4:  # a vehicle seen once
            dets += [Detection(d.camera, "once", d.keypoints, d.confidence) for d in frame.detections]
        if i >= 10:  # a track whose detections name a camera the tracker does not have
            dets += [Detection("cam9", "ghost", d.keypoints, d.confidence) for d in frame.detections[:1]]
        frames.append(Frame(frame.t, dets))
    scene.frames = frames
    run = track_scene(scene)
    status = {(f, v.id): v.status for f, fr in enumerate(run.frames) for v in fr.vehicles}
    assert all(status[(f, "v1")] == Status.CONVERGED for f in range(20) if f not in (5, 6, 7))
    assert status[(4, "once")] == Status.CONVERGED
    assert any("'once'" in m and "one frame only" in m for m in run.messages)
    assert all(status[(f, "ghost")] == Status.FAILED for f in range(10, 20))
    (rot, trans), _ = mean_errors(sim, only(run.frames, "v1"))
    assert rot < 1.5 and trans < 8.0


def only(frames, vid):
    """The frames' results of one track (empty where it is absent)."""
    from vfactor.result import FrameResult

    return [FrameResult(f.t, [v for v in f.vehicles if v.id == vid]) for f in frames]


def test_tracker_rejects_time_going_backwards(sim):
    tracker = Tracker(sim.scene.cameras)
    tracker.add_frame(sim.scene.frames[1])
    with pytest.raises(InputError, match="does not follow"):
        tracker.add_frame(sim.scene.frames[0])


def test_running_track_takes_frames_with_two_keypoints(sim):
    """From a track's third pose on the motion factors fix the pose, so two keypoints are used, as batch uses them."""

    def two_keypoints(frame):
        d = frame.detections[0]
        kept = np.flatnonzero(d.confidence > 0)[:2]
        confidence = np.zeros_like(d.confidence)
        confidence[kept] = d.confidence[kept]
        return Frame(frame.t, [Detection(d.camera, d.vehicle, d.keypoints, confidence)])

    scene = copy.copy(sim.scene)
    scene.frames = [two_keypoints(f) if i in (1, 10) else f for i, f in enumerate(sim.scene.frames)]
    run = track_scene(scene, **FIXED)
    assert run.online[1].vehicles[0].status == Status.DEGENERATE  # second pose: only the non-holonomic factor
    assert run.online[10].vehicles[0].ok
    mine, batch = run.frames[10].vehicles[0], smooth_scene(scene, **FIXED)[10].vehicles[0]
    assert np.linalg.norm(mine.world_T_vehicle.translation() - batch.world_T_vehicle.translation()) < 0.01
    truth = sim.truth[10][mine.id].world_T_vehicle
    assert np.linalg.norm(mine.world_T_vehicle.translation() - truth.translation()) < 0.15


def test_motion_model_allows_a_fast_intersection_turn():
    """A left turn of radius 6.6 m at 11.6 m/s (1.76 rad/s, tracks_3veh seed 2) is inside the yaw-rate bound."""
    import gtsam

    from vfactor.factors.motion import MotionModel, nonholonomic_factor

    dt, speed, yaw_rate = 0.1, 11.6, 1.76
    values = gtsam.Values()
    values.insert(0, gtsam.Pose3())
    step = gtsam.Pose3.Expmap(np.array([0, 0, yaw_rate * dt, speed * dt, 0, 0]))
    values.insert(1, step)
    assert nonholonomic_factor(0, 1, dt, MotionModel()).unwhitenedError(values)[4] == 0.0


def test_batch_shapes_of_three_vehicles_within_5cm_van_included():
    """Issue 3's setting (tracks_3cam: 30 frames, 3 vehicles, 3 cameras): every final shape within 5 cm.

    The van stands with its back cut by one image for part of the track: it needs
    the truncation at the image border and the heavy-tailed shape prior
    (docs/results.md; with the Gaussian prior at weight 0.3 and no truncation
    its van was 4.5 cm on this seed and 5.9 cm on seed 3).
    """
    sim = simulate("tracks_3cam", seed=0)
    final = {}
    for f, frame in enumerate(smooth_scene(sim.scene, TrackOptions(covariance=False))):
        for v in frame.vehicles:
            assert v.ok, (f, v.id, v.status)
            final[v.id] = 100 * np.linalg.norm(v.keypoints_vehicle - sim.truth[f][v.id].keypoints_vehicle, axis=1).mean()
    assert len(final) == 3 and max(final.values()) <= 5.0, final


def _mean_errors(results, truth):
    errors = [pose_errors(v.world_T_vehicle, v.keypoints_world, truth[f][v.id].world_T_vehicle,
                          truth[f][v.id].keypoints_world) for f, frame in enumerate(results) for v in frame.vehicles
              if v.ok]
    return np.mean([e["rotation_deg"] for e in errors]), np.mean([e["translation_cm"] for e in errors])


@pytest.mark.parametrize("count", [3, 5])
def test_ids_that_do_not_follow_one_vehicle_are_reported_not_averaged(count):
    """intersection_multi draws new vehicles every frame under the ids v1-v3 (and v1-v5 with five at once):
    tracking them as tracks averaged different vehicles (72 deg and 3.8 m mean error, all 'converged'); each
    jump is now a new segment, said so."""
    import dataclasses

    scenario = load_scenario("intersection_multi")
    if count != scenario.vehicles_per_frame:
        scenario = dataclasses.replace(scenario, vehicles_per_frame=count, region=((-7.0, 7.0), (-7.0, 7.0)))
    sim = simulate(scenario, seed=0, num_frames=8)
    run = track_scene(sim.scene, TrackOptions(covariance=False))
    ids = [f"v{k}" for k in range(1, count + 1)]
    reports = {vid: m for vid in ids for m in run.messages if m.startswith(f"vehicle '{vid}': ")}
    assert set(reports) == set(ids), run.messages
    assert all("jumps beyond the motion model" in m and "does not follow one vehicle" in m for m in reports.values())
    segments = [v for frame in run.frames[1:] for v in frame.vehicles if "a new segment of the track" in v.message]
    assert len(segments) >= 0.7 * 7 * count  # of the poses after the first frame
    rotation, translation = _mean_errors(run.frames, sim.truth)
    alone = _mean_errors(solve_scene(sim.scene, SolveOptions(covariance=False)), sim.truth)
    # three vehicles: frame by frame 3.1 deg, 5.4 cm; tracked 9.4 deg, 21 cm, five: 2.7 deg, 5.4 cm and 11.4 deg,
    # 22 cm (medians 3.7 and 2.6 deg, as frame by frame): a vehicle re-drawn near the last one of its id, with a
    # like heading, is within the gate of a one-pose track and still merged into it, and the segment's poses keep
    # the estimates smoothed over it (online, before the segment ended: 8.6 and 6.5 deg)
    assert rotation < 5 * alone[0] and translation < 5 * alone[1] and rotation < 12, (rotation, translation, alone)


def test_a_smooth_track_never_jumps(sim):
    tracker = Tracker(sim.scene.cameras, TrackOptions(covariance=False))
    for i, frame in enumerate(sim.scene.frames):
        tracker.add_frame(frame, i)
    assert tracker.jumps == {}


def test_a_segment_ended_by_a_jump_keeps_its_smoothed_estimates(sim):
    """A track that jumps (another vehicle under its id) starts a new segment; the poses of the segment it ends
    keep the estimates smoothed over that whole segment, as if the jump had never come, not their online ones
    (they did until the smoother was dropped: 3-5 deg instead of 0.5-1 deg on an associated track)."""
    import dataclasses

    frames = sim.scene.frames[:12]
    step = frames[-1].t - frames[-2].t
    # the vehicle's detections of the first frame, shown after the last: metres behind where it has driven to
    jumped = dataclasses.replace(frames[0], t=frames[-1].t + step)
    before = track_scene(dataclasses.replace(sim.scene, frames=frames), TrackOptions(covariance=False))
    run = track_scene(dataclasses.replace(sim.scene, frames=frames + [jumped]), TrackOptions(covariance=False))
    assert "a new segment of the track" in run.frames[-1].vehicles[0].message
    moved = 0.0
    for f in range(len(frames)):
        final, alone = run.frames[f].vehicles[0], before.frames[f].vehicles[0]
        assert final.ok
        assert np.linalg.norm(final.world_T_vehicle.localCoordinates(alone.world_T_vehicle)) < 1e-3
        assert np.allclose(final.keypoints_vehicle, alone.keypoints_vehicle, atol=1e-3)
        moved = max(moved, np.linalg.norm(run.online[f].vehicles[0].world_T_vehicle.localCoordinates(
            final.world_T_vehicle)))
    assert moved > 1e-2  # smoothing moved the early poses: the test tells online from smoothed


def _with_detector_offsets(sim, sigma: float, seed: int):
    """``sim``'s scene whose detections carry ``shape_sigma = sigma`` and err as the pose offsets model: each
    camera sees the vehicle moved by its own fixed rigid motion (drawn from the offsets' prior at the vehicle's
    size, about sigma / 3.5 of shift and sigma / 5 m radians of turn at 9 m^3) in every frame, on top of the
    simulator's independent pixel noise: errors that repeat from frame to frame."""
    from vfactor.graph import GraphConfig, detector_offset_prior

    rng = np.random.default_rng(seed)
    prior = detector_offset_prior(0, sigma, sim.truth[0][sim.scene.frames[0].detections[0].vehicle].wireframe
                                  .vehicle_p_keypoints, size_exponent=GraphConfig().shape_sigma_size_exponent)
    R = prior.noiseModel().R()  # the prior's square-root information
    offsets = {name: gtsam.Pose3.Expmap(np.linalg.solve(R, rng.normal(size=6))) for name in sim.scene.cameras}
    return _seen_moved(sim, lambda d: offsets[d.camera], shape_sigma=sigma)


def _seen_moved(sim, motion, **fields):
    """``sim``'s scene with each detection's keypoints those of its vehicle moved by ``motion(detection)`` (a
    ``gtsam.Pose3`` of the body frame) on top of the simulator's pixel noise, and ``fields`` set on it."""
    frames = []
    for f, frame in enumerate(sim.scene.frames):
        detections = []
        for d in frame.detections:
            truth = sim.truth[f][d.vehicle]
            camera = sim.scene.cameras[d.camera]
            seen_T = truth.world_T_vehicle.compose(motion(d))
            moved = seen_T.transformFrom(truth.wireframe.vehicle_p_keypoints.T).T
            shift = camera.project(moved)[0] - camera.project(truth.keypoints_world)[0]
            detections.append(dataclasses.replace(d, keypoints=d.keypoints + shift, **fields))
        frames.append(dataclasses.replace(frame, detections=detections))
    return dataclasses.replace(sim.scene, frames=frames)


def _mean_nees(sim, frames):
    from vfactor.metrics import pose_nees

    return np.mean([pose_nees(v.world_T_vehicle, v.pose_covariance, sim.truth[f][v.id].world_T_vehicle)
                    for f, frame in enumerate(frames) for v in frame.vehicles if v.ok])


def test_detector_offsets_model_errors_that_repeat_from_frame_to_frame(sim):
    """With each camera's view of the vehicle off by its own fixed rigid motion, a track that counts every frame
    as new information is far too sure of its poses; one pose offset per camera (its prior from the detections'
    shape_sigma) keeps the covariances near the errors, in the tracker and in batch smoothing. Without the offsets
    in the estimate (``detector_offsets=False``) the smoothed covariances still consider them where the detections
    say how large they are: the same poses, covariances near their errors; without a ``shape_sigma`` they cannot."""
    clean = dataclasses.replace(load_scenario("intersection_2cam_track"),
                                noise=NoiseModel(relative_sigma=0.003, outlier_rate=0, swap_rate=0, missing_rate=0))
    truth = simulate(clean, seed=1)
    scene = _with_detector_offsets(truth, 0.04, seed=5)
    unaware = dataclasses.replace(scene, frames=[dataclasses.replace(
        f, detections=[dataclasses.replace(d, shape_sigma=None) for d in f.detections]) for f in scene.frames])
    plain = track_scene(unaware, TrackOptions(detector_offsets=False))
    assert _mean_nees(truth, plain.frames) > 3 * 6  # the repeated errors counted as new in every frame
    (rotation_plain, _), _ = mean_errors(truth, plain.frames)
    considered_run = track_scene(scene, TrackOptions(detector_offsets=False))
    considered = considered_run.frames
    for frames in (considered, smooth_scene(scene, TrackOptions(detector_offsets=False))):
        assert 0.4 * 6 < _mean_nees(truth, frames) < 1.5 * 6
    # the online (filtered) covariances consider them too, frame by frame (track._considered_offsets)
    assert _mean_nees(truth, plain.online) > 3 * 6
    assert 0.4 * 6 < _mean_nees(truth, considered_run.online) < 1.5 * 6
    for a, b in zip(plain.frames, considered):  # the estimate is the unaware track's
        for u, v in zip(a.vehicles, b.vehicles):
            np.testing.assert_allclose(u.world_T_vehicle.matrix(), v.world_T_vehicle.matrix(), atol=1e-9)
    tracker_options = TrackOptions(detector_offsets=True)
    offsets = track_scene(scene, tracker_options)
    batch = smooth_scene(scene, tracker_options)
    for frames in (offsets.frames, batch):
        assert all(v.ok for fr in frames for v in fr.vehicles)
        assert 0.4 * 6 < _mean_nees(truth, frames) < 1.5 * 6
        (rotation, translation), _ = mean_errors(truth, frames)
        assert rotation < rotation_plain and translation < 5.0


def test_the_online_covariance_adds_each_unestimated_offset_through_its_cameras_share(sim):
    """track._considered_offsets: one camera alone moves the pose by its whole offset (the term is the offset
    prior's covariance); with two, each by its share of the frame's pose information, the terms adding up; a
    camera whose offset the track estimates, or without a shape_sigma, adds nothing."""
    from vfactor.graph import GraphConfig, detector_offset_prior
    from vfactor.track import _considered_offsets

    config = GraphConfig()
    frame, truth = sim.scene.frames[0], sim.truth[0]
    vid = frame.vehicle_ids()[0]
    detections = [dataclasses.replace(d, shape_sigma=0.04) for d in frame.detections_of(vid)]
    assert len(detections) == 2
    pose, wireframe = truth[vid].world_T_vehicle, truth[vid].wireframe
    obs = observations_from_detections(detections, sim.scene.cameras, config)
    prior = detector_offset_prior(0, 0.04, wireframe.vehicle_p_keypoints,
                                  size_exponent=config.shape_sigma_size_exponent).noiseModel().covariance()
    alone = observations_from_detections(detections[:1], sim.scene.cameras, config)
    np.testing.assert_allclose(_considered_offsets(alone, {}, pose, wireframe, config), prior, rtol=1e-5, atol=1e-12)
    both = _considered_offsets(obs, {}, pose, wireframe, config)
    assert np.all(np.linalg.eigvalsh(both) > 0) and not np.allclose(both, 2 * prior, rtol=0.05)
    own = {detections[0].camera: 7}  # the track estimates that camera's offset: only the other one is considered
    one = _considered_offsets(obs, own, pose, wireframe, config)
    assert np.all(np.linalg.eigvalsh(both - one) > -1e-15) and np.trace(one) < np.trace(both)
    plain = observations_from_detections(frame.detections_of(vid), sim.scene.cameras, config)
    assert not np.any(_considered_offsets(plain, {}, pose, wireframe, config))


def _with_detector_bias(sim, bias_sigma, seed: int, shape_sigma: float | None = None):
    """``sim``'s scene whose detections carry ``bias_sigma`` (and ``shape_sigma``) and err as the detector's bias
    models it: every camera sees each vehicle moved by one rigid motion of its body frame, drawn once per vehicle
    from ``bias_sigma``, in every frame, on top of the simulator's independent pixel noise."""
    rng = np.random.default_rng(seed)
    vehicles = sorted({d.vehicle for frame in sim.scene.frames for d in frame.detections})
    bias = {v: gtsam.Pose3.Expmap(rng.normal(size=6) * np.asarray(bias_sigma)) for v in vehicles}
    return _seen_moved(sim, lambda d: bias[d.vehicle], bias_sigma=tuple(bias_sigma), shape_sigma=shape_sigma)


@pytest.mark.slow  # 6 s each; test_detector_offsets_model_errors_that_repeat_from_frame_to_frame runs the offsets
@pytest.mark.parametrize("plane", [False, True])
def test_a_detector_bias_keeps_track_covariances_near_errors_that_no_frame_averages(plane):
    """Each vehicle seen moved by one rigid motion in every frame and camera (the detector's bias): a track that
    counts every frame as new is far too sure of its poses; with the detections' ``bias_sigma`` the track's common
    offset keeps them near their errors, in the tracker (and its fixed lag) and in batch smoothing, without a road
    plane and with one (and each camera's own offset, from a ``shape_sigma``), and the errors are no worse. Nine
    draws of the bias (three scenes of three vehicles): the mean NEES of so few draws spreads by about a fifth."""
    from vfactor.factors.ground_plane import GroundPlane

    clean = dataclasses.replace(load_scenario("library_tracks_2cam"),
                                noise=NoiseModel(relative_sigma=0.003, outlier_rate=0, swap_rate=0, missing_rate=0))
    bias_sigma = (0.01, 0.01, 0.004, 0.04, 0.02, 0.03)
    nees = {name: [] for name in ("unaware", "tracker", "fixed lag", "batch")}
    for seed in (1, 2, 3):
        truth = simulate(clean, seed=seed, num_frames=12)
        scene = _with_detector_bias(truth, bias_sigma, seed=seed, shape_sigma=0.04 if plane else None)
        if plane:
            scene = dataclasses.replace(scene, ground_plane=GroundPlane((0.0, 0.0, 1.0), 0.0))
        unaware = dataclasses.replace(scene, frames=[dataclasses.replace(
            f, detections=[dataclasses.replace(d, bias_sigma=None) for d in f.detections]) for f in scene.frames])
        plain = track_scene(unaware)
        (rotation_plain, translation_plain), _ = mean_errors(truth, plain.frames)
        nees["unaware"].append(_mean_nees(truth, plain.frames))
        runs = {"tracker": track_scene(scene).frames, "batch": smooth_scene(scene)}
        if not plane:
            runs["fixed lag"] = track_scene(scene, TrackOptions(lag=0.5)).frames
        for name, frames in runs.items():
            assert all(v.ok for fr in frames for v in fr.vehicles)
            nees[name].append(_mean_nees(truth, frames))
            (rotation, translation), _ = mean_errors(truth, frames)
            assert rotation < 1.2 * rotation_plain + 0.05 and translation < 1.2 * translation_plain + 0.5
    assert np.mean(nees["unaware"]) > 3 * 6  # the repeated error counted as new in every frame
    for name in ("tracker", "fixed lag", "batch") if not plane else ("tracker", "batch"):
        assert 0.35 * 6 < np.mean(nees[name]) < 1.5 * 6, (name, nees[name])
    if plane:  # no offsets at all: the bias is not modelled, the track is as if the detections had no bias_sigma
        off = TrackOptions(detector_offsets=False)
        for a, b in zip(track_scene(scene, off).frames, track_scene(unaware, off).frames):
            for u, w in zip(a.vehicles, b.vehicles):
                np.testing.assert_array_equal(u.pose_covariance, w.pose_covariance)


def test_detector_offsets_need_a_shape_sigma(sim):
    """Detections without a shape_sigma (the simulator's) get no offset: the same estimates to the bit."""
    scene = copy.deepcopy(sim.scene)
    plain, offsets = track_scene(scene), track_scene(scene, TrackOptions(detector_offsets=True))
    for a, b in zip(plain.frames, offsets.frames):
        np.testing.assert_array_equal(a.vehicles[0].world_T_vehicle.matrix(), b.vehicles[0].world_T_vehicle.matrix())
        np.testing.assert_array_equal(a.vehicles[0].pose_covariance, b.vehicles[0].pose_covariance)


def test_detector_offsets_default_to_on_where_the_track_has_a_road_plane(sim):
    """``detector_offsets=None`` (the default): offsets where the scene gives a road plane (with a plane they made
    the network's two-camera tracks' covariances consistent: docs/results.md), none without one; True / False
    force them."""
    from vfactor.factors.ground_plane import GroundPlane

    plane = GroundPlane((0.0, 0.0, 1.0), 0.0)
    assert not TrackOptions().uses_detector_offsets
    assert TrackOptions(solve=SolveOptions(ground_plane=plane)).uses_detector_offsets
    assert not TrackOptions(solve=SolveOptions(ground_plane=plane), detector_offsets=False).uses_detector_offsets
    assert TrackOptions(detector_offsets=True).uses_detector_offsets
    with pytest.raises(ValueError, match="detector_offsets"):
        TrackOptions(detector_offsets="yes")
    scene = _with_detector_offsets(sim, 0.04, seed=5)
    frames = dataclasses.replace(scene, frames=scene.frames[:6])
    for given, expected in ((None, False), (plane, True)):
        tracker = Tracker(scene.cameras, TrackOptions(solve=SolveOptions(ground_plane=given), covariance=False))
        for i, frame in enumerate(frames.frames):
            tracker.add_frame(frame, i)
        assert bool(tracker._tracks["v1"].offsets) == expected
    on = track_scene(dataclasses.replace(frames, ground_plane=plane), TrackOptions(covariance=False))
    forced = track_scene(dataclasses.replace(frames, ground_plane=plane),
                         TrackOptions(covariance=False, detector_offsets=True))
    for a, b in zip(on.frames, forced.frames):
        np.testing.assert_array_equal(a.vehicles[0].world_T_vehicle.matrix(), b.vehicles[0].world_T_vehicle.matrix())



def test_a_track_with_a_road_plane_estimates_its_own_hub_height():
    """With a road plane a track's hub height (the wheel radius) is one variable its poses share
    (docs/factors.md, "The hub height of a track"), not 30 independent factors at the default 0.34 m: the Nissan
    Titan of ``library_tracks`` seed 300 (0.414 m wheels) came out 4.0-4.4 cm low over its whole track, the
    Jumper van beside it (0.341 m) 0.3 cm. Its estimate is in the results, the same in every pose."""
    from vfactor.evaluation import held_out_scene_model

    sim = simulate(load_scenario("library_tracks"), seed=300)
    model = held_out_scene_model(sim)
    runs = {"batch": smooth_scene(sim.scene, TrackOptions(), prior=model),
            "isam2": track_scene(sim.scene, TrackOptions(), prior=model).frames}
    for name, frames in runs.items():
        heights, dz, preset = {}, {}, {}
        for f, frame in enumerate(frames):
            for v in frame.vehicles:
                assert v.ok, (name, f, v.id, v.message)
                truth = sim.truth[f][v.id]
                heights.setdefault(v.id, set()).add(round(v.extras["hub_height"], 9))
                dz.setdefault(v.id, []).append(v.world_T_vehicle.translation()[2] - truth.world_T_vehicle.translation()[2])
                preset[v.id] = (truth.preset, truth.wheel_radius)
        assert all(len(h) == 1 for h in heights.values()), (name, heights)  # one value per track
        for vid, (model_name, wheel_radius) in preset.items():
            assert abs(next(iter(heights[vid])) - wheel_radius) < 0.025, (name, model_name)
            assert abs(np.mean(dz[vid])) < 0.025, (name, model_name)
        assert "nissan_titan_a61_crew" in {p for p, _ in preset.values()}  # the prior's 0.34 m is 7.4 cm below it



def test_a_track_starts_from_its_first_frame_solved_as_solve_vehicle_solves_it():
    """A track's first frame is solved with its keypoints' sigmas sized by the vehicle it finds, as
    ``solve_vehicle`` solves a frame: the Jumper van of ``library_tracks`` seed 220 enters cam0's view with 4
    keypoints, which sized by their own small box outweighed the other cameras, and its first frame was failed
    (the cameras "disagree") where ``vfactor solve`` solves it."""
    sim = simulate(load_scenario("library_tracks"), seed=220)
    scene = dataclasses.replace(sim.scene, frames=sim.scene.frames[:3])
    first = track_scene(scene, TrackOptions(covariance=False)).frames[0]
    assert all(v.ok for v in first.vehicles), [(v.id, v.message) for v in first.vehicles]


def test_a_track_does_not_narrow_calibrated_covariances(sim):
    """A detector's calibrated covariances (the keypoint network's) are a floor in tracks, as in the one-frame
    covariances: the residuals of a fit that absorbs such a detector's errors understate them, and a track at their
    noise scale (0.2-0.45 on the network's keypoints) weighed its keypoints 5-25 times their calibrated information
    (docs/results.md, "Tracking from images"). Uncalibrated covariances still follow the residuals."""
    def given(calibrated):  # covariances of twice the simulator's pixel noise: the residuals say less
        frames = []
        for frame in sim.scene.frames:
            detections = []
            for d in frame.detections:
                sigma = 2 * 0.03 * d.box_diagonal() / np.maximum(d.confidence, 0.1)
                covariance = sigma[:, None, None] ** 2 * np.eye(2)
                detections.append(dataclasses.replace(d, covariance=covariance, covariance_calibrated=calibrated))
            frames.append(dataclasses.replace(frame, detections=detections))
        return dataclasses.replace(sim.scene, frames=frames)

    spread = {}
    for calibrated in (False, True):
        run = track_scene(given(calibrated))
        assert all(v.ok for fr in run.frames for v in fr.vehicles)
        assert run.frames[-1].vehicles[0].extras["noise_scale"] < 0.8  # the residuals say the sigmas are too wide
        spread[calibrated] = np.median([np.trace(fr.vehicles[0].pose_covariance) for fr in run.frames])
    assert spread[True] > 1.5 * spread[False]




def test_a_young_track_off_by_metres_is_rejoined_not_split(sim):
    """A young track can be what is wrong, not the id: here cam1 alone sees the vehicle for six frames, and then
    cam0's first three views give the keypoints of a vehicle 5 m further along its heading (as a detector's
    keypoints of a vehicle entering the view, cut by the image border, were on library_tracks_2cam seed 10 from
    rendered images), which drag the track metres off. When cam0's keypoints are right again they lie beyond the
    jump gate. The track is re-solved with them, every pose from its own frame's solve, and goes on as one
    track; it used to split into a new segment and keep its first ten poses 2.2-2.6 m off."""
    cam0 = sim.scene.cameras["cam0"]
    frames = []
    for f, frame in enumerate(sim.scene.frames):
        detections = [d for d in frame.detections if f >= 6 or d.camera == "cam1"]
        if f in (6, 7, 8):
            truth = sim.truth[f]["v1"]
            ahead = truth.keypoints_world + 5.0 * truth.world_T_vehicle.rotation().matrix()[:, 0]
            shift = cam0.project(ahead)[0] - cam0.project(truth.keypoints_world)[0]
            detections = [dataclasses.replace(d, keypoints=d.keypoints + shift) if d.camera == "cam0" else d
                          for d in detections]
        frames.append(dataclasses.replace(frame, detections=detections))
    scene = dataclasses.replace(sim.scene, frames=frames)
    run = track_scene(scene)

    def translation_cm(results):
        return np.array([pose_errors(fr.vehicles[0].world_T_vehicle, fr.vehicles[0].keypoints_world,
                                     sim.truth[f]["v1"].world_T_vehicle, sim.truth[f]["v1"].keypoints_world)[
                                         "translation_cm"] for f, fr in enumerate(results)])

    assert translation_cm(run.online)[6:10].min() > 200  # the track dragged off by the wrong views
    assert not any("jumps" in m for m in run.messages), run.messages
    assert sum("re-solved with this frame" in fr.vehicles[0].message for fr in run.frames) == 1
    final = translation_cm(run.frames)
    assert final[:10].max() < 60 and final[10:].max() < 25, final
    # with a fixed lag shorter than the young phase the young track's poses stay in its smoother until it has
    # grown up (_YOUNG_HOLD_FRAMES), so that it can still be re-solved: the same one track
    lagged = track_scene(scene, TrackOptions(lag=0.3))
    assert not any("jumps" in m for m in lagged.messages), lagged.messages
    assert translation_cm(lagged.frames)[:10].max() < 100


def test_a_track_one_camera_sees_holds_a_bounded_window(sim):
    """A track that only one camera ever sees stays young (nothing re-anchors it); with a fixed lag its window
    and its young-frame store stay bounded however long it runs."""
    import vfactor.track as track_module

    frames = [dataclasses.replace(f, detections=[d for d in f.detections if d.camera == "cam1"])
              for f in sim.scene.frames]
    scene = dataclasses.replace(sim.scene, frames=frames)
    hold = track_module._YOUNG_HOLD_FRAMES
    track_module._YOUNG_HOLD_FRAMES = 6
    try:
        tracker = Tracker(scene.cameras, TrackOptions(lag=0.35))
        for i, frame in enumerate(scene.frames):
            assert tracker.add_frame(frame, i).vehicles[0].ok
            assert len(tracker.estimates()) <= 6 + 4  # the held poses, then the lag's (0.35 s at 10 Hz)
            assert len(tracker._tracks["v1"].young_frames) <= 7
    finally:
        track_module._YOUNG_HOLD_FRAMES = hold



def turned_frames(sim, turns: dict[int, float]):
    """``sim``'s frames with every camera's keypoints of v1 in frame ``f`` those of the vehicle turned by
    ``turns[f]`` radians in place (about its vertical), with the simulator's noise."""
    import gtsam

    frames = []
    for f, frame in enumerate(sim.scene.frames):
        if f in turns:
            truth = sim.truth[f]["v1"]
            turned = truth.world_T_vehicle.compose(gtsam.Pose3(gtsam.Rot3.Rz(turns[f]), np.zeros(3)))
            world = turned.transformFrom(truth.wireframe.vehicle_p_keypoints.T).T
            detections = []
            for d in frame.detections:
                camera = sim.scene.cameras[d.camera]
                noise = d.keypoints - camera.project(truth.keypoints_world)[0]
                detections.append(dataclasses.replace(d, keypoints=camera.project(world)[0] + noise))
            frame = dataclasses.replace(frame, detections=detections)
        frames.append(frame)
    return dataclasses.replace(sim.scene, frames=frames)


def assert_bad_frames_left_out(sim, scene, bad: set, options=TrackOptions()):
    """Tracked, the ``bad`` frames are left out of the track (their poses from its motion, said in their messages),
    no jump is reported, and every pose is within 5 deg and 25 cm of the truth."""
    run = track_scene(scene, options)
    assert not any("jumps" in m for m in run.messages), run.messages
    for f in bad:
        assert "left out of the track" in run.frames[f].vehicles[0].message, (f, run.frames[f].vehicles[0].message)
    errors = [pose_errors(fr.vehicles[0].world_T_vehicle, fr.vehicles[0].keypoints_world,
                          sim.truth[f]["v1"].world_T_vehicle, sim.truth[f]["v1"].keypoints_world)
              for f, fr in enumerate(run.frames)]
    assert max(e["rotation_deg"] for e in errors) < 5 and max(e["translation_cm"] for e in errors) < 25, errors
    return run


def test_one_frame_of_a_vehicle_turned_round_is_left_out_not_a_new_segment(sim):
    """A learnt detector now and then gives one frame's keypoints of the vehicle turned round
    (library_tracks_2cam seed 12 from rendered images: both cameras' keypoints of one frame fit the vehicle
    165 deg off). That frame lies beyond the motion model's gate and starts a new segment; the next frame, right
    again, follows the ended segment, which goes on, and the bad frame's pose goes back into it from the track's
    motion alone, with a message (it used to leave three segments and two jumps, the bad frame turned round)."""
    scene = turned_frames(sim, {10: np.pi})
    run = assert_bad_frames_left_out(sim, scene, {10})
    # the bad frame: online its own (turned) solve, finally the track's pose for its time
    assert run.online[10].vehicles[0].world_T_vehicle.rotation().matrix()[:, 0] @ \
        sim.truth[10]["v1"].world_T_vehicle.rotation().matrix()[:, 0] < 0
    lagged = track_scene(scene, TrackOptions(lag=0.3))
    assert not any("jumps" in m for m in lagged.messages) and "left out" in lagged.frames[10].vehicles[0].message


def test_a_run_of_bad_frames_is_left_out_not_new_segments(sim):
    """A view hidden behind another vehicle for a few frames, the network putting the hidden vehicle's keypoints on
    the one in front (``library_tracks_2cam`` seed 241 from rendered images: a pickup's keypoints 59-173 deg off in
    three frames, which left four segments and three jumps, the poses 12 deg / 96 cm off on average): the frames
    after the run follow the segment the first jump ended, which is held through the run and goes on, the bad
    frames' poses from its motion."""
    turns = {10: np.pi, 11: np.pi, 12: 0.6 * np.pi}  # the third another pose again: a jump from the second segment
    assert_bad_frames_left_out(sim, turned_frames(sim, turns), set(turns))
    assert_bad_frames_left_out(sim, turned_frames(sim, turns), set(turns), TrackOptions(lag=0.5))
    # longer than the hold (track._RESUME_FRAMES): the keypoints say so for good, and the track splits as before
    from vfactor.track import _RESUME_FRAMES

    run = track_scene(turned_frames(sim, {f: np.pi for f in range(10, 10 + 2 * _RESUME_FRAMES)}))
    assert any("jumps" in m for m in run.messages), run.messages
    assert not any("left out of the track" in v.message for fr in run.frames for v in fr.vehicles)


def test_a_frame_that_does_not_join_a_young_track_leaves_its_shape_choice_as_it_was(sim):
    """Another vehicle's keypoints under a young track's id: the track is re-solved with them to see whether it
    was the track that was off (Tracker._rejoined); they do not join, and the segment the jump ends keeps the
    prior, noise scale and body type it had, not those the trial re-solve chose with the stranger's frame."""
    frames = [dataclasses.replace(f, detections=[d for d in f.detections if d.camera == "cam1"])
              for f in sim.scene.frames[:8]]  # one camera: the track stays young
    jumped = dataclasses.replace(frames[2], t=frames[-1].t + frames[-1].t - frames[-2].t)  # where it was 6 frames ago
    tracker = Tracker(sim.scene.cameras, TrackOptions(covariance=False))
    for i, frame in enumerate(frames):
        tracker.add_frame(frame, i)
    track = tracker._tracks["v1"]
    assert track.young and len(track.poses) >= 5
    kept = {name: getattr(track, name) for name in ("noise_scale", "body_type", "body_type_probability")}
    prior_mean = np.asarray(track.prior.mean).copy()
    result = tracker.add_frame(jumped, len(frames)).vehicles[0]
    assert "a new segment of the track" in result.message
    ended = track.previous
    assert {name: ended[name] for name in kept} == kept
    np.testing.assert_array_equal(np.asarray(ended["prior"].mean), prior_mean)


@pytest.fixture(scope="module")
def entering():
    """tracks_3veh seed 9, frames 5-15, v1 alone: cam1 alone sees it enter its view, and its first frame's solve is
    64 cm off in depth; the second frame's keypoints lie 3.6 m from where that pose (no velocity yet) puts it."""
    sim = simulate(load_scenario("tracks_3veh"), seed=9)
    frames = [dataclasses.replace(f, detections=[d for d in f.detections if d.vehicle == "v1"])
              for f in sim.scene.frames[5:16]]
    return sim, frames, sim.truth[5:16]


def test_a_camera_whose_detector_turned_the_vehicle_round_is_relabelled_at_the_prediction(entering):
    """cam1 alone sees v1 enter; in three frames its detector reads the vehicle's front as its back (every keypoint
    under the label of the one diagonally across, as the keypoint network does for a vehicle seen nearly end-on).
    Before, the track followed those keypoints round (35-174 deg off online, four frames); the tracker, whose
    track drives forwards, relabels them at its prediction, says so, and stays within a few degrees."""
    from vfactor.keypoints import TURN_PERMUTATION
    from vfactor.metrics import rotation_error_deg

    sim, frames, truth = entering

    def turned(d):
        return dataclasses.replace(d, keypoints=d.keypoints[TURN_PERMUTATION],
                                   confidence=d.confidence[TURN_PERMUTATION])

    confused = [dataclasses.replace(f, detections=[turned(d) if i in (3, 4, 5) and d.camera == "cam1" else d
                                                   for d in f.detections]) for i, f in enumerate(frames)]
    tracker = Tracker(sim.scene.cameras, TrackOptions())
    for i, frame in enumerate(confused):
        v = tracker.add_frame(frame, i).vehicles[0]
        assert rotation_error_deg(v.world_T_vehicle, truth[i]["v1"].world_T_vehicle) < 10, i
        assert ("turned round" in v.message) == (i in (3, 4, 5)), (i, v.message)


def _translations_cm(results, truth):
    return np.array([pose_errors(fr.vehicles[0].world_T_vehicle, fr.vehicles[0].keypoints_world,
                                 truth[f]["v1"].world_T_vehicle, truth[f]["v1"].keypoints_world)["translation_cm"]
                     for f, fr in enumerate(results)])


@pytest.mark.parametrize("lag", [None, 0.3])
def test_a_first_pose_off_in_depth_is_taken_back_when_the_next_segment_knows_the_motion(entering, lag):
    """The jump after a one-pose track split it and left that pose as it was solved alone (64 cm off here, 1-2.5 m
    on other scenes); once the segment after the jump has five poses, its motion leads back to the ended pose,
    which is solved again with it (Tracker._take_back) and the jump withdrawn: the taken-back pose ends where
    batch smoothing of the same frames puts it. The new segment's own estimates are untouched (online the same as
    before). (Since the keypoints' sigmas follow the vehicle's size, cam0's 2-9 keypoints of the vehicle entering
    its view count for less, and this track, batch smoothing's too, is 11-31 cm off, from 3-11 cm.)"""
    sim, frames, truth = entering
    scene = dataclasses.replace(sim.scene, frames=frames)
    run = track_scene(scene, TrackOptions(lag=lag))
    online, final = _translations_cm(run.online, truth), _translations_cm(run.frames, truth)
    batch = _translations_cm(smooth_scene(scene, TrackOptions(covariance=False)), truth)
    assert online[0] > 50 and online[1] > 200  # the first two frames alone, each off in depth
    assert not any("jumps" in m for m in run.messages), run.messages
    assert "taken back into the track" in run.frames[0].vehicles[0].message
    assert np.abs(final - batch).max() < 5 and final.max() < 40, (final, batch)
    covariance = run.frames[0].vehicles[0].pose_covariance
    assert covariance is not None and np.all(np.linalg.eigvalsh(covariance) > 0)


def test_two_short_segments_in_a_row_are_taken_back_together():
    """tracks_3veh seed 41: cam1's first two views of v1 are solved 1.2 m and 11 m off, each beyond the jump gate
    of the one before, so the track split twice; both one-pose segments are kept, chained, and taken back together
    once the third segment knows the motion (each segment's first poses joined to the ones before by motion
    factors). Both jumps are withdrawn."""
    sim = simulate(load_scenario("tracks_3veh"), seed=41)
    frames = [dataclasses.replace(f, detections=[d for d in f.detections if d.vehicle == "v1"])
              for f in sim.scene.frames[5:17]]
    truth = sim.truth[5:17]
    run = track_scene(dataclasses.replace(sim.scene, frames=frames), TrackOptions(covariance=False))
    online, final = _translations_cm(run.online, truth), _translations_cm(run.frames, truth)
    assert online[0] > 100 and online[1] > 1000
    assert not any("jumps" in m for m in run.messages), run.messages
    assert all("taken back" in run.frames[f].vehicles[0].message for f in (0, 1))
    assert final.max() < 30, final  # 18 and 13 cm for the two taken back (they were kept 118 cm and 11 m off)


def test_another_vehicles_pose_before_a_jump_is_not_taken_back(entering):
    """The keypoints of another vehicle (v2, 14 m away) under v1's id in the first frame: the segment after the
    jump cannot explain them with its motion, so the ended pose keeps its own estimate and the jump is reported."""
    sim, frames, truth = entering
    stranger = [dataclasses.replace(d, vehicle="v1") for d in sim.scene.frames[5].detections
                if d.vehicle == "v2" and d.camera == "cam1"]
    frames = [dataclasses.replace(frames[0], detections=stranger)] + frames[1:]
    run = track_scene(dataclasses.replace(sim.scene, frames=frames), TrackOptions(covariance=False))
    assert any("1 jumps beyond the motion model" in m for m in run.messages), run.messages
    assert "taken back" not in run.frames[0].vehicles[0].message
    assert run.frames[0].vehicles[0].world_T_vehicle.equals(run.online[0].vehicles[0].world_T_vehicle, 1e-3)
    alone = track_scene(dataclasses.replace(sim.scene, frames=frames[1:]), TrackOptions(covariance=False))
    assert all(a.vehicles[0].world_T_vehicle.equals(b.vehicles[0].world_T_vehicle, 1e-3)  # as if tracked alone
               for a, b in zip(run.frames[1:], alone.frames))


@pytest.mark.parametrize("lag", [None, 0.5])
def test_an_outlier_among_a_leaving_vehicles_last_keypoints_is_gated_on_the_prediction(lag):
    """tracks_3veh seed 39: a van leaves cam1's view with 4, 3 and 2 keypoints in its last frames, one of the four
    an outlier (21 sigmas off). The robust loss cannot outvote it among four: with a fixed lag it turned the
    window's poses by up to 67 deg (3 m off, all 'converged'); without, the outlier's PnP pose 8.8 m off was taken
    for a jump and the last frames went unsolved. Gated on the track's prediction it is left out, said so."""
    sim = simulate(load_scenario("tracks_3veh"), seed=39)
    frames = [dataclasses.replace(f, detections=[d for d in f.detections if d.vehicle == "v2"])
              for f in sim.scene.frames[12:27]]
    truth = sim.truth[12:27]
    run = track_scene(dataclasses.replace(sim.scene, frames=frames), TrackOptions(lag=lag, covariance=False))
    assert not any("jumps" in m for m in run.messages), run.messages
    assert "1 of its 4 keypoints (cam1 keypoint 0) left out" in run.frames[12].vehicles[0].message
    errors = [pose_errors(fr.vehicles[0].world_T_vehicle, fr.vehicles[0].keypoints_world,
                          truth[f]["v2"].world_T_vehicle, truth[f]["v2"].keypoints_world)
              for f, fr in enumerate(run.frames)]
    assert all(fr.vehicles[0].status == Status.CONVERGED for fr in run.frames)
    assert max(e["rotation_deg"] for e in errors) < 5 and max(e["translation_cm"] for e in errors) < 60, errors


@pytest.mark.parametrize("lag", [None, 0.5])
@pytest.mark.parametrize("scenario, seed, vid, frames, level", [("tracks_3veh", 133, "v2", 24, None),
                                                                ("library_tracks_2cam", 158, "v2", 28, None),
                                                                ("tracks_3veh", 174, "v2", 25, "hard")])
def test_a_start_beyond_the_jump_gate_that_is_no_new_segment_does_not_start_the_pose(scenario, seed, vid, frames,
                                                                                     level, lag):
    """A vehicle that cam0 lost leaves cam1's view. tracks_3veh seed 133: the four keypoints of frame 21 fit the
    prediction (13 cm off) at a cost of 9.0 and a PnP pose 9.3 m off at 5.0; library_tracks_2cam seed 158: nine of
    frame 20 (one an outlier) at 50.2 and 50.1, 12.7 m off; seed 174 at hard noise: four of frame 22 at 9.9 and 2.9,
    10.8 m and 148 deg off. Beyond the jump gate, but not the quarter of the cost a new segment needs, those poses
    still started the new pose, and a fixed lag's smoother settled there: 2.2 m off, then 4.5 m; the window turned
    by up to 58 deg, then a false new segment 2.9 m off; turned by up to 78 deg, 4.3 m off; every pose
    'converged'. Now the prediction starts it (vfactor.track._START_COST_RATIO)."""
    from vfactor.evaluation import NOISE_LEVELS, noise_variant

    scenario = load_scenario(scenario)
    sim = simulate(noise_variant(scenario, **NOISE_LEVELS[level]) if level else scenario, seed=seed)
    kept = [dataclasses.replace(f, detections=[d for d in f.detections if d.vehicle == vid])
            for f in sim.scene.frames[:frames]]
    run = track_scene(dataclasses.replace(sim.scene, frames=kept), TrackOptions(lag=lag, covariance=False))
    assert not any("jumps" in m for m in run.messages), run.messages
    errors = [pose_errors(fr.vehicles[0].world_T_vehicle, fr.vehicles[0].keypoints_world,
                          sim.truth[f][vid].world_T_vehicle, sim.truth[f][vid].keypoints_world)
              for f, fr in enumerate(run.frames)]
    assert max(e["translation_cm"] for e in errors[14:]) < 50, [round(e["translation_cm"]) for e in errors]
    assert max(e["rotation_deg"] for e in errors[14:]) < 10, [round(e["rotation_deg"]) for e in errors]


def test_a_poor_fit_frame_does_not_start_its_pose_in_batch_smoothing():
    """tracks_3veh seed 169 at hard noise: the one-frame solve of v1's frame 13 is a poor fit turned over (178 deg,
    its keypoints fit twice worse than their sigmas). Batch smoothing started that pose from it, with every other
    within 31 deg, and Levenberg-Marquardt turned the whole track over (wheels where the roof is, 1.5 m off, a cost
    of 998 against 917 upright), every pose 'converged'. A poor fit now starts no pose after a track's first: the
    pose before it does."""
    from vfactor.evaluation import NOISE_LEVELS, noise_variant

    sim = simulate(noise_variant(load_scenario("tracks_3veh"), **NOISE_LEVELS["hard"]), seed=169)
    frames = [dataclasses.replace(f, detections=[d for d in f.detections if d.vehicle == "v1"])
              for f in sim.scene.frames]
    out = smooth_scene(dataclasses.replace(sim.scene, frames=frames), TrackOptions(covariance=False))
    errors = [pose_errors(fr.vehicles[0].world_T_vehicle, fr.vehicles[0].keypoints_world,
                          sim.truth[f]["v1"].world_T_vehicle, sim.truth[f]["v1"].keypoints_world)
              for f, fr in enumerate(out) if fr.vehicles and fr.vehicles[0].ok]
    assert len(errors) >= 20
    assert max(e["rotation_deg"] for e in errors) < 10, [round(e["rotation_deg"]) for e in errors]


@pytest.mark.parametrize("shape_sigma", [1e-300, 1e300])
def test_an_absurd_shape_sigma_is_held_to_its_range_in_frames_and_tracks(shape_sigma):
    """A detection's ``shape_sigma`` of 1e-300 m (the widening's ``sigma ** -2`` overflowed: an ``OverflowError``
    out of the one-frame solve) or 1e300 m: held within ``SHAPE_SIGMA_RANGE``, every frame and track is solved with
    finite covariances, with and without the cameras' offsets in the estimate; only offsets as loose as ten metres
    may leave a track's pose undetermined, which is then reported ``failed``, never raised."""
    from vfactor.graph import (SHAPE_SIGMA_RANGE, detector_offset_prior, detector_shape_sigmas,
                               observations_from_detections)
    from vfactor.solve import solve_vehicle

    sim = simulate(load_scenario("library_tracks_2cam"), seed=3, num_frames=8)
    scene = dataclasses.replace(sim.scene, frames=[
        dataclasses.replace(f, detections=[dataclasses.replace(d, shape_sigma=shape_sigma) for d in f.detections])
        for f in sim.scene.frames])
    frame = scene.frames[0]
    obs = observations_from_detections(frame.detections, scene.cameras)
    assert all(SHAPE_SIGMA_RANGE[0] <= s <= SHAPE_SIGMA_RANGE[1] for s in detector_shape_sigmas(obs).values())
    truth = sim.truth[0][frame.vehicle_ids()[0]]  # a caller giving the prior a detection's raw shape_sigma
    R = detector_offset_prior(0, shape_sigma, truth.wireframe.vehicle_p_keypoints).noiseModel().R()
    assert np.all(np.isfinite(R)) and np.linalg.matrix_rank(R) == 6
    results = [solve_vehicle(frame.detections_of(vid), scene.cameras) for vid in frame.vehicle_ids()]
    runs = [results, *(f.vehicles for f in track_scene(scene).frames), *(f.vehicles for f in smooth_scene(scene))]
    for vehicles in runs:
        for v in vehicles:
            assert v.ok and np.all(np.isfinite(v.pose_covariance))
    for frame in track_scene(scene, TrackOptions(detector_offsets=True)).frames:
        for v in frame.vehicles:
            assert (v.ok and np.all(np.isfinite(v.pose_covariance))) or (v.status.value == "failed" and v.message)
            assert v.ok or shape_sigma > 1.0


def test_a_failed_frame_leaves_the_earlier_poses_their_online_results():
    """A frame that fails (a detection naming an unknown camera) restarts the track; Tracker.estimates() kept only
    the new segment's poses and dropped the earlier ones, which track_scene reports (filtered)."""
    sim = simulate("intersection_2cam_track", seed=0, num_frames=8)
    frames = list(sim.scene.frames)
    bad = frames[4]
    frames[4] = dataclasses.replace(bad, detections=[dataclasses.replace(d, camera="camX") if i == 0 else d
                                                     for i, d in enumerate(bad.detections)])
    tracker = Tracker(sim.scene.cameras)
    online = [tracker.add_frame(frame).vehicles[0] for frame in frames]
    assert online[4].status == Status.FAILED and all(v.ok for i, v in enumerate(online) if i != 4)
    estimates = tracker.estimates(covariance=True)
    assert sorted(i for i, _ in estimates) == [0, 1, 2, 3, 5, 6, 7]
    for i in range(4):  # the results add_frame gave them, labelled as such
        assert estimates[(i, online[i].id)].world_T_vehicle.equals(online[i].world_T_vehicle, 1e-12)
        assert estimates[(i, online[i].id)].extras["covariance"] == "filtered"
    run = track_scene(dataclasses.replace(sim.scene, frames=frames))
    assert [f.vehicles[0].extras.get("covariance") for f in run.frames] == ["filtered"] * 4 + [None] + ["smoothed"] * 3


def test_the_estimates_of_a_fixed_lag_are_labelled_fixed_lag(sim):
    for lag, kind in ((0.5, "fixed_lag"), (None, "smoothed")):
        tracker = Tracker(sim.scene.cameras, TrackOptions(lag=lag))
        for frame in sim.scene.frames:
            tracker.add_frame(frame)
        kinds = {v.extras.get("covariance") for v in tracker.estimates(covariance=True).values()}
        assert kinds == {kind}, (lag, kinds)


def test_a_frame_index_a_track_holds_is_refused():
    sim = simulate("intersection_2cam_track", seed=0, num_frames=4)
    tracker = Tracker(sim.scene.cameras)
    for index, frame in zip((0, 1), sim.scene.frames):
        tracker.add_frame(frame, frame_index=index)
    with pytest.raises(InputError) as raised:  # it failed with GTSAM's "key already exists" and overwrote frame 1
        tracker.add_frame(sim.scene.frames[2], frame_index=1)
    assert raised.value.field == "frame_index" and "already names the frame at 0.1 s" in raised.value.problem
    assert tracker.add_frame(sim.scene.frames[2], frame_index=2).vehicles[0].ok  # the refused frame left no trace
    assert sorted(i for i, _ in tracker.estimates()) == [0, 1, 2]


def _ids_swapped(scene: Scene, a: str, b: str, from_frame: int) -> Scene:
    """The scene with vehicles ``a`` and ``b`` exchanging their ids from ``from_frame`` on (an id switch)."""
    swap = {a: b, b: a}
    frames = [f if i < from_frame else dataclasses.replace(f, detections=[
        dataclasses.replace(d, vehicle=swap.get(d.vehicle, d.vehicle)) for d in f.detections])
        for i, f in enumerate(scene.frames)]
    return dataclasses.replace(scene, frames=frames)


def test_batch_smoothing_cuts_a_track_where_its_id_follows_another_vehicle():
    """Two vehicles exchange their ids half way (tracks_3veh seed 1, v1 and v3 from frame 15): batch smoothing bent
    each track onto both vehicles (v1 14.5 m off before the switch, every pose `converged`, no message); it now
    cuts the tracks at the tracker's jumps and smooths each piece on its own."""
    sim = simulate("tracks_3veh", seed=1)
    scene = _ids_swapped(sim.scene, "v1", "v3", 15)
    results = smooth_scene(scene)
    truth_of = lambda f, vid: sim.truth[f][{"v1": "v3", "v3": "v1"}.get(vid, vid) if f >= 15 else vid]  # noqa: E731
    for vid in ("v1", "v3"):
        first = next(v for v in results[15].vehicles if v.id == vid)
        assert first.message.startswith("a new segment of the track:"), first.message
    errors = [pose_errors(v.world_T_vehicle, v.keypoints_world, truth_of(f, v.id).world_T_vehicle,
                          truth_of(f, v.id).keypoints_world)["translation_cm"]
              for f, frame in enumerate(results) for v in frame.vehicles if v.ok]
    assert max(errors) < 100.0, max(errors)
    assert smooth_scene(sim.scene)[15].vehicles[0].message == ""  # no switch: no cut


def test_batch_smoothing_gives_a_frame_without_keypoints_no_pose(sim):
    frames = list(sim.scene.frames)
    vid = frames[4].detections[0].vehicle
    frames[4] = dataclasses.replace(frames[4], detections=[
        dataclasses.replace(d, confidence=np.zeros(12), keypoints=np.full((12, 2), np.nan)) if d.vehicle == vid else d
        for d in frames[4].detections])
    results = smooth_scene(dataclasses.replace(sim.scene, frames=frames))
    (unseen,) = [v for v in results[4].vehicles if v.id == vid]
    assert unseen.status == Status.DEGENERATE and unseen.message == "no keypoint seen in this frame"
    assert all(v.ok for i, f in enumerate(results) for v in f.vehicles if i != 4 or v.id != vid)


def test_batch_smoothing_says_what_tracking_says_of_the_scene(sim):
    from vfactor.track import scene_notes

    shuffled = dataclasses.replace(sim.scene, frames=list(reversed(sim.scene.frames)))
    assert scene_notes(shuffled, smooth_scene(shuffled)) == track_scene(shuffled).messages
    assert scene_notes(shuffled, smooth_scene(shuffled))[0].startswith("frames are not in time order")


def test_a_smoother_stalled_short_of_its_minimum_is_solved_again():
    """iSAM2's dogleg can stall far from the minimum of its own graph (long_track, 1000 frames, a 1 s lag: a braking
    vehicle 2.5 m off over four frames of good keypoints, then taken for a jump). Here a smoother is restarted from
    its poses shifted 1.5 m: its steps leave it 1.2 m off at four times the graph's least error; Tracker._unstuck
    solves the graph by LM and restarts the smoother from the solution."""
    sim = simulate("tracks_3veh", seed=3, num_frames=12)
    tracker = Tracker(sim.scene.cameras, TrackOptions(lag=0.5, covariance=False, optimizer="dogleg"))
    for i, frame in enumerate(sim.scene.frames[:10]):
        tracker.add_frame(frame, i)
    track = tracker._tracks[sim.scene.frames[9].vehicle_ids()[0]]
    settled = track.smoother.calculateEstimate()
    _, t, key = track.poses[-1]
    factors = track.smoother.getFactors()
    graph = gtsam.NonlinearFactorGraph()
    for j in range(factors.size()):
        if factors.at(j) is not None:
            graph.add(factors.at(j))
    shifted = gtsam.Values(settled)
    for *_, k in track.poses:
        shifted.update(k, settled.atPose3(k).compose(gtsam.Pose3(gtsam.Rot3(), np.array([1.5, 0.0, 0.0]))))
    tracker._restart_smoother(track, graph, shifted, t, False)
    stalled = track.smoother.calculateEstimate()
    assert np.linalg.norm(stalled.atPose3(key).translation() - settled.atPose3(key).translation()) > 1.0
    assert graph.error(stalled) > 2.0 * graph.error(settled)
    again, _ = tracker._unstuck(track, key, t, stalled, tracker._wireframe(stalled, track))
    assert again.atPose3(key).equals(track.smoother.calculateEstimate().atPose3(key), 1e-12)
    assert np.linalg.norm(again.atPose3(key).translation() - settled.atPose3(key).translation()) < 0.01
    assert graph.error(again) < 1.01 * graph.error(settled)


def test_tracks_take_the_box_model_of_their_solve_options():
    """SolveOptions.box_model was used by one-frame solves only: tracks (online and batch) drew their boxes with the
    default model whatever the user gave (a user's audit, 2026-12-07)."""
    import dataclasses as dc

    from vfactor.box import default_box_model
    from vfactor.sim import simulate
    from vfactor.solve import SolveOptions
    from vfactor.track import TrackOptions, smooth_scene, track_scene

    base = default_box_model()
    longer = dc.replace(base, mean={t: m + np.array([0.5, 0.0, 0.0, 0.0, 0.0]) for t, m in base.mean.items()})
    scene = simulate("intersection_2cam_track", seed=0, num_frames=4).scene
    def frames(out):  # track_scene's TrackRun or smooth_scene's frames
        return out.frames if hasattr(out, "frames") else out

    for run in (track_scene, smooth_scene):
        plain = frames(run(scene, TrackOptions(covariance=False)))
        mine = frames(run(scene, TrackOptions(covariance=False, solve=SolveOptions(box_model=longer))))
        a = [v.box.size for f in plain for v in f.vehicles if v.box is not None]
        b = [v.box.size for f in mine for v in f.vehicles if v.box is not None]
        assert a and len(a) == len(b)
        assert not np.allclose(a, b), run.__name__


def test_batch_names_a_camera_whose_detections_follow_another_vehicle():
    """cam0's 2D tracker swaps two vehicles' ids half way, cam1 keeps them: the robust loss outvoted cam0 and every
    frame came out `converged` without a word (a user's audit). The frames now name the camera."""
    import dataclasses as dc

    from vfactor.sim import simulate
    from vfactor.track import smooth_scene

    scene = simulate("tracks_3veh", seed=2, num_frames=30).scene
    scene = dc.replace(scene, frames=scene.frames[8:])  # v1 and v3 in both cameras
    swap = {"v1": "v3", "v3": "v1"}
    swapped = dc.replace(scene, frames=[dc.replace(f, detections=[
        dc.replace(d, vehicle=swap.get(d.vehicle, d.vehicle)) if d.camera == "cam0" and i >= 7 else d
        for d in f.detections]) for i, f in enumerate(scene.frames)])
    plain = smooth_scene(scene)
    assert not any(v.extras.get("camera_fit_noise_scale") for f in plain for v in f.vehicles)
    odd = smooth_scene(swapped)
    for i in range(8, 21):
        v1 = {v.id: v for v in odd[i].vehicles}["v1"]
        assert set(v1.extras["camera_fit_noise_scale"]) == {"cam0"}, i
        assert "the keypoints of camera 'cam0' fit the track" in v1.message


def test_a_fixed_lag_track_does_not_drift():
    """With iSAM2's dogleg throughout (the default until 2026-12-07) a fixed-lag track fell behind: long_track with
    a 1 s lag, its online poses 12-18 cm off and their pose NEES 2-5x after 6 s (41-69 % under the chi2 95 % bound),
    where Gauss-Newton steps once the track is no longer young (the default now) keep 4-5 cm and 98-100 % (a user's
    audit found it over minutes of a stream); 14 s here."""
    from vfactor.evaluation import held_out_scene_model, pose_rows

    sim = simulate("long_track", seed=1, num_frames=140)
    run = track_scene(sim.scene, TrackOptions(lag=1.0), prior=held_out_scene_model(sim))
    late = [r for r in pose_rows(sim, run.online) if r["frame"] >= 60 and "rotation_deg" in r]
    assert len(late) > 70
    assert np.mean([r["translation_cm"] for r in late]) < 7.0
    assert np.mean([r["pose_nees"] < 12.59 for r in late]) > 0.95


def test_batch_gives_each_camera_its_noise_scale_where_the_cameras_differ():
    """Both cameras' keypoints equally precise, one camera's scores ten times lower: batch smoothing weighed that
    camera too little and the other too much (pose NEES 10.4 where equal scores gave 4.0, a user's audit). Over a
    track each camera's keypoints say their own scale: where they differ threefold the track is smoothed again
    with each camera's (here 6.0)."""
    import dataclasses as dc

    from vfactor.sim import simulate
    from vfactor.track import smooth_scene

    plain = simulate("intersection_2cam_track", seed=2, num_frames=12).scene
    low = dc.replace(plain, frames=[dc.replace(f, detections=[
        dc.replace(d, confidence=d.confidence / 10) if d.camera == "cam1" else d for d in f.detections])
        for f in plain.frames])
    equal, smoothed = smooth_scene(plain), smooth_scene(low)
    assert not any("camera_noise_factors" in v.extras for f in equal for v in f.vehicles)
    factors = [v.extras["camera_noise_factors"] for f in smoothed for v in f.vehicles if v.ok]
    assert factors and all(f["cam1"] / f["cam0"] < 0.3 for f in factors)
    for a, b in zip(equal, smoothed):  # the poses' sigmas as with equal scores
        for u, v in zip(a.vehicles, b.vehicles):
            ratio = np.sqrt(np.diag(v.pose_covariance) / np.diag(u.pose_covariance))
            assert np.all((ratio > 0.8) & (ratio < 1.3)), ratio  # one scale for all: 0.68-1.54


def test_the_tracker_gives_each_camera_its_noise_scale_where_the_cameras_differ():
    """The same with iSAM2: one scale for all kept that camera's sigmas ten times too wide and the other's too narrow
    (pose NEES 3.4x where equal scores gave 0.6x, translation 5.1 against 2.3 cm, over 30 frames); a young track's
    re-solve now finds each camera's factor as batch smoothing does, and the track keeps them."""
    import dataclasses as dc

    from vfactor.evaluation import pose_rows

    sim = simulate("intersection_2cam_track", seed=2, num_frames=12)
    low = dc.replace(sim.scene, frames=[dc.replace(f, detections=[
        dc.replace(d, confidence=d.confidence / 10) if d.camera == "cam1" else d for d in f.detections])
        for f in sim.scene.frames])
    equal, tracked = track_scene(sim.scene).frames, track_scene(low).frames
    assert not any("camera_noise_factors" in v.extras for f in equal for v in f.vehicles)
    factors = [v.extras["camera_noise_factors"] for f in tracked[6:] for v in f.vehicles if v.ok]
    assert factors and all(f["cam1"] / f["cam0"] < 0.3 for f in factors)
    for a, b in zip(equal[6:], tracked[6:]):  # the poses' sigmas about as with equal scores
        for u, v in zip(a.vehicles, b.vehicles):
            ratio = np.sqrt(np.diag(v.pose_covariance) / np.diag(u.pose_covariance))
            assert np.all((ratio > 0.75) & (ratio < 1.35)), ratio
    nees = [np.mean([r["pose_nees"] for r in pose_rows(sim, run) if "pose_nees" in r]) for run in (equal, tracked)]
    assert nees[1] < 1.5 * nees[0] + 1.0, nees


def test_a_young_track_keeps_the_dogleg():
    """Gauss-Newton steps throughout diverged at a young track at hard noise (library_tracks_2cam seed 326: a pose
    16.5 m off, `converged`); the default takes the dogleg's steps while the track is young."""
    from vfactor.evaluation import NOISE_LEVELS, held_out_scene_model, noise_variant, pose_rows

    sim = simulate(noise_variant(load_scenario("library_tracks_2cam"), **NOISE_LEVELS["hard"]), seed=326)
    run = track_scene(sim.scene, TrackOptions(), prior=held_out_scene_model(sim))
    final = [r for r in pose_rows(sim, run.frames) if "translation_cm" in r]
    assert len(final) > 60 and max(r["translation_cm"] for r in final) < 100.0


def test_a_bus_tracks_young_resolve_does_not_start_from_frames_taken_for_a_smaller_vehicle():
    """Two cameras, no road plane: of a bus's first frames solved alone two came out an estate 19 m off and a van
    3.4 m off (a smaller vehicle along the cameras' rays); the young track's re-solve started there and kept the
    track 135 degrees and 16 m off for ten frames. Frames of another type than the track's, where one of the two is
    far from the pooled prior, now start from their neighbours' poses."""
    from vfactor.evaluation import held_out_scene_model

    sim = simulate(load_scenario("library_bus_tracks_2cam"), seed=13)
    run = track_scene(sim.scene, prior=held_out_scene_model(sim))
    errors = [pose_errors(v.world_T_vehicle, v.keypoints_world, sim.truth[f][v.id].world_T_vehicle,
                          sim.truth[f][v.id].keypoints_world)
              for f, frame in enumerate(run.frames) for v in frame.vehicles if v.id == "v1" and v.ok]
    assert len(errors) >= 8 and {v.body_type for fr in run.frames for v in fr.vehicles if v.id == "v1"} == {"bus"}
    assert max(e["rotation_deg"] for e in errors) < 5.0 and max(e["translation_cm"] for e in errors) < 60.0, \
        [(round(e["rotation_deg"]), round(e["translation_cm"])) for e in errors]  # were 135 deg, 16 m


def test_a_young_bus_track_some_of_whose_frames_came_out_vans_is_a_bus():
    """Four of a bus's first seven frames solved alone came out a van or an SUV, metres off; their shape Gaussians,
    each linearised at its own frame's solution, outweighed the bus frames', and the tracker reported a van to the
    end. A young track whose frames are of both kinds is solved as each, and the better-fitting kind kept."""
    from vfactor.evaluation import held_out_scene_model

    sim = simulate(load_scenario("library_bus_tracks_2cam"), seed=1)
    run = track_scene(sim.scene, prior=held_out_scene_model(sim))
    types = [v.body_type for fr in run.frames for v in fr.vehicles if v.id == "v1" and v.ok]
    assert types and set(types[-15:]) == {"bus"}, types


def test_a_track_weighs_its_body_types_by_its_detectors_classes():
    """library_bus_tracks_2cam seed 36, the bus alone: without a road plane its two cameras' keypoints fit a van
    nearer the cameras as well, and the track was a van in every frame; the tracker and batch smoothing dropped
    the 2D detector's classes that a one-frame solve weighs the body types by. With ``"class": "bus"`` on its
    detections it is a bus in every frame, as without the class it is not."""
    from vfactor.evaluation import body_type_of, held_out_scene_model

    sim = simulate(load_scenario("library_bus_tracks_2cam"), seed=36)
    bus = next(v for f in sim.truth for v, t in f.items() if body_type_of(t.preset) == "bus")  # it enters later
    model = held_out_scene_model(sim)

    def scene_with(vehicle_class):
        frames = [Frame(f.t, [dataclasses.replace(d, vehicle_class=vehicle_class) for d in f.detections
                              if d.vehicle == bus]) for f in sim.scene.frames]
        return dataclasses.replace(sim.scene, frames=[f for f in frames if f.detections])

    def kinds(frames):
        return {v.body_type for f in frames for v in f.vehicles if v.ok}

    options = TrackOptions(covariance=False)
    assert kinds(track_scene(scene_with(None), options, prior=model).frames) == {"van"}
    assert kinds(track_scene(scene_with("bus"), options, prior=model).frames) == {"bus"}
    assert kinds(smooth_scene(scene_with("bus"), options, prior=model)) == {"bus"}


def test_one_cameras_keypoints_along_its_ray_are_its_depth_not_a_new_segment():
    """library_tracks_2cam seed 1115, the Transit Connect (v2) leaving cam0's view: frame 23's six keypoints, cam1's
    alone, fit the track's shape 4.1 m further along cam1's ray at 0.13 of the cost at the motion's prediction. That
    started a new segment 1.6 m off, which the later one-camera frames kept (the final shape 23 cm off). One view's
    depth is what it fixes least and a mature track's motion fixes it: no new segment, said so, the final shape
    within 5 cm. (Another vehicle under an id, seen elsewhere or by another camera, still starts one:
    test_ids_that_do_not_follow_one_vehicle_are_reported_not_averaged.)"""
    from vfactor.evaluation import final_shape_errors, held_out_scene_model

    sim = simulate(load_scenario("library_tracks_2cam"), seed=1115)
    scene = dataclasses.replace(sim.scene, frames=[
        dataclasses.replace(f, detections=[d for d in f.detections if d.vehicle == "v2"]) for f in sim.scene.frames])
    run = track_scene(scene, TrackOptions(covariance=False), prior=held_out_scene_model(sim))
    assert not any("jumps" in m for m in run.messages), run.messages
    message = run.frames[23].vehicles[0].message
    assert message.startswith("its keypoints put it 4.1 m from where its motion predicts along the ray of camera "
                              "'cam1', the only one that sees it: taken as that view's depth"), message
    errors = final_shape_errors(sim, run.frames)["v2"]
    assert 100 * np.linalg.norm(errors, axis=1).mean() < 5.0
