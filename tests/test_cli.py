"""The vfactor command: every subcommand end to end, and bad input -> a named field and exit code 2."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from vfactor.cli import main
from vfactor.scene import load_results


@pytest.fixture
def simulated(tmp_path):
    scene = tmp_path / "scene.json"
    assert main(["simulate", "intersection_2cam", "--out", str(scene), "--frames", "3", "--seed", "4"]) == 0
    return scene


def run_bad(tmp_path, capsys, data, *extra):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data) if not isinstance(data, str) else data)
    code = main(["solve", str(path), "--out", str(tmp_path / "r.json"), *extra])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err


def test_simulate_then_solve_round_trips(simulated, tmp_path, capsys):
    out = tmp_path / "result.json"
    assert main(["solve", str(simulated), "--out", str(out)]) == 0
    assert "solved 3 of 3 vehicles" in capsys.readouterr().out
    frames = load_results(out)
    assert len(frames) == 3 and all(v.status.value == "converged" for f in frames for v in f.vehicles)
    assert frames[0].vehicles[0].pose_covariance.shape == (6, 6)
    assert (tmp_path / "scene_truth.json").is_file()


def test_simulate_lists_scenarios(capsys):
    assert main(["simulate", "--list"]) == 0
    assert "intersection_2cam" in capsys.readouterr().out


def base_scene(simulated):
    return json.loads(simulated.read_text())


@pytest.mark.parametrize(
    "mutate, field",
    [
        (lambda d: d["frames"][0]["detections"][0]["keypoints"].pop(), "frames[0].detections[0].keypoints"),
        (lambda d: d["frames"][0]["detections"][0].update(camera="cam9"), "frames[0].detections[0].camera"),
        (lambda d: d["cameras"][0].update(K=[[0, 0, 640], [0, 800, 360], [0, 0, 1]]), "cameras[0].K"),
        (lambda d: d["cameras"][1].update(world_T_camera=np.eye(3).tolist()), "cameras[1].world_T_camera"),
        (lambda d: d["frames"][1].pop("t"), "frames[1].t"),
    ],
)
def test_bad_scene_names_the_field(simulated, tmp_path, capsys, mutate, field):
    data = base_scene(simulated)
    mutate(data)
    code, err = run_bad(tmp_path, capsys, data)
    assert code == 2
    assert field in err


def test_nan_keypoint_is_rejected(simulated, tmp_path, capsys):
    text = simulated.read_text()
    data = json.loads(text)
    data["frames"][0]["detections"][0]["keypoints"][3][0] = 1e400  # json writes Infinity
    code, err = run_bad(tmp_path, capsys, json.dumps(data).replace("Infinity", "NaN"))
    assert code == 2 and "frames[0].detections[0].keypoints[3]" in err


def test_missing_and_malformed_files(tmp_path, capsys):
    assert main(["solve", str(tmp_path / "nope.json"), "--out", str(tmp_path / "r.json")]) == 2
    assert "nope.json" in capsys.readouterr().err
    code, err = run_bad(tmp_path, capsys, "{not json")
    assert code == 2 and "bad.json" in err


def test_vehicle_behind_a_camera_is_reported_with_exit_3(simulated, tmp_path, capsys):
    data = base_scene(simulated)
    T = np.array(data["cameras"][1]["world_T_camera"])
    T[:3, :3] = T[:3, :3] @ np.diag([-1.0, 1.0, -1.0])  # turned around: looks away from the road
    data["cameras"][1]["world_T_camera"] = T.tolist()
    code, err = run_bad(tmp_path, capsys, data)
    assert code == 3  # EXIT_UNSOLVED: good input, a vehicle that cannot be solved
    assert "cameras[1]" in err and "world_T_camera" in err
    frames = load_results(tmp_path / "r.json")  # the result is still written, with statuses
    assert len(frames) == 3


def test_demo_writes_pictures_and_results(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--frames", "2"]) == 0
    text = capsys.readouterr().out
    assert "mean vfactor" in text and "mean triangulation" in text
    for name in ("scene.json", "scene_truth.json", "result.json", "overlay_cam0.png", "overlay_cam1.png", "estimate_3d.png"):
        assert (out / name).stat().st_size > 0, name


def test_eval_prints_the_comparison(tmp_path, capsys):
    md = tmp_path / "acc.md"
    assert main(["eval", "--frames", "3", "--markdown", str(md)]) == 0
    out = capsys.readouterr().out
    for method in ("factor_graph", "triangulation", "known_shape"):
        assert method in out
    assert "vfactor eval --frames 3" in md.read_text()
    assert "Per camera count" not in out  # library_2cam: two cameras see every vehicle


def test_eval_on_the_user_s_rig(tmp_path, capsys):
    """``vfactor eval --rig SCENE`` solves the scenario's vehicles as the cameras of the user's scene file see them
    (and ``eval tracks --rig`` its tracks); a rig whose road is not the world's z = 0 and --rig beside an experiment
    that takes no scenario are named input errors."""
    rig = tmp_path / "my_rig.json"
    assert main(["simulate", "rig_opposite_2cam", "--frames", "1", "--out", str(rig), "-q"]) == 0
    assert main(["eval", "--rig", str(rig), "--frames", "6", "--levels", "paper"]) == 0
    out = capsys.readouterr().out
    assert "### library_2cam on my_rig (paper)" in out and f"--rig {rig}" in out
    row = next(line for line in out.splitlines() if line.startswith("| factor_graph |"))
    assert row.split("|")[2].strip() == "6" and row.split("|")[3].strip() == "0", row  # six vehicles, none failed
    assert main(["eval", "tracks", "--rig", str(rig), "--scenario", "library_tracks_2cam"]) == 0
    assert "### library_tracks_2cam on my_rig, seed 0: 30 frames" in capsys.readouterr().out
    data = json.loads(rig.read_text())
    data["ground_plane"] = {"normal": [0.0, 0.0, 1.0], "offset": 2.0}
    rig.write_text(json.dumps(data))
    assert main(["eval", "--rig", str(rig), "--frames", "2"]) == 2
    assert "--rig" in capsys.readouterr().err
    assert main(["eval", "paper", "--rig", str(rig)]) == 2
    assert "--rig" in capsys.readouterr().err


def test_eval_reports_per_camera_count_where_the_count_varies(capsys):
    """Where vehicles are seen by different numbers of cameras, ``vfactor eval`` adds the accuracy and the
    covariances' consistency per camera count (the project reports per class, camera count included)."""
    assert main(["eval", "--scenario", "rig_spread_4cam", "--frames", "10", "--levels", "paper", "--road-plane"]) == 0
    out = capsys.readouterr().out
    section = out[out.index("Per camera count"):]
    accuracy = section[section.index("| cameras | vehicles | factor_graph"):].split("\n\n")[0].splitlines()[2:]
    counts = {int(line.split("|")[1]): int(line.split("|")[2]) for line in accuracy}
    assert len(counts) > 1 and set(counts) <= {1, 2, 3, 4} and sum(counts.values()) == 10, counts
    consistency = section[section.index("| cameras | vehicles | pose NEES"):].split("\n\n")[0].splitlines()[2:]
    assert [line.split("|")[1].strip() for line in consistency] == [str(c) for c in sorted(counts)] + ["all"]


def test_eval_association_at_a_noise_level_beside_the_true_ids(tmp_path, capsys):
    """``vfactor eval association --levels hard`` replaces the scenario's keypoint noise and says so in its tables
    and in the command it echoes; a noise level of an experiment that has none is a named input error."""
    md = tmp_path / "assoc.md"
    assert main(["eval", "association", "--scenario", "intersection_2cam_track", "--frames", "6", "--levels", "hard",
                 "--markdown", str(md)]) == 0
    out = capsys.readouterr().out
    assert "keypoint noise hard" in out and "| intersection_2cam_track (hard) | 0 | 6 |" in out
    row = next(line for line in out.splitlines() if line.startswith("| intersection_2cam_track (hard)"))
    precision, recall = (float(x) for x in row.split("|")[5:7])
    assert 0.9 <= precision <= 1.0 and 0.9 <= recall <= 1.0, row
    assert "vfactor eval association --scenario intersection_2cam_track --frames 6 --levels hard" in md.read_text()
    assert main(["eval", "tracks", "--levels", "hard"]) == 2
    assert "--levels" in capsys.readouterr().err
    assert main(["eval", "association", "--levels", "harder"]) == 2
    assert "--levels" in capsys.readouterr().err


def test_eval_tracks_over_noise_draws(capsys):
    assert main(["eval", "tracks", "--scenario", "intersection_2cam_track", "--frames", "6", "--draws", "2"]) == 0
    out = capsys.readouterr().out
    assert "over 2 draws of the keypoint noise" in out and "| v1 | 2 |" in out
    assert "--draws 2" in out
    assert "Pose NEES per body-frame axis" in out and "| isam2 | 6 |" in out  # roll ... z, each 1 when consistent
    assert main(["eval", "tracks", "--draws", "-1"]) == 2
    assert "--draws" in capsys.readouterr().err
    assert main(["eval", "tracks", "--lag", "0"]) == 2
    assert "--lag" in capsys.readouterr().err
    assert main(["eval", "tracks", "--scenario", "intersection_2cam_track", "--frames", "4", "--body-motion", "5,2"]) == 0
    assert "--body-motion 5,2" in capsys.readouterr().out
    for bad in ("5", "5,x", "-1,2", "5,30"):
        assert main(["eval", "tracks", f"--body-motion={bad}"]) == 2
        assert "--body-motion" in capsys.readouterr().err
    assert main(["eval", "--body-motion", "5,2"]) == 2  # one-frame scenes have no accelerations
    assert "--body-motion" in capsys.readouterr().err
    assert main(["eval", "tracks", "--scenario", "accuracy_2cam"]) == 2  # independent frames: nothing to track
    assert "no motion" in capsys.readouterr().err


def test_eval_tracks_pools_its_seeds_per_body_type_and_camera_count(capsys):
    """With several seeds, ``vfactor eval tracks`` ends with the seeds pooled per body type and per camera count, and
    each body type's final shapes against 5 cm (the project reports per class, not only means)."""
    assert main(["eval", "tracks", "--scenario", "intersection_2cam_track", "--frames", "6", "--seeds", "2"]) == 0
    out = capsys.readouterr().out
    pooled = out[out.index("### intersection_2cam_track, seeds 0-1 pooled"):]
    assert "Pooled, per body type" in pooled and "Pooled, per cameras" in pooled and "| 2 cameras |" in pooled
    table = pooled[pooled.index("| body type | scene | tracks |"):].split("\n\n")[0].splitlines()
    tracks = sum(int(line.split("|")[3]) for line in table[2:] if line.startswith("| "))
    assert tracks == 2  # one vehicle a seed
    row = next(line for line in pooled.splitlines() if line.startswith("| all | intersection_2cam_track"))
    isam2 = row.split("|")[5]  # frame_by_frame, isam2_online, isam2: rotation / translation / NEES
    rotation, translation = (float(x) for x in isam2.split("/")[:2])
    assert 0 < rotation < 5 and 0 < translation < 30, row


def test_unknown_scenario_and_bad_counts_exit_2(tmp_path, capsys):
    assert main(["simulate", "no_such_rig", "--out", str(tmp_path / "s.json")]) == 2
    assert "packaged" in capsys.readouterr().err
    assert main(["demo", "--frames", "0", "--out", str(tmp_path / "d")]) == 2
    capsys.readouterr()
    assert main(["eval", "paper", "--seeds", "2"]) == 2  # one seed: not silently the first of two
    err = capsys.readouterr().err
    assert "--seeds" in err and "one seed" in err and len(err.strip().splitlines()) == 1
    for args, flag in ((["eval", "--draws", "3"], "--draws"), (["eval", "--lag", "1"], "--lag"),
                       (["eval", "tracks", "--figures", str(tmp_path)], "--figures"),
                       (["eval", "--sweep-frames", "5"], "--sweep-frames"),
                       (["eval", "tracks", "--clipped-boxes"], "--clipped-boxes"),
                       (["eval", "--no-detector-offsets"], "--detector-offsets")):
        assert main(args) == 2, args  # another experiment's option: named, not silently dropped
        err = capsys.readouterr().err
        assert err.startswith(f"vfactor eval: error: {flag}: only eval ") and len(err.strip().splitlines()) == 1, err


def test_help_teaches_and_module_runs():
    out = subprocess.run([sys.executable, "-m", "vfactor", "--help"], capture_output=True, text=True, check=True).stdout
    assert "vfactor demo" in out and "world_T_vehicle" in out


def test_track_writes_results_and_plot(tmp_path, capsys):
    scene = tmp_path / "track.json"
    assert main(["simulate", "intersection_2cam_track", "--out", str(scene), "--frames", "8"]) == 0
    out, plot = tmp_path / "tracked.json", tmp_path / "tracks.png"
    assert main(["track", str(scene), "--out", str(out), "--plot", str(plot)]) == 0
    assert "tracked 1 vehicles over 8 frames" in capsys.readouterr().out
    frames = load_results(out)
    assert len(frames) == 8 and all(f.vehicles[0].status.value == "converged" for f in frames)
    assert plot.stat().st_size > 0
    from vfactor.scene import load_scene
    from vfactor.track import TrackOptions, track_scene

    api = track_scene(load_scene(scene), TrackOptions()).frames  # the CLI runs the tracker's default settings
    for a, b in zip(frames, api):
        assert np.allclose(a.vehicles[0].world_T_vehicle.matrix(), b.vehicles[0].world_T_vehicle.matrix(), atol=1e-9)
        assert np.allclose(a.vehicles[0].wireframe.vehicle_p_keypoints, b.vehicles[0].wireframe.vehicle_p_keypoints,
                           atol=1e-9)
    assert main(["track", str(scene), "--out", str(out), "--lag", "0.3", "--online"]) == 0
    assert main(["track", str(scene), "--out", str(out), "--batch"]) == 0
    assert main(["track", str(scene), "--out", str(out), "--lag", "-1"]) == 2
    assert "--lag" in capsys.readouterr().err


def test_track_with_detector_offsets(tmp_path):
    """``--detector-offsets`` gives each camera's detections that carry a shape_sigma their own pose offset, in
    the tracker (also with a lag) and batch smoothing: the CLI's results are the API's with the option."""
    from vfactor.scene import load_scene
    from vfactor.track import TrackOptions, track_scene

    scene = tmp_path / "track.json"
    assert main(["simulate", "intersection_2cam_track", "--out", str(scene), "--frames", "8"]) == 0
    data = json.loads(scene.read_text())
    for frame in data["frames"]:
        for detection in frame["detections"]:
            detection["shape_sigma"] = 0.04
    scene.write_text(json.dumps(data))
    out = tmp_path / "tracked.json"
    assert main(["track", str(scene), "--out", str(out), "--detector-offsets"]) == 0
    frames = load_results(out)
    api = track_scene(load_scene(scene), TrackOptions(detector_offsets=True)).frames
    plain = track_scene(load_scene(scene), TrackOptions()).frames
    for a, b, c in zip(frames, api, plain):
        assert np.allclose(a.vehicles[0].world_T_vehicle.matrix(), b.vehicles[0].world_T_vehicle.matrix(), atol=1e-9)
        assert not np.allclose(a.vehicles[0].pose_covariance, c.vehicles[0].pose_covariance, rtol=1e-3)
    for extra in (["--lag", "0.3"], ["--batch"]):
        assert main(["track", str(scene), "--out", str(out), "--detector-offsets", *extra]) == 0
        assert all(f.vehicles[0].status.value == "converged" for f in load_results(out))


def test_eval_paper_writes_tables_and_plots(tmp_path, capsys):
    md, figures = tmp_path / "paper.md", tmp_path / "figures"
    assert main(["eval", "paper", "--frames", "3", "--sweep-frames", "3", "--markdown", str(md),
                 "--figures", str(figures)]) == 0
    text = md.read_text()
    assert "Table II layout" in text and "Table I layout" in text and "| cpo |" in text
    assert (figures / "paper_noise.png").stat().st_size > 0 and (figures / "paper_cameras.png").stat().st_size > 0
