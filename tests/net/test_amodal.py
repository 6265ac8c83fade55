"""Boxes clipped by the image border replaced by the solved vehicles' boxes (vfactor.net.amodal).

On one rendered frame of tracks_3veh seed 231, whose van is cut by cam1's border, with the boxes a 2D detector
gives (clipped to the image) and the shipped weights (skipped where torch or an OpenGL context is missing).
"""

from __future__ import annotations

import dataclasses
import json

import gtsam
import numpy as np
import pytest

pytest.importorskip("torch")

from vfactor.box import vehicle_box  # noqa: E402
from vfactor.cli import main  # noqa: E402
from vfactor.evaluation import body_type_of  # noqa: E402
from vfactor.heatmaps import clipped_by_border, edges_at_border  # noqa: E402
from vfactor.net.amodal import amodal_boxes, projected_box, redetect_clipped  # noqa: E402
from vfactor.net.infer import KeypointDetector  # noqa: E402
from vfactor.net.pipeline import detect_scene  # noqa: E402
from vfactor.result import FrameResult, Status, VehicleResult  # noqa: E402

from tests.net.rendered import cut_van_frame, require_rendering  # noqa: E402


def _iou(a, b) -> float:
    inter = max(0.0, min(a[2], b[2]) - max(a[0], b[0])) * max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


@pytest.fixture(scope="module")
def clipped(tmp_path_factory):
    """(simulation, rendered scene with clipped boxes, the true results: each vehicle's true pose, shape and box)."""
    require_rendering()
    from vfactor.render.scenes import render_simulation

    sim = cut_van_frame()
    rendered = render_simulation(sim, tmp_path_factory.mktemp("clipped"), seed=231, clip_boxes=True)
    truth = [FrameResult(frame.t, [
        VehicleResult(vid, Status.CONVERGED, world_T_vehicle=t.world_T_vehicle, wireframe=t.wireframe,
                      box=vehicle_box(t.world_T_vehicle, t.wireframe, None, {body_type_of(t.preset): 1.0}))
        for vid, t in sim.truth[f].items()]) for f, frame in enumerate(sim.scene.frames)]
    return sim, rendered, truth


def test_a_box_at_the_image_border_is_clipped():
    assert edges_at_border((-0.5, 10, 300, 719.5), 1280, 720) == (True, False, False, True)
    assert clipped_by_border((0.2, 10, 300, 200), (1280, 720))
    assert clipped_by_border((900, 10, 1279.4, 200), (1280, 720))
    assert not clipped_by_border((5, 10, 300, 200), (1280, 720))
    assert not clipped_by_border((-80, 10, 300, 200), (1280, 720))  # a whole vehicle's box, beyond the border


def test_the_projected_box_of_a_vehicle_is_its_rendered_box(clipped):
    """The image box of a vehicle's 3D box (from its true pose and shape), shrunk to the body, against the rendered
    vehicle's own box, beyond the image border too."""
    sim, rendered, truth = clipped
    boxes = {v.id: v.box for v in truth[0].vehicles}
    ious = [_iou(projected_box(sim.scene.cameras[camera], boxes[vid]), box)
            for (camera, vid), box in rendered.boxes_true[0].items()]
    assert len(ious) >= 4 and min(ious) > 0.7 and np.median(ious) > 0.8
    camera = sim.scene.cameras["cam0"]
    behind = dataclasses.replace(next(iter(boxes.values())), world_T_box=gtsam.Pose3(np.asarray(camera.world_T_camera)))
    assert projected_box(camera, behind) is None  # a box around the camera: corners behind it


def test_clipped_boxes_become_the_solved_vehicles_whole_boxes(clipped):
    sim, rendered, truth = clipped
    scene = rendered.scene
    out, replaced = amodal_boxes(scene, truth)
    at_border = [clipped_by_border(d.roi, scene.cameras[d.camera].image_size) for d in scene.frames[0].detections]
    assert replaced == sum(at_border) >= 1
    for before, after, cut in zip(scene.frames[0].detections, out.frames[0].detections, at_border):
        if not cut:
            assert after is before
            continue
        assert after.from_image and np.all(np.isnan(after.keypoints)) and after.shape_sigma is None
        whole = rendered.boxes_true[0][(after.camera, after.vehicle)]
        assert _iou(after.roi, whole) > 0.75 > _iou(before.roi, whole)  # beyond the border, as the vehicle is
    # a vehicle solved elsewhere (10 m on) keeps its box: where both can be seen, the boxes must agree
    moved = [FrameResult(truth[0].t, [dataclasses.replace(v, box=dataclasses.replace(
        v.box, world_T_box=gtsam.Pose3(v.box.world_T_box.rotation(), v.box.world_T_box.translation() + [10.0, 0, 0])))
        for v in truth[0].vehicles])]
    assert amodal_boxes(scene, moved)[1] == 0
    unsolved = [FrameResult(truth[0].t, [VehicleResult(v.id, Status.FAILED) for v in truth[0].vehicles])]
    assert amodal_boxes(scene, unsolved)[1] == 0
    with pytest.raises(ValueError, match="results: expected one per frame"):
        amodal_boxes(scene, truth * 2)


def test_keypoints_found_again_in_the_whole_box_are_closer_to_the_truth(clipped):
    """The shipped network on the clipped boxes puts the keypoints it cannot see inside them; in the whole box it
    finds them beyond the border."""
    sim, rendered, truth = clipped
    detector = KeypointDetector()
    first = detect_scene(rendered.scene, detector)
    again, replaced = redetect_clipped(first, truth, detector)
    assert replaced >= 1

    def errors(scene):  # pixels, the keypoints of the detections whose boxes were clipped
        out = []
        for given, det in zip(rendered.scene.frames[0].detections, scene.frames[0].detections):
            if clipped_by_border(given.roi, scene.cameras[det.camera].image_size):
                true_uv = rendered.keypoints_true[0][(det.camera, det.vehicle)]
                out.append(np.linalg.norm(det.keypoints - true_uv, axis=1))
        return np.concatenate(out)

    before, after = errors(first), errors(again)
    assert np.nanmedian(after) < 0.7 * np.nanmedian(before)
    assert redetect_clipped(first, [FrameResult(0.0, [])], detector) == (first, 0)  # nothing to replace: as it was


def test_cli_amodal_pass(clipped, tmp_path, capsys):
    sim, rendered, truth = clipped
    out = tmp_path / "tracks.json"
    assert main(["track", str(rendered.path), "--out", str(out), "--amodal-pass", "--no-covariance"]) in (0, 3)
    assert "amodal pass:" in capsys.readouterr().out and json.loads(out.read_text())["frames"]
    assert main(["solve", str(rendered.path), "--out", str(tmp_path / "s.json"), "--amodal-pass",
                 "--save-detections", str(tmp_path / "d.json")]) == 2
    assert "--amodal-pass: not with --save-detections" in capsys.readouterr().err
    keypoints = tmp_path / "keypoints.json"  # a scene whose detections give keypoints: nothing for the network
    main(["solve", str(rendered.path), "--out", str(tmp_path / "s.json"), "--save-detections", str(keypoints)])
    capsys.readouterr()
    assert main(["track", str(keypoints), "--out", str(tmp_path / "t.json"), "--amodal-pass",
                 "--allow-outside-paths"]) == 2
    assert "--amodal-pass: no detection of the scene is given as an image box" in capsys.readouterr().err
    assert main(["eval", "frames", "--amodal-pass"]) == 2
    assert "--amodal-pass: only with eval images --clipped-boxes" in capsys.readouterr().err
