"""The renderer: K exactly, features at the projected keypoints, depth, occlusion flags, distortion."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from vfactor.camera import Camera
from vfactor.render.mesh import Appearance, Part, box_mesh
from vfactor.render.renderer import OCCLUDER_ID, Renderer, VehicleInstance, keypoint_annotations
from vfactor.sim.visibility import self_occluded

from .conftest import FLAT, blob_centroid, camera_around, prius_on_road

RIM = (0.0, 0.9, 0.0)
CAP = (0.9, 0.0, 0.9)
HEAD = (0.0, 0.0, 1.0)
TAIL = (1.0, 0.0, 0.0)
LOOK = Appearance(paint=(0.5, 0.5, 0.5), trim=(0.2, 0.2, 0.2), rim=RIM, cap=CAP, head_light=HEAD, tail_light=TAIL,
                  light_emission=0.0, texture=0.0, paint_specular=0.0, glass_specular=0.0)


@pytest.fixture(scope="module")
def renderer(gl_context):
    return Renderer(640, 480, supersample=2)


def test_projected_keypoints_land_on_their_features(renderer):
    wf, pose, r = prius_on_road()
    cam = camera_around(pose, 60.0, 6.0, 12.0)  # front-left quarter: left hubs, both front lights
    res = renderer.render(cam, [(wf, pose, LOOK, r)], light=FLAT, ground=False)
    ann = res.annotations[0]
    assert ann.visible[[0, 2, 4, 5, 6, 8, 9, 10, 11]].all() and ann.self_occluded[[1, 3, 7]].all()
    px = np.rint(ann.uv).astype(int)
    for k in (0, 2):  # the hub is the centre of the cap, inside the green rim
        u, v = px[k]
        assert res.part_ids[v, u] == Part.RIM and res.vehicle_ids[v, u] == 0
        r_, g, b = res.image[v, u]
        assert r_ > 150 and b > 150 and g < 60, res.image[v, u]  # the magenta cap
    for k in (4, 5):  # the lights' outer corners: blue head-light pixels next to them
        u, v = px[k]
        win = res.part_ids[v - 1 : v + 2, u - 1 : u + 2]
        assert (win == Part.HEAD_LIGHT).any()
        blue = res.image[v - 1 : v + 2, u - 1 : u + 2].reshape(-1, 3)
        assert (blue[:, 2] > 150).any() and (blue[:, 0] < 60).any()
    for k in (8, 9, 10, 11):  # roof corners: on the vehicle; the windshield's corners touch its glass
        u, v = px[k]
        win = res.part_ids[v - 2 : v + 3, u - 2 : u + 3]
        assert (win == Part.BODY).any() and (res.vehicle_ids[v - 1 : v + 2, u - 1 : u + 2] == 0).any()
        if k in (8, 9):
            assert (win == Part.GLASS).any()


@pytest.mark.parametrize("K", [
    [[700.0, 0.0, 319.5], [0.0, 700.0, 239.5], [0.0, 0.0, 1.0]],
    [[820.0, 3.0, 301.2], [0.0, 760.0, 255.7], [0.0, 0.0, 1.0]],  # skew, fx != fy, off-centre principal point
])
def test_opengl_projection_uses_K_exactly(renderer, K):
    """The hub caps' rendered centroids sit on Camera.project of the hubs within a fraction of a pixel."""
    wf, pose, r = prius_on_road()
    base = camera_around(pose, 90.0, 5.0, 9.0)  # a side view: the caps are nearly round
    cam = Camera("k", K, base.world_T_camera, image_size=(640, 480))
    res = renderer.render(cam, [(wf, pose, LOOK, r)], light=FLAT, ground=False)
    cap = (res.image[..., 0] > 120) & (res.image[..., 2] > 120) & (res.image[..., 1] < 80)
    uv = res.annotations[0].uv
    for k in (0, 2):
        assert np.linalg.norm(blob_centroid(cap, uv[k]) - uv[k]) < 0.35, k


def test_depth_matches_the_geometry(renderer):
    wf, pose, r = prius_on_road()
    cam = camera_around(pose, 40.0, 7.0, 15.0)
    res = renderer.render(cam, [(wf, pose, LOOK, r)], light=FLAT)
    ann = res.annotations[0]
    for k in (0, 2, 8, 9):  # hubs (on the cap plane) and the windshield corners
        u, v = np.rint(ann.uv[k]).astype(int)
        window = res.depth[v - 1 : v + 2, u - 1 : u + 2]
        assert np.abs(window - ann.depth[k]).min() < 0.03, (k, window, ann.depth[k])
    # The road: depth of a pixel on z = 0 is exact.
    v, u = 470, 20
    assert res.vehicle_ids[v, u] == -1 and res.part_ids[v, u] == Part.GROUND
    ray = np.linalg.solve(cam.K, [u, v, 1.0])
    R, t = cam.world_T_camera[:3, :3], cam.world_T_camera[:3, 3]
    z_true = -t[2] / (R @ ray)[2]
    assert abs(res.depth[v, u] - z_true) < 0.02 * z_true / 10


@pytest.mark.parametrize("azimuth", [30.0, 60.0, 90.0, 120.0, 150.0, 210.0, 240.0, 270.0, 300.0, 330.0])
def test_self_occlusion_agrees_with_the_hull_model_and_the_depth_buffer(renderer, azimuth):
    wf, pose, r = prius_on_road()
    cam = camera_around(pose, azimuth, 7.0, 14.0)
    res = renderer.render(cam, [(wf, pose, LOOK, r)], light=FLAT, ground=False)
    ann = res.annotations[0]
    hull = self_occluded(cam, wf, pose, r)
    # Hubs and roof corners: the mesh and vfactor.sim.visibility's convex hull agree.
    # (Lights can differ: the hull lies flat from the lights to the roof, so it shows far-side lights
    # over the hood that the mesh's hood hides; docs/rendering.md.)
    idx = [0, 1, 2, 3, 8, 9, 10, 11]
    assert np.array_equal(ann.self_occluded[idx], hull[idx])
    # Near-side lights of quarter views are visible in both.
    near = {30.0: [4], 60.0: [4], 120.0: [6], 150.0: [6], 210.0: [7], 240.0: [7], 300.0: [5], 330.0: [5]}
    for k in near.get(azimuth, []):
        assert not ann.self_occluded[k] and not hull[k]
    # The depth buffer: something nearer at hidden keypoints; the keypoint's own surface at visible ones.
    for k in range(12):
        u, v = np.rint(ann.uv[k]).astype(int)
        window = res.depth[v - 1 : v + 2, u - 1 : u + 2]
        if ann.self_occluded[k]:
            assert res.depth[v, u] < ann.depth[k] - 0.05, k
        else:
            assert window.max() > ann.depth[k] - 0.03, k


def test_occlusion_by_another_object(renderer):
    wf, pose, r = prius_on_road()
    cam = camera_around(pose, 90.0, 6.0, 12.0)
    t = pose.translation()
    near = t[:2] + 0.2 * (cam.center[:2] - t[:2])
    wall = box_mesh([near[0], near[1], 1.25], (0.8, 0.8, 2.5), yaw=0.3, color=(0.9, 0.9, 0.1))
    res = renderer.render(cam, [(wf, pose, LOOK, r)], light=FLAT, occluders=[wall], ground=False)
    ann = res.annotations[0]
    assert ann.occluded_by_other.any() and not ann.occluded_by_other.all()
    for k in np.nonzero(ann.occluded_by_other)[0]:
        u, v = np.rint(ann.uv[k]).astype(int)
        assert res.vehicle_ids[v, u] == OCCLUDER_ID
    assert not ann.visible[ann.occluded_by_other].any()
    # A second vehicle in front hides the first one's keypoints too, and not its own.
    front = t[:2] + 2.2 / 12.0 * (cam.center[:2] - t[:2])
    wf2, pose2, r2 = prius_on_road(yaw=0.4, x=front[0], y=front[1])
    res2 = renderer.render(cam, [(wf, pose, LOOK, r), (wf2, pose2, None, r2)], ground=False, light=FLAT)
    assert res2.annotations[0].occluded_by_other[[0, 2]].all()  # the near-side hubs
    assert not res2.annotations[1].occluded_by_other.any()
    assert set(np.unique(res2.vehicle_ids)) == {-1, 0, 1}


@pytest.mark.parametrize("model, dist", [("pinhole", [-0.25, 0.08, 0.001, -0.001, 0.0]),
                                         ("fisheye", [0.05, -0.01, 0.002, 0.0])])
def test_lens_distortion_by_remapping(renderer, model, dist):
    wf, pose, r = prius_on_road()
    base = camera_around(pose, 90.0, 5.0, 9.0, hfov_deg=60.0)
    cam = Camera("d", base.K, base.world_T_camera, dist=dist, image_size=(640, 480), model=model)
    res = renderer.render(cam, [(wf, pose, LOOK, r)], light=FLAT, ground=False)
    cap = (res.image[..., 0] > 120) & (res.image[..., 2] > 120) & (res.image[..., 1] < 80)
    uv = res.annotations[0].uv
    undistorted = cam.K @ np.c_[cam.undistort_pixels(uv), np.ones(12)].T
    assert np.abs(undistorted[:2].T - uv).max() > 2.0  # distortion matters here
    for k in (0, 2):
        assert np.linalg.norm(blob_centroid(cap, uv[k]) - uv[k]) < 0.6, k


def test_background_image_and_rgb_order(gl_context):
    renderer = Renderer(160, 120, supersample=1)
    wf, pose, r = prius_on_road()
    cam = camera_around(pose, 45.0, 6.0, 14.0, size=(160, 120))
    background = np.zeros((120, 160, 3), np.uint8)
    background[..., 1] = 200
    red = Appearance(paint=(0.9, 0.05, 0.05), texture=0.0)
    res = renderer.render(cam, [(wf, pose, red, r)], background=background, ground=False, light=FLAT)
    empty = np.isinf(res.depth)
    assert empty.any() and (res.image[empty] == [0, 200, 0]).all()
    body = res.part_ids == Part.BODY
    assert (res.image[body][:, 0].astype(int) > res.image[body][:, 2].astype(int) + 50).mean() > 0.8  # RGB


def test_annotations_without_rendering_and_inputs(gl_context):
    wf, pose, r = prius_on_road()
    cam = camera_around(pose, 45.0, 6.0, 14.0)
    a = keypoint_annotations(cam, [VehicleInstance(wf, pose, None, r)])[0]
    uv, depth = cam.project(wf.in_world(pose))
    assert np.allclose(a.uv, uv) and np.allclose(a.depth, depth)
    # The box is in pixel edges (u + 0.5), and holds every keypoint (they are mesh vertices).
    assert a.box[0] <= uv[:, 0].min() + 0.5 + 1e-9 and a.box[2] >= uv[:, 0].max() + 0.5 - 1e-9
    assert a.box[1] <= uv[:, 1].min() + 0.5 + 1e-9 and a.box[3] >= uv[:, 1].max() + 0.5 - 1e-9
    with pytest.raises(ValueError, match="image_size"):
        Renderer(100, 100, supersample=1).render(cam, [(wf, pose)])
    with pytest.raises(TypeError, match="vehicles"):
        keypoint_annotations(cam, [wf])
    flying = pose.compose(gtsam.Pose3(gtsam.Rot3(), np.array([0.0, 0.0, 3.0])))
    with pytest.raises(ValueError, match="wheel_radius"):
        keypoint_annotations(cam, [(wf, flying)])  # hubs 3 m above the road and no wheel radius given
