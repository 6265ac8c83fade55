"""The image-to-pose pipeline: rendered camera images and boxes -> keypoint network -> factor graph.

Uses the shipped weights on images rendered from a simulated two-camera scene
(skipped where torch or an OpenGL context is missing).
"""

from __future__ import annotations

import dataclasses
import json
import shutil

import cv2
import numpy as np
import pytest

pytest.importorskip("torch")

from vfactor.cli import main  # noqa: E402
from vfactor.errors import InputError, SceneError  # noqa: E402
from vfactor.metrics import pose_errors  # noqa: E402
from vfactor.net.infer import KeypointDetector  # noqa: E402
from vfactor.net.pipeline import detect_scene  # noqa: E402
from vfactor.scene import load_results, load_scene  # noqa: E402
from vfactor.sim import simulate  # noqa: E402
from vfactor.solve import solve_scene  # noqa: E402

from tests.net.rendered import cut_van_frame, require_rendering  # noqa: E402


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """Two frames of intersection_2cam rendered (images + boxes), with the simulation."""
    require_rendering()
    from vfactor.render.scenes import render_simulation

    sim = simulate("intersection_2cam", seed=3, num_frames=2)
    return sim, render_simulation(sim, tmp_path_factory.mktemp("rendered"), seed=3)


@pytest.fixture(scope="module")
def detector():
    return KeypointDetector()


def test_rendered_scene_gives_boxes_only_and_reloads(rendered):
    sim, r = rendered
    scene = load_scene(r.path)
    assert len(scene.frames) == 2 and set(scene.frames[0].images) == set(sim.scene.cameras)
    assert scene.undetected() == [(f, j) for f, fr in enumerate(sim.scene.frames) for j in range(len(fr.detections))]
    for f, frame in enumerate(scene.frames):
        for det in frame.detections:
            x0, y0, x1, y1 = r.boxes_true[f][(det.camera, det.vehicle)]
            side = max(x1 - x0, y1 - y0)
            assert np.allclose(det.roi, (x0, y0, x1, y1), atol=0.15 * side)  # a detector's box: noisy, not wild
            image = cv2.imread(frame.images[det.camera])
            assert image.shape == (720, 1280, 3)
    with pytest.raises(InputError, match="keypoint network"):
        solve_scene(scene)


def test_network_keypoints_and_graph_recover_the_vehicles(rendered, detector, tmp_path):
    sim, r = rendered
    detected = detect_scene(load_scene(r.path), detector, heatmaps_dir=tmp_path / "hm")
    assert detected.undetected() == []
    errors = []
    for f, frame in enumerate(detected.frames):
        for det in frame.detections:
            key = (det.camera, det.vehicle)
            visible = r.visible[f][key] & (det.confidence > 0)
            assert visible.sum() >= 4
            px = np.linalg.norm(det.keypoints[visible] - r.keypoints_true[f][key][visible], axis=1)
            x0, y0, x1, y1 = detector.crop_box(r.boxes_true[f][key])
            assert np.mean(px <= 0.1 * (x1 - x0)) >= 0.75  # PCK@0.1 of the crop side
            assert det.covariance.shape == (12, 2, 2) and np.isfinite(det.covariance[visible]).all()
            assert det.covariance_calibrated  # the shipped weights' calibration was applied
            assert det.heatmaps is not None and np.load(det.heatmaps).shape[0] == 12
    for f, frame_result in enumerate(solve_scene(detected)):
        for v in frame_result.vehicles:
            assert v.ok, v.message
            truth = sim.truth[f][v.id]
            errors.append(pose_errors(v.world_T_vehicle, v.keypoints_world, truth.world_T_vehicle,
                                      truth.keypoints_world))
    assert np.mean([e["rotation_deg"] for e in errors]) < 5.0
    assert np.mean([e["translation_cm"] for e in errors]) < 30.0


def test_images_of_the_wrong_size_or_unreadable_are_named(rendered, detector, tmp_path):
    _, r = rendered
    data = json.loads(r.path.read_text())
    for frame in data["frames"]:  # absolute paths: the edited scene is written elsewhere
        frame["images"] = {name: str(r.path.parent / path) for name, path in frame["images"].items()}
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.zeros((100, 200, 3), np.uint8))
    broken = tmp_path / "broken.png"
    broken.write_bytes(b"not an image")
    for path, message in ((small, "200x100 pixels but the camera's image_size is 1280x720"),
                          (broken, "cannot read an image")):
        edited = json.loads(json.dumps(data))
        edited["frames"][1]["images"]["cam1"] = str(path)
        scene_path = tmp_path / "scene.json"
        scene_path.write_text(json.dumps(edited))
        scene = load_scene(scene_path, allow_outside_paths=True)  # the images are the fixture's
        with pytest.raises(SceneError) as info:
            detect_scene(scene, detector)
        assert info.value.field == "frames[1].images.cam1" and message in str(info.value)


def test_cli_solve_runs_the_network_and_saves_the_detections(rendered, tmp_path, capsys):
    _, r = rendered
    folder = tmp_path / "scene"
    shutil.copytree(r.path.parent, folder)
    out, saved = tmp_path / "result.json", tmp_path / "detected.json"
    assert main(["solve", str(folder / "scene.json"), "--out", str(out), "--save-detections", str(saved)]) == 0
    assert "keypoint network: 4 boxes" in capsys.readouterr().out
    results = load_results(out)
    assert [len(f.vehicles) for f in results] == [1, 1] and all(v.ok for f in results for v in f.vehicles)
    detected = load_scene(saved)  # reloads with the network's keypoints; the heatmaps beside it
    assert detected.undetected() == [] and (tmp_path / "detected_heatmaps").is_dir()
    # Solving the saved detections again gives the same estimate.
    assert main(["solve", str(saved), "--out", str(tmp_path / "again.json"), "--quiet"]) == 0
    again = load_results(tmp_path / "again.json")
    for a, b in zip(results, again):
        np.testing.assert_allclose(a.vehicles[0].keypoints_world, b.vehicles[0].keypoints_world, atol=1e-6)
        np.testing.assert_allclose(a.vehicles[0].pose_covariance, b.vehicles[0].pose_covariance, rtol=1e-9)
    # Saving them changes nothing: the detector's boxes stay the roi (the crop boxes the heatmaps cover, which can
    # reach past the image, made views count as cut by its border); the heatmaps' box is heatmaps_roi.
    assert main(["solve", str(folder / "scene.json"), "--out", str(tmp_path / "plain.json"), "--quiet"]) == 0
    assert (tmp_path / "plain.json").read_text() == out.read_text()
    for given, kept in zip(load_scene(folder / "scene.json").frames, detected.frames):
        for g, d in zip(given.detections, kept.detections):
            assert d.roi == g.roi and d.heatmaps_roi is not None and d.heatmaps_roi != d.roi


def test_cli_bad_weights_is_input_error(rendered, tmp_path, capsys):
    _, r = rendered
    bad = tmp_path / "w.pt"
    bad.write_bytes(b"junk")
    assert main(["solve", str(r.path), "--out", str(tmp_path / "r.json"), "--weights", str(bad)]) == 2
    assert "--weights" in capsys.readouterr().err
    assert main(["solve", str(r.path), "--out", str(tmp_path / "r.json"), "--weights", str(tmp_path / "none.pt")]) == 2


def test_demo_images_writes_overlays_with_heatmaps(rendered, tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--images", "--frames", "1", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "keypoint network: 2 boxes" in text and "mean vfactor" in text
    for name in ("scene.json", "scene_keypoints.json", "scene_truth.json", "result.json", "overlay_cam0.png",
                 "overlay_cam1.png", "estimate_3d.png", "images/f0000_cam0.png"):
        assert (out / name).is_file(), name
    assert load_scene(out / "scene.json").undetected() == [(0, 0), (0, 1)]
    assert len(list((out / "heatmaps").glob("*.npy"))) == 2
    overlay = cv2.imread(str(out / "overlay_cam0.png"))
    image = cv2.imread(str(out / "images" / "f0000_cam0.png"))
    assert overlay.shape == image.shape and np.abs(overlay.astype(int) - image).mean() > 1.0


def test_cli_track_runs_the_network_too(rendered, tmp_path, capsys):
    _, r = rendered
    out = tmp_path / "track.json"
    assert main(["track", str(r.path), "--out", str(out), "--no-covariance"]) == 0
    assert "keypoint network: 4 boxes" in capsys.readouterr().out
    assert all(v.ok for f in load_results(out) for v in f.vehicles)


def test_cli_fit_ground_runs_the_network_on_image_boxes(rendered, tmp_path, capsys):
    """fit-ground finds the keypoints of a scene given as image boxes before it tracks; two frames of one vehicle
    are too little traffic for a plane, said in one line (the network ran: two poses were tracked)."""
    sim, r = rendered
    out = tmp_path / "with_plane.json"
    assert main(["fit-ground", str(r.path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "2 solved vehicle poses; a road plane needs at least 10" in err and not out.exists()


def test_cli_eval_images(rendered, tmp_path, capsys):
    md = tmp_path / "images.md"
    assert main(["eval", "images", "--frames", "2", "--seed", "4", "--markdown", str(md)]) == 0
    text = md.read_text()
    assert "vfactor eval images --frames 2 --seed 4" in text
    for method in ("factor_graph", "triangulation", "pnp", "known_shape", "factor_graph_simulated_noise"):
        assert f"| {method} | 2 |" in text
    assert "Tracking" not in text  # accuracy_2cam's frames hold new vehicles each: nothing to track
    assert main(["eval", "images", "--frames", "1", "--seed", "4", "--clipped-boxes", "--markdown", str(md)]) == 0
    assert "1 frames, seed 4, boxes clipped to the image" in md.read_text()
    assert main(["eval", "images", "--scenario", "library_2cam", "--frames", "1", "--seed", "4", "--no-real-roofs",
                 "--markdown", str(md)]) == 0
    assert "1 frames, seed 4, roofs at the window tops" in md.read_text()
    assert main(["eval", "images", "--frames", "1", "--seed", "4", "--seeds", "2", "--markdown", str(md)]) == 0
    text = md.read_text()  # each seed's report, then the seeds pooled per body type
    assert "1 frames, seed 4" in text and "1 frames, seed 5" in text and "seeds 4-5 pooled" in text
    pooled = text[text.index("seeds 4-5 pooled"):]
    assert "| all | 2 |" in pooled.split("Consistency", 1)[1]  # two vehicles: one a seed


def test_cli_eval_images_evaluates_the_given_weights(rendered, tmp_path, capsys):
    """--weights: another network's keypoints (here the shipped one without its error of the shape: the same
    estimates, narrower keypoint covariances); a bad file or another experiment is named bad input."""
    from vfactor.net.calibrate import CovarianceCalibration, write_calibration
    from vfactor.net.infer import default_weights_path

    weights = tmp_path / "no_shape_error.pt"
    shutil.copy(default_weights_path(), weights)
    calibration = KeypointDetector(weights).calibration
    write_calibration(weights, CovarianceCalibration(**{**calibration.to_dict(), "shape_sigma": 0.0}))
    texts = []
    for extra in ([], ["--weights", str(weights)]):
        md = tmp_path / f"images{len(extra)}.md"
        assert main(["eval", "images", "--frames", "1", "--seed", "4", "--markdown", str(md), *extra]) == 0
        texts.append(md.read_text())
    fg = [next(line for line in t.splitlines() if line.startswith("| factor_graph | 1 |")) for t in texts]
    assert fg[0].split("|")[:-2] == fg[1].split("|")[:-2]  # the same errors (the last column is the time)
    nees = [t.split("Consistency of the factor graph's covariances from the network", 1)[1].split("The same", 1)[0]
            for t in texts]
    assert nees[0] != nees[1]
    capsys.readouterr()
    assert main(["eval", "images", "--weights", str(tmp_path / "none.pt")]) == 2
    assert "--weights" in capsys.readouterr().err
    assert main(["eval", "frames", "--weights", str(weights)]) == 2
    assert "--weights" in capsys.readouterr().err
    assert main(["eval", "tracks", "--real-roofs"]) == 2
    err = capsys.readouterr().err
    assert err == "vfactor eval: error: --real-roofs: eval tracks renders no images (eval images does)\n"
    assert main(["eval", "frames", "--no-real-roofs"]) == 2
    assert capsys.readouterr().err.startswith("vfactor eval: error: --no-real-roofs: eval frames renders no images")


def test_lens_distortion_end_to_end(rendered, detector, tmp_path):
    """Barrel-distorted cameras: rendered with the distortion, keypoints found in the distorted image, the
    projection factors undo it."""
    import dataclasses

    from vfactor.render.scenes import render_simulation

    sim = simulate("intersection_2cam", seed=6, num_frames=2)
    cameras = {name: dataclasses.replace(cam, dist=np.array([-0.25, 0.08, 0.0, 0.0, 0.0]))
               for name, cam in sim.scene.cameras.items()}
    sim = dataclasses.replace(sim, scene=dataclasses.replace(sim.scene, cameras=cameras))
    r = render_simulation(sim, tmp_path, seed=6)
    detected = detect_scene(r.scene, detector)
    for f, frame in enumerate(detected.frames):
        for det in frame.detections:
            key = (det.camera, det.vehicle)
            # The true keypoints are projected with the distortion: the network finds them there.
            np.testing.assert_allclose(r.keypoints_true[f][key],
                                       cameras[det.camera].project(sim.truth[f][det.vehicle].keypoints_world)[0])
            visible = r.visible[f][key] & (det.confidence > 0)
            x0, y0, x1, y1 = detector.crop_box(r.boxes_true[f][key])
            px = np.linalg.norm(det.keypoints[visible] - r.keypoints_true[f][key][visible], axis=1)
            assert np.mean(px <= 0.1 * (x1 - x0)) >= 0.75
    for f, frame_result in enumerate(solve_scene(detected)):
        for v in frame_result.vehicles:
            truth = sim.truth[f][v.id]
            e = pose_errors(v.world_T_vehicle, v.keypoints_world, truth.world_T_vehicle, truth.keypoints_world)
            assert v.ok and e["rotation_deg"] < 6.0 and e["translation_cm"] < 40.0, (f, e)


def test_eval_images_tracks_a_multi_frame_scenario(rendered):
    from vfactor.net.end_to_end import evaluate_images, images_report

    evaluation = evaluate_images("intersection_2cam_track", frames=3, seed=1)
    assert evaluation["tracking"] is not None
    assert set(evaluation["tracking"]["errors"]) == {"frame_by_frame", "isam2_online", "isam2", "isam2_lag", "batch"}
    isam2 = [r for r in evaluation["tracking"]["errors"]["isam2"] if "rotation_deg" in r]
    assert len(isam2) == 3 and np.mean([r["rotation_deg"] for r in isam2]) < 5.0
    report = images_report(evaluation)
    assert "Tracking from the network's keypoints" in report
    k = evaluation["keypoints"]  # the calibration check per body type: every detection counted in one class
    assert set(k["by_body_type"]) and sum(g["d2_count"] for g in k["by_body_type"].values()) == k["d2_count"] > 0
    assert 0.2 < k["d2_mean"] < 20.0 and "mean d2 of PCK-correct keypoints" in report
    views = k["by_view"]  # vehicles whole in the image and cut by its border: every detection in one of them
    assert set(views) <= {"whole", "cut"} and sum(v["d2_count"] for v in views.values()) == k["d2_count"]
    assert sum(v["visible"] for v in views.values()) == k["visible"] and "| whole in the image |" in report


def test_a_box_beyond_the_image_border_is_cut():
    from vfactor.graph import roi_cut_by_border

    assert not roi_cut_by_border((-0.5, -0.5, 1279.5, 719.5), (1280, 720))  # the image's pixel edges
    assert roi_cut_by_border((-3.0, 10.0, 200.0, 100.0), (1280, 720))
    assert roi_cut_by_border((10, 10, 1281, 100), (1280, 720))
    assert roi_cut_by_border((10.0, 650.0, 200.0, 721.0), (1280, 720))


def test_keypoint_accuracy_d2_is_the_mahalanobis_distance_of_the_pck_correct_keypoints():
    """A 3-4-5 error under a covariance of 25 px^2 has d2 = 1; a keypoint beyond PCK@0.1 and one without a covariance
    do not count; per class the figures of that class's detections alone."""
    from vfactor.net.end_to_end import _accuracy

    truth = np.zeros((2, 12, 2))
    pred = truth.copy()
    pred[:, :, 0], pred[:, :, 1] = 3.0, 4.0
    pred[0, 0] = [50.0, 0.0]  # beyond 0.1 * 100 px: a PCK failure
    cov = np.tile(25.0 * np.eye(2), (2, 12, 1, 1))
    cov[1, 5] = np.nan  # no covariance
    mask = np.ones((2, 12), dtype=bool)
    out = _accuracy(pred, truth, mask, ~mask, np.array([100.0, 100.0]), cov)
    assert out["d2_count"] == 22 and out["d2_mean"] == pytest.approx(1.0)
    assert out["pck_visible"] == pytest.approx(23 / 24)


def test_rendered_scenes_report_only_boxes_the_network_takes():
    """The simulated 2D detector's rule (render_simulation's min_inside) is the network's MIN_ROI_INSIDE."""
    import inspect

    from vfactor.net.crop import MIN_ROI_INSIDE
    from vfactor.render.scenes import render_simulation

    assert inspect.signature(render_simulation).parameters["min_inside"].default == MIN_ROI_INSIDE


def test_detection_on_a_dask_cluster_equals_in_process(rendered, detector, tmp_path):
    """detect_scene's units (a frame's boxes) on two workers, each loading the weights once: the same keypoints."""
    pytest.importorskip("distributed")
    from vfactor.parallel import DaskEngine

    _, r = rendered
    scene = load_scene(r.path)
    serial = detect_scene(scene, detector)
    with DaskEngine(workers=2, warm=False) as engine:
        distributed = detect_scene(scene, detector, heatmaps_dir=tmp_path / "hm", engine=engine)
    for a, b in zip(serial.frames, distributed.frames):
        for da, db in zip(a.detections, b.detections):
            np.testing.assert_allclose(db.keypoints, da.keypoints, atol=1e-5)
            np.testing.assert_allclose(db.confidence, da.confidence, atol=1e-6)
            assert not db.from_image and db.heatmaps and (tmp_path / "hm").joinpath(db.heatmaps).exists()


def test_rendered_scenes_can_give_boxes_clipped_by_the_image(tmp_path):
    """render_simulation(clip_boxes=True): every box within the image, as a 2D detector gives it (tracks_3veh seed
    231's van is cut by cam1's border in every frame); the images and the true (whole) boxes are the same."""
    require_rendering()
    from vfactor.graph import roi_cut_by_border
    from vfactor.render.scenes import render_simulation

    sim = cut_van_frame()
    whole = render_simulation(sim, tmp_path / "whole", seed=231)
    clipped = render_simulation(sim, tmp_path / "clipped", seed=231, clip_boxes=True)
    assert whole.boxes_true == clipped.boxes_true
    cut = 0
    for a, b in zip(whole.scene.frames[0].detections, clipped.scene.frames[0].detections):
        width, height = whole.scene.cameras[a.camera].image_size
        assert b.roi[0] >= -0.5 and b.roi[1] >= -0.5 and b.roi[2] <= width - 0.5 and b.roi[3] <= height - 0.5
        if roi_cut_by_border(a.roi, (width, height)):
            cut += 1
            assert b.roi != a.roi
        else:
            assert b.roi == a.roi
    assert cut >= 1
    image = cv2.imread(str(whole.scene.frames[0].images["cam1"]))
    assert np.array_equal(image, cv2.imread(str(clipped.scene.frames[0].images["cam1"])))
