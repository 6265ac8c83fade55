"""Helpers and fixtures of the output-format tests: boxes of known pose on known cameras, and one real solve."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

from vfactor.box import Box
from vfactor.camera import Camera
from vfactor.observations import Detection, Frame, Scene
from vfactor.result import FrameResult, Status, VehicleResult

K = np.array([[1000.0, 0.0, 639.5], [0.0, 1000.0, 359.5], [0.0, 0.0, 1.0]])
MM = 1e-3
DEG = math.radians(0.1)


def level_camera() -> Camera:
    """At (0, 0, 1.5) looking along world +x: camera x = world -y, camera y = world -z, camera z = world +x."""
    T = np.eye(4)
    T[:3, :3] = np.column_stack([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    T[:3, 3] = [0.0, 0.0, 1.5]
    return Camera("level", K, T, image_size=(1280, 720))


def tilted_camera() -> Camera:
    """On a 6 m pole at (0, -4, 6), looking down at (15, 2, 0) (about 20 degrees), with lens distortion."""
    eye, target = np.array([0.0, -4.0, 6.0]), np.array([15.0, 2.0, 0.0])
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = eye
    return Camera("tilted", K, T, dist=[-0.05, 0.01, 0.0, 0.0, 0.0], image_size=(1280, 720))


def make_box(centre, yaw_deg: float, pitch_deg: float = 0.0, roll_deg: float = 0.0, size=(4.5, 1.8, 1.5)) -> Box:
    R = gtsam.Rot3.Ypr(math.radians(yaw_deg), math.radians(pitch_deg), math.radians(roll_deg))
    return Box(gtsam.Pose3(R, np.asarray(centre, float)), np.asarray(size, float), size_sigma=np.array([0.2, 0.1, 0.05]),
               heading=math.radians(yaw_deg), heading_sigma=0.03, centre_sigma=np.array([0.1, 0.08, 0.05]))


def solved(vid: str, box: Box, posterior: dict | None = None) -> VehicleResult:
    posterior = posterior or {"sedan": 0.9, "suv": 0.1}
    best = max(posterior, key=posterior.get)
    return VehicleResult(id=vid, status=Status.CONVERGED, world_T_vehicle=box.world_T_box, box=box,
                         pose_covariance=np.diag([1e-4, 1e-4, 4e-4, 0.01, 0.01, 0.004]), body_type=best,
                         body_type_probability=posterior[best], extras={"body_type_posterior": posterior})


def failed(vid: str) -> VehicleResult:
    return VehicleResult(id=vid, status=Status.FAILED, message="LM raised on every start")


def detection(camera: Camera, vid: str, box: Box) -> Detection:
    """The box's 8 corners and its centre-front/back stand in for 12 keypoints: projected, 2 unseen."""
    corners = np.vstack([_corners(box), box.world_T_box.transformFrom(np.array([2.0, 0, 0]))[None],
                         box.world_T_box.transformFrom(np.array([-2.0, 0, 0]))[None],
                         box.world_T_box.translation()[None], box.world_T_box.translation()[None]])
    uv, _ = camera.project(corners)
    confidence = np.full(12, 0.9)
    confidence[[10, 11]] = 0.0
    uv[[10, 11]] = np.nan
    return Detection(camera.name, vid, uv, confidence)


def _corners(box: Box) -> np.ndarray:
    l, w, h = box.size / 2
    return np.array([box.world_T_box.transformFrom(np.array([sx * l, sy * w, sz * h]))
                     for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)])


@pytest.fixture(scope="session")
def known():
    """Three frames on a level and a tilted camera, with the boxes the tests know by heart.

    Frame 0: ``a`` heading +90 deg at (10, 2, 0.75); ``b`` heading 0 with pitch 5 and roll -3 deg at (14, -3, 0.8);
    ``c`` failed. Frame 1 (t = 0.5 s): ``a`` moved 2.5 m along +y (5 m/s), ``b`` still, a pickup ``d`` at heading
    180 deg. Frame 2 (t = 1.0 s): ``a`` another 2.5 m.
    """
    cams = {"level": level_camera(), "tilted": tilted_camera()}
    a0, a1, a2 = (make_box([10.0, 2.0 + 2.5 * k, 0.75], 90.0) for k in range(3))
    b = make_box([14.0, -3.0, 0.8], 0.0, 5.0, -3.0, size=(4.8, 1.9, 1.6))
    d = make_box([25.0, 4.0, 0.95], 180.0, size=(5.3, 1.9, 1.9))
    pickup = {"pickup": 0.7, "suv": 0.2, "van": 0.1}
    results = [
        FrameResult(0.0, [solved("a", a0), solved("b", b), failed("c")]),
        FrameResult(0.5, [solved("a", a1), solved("b", b), solved("d", d, pickup)]),
        FrameResult(1.0, [solved("a", a2)]),
    ]
    frames = [Frame(r.t, [detection(cam, v.id, v.box) for cam in cams.values() for v in r.vehicles if v.box])
              for r in results]
    frames[0].detections.append(detection(cams["level"], "c", a0))
    return Scene(cams, frames), results


@pytest.fixture(scope="session")
def real():
    """A real two-camera solve of two simulated frames (intersection_2cam, seed 0)."""
    from vfactor.sim import load_scenario, simulate
    from vfactor.solve import solve_scene

    sim = simulate(load_scenario("intersection_2cam"), seed=0, num_frames=2)
    return sim.scene, solve_scene(sim.scene)


@pytest.fixture(scope="session")
def real_track():
    """A real track of three simulated frames (intersection_2cam, seed 0): boxes without sigmas."""
    from vfactor.sim import load_scenario, simulate
    from vfactor.track import track_scene

    sim = simulate(load_scenario("intersection_2cam"), seed=0, num_frames=3)
    return sim.scene, track_scene(sim.scene).frames


def rotation_error(R1, R2) -> float:
    """Angle (rad) of R1^T R2."""
    c = (np.trace(np.asarray(R1).T @ np.asarray(R2)) - 1.0) / 2.0
    return float(math.acos(min(1.0, max(-1.0, c))))


def assert_same_box(got: Box, want: Box, rotation: bool = True):
    assert np.allclose(got.world_T_box.translation(), want.world_T_box.translation(), atol=MM)
    assert np.allclose(got.size, want.size, atol=MM)
    assert abs(math.remainder(got.heading - want.heading, 2 * math.pi)) < DEG
    if rotation:
        assert rotation_error(got.world_T_box.rotation().matrix(), want.world_T_box.rotation().matrix()) < DEG
