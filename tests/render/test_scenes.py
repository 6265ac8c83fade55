"""render_simulation: camera images of a simulated scene and the scene file of images and boxes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from vfactor.render.scenes import render_simulation
from vfactor.scene import load_scene
from vfactor.sim import simulate


def test_images_boxes_and_truth(gl_context, tmp_path):
    sim = simulate("intersection_2cam", seed=5, num_frames=1)
    r = render_simulation(sim, tmp_path, seed=5, box_noise=0.0, pixel_noise=0.0)
    scene = load_scene(tmp_path / "scene.json")
    assert r.path == tmp_path / "scene.json"
    assert [(d.camera, d.vehicle) for d in scene.frames[0].detections] == \
        [(d.camera, d.vehicle) for d in sim.scene.frames[0].detections]
    for det in scene.frames[0].detections:
        key = (det.camera, det.vehicle)
        assert det.from_image and det.roi == pytest.approx(r.boxes_true[0][key])
        # The box holds every keypoint of the vehicle (some lie on its edges: the mesh is built around
        # them); the true keypoints are the simulation's projections.
        uv = r.keypoints_true[0][key]
        x0, y0, x1, y1 = det.roi
        assert np.all((uv[:, 0] >= x0 - 1) & (uv[:, 0] <= x1 + 1) & (uv[:, 1] >= y0 - 1) & (uv[:, 1] <= y1 + 1))
        expected = sim.scene.cameras[det.camera].project(sim.truth[0][det.vehicle].keypoints_world)[0]
        np.testing.assert_allclose(uv, expected, atol=1e-6)
        assert r.visible[0][key].sum() >= 4


def test_real_roofs_raise_a_high_roof_vans_box_and_not_its_keypoints(gl_context, tmp_path):
    sim = simulate("library_2cam", seed=300, num_frames=6)  # frame 5: a Renault Master L2H2 (high roof)
    sim = dataclasses.replace(sim, scene=dataclasses.replace(sim.scene, frames=sim.scene.frames[5:]),
                              truth=sim.truth[5:])
    assert [t.preset for t in sim.truth[0].values()] == ["renault_master_3_l2h2"]
    low = render_simulation(sim, tmp_path / "low", seed=1, box_noise=0.0, pixel_noise=0.0, real_roofs=False)
    high = render_simulation(sim, tmp_path / "high", seed=1, box_noise=0.0, pixel_noise=0.0)  # the default
    for key, box in low.boxes_true[0].items():  # the roof shows above the window tops: the box's top rises
        assert high.boxes_true[0][key][1] < box[1] - 10, key
        np.testing.assert_allclose(high.boxes_true[0][key][3], box[3], atol=1.0)
        np.testing.assert_array_equal(high.keypoints_true[0][key], low.keypoints_true[0][key])


def test_same_seed_same_images(gl_context, tmp_path):
    sim = simulate("intersection_2cam", seed=5, num_frames=1)
    a = render_simulation(sim, tmp_path / "a", seed=1)
    b = render_simulation(sim, tmp_path / "b", seed=1)
    for name in sim.scene.cameras:
        assert (tmp_path / "a" / "images" / f"f0000_{name}.png").read_bytes() == \
            (tmp_path / "b" / "images" / f"f0000_{name}.png").read_bytes()
    assert [d.roi for d in a.scene.frames[0].detections] == [d.roi for d in b.scene.frames[0].detections]


def test_bad_arguments(tmp_path):
    sim = simulate("intersection_2cam", seed=5, num_frames=1)
    with pytest.raises(ValueError, match="box_noise, pixel_noise"):
        render_simulation(sim, tmp_path, box_noise=-0.1)
    cam = next(iter(sim.scene.cameras))
    cameras = dict(sim.scene.cameras)
    cameras[cam] = dataclasses.replace(cameras[cam], image_size=None)
    blind = dataclasses.replace(sim, scene=dataclasses.replace(sim.scene, cameras=cameras))
    with pytest.raises(ValueError, match=f"cameras.{cam}.image_size"):
        render_simulation(blind, tmp_path)
