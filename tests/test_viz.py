"""Tests of vfactor.viz: camera stand-in images, overlays, the estimates figure."""

from __future__ import annotations

import cv2
import gtsam
import matplotlib
import numpy as np
import pytest

from vfactor import viz
from vfactor.camera import Camera
from vfactor.observations import Detection, Frame
from vfactor.result import FrameResult, Status, VehicleResult
from vfactor.wireframe import PRESETS

WIDTH, HEIGHT = 640, 480
K = np.array([[800.0, 0.0, 319.5], [0.0, 800.0, 239.5], [0.0, 0.0, 1.0]])


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """world_T_camera of an OpenCV camera (x right, y down, z forward) at ``eye`` looking at ``target``."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = eye
    return T


def make_camera(name="cam0", eye=(-15.0, -6.0, 3.0), dist=None, model="pinhole") -> Camera:
    # About 9 degrees down: the horizon crosses the top half of the image.
    return Camera(name, K, look_at(eye, (0.0, 0.0, 0.5)), dist=dist, image_size=(WIDTH, HEIGHT), model=model)


@pytest.fixture
def vehicle():
    wireframe = PRESETS["toyota_prius"].wireframe()
    pose = gtsam.Pose3(gtsam.Rot3.Yaw(np.radians(30.0)), np.array([0.0, 0.0, 0.32]))
    result = VehicleResult(
        id="v1",
        status=Status.CONVERGED,
        world_T_vehicle=pose,
        wireframe=wireframe,
        pose_covariance=np.diag([1e-5, 1e-5, 4e-5, 0.03**2, 0.01**2, 0.005**2]),
    )
    truth_pose = gtsam.Pose3(gtsam.Rot3.Yaw(np.radians(31.0)), np.array([0.02, -0.01, 0.32]))
    return result, {"v1": (truth_pose, wireframe)}


def detection_of(camera: Camera, points_world: np.ndarray, vehicle="v1") -> Detection:
    uv, _ = camera.project(points_world)
    confidence = np.linspace(0.2, 1.0, 12)
    confidence[[3, 9]] = 0.0
    keypoints = uv.copy()
    keypoints[confidence == 0] = np.nan
    return Detection(camera=camera.name, vehicle=vehicle, keypoints=keypoints, confidence=confidence)


def is_sky(bgr: np.ndarray) -> np.ndarray:
    """Bluish: blue clearly above red."""
    b, r = bgr[..., 0].astype(int), bgr[..., 2].astype(int)
    return b - r > 25


def is_ground(bgr: np.ndarray) -> np.ndarray:
    """Grey: channels close together."""
    b, r = bgr[..., 0].astype(int), bgr[..., 2].astype(int)
    return np.abs(b - r) < 15


def test_public_names():
    for name in viz.__all__:
        assert hasattr(viz, name), name
    assert {"draw_view", "draw_overlay", "plot_estimates", "write_overlays"} <= set(viz.__all__)


# ----------------------------------------------------------------- draw_view
def test_draw_view_shape_dtype_sky_above_ground_below():
    img = viz.draw_view(make_camera())
    assert img.shape == (HEIGHT, WIDTH, 3)
    assert img.dtype == np.uint8
    # Horizon: v = cy - fy tan(pitch), about 115 px for this camera.
    top = img[40:80, 200:]  # right of the name label
    bottom = img[HEIGHT // 2 :]
    assert is_sky(top).mean() > 0.95
    assert is_ground(bottom).mean() > 0.95
    assert not is_sky(bottom).any()


def test_draw_view_has_grid_lines_on_the_ground():
    img = viz.draw_view(make_camera())
    rows = img[HEIGHT - 60 :].astype(int).sum(axis=2)
    # Lines are lighter than the plain ground between them.
    assert rows.max() - np.median(rows) > 60


def test_draw_view_size_defaults_to_principal_point():
    camera = Camera("c", K, look_at((-15.0, -6.0, 3.0), (0.0, 0.0, 0.5)))
    assert viz.draw_view(camera).shape == (480, 640, 3)
    assert viz.draw_view(camera, image_size=(320, 200)).shape == (200, 320, 3)


def test_draw_view_with_distortion_and_without_ground():
    distorted = make_camera(dist=[-0.3, 0.1, 0.001, -0.001, 0.0])
    img = viz.draw_view(distorted)
    assert img.shape == (HEIGHT, WIDTH, 3)
    assert is_ground(img[HEIGHT // 2 :]).mean() > 0.95
    looking_up = Camera("up", K, look_at((0.0, 0.0, 2.0), (5.0, 0.0, 12.0)), image_size=(WIDTH, HEIGHT))
    sky = viz.draw_view(looking_up)
    assert is_sky(sky[100:]).all()


def test_draw_view_with_the_other_lens_models():
    for camera in (make_camera(dist=[-0.3, 0.1, 0.001, -0.001, 0.01, 0.05, -0.01, 0.002, 0.001, 0.0, 0.001, 0.0,
                                     0.01, -0.01]),
                   make_camera(model="fisheye", dist=[0.05, -0.01, 0.002, 0.0])):
        img = viz.draw_view(camera)
        assert img.shape == (HEIGHT, WIDTH, 3)
        assert is_ground(img[HEIGHT // 2 :]).mean() > 0.95


# -------------------------------------------------------------- draw_overlay
@pytest.mark.parametrize("model, dist", [("pinhole", None), ("fisheye", [0.05, -0.01, 0.002, 0.0])])
def test_draw_overlay_marks_projected_keypoints(vehicle, model, dist):
    result, _ = vehicle
    camera = make_camera(model=model, dist=dist)
    base = viz.draw_view(camera)
    before = base.copy()
    out = viz.draw_overlay(base, camera, keypoints_world=result.keypoints_world, legend=False)
    np.testing.assert_array_equal(base, before)  # input untouched
    assert out is not base and out.shape == base.shape and out.dtype == np.uint8
    uv, depth = camera.project(result.keypoints_world)
    assert np.all(depth > 0)
    for k in range(4):  # the wheel hubs
        u, v = np.round(uv[k]).astype(int)
        assert 0 <= u < WIDTH and 0 <= v < HEIGHT
        assert np.any(out[v, u] != base[v, u]), f"wheel hub {k} not drawn"
    # Far from the vehicle nothing changes.
    np.testing.assert_array_equal(out[:30, -30:], base[:30, -30:])


def test_draw_overlay_observed_keypoints_skip_unseen(vehicle):
    result, _ = vehicle
    camera = make_camera()
    base = viz.draw_view(camera)
    detection = detection_of(camera, result.keypoints_world)
    # Move the unseen keypoint 3 somewhere empty: it must not be drawn there.
    detection.keypoints[3] = (600.0, 400.0)
    out = viz.draw_overlay(base, camera, detection=detection, legend=False)
    for k in np.nonzero(detection.confidence > 0)[0]:
        u, v = np.round(detection.keypoints[k]).astype(int)
        assert np.any(out[v, u] != base[v, u]), f"observed keypoint {k} not drawn"
    np.testing.assert_array_equal(out[390:411, 590:611], base[390:411, 590:611])
    # Colour by confidence: the most confident keypoint is drawn green.
    u, v = np.round(detection.keypoints[11]).astype(int)
    b, g, r = out[v, u].astype(int)
    assert g > 150 and g > r and g > b


def test_draw_overlay_truth_and_estimate(vehicle):
    result, truth = vehicle
    camera = make_camera()
    base = viz.draw_view(camera)
    pose, wireframe = truth["v1"]
    only_truth = viz.draw_overlay(base, camera, truth_keypoints_world=wireframe.in_world(pose), legend=False)
    assert np.count_nonzero(np.any(only_truth != base, axis=2)) > 100
    both = viz.draw_overlay(
        base, camera, keypoints_world=result.keypoints_world, truth_keypoints_world=wireframe.in_world(pose)
    )
    assert np.count_nonzero(np.any(both != only_truth, axis=2)) > 100


def test_draw_overlay_skips_points_behind_camera(vehicle):
    result, _ = vehicle
    camera = make_camera()
    base = viz.draw_view(camera)
    # Mirror the vehicle through the camera centre: everything behind it.
    behind = 2 * camera.center - result.keypoints_world
    assert np.all(camera.project(behind)[1] < 0)
    out = viz.draw_overlay(base, camera, keypoints_world=behind, truth_keypoints_world=behind, legend=False)
    np.testing.assert_array_equal(out, base)


def test_draw_overlay_straddling_the_camera_does_not_fail():
    camera = make_camera(dist=[-0.3, 0.1, 0.0, 0.0, 0.0])
    wireframe = PRESETS["toyota_prius"].wireframe()
    # The car's middle at the camera: some keypoints in front, some behind.
    pose = gtsam.Pose3(gtsam.Rot3(), camera.center - np.array([0.0, 0.0, 1.0]))
    points = wireframe.in_world(pose)
    depth = camera.project(points)[1]
    assert (depth > 0).any() and (depth < 0).any()
    out = viz.draw_overlay(viz.draw_view(camera), camera, keypoints_world=points)
    assert out.shape == (HEIGHT, WIDTH, 3)


def test_draw_overlay_heatmaps_blend_inside_roi():
    camera = make_camera()
    base = viz.draw_view(camera)
    heatmaps = np.zeros((12, 32, 32))
    heatmaps[0, 14:18, 14:18] = 1.0
    roi = (100.0, 200.0, 228.0, 328.0)  # 4 px per heatmap pixel
    out = viz.draw_overlay(base, camera, heatmaps=heatmaps, roi=roi, legend=False)
    assert np.any(out[264, 164] != base[264, 164])  # the peak, at the roi's centre
    np.testing.assert_array_equal(out[:150], base[:150])  # above the roi
    np.testing.assert_array_equal(out[:, 300:], base[:, 300:])  # right of the roi


def test_draw_overlay_heatmap_peak_lands_where_vfactor_heatmaps_maps_it():
    camera = make_camera()
    base = np.full((HEIGHT, WIDTH, 3), 60, np.uint8)
    heatmaps = np.zeros((12, 32, 32))
    heatmaps[5, 10, 20] = 1.0  # row 10, column 20
    roi = (100.0, 200.0, 228.0, 328.0)  # edges; 4 image px per heatmap px
    out = viz.draw_overlay(base, camera, heatmaps=heatmaps, roi=roi, legend=False)
    change = np.abs(out.astype(int) - base).sum(axis=2)
    v, u = np.unravel_index(np.argmax(change[205:320, 105:220]), (115, 115))
    # Centre of heatmap pixel (col 20, row 10): u = x0 + (20 + 0.5) * 4 - 0.5 = 181.5, v = 241.5.
    assert abs(u + 105 - 181.5) <= 1.5 and abs(v + 205 - 241.5) <= 1.5


def test_draw_overlay_accepts_grey_images_and_rejects_bad_shapes(vehicle):
    result, _ = vehicle
    camera = make_camera()
    grey = np.full((HEIGHT, WIDTH), 90, np.uint8)
    assert viz.draw_overlay(grey, camera, keypoints_world=result.keypoints_world).shape == (HEIGHT, WIDTH, 3)
    with pytest.raises(ValueError, match="keypoints_world"):
        viz.draw_overlay(grey, camera, keypoints_world=np.zeros((11, 3)))
    with pytest.raises(ValueError, match="heatmaps"):
        viz.draw_overlay(grey, camera, heatmaps=np.zeros((3, 8, 8)))
    with pytest.raises(ValueError, match="image"):
        viz.draw_overlay(np.zeros((4, 4, 2), np.uint8), camera)


# ---------------------------------------------------------------- covariances
def test_position_covariance_world_rotates_the_body_block():
    pose = gtsam.Pose3(gtsam.Rot3.Yaw(np.pi / 2), np.array([1.0, 2.0, 0.0]))
    cov = np.diag([1e-4, 2e-4, 3e-4, 4.0, 1.0, 0.25])
    world = viz.position_covariance_world(pose, cov)
    # Body x (variance 4) points along world y after a 90 degree yaw.
    np.testing.assert_allclose(world, np.diag([1.0, 4.0, 0.25]), atol=1e-12)
    with pytest.raises(ValueError, match="pose_covariance"):
        viz.position_covariance_world(pose, np.eye(3))


# -------------------------------------------------------------------- figures
def test_plot_estimates_writes_a_png(tmp_path, vehicle):
    result, truth = vehicle
    cameras = {"cam0": make_camera("cam0"), "cam1": make_camera("cam1", eye=(10.0, -12.0, 6.0))}
    failed = VehicleResult(id="v2", status=Status.DEGENERATE, message="2 keypoints seen")
    no_cov = VehicleResult(
        id="v3", status=Status.MAX_ITERATIONS,
        world_T_vehicle=gtsam.Pose3(gtsam.Rot3(), np.array([4.0, 3.0, 0.32])), wireframe=result.wireframe,
    )
    backend = matplotlib.get_backend()
    path = viz.plot_estimates(cameras, [result, failed, no_cov], truth, tmp_path / "sub" / "est.png", title="test")
    assert matplotlib.get_backend() == backend  # pyplot's backend untouched
    assert path.is_file() and path.stat().st_size > 10_000
    img = cv2.imread(str(path))
    assert img is not None and img.shape[0] > 400 and img.shape[1] > 800
    # Without truth, without cameras, nothing but failures: still a figure.
    assert cv2.imread(str(viz.plot_estimates(cameras, [result], None, tmp_path / "b.png"))) is not None
    assert cv2.imread(str(viz.plot_estimates({}, [failed], None, tmp_path / "c.png"))) is not None
    with pytest.raises(ValueError, match="sigma"):
        viz.plot_estimates(cameras, [result], None, tmp_path / "d.png", sigma=0)


def test_plot_estimates_grows_a_panel_per_vehicle_and_a_table_row_per_result(tmp_path, vehicle):
    import dataclasses

    result, truth = vehicle
    cameras = {"cam0": make_camera("cam0")}
    many = [dataclasses.replace(result, id=f"v{k}", world_T_vehicle=gtsam.Pose3(
        gtsam.Rot3.Yaw(0.4 * k), np.array([6.0 * (k % 4), 6.0 * (k // 4), 0.32]))) for k in range(8)]
    one = cv2.imread(str(viz.plot_estimates(cameras, many[:1], None, tmp_path / "one.png")))
    eight = cv2.imread(str(viz.plot_estimates(cameras, many, None, tmp_path / "eight.png")))
    # a second row of panels (six to a row) and seven more table rows make the figure taller, not more crowded
    assert eight.shape[0] > one.shape[0] + 250 and eight.shape[1] == one.shape[1]


def test_vehicle_tags_never_overlap():
    img = np.full((200, 300, 3), 128, np.uint8)
    anchors = [(150.0, 100.0 + d) for d in (0, 2, 4, 6, 8)] + [(5.0, 3.0), (298.0, 199.0)]
    rects = viz._draw_tags(img, [(f"v{k}", a) for k, a in enumerate(anchors)], 0.6)
    assert len(rects) == len(anchors)
    for i, a in enumerate(rects):
        assert 0 <= a[0] < a[2] <= 300 and 0 <= a[1] < a[3] <= 200, a
        for b in rects[i + 1:]:
            assert not (a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]), (a, b)


# ------------------------------------------------------------------- overlays
def test_write_overlays_one_file_per_camera(tmp_path, vehicle):
    result, truth = vehicle
    cameras = {
        "north": make_camera("north"),
        "east": Camera("east", K, look_at((12.0, 5.0, 6.0), (0.0, 0.0, 0.5)), image_size=(320, 240)),
    }
    frame = Frame(t=0.5, detections=[detection_of(cameras["north"], result.keypoints_world)])
    paths = viz.write_overlays(tmp_path / "out", cameras, frame, [result], truth)
    assert [p.name for p in paths] == ["overlay_north.png", "overlay_east.png"]
    for path, camera in zip(paths, cameras.values()):
        img = cv2.imread(str(path))
        assert img is not None
        assert img.shape[1::-1] == camera.image_size


# --------------------------------------------------------------- trajectories
DT = 0.1
NUM_TRACK_FRAMES = 15


def track_cameras() -> dict[str, Camera]:
    """Two pole cameras on opposite corners of an intersection, as in intersection_2cam."""
    return {
        "cam0": make_camera("cam0", eye=(-14.0, -11.0, 7.5)),
        "cam1": make_camera("cam1", eye=(13.0, 12.0, 7.0)),
    }


def tracking_results(gap: bool = True):
    """A 15-frame, 2-track tracking result with truth and frame-by-frame estimates.

    v1 drives along +x at 8 m/s in the near lane, v2 along -x at 6 m/s in the far
    lane. The tracked covariance shrinks with the frames (std 20 cm for v1, 26 cm for v2, over sqrt(f + 1)
    along the car, half across); the frame-by-frame one stays at 20 cm. With
    ``gap``, v2 fails in frames 6 and 7, and a third vehicle v3 is detected once
    and comes out degenerate.
    """
    rng = np.random.default_rng(3)
    shapes = {"v1": PRESETS["toyota_prius"].wireframe(), "v2": PRESETS["toyota_prius"].wireframe().scaled(1.1)}
    starts = {"v1": (-8.0, -1.75, 0.0, 8.0), "v2": (7.0, 1.75, np.pi, 6.0)}  # x, y, yaw, speed
    frames, truth, frame_by_frame = [], [], []
    for f in range(NUM_TRACK_FRAMES):
        t = f * DT
        tracked, independent, true = [], [], {}
        for vid, (x0, y0, yaw, speed) in starts.items():
            heading = np.array([np.cos(yaw), np.sin(yaw), 0.0])
            pose = gtsam.Pose3(gtsam.Rot3.Yaw(yaw), np.array([x0, y0, 0.33]) + speed * t * heading)
            true[vid] = (pose, shapes[vid])
            if gap and vid == "v2" and f in (6, 7):
                tracked.append(VehicleResult(id=vid, status=Status.FAILED, message="solve raised"))
                independent.append(VehicleResult(id=vid, status=Status.DEGENERATE, message="3 keypoints seen"))
                continue
            std = (0.20 if vid == "v1" else 0.26) / np.sqrt(f + 1.0)
            cov = np.diag([(0.02 / np.sqrt(f + 1)) ** 2, 1e-5, (0.04 / np.sqrt(f + 1)) ** 2, std**2, (std / 2) ** 2,
                           (std / 3) ** 2])
            noise = rng.normal(size=3) * [std, std / 2, std / 3]
            est = gtsam.Pose3(gtsam.Rot3.Yaw(yaw + rng.normal() * 0.01), pose.transformFrom(noise))
            tracked.append(VehicleResult(id=vid, status=Status.CONVERGED, world_T_vehicle=est,
                                         wireframe=shapes[vid], pose_covariance=cov))
            cov_fbf = np.diag([4e-4, 4e-4, 2e-3, 0.2**2, 0.1**2, 0.07**2])
            noise = rng.normal(size=3) * [0.2, 0.1, 0.07]
            est = gtsam.Pose3(gtsam.Rot3.Yaw(yaw + rng.normal() * 0.04), pose.transformFrom(noise))
            independent.append(VehicleResult(id=vid, status=Status.CONVERGED, world_T_vehicle=est,
                                             wireframe=shapes[vid], pose_covariance=cov_fbf))
        if gap and f == 9:
            tracked.append(VehicleResult(id="v3", status=Status.DEGENERATE, message="2 keypoints seen"))
        frames.append(FrameResult(t=t, vehicles=tracked))
        frame_by_frame.append(FrameResult(t=t, vehicles=independent))
        truth.append(true)
    return frames, truth, frame_by_frame


def test_plot_trajectories_writes_a_png(tmp_path):
    frames, truth, frame_by_frame = tracking_results()
    backend = matplotlib.get_backend()
    path = viz.plot_trajectories(
        track_cameras(), frames, tmp_path / "sub" / "trajectories.png", truth=truth, title="test",
        frame_by_frame=frame_by_frame,
    )
    assert matplotlib.get_backend() == backend
    assert path == tmp_path / "sub" / "trajectories.png"
    assert path.is_file() and path.stat().st_size > 50_000
    img = cv2.imread(str(path))
    assert img is not None and img.shape[0] > 800 and img.shape[1] > 1200
    # Not a blank page: plenty of non-white pixels, and the track colours appear.
    assert np.mean(np.any(img < 240, axis=2)) > 0.05


def test_plot_trajectories_accepts_vehicle_truth_and_plain_inputs(tmp_path):
    from vfactor.sim import VehicleTruth

    frames, truth, _ = tracking_results(gap=False)
    vt = [{vid: VehicleTruth(pose, wf, "toyota_prius") for vid, (pose, wf) in entry.items()} for entry in truth]
    vt[4] = None  # a frame without truth
    path = viz.plot_trajectories(track_cameras(), frames, tmp_path / "a.png", truth=vt, sigma=2.0, ellipse_every=3)
    assert cv2.imread(str(path)) is not None
    # Lists of VehicleResults instead of FrameResults, no cameras, no truth.
    lists = [fr.vehicles for fr in frames]
    assert cv2.imread(str(viz.plot_trajectories({}, lists, tmp_path / "b.png", ellipse_every=1))) is not None


def test_plot_trajectories_gaps_failures_and_degenerate_inputs(tmp_path):
    frames, truth, frame_by_frame = tracking_results(gap=True)
    # v2 fails in frames 6-7 (a break in its track), v3 exists only as a degenerate result.
    assert not frames[6].vehicles[1].ok and frames[9].vehicles[-1].id == "v3"
    path = viz.plot_trajectories(track_cameras(), frames, tmp_path / "gap.png", truth=truth,
                                 frame_by_frame=frame_by_frame, ellipse_every=2)
    assert cv2.imread(str(path)) is not None
    # No covariances at all, one frame, nothing but failures, no frames.
    no_cov = [FrameResult(fr.t, [VehicleResult(r.id, r.status, r.world_T_vehicle, r.wireframe, None)
                                  for r in fr.vehicles]) for fr in frames]
    assert cv2.imread(str(viz.plot_trajectories(track_cameras(), no_cov, tmp_path / "c.png", truth=truth)))is not None
    assert cv2.imread(str(viz.plot_trajectories(track_cameras(), frames[:1], tmp_path / "d.png"))) is not None
    failed = [FrameResult(0.0, [VehicleResult("v1", Status.FAILED, message="x")])]
    assert cv2.imread(str(viz.plot_trajectories(track_cameras(), failed, tmp_path / "e.png"))) is not None
    assert cv2.imread(str(viz.plot_trajectories({}, [], tmp_path / "f.png"))) is not None
    # Times that do not increase: frame indices on the time axis.
    same_t = [FrameResult(0.0, fr.vehicles) for fr in frames]
    assert cv2.imread(str(viz.plot_trajectories(track_cameras(), same_t, tmp_path / "g.png"))) is not None


def test_plot_trajectories_rejects_bad_arguments(tmp_path):
    frames, truth, frame_by_frame = tracking_results(gap=False)
    cameras = track_cameras()
    for sigma in (0, -1.0, float("nan"), float("inf"), "three"):
        with pytest.raises(ValueError, match="sigma"):
            viz.plot_trajectories(cameras, frames, tmp_path / "x.png", sigma=sigma)
    for every in (0, -2, 2.5, True, "5"):
        with pytest.raises(ValueError, match="ellipse_every"):
            viz.plot_trajectories(cameras, frames, tmp_path / "x.png", ellipse_every=every)
    with pytest.raises(ValueError, match="truth"):
        viz.plot_trajectories(cameras, frames, tmp_path / "x.png", truth=truth[:-1])
    with pytest.raises(ValueError, match="frame_by_frame"):
        viz.plot_trajectories(cameras, frames, tmp_path / "x.png", frame_by_frame=frame_by_frame[1:])
    assert not (tmp_path / "x.png").exists()
