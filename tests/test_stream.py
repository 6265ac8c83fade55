"""vfactor.stream and ``vfactor track -`` / ``--follow``: JSON Lines in, a result line per frame out."""

from __future__ import annotations

import dataclasses
import io
import json
import sys
import threading
import time

import numpy as np
import pytest

from vfactor.cli import main
from vfactor.errors import InputError
from vfactor.scene import scene_to_dict
from vfactor.sim import simulate
from vfactor.solve import SolveOptions
from vfactor.stream import StreamTracker, follow_lines, track_stream
from vfactor.track import Tracker, TrackOptions, track_scene


@pytest.fixture(scope="module")
def sim():
    return simulate("tracks_3veh", seed=3, num_frames=8)


def _lines(scene) -> list[str]:
    data = scene_to_dict(scene)
    frames = data.pop("frames")
    return [json.dumps(data) + "\n"] + [json.dumps(f) + "\n" for f in frames]


def test_stream_gives_the_online_estimates_of_track_scene(sim):
    options = TrackOptions(solve=SolveOptions(covariance=False), lag=0.5, covariance=False)
    items = list(track_stream(_lines(sim.scene), options))
    online = track_scene(sim.scene, options).online
    assert [item.frame for item in items] == list(range(len(sim.scene.frames)))
    for item, expected in zip(items, online):
        assert not item.note and not item.error
        assert [v.id for v in item.result.vehicles] == [v.id for v in expected.vehicles]
        for v, w in zip(item.result.vehicles, expected.vehicles):
            assert v.status == w.status
            assert np.allclose(v.world_T_vehicle.matrix(), w.world_T_vehicle.matrix(), atol=1e-9)


def test_a_stream_goes_on_past_the_key_schemes_frame_numbers(sim):
    """A live stream at 10 Hz reaches frame 10^6 (KeyScheme.frame_stride) after 28 hours: it went on raising there."""
    options = TrackOptions(solve=SolveOptions(covariance=False), lag=0.5, covariance=False)
    tracker = StreamTracker(sim.scene, options)
    stride = tracker.tracker.keys.frame_stride
    results = [tracker.add(frame, stride - 4 + n) for n, frame in enumerate(sim.scene.frames)]
    online = track_scene(sim.scene, options).online
    for (result, note), expected in zip(results, online):
        assert note == "" and [v.status for v in result.vehicles] == [v.status for v in expected.vehicles]
        for v, w in zip(result.vehicles, expected.vehicles):
            assert np.allclose(v.world_T_vehicle.matrix(), w.world_T_vehicle.matrix(), atol=1e-9)


def test_late_and_bad_lines_are_reported_and_the_stream_goes_on(sim):
    lines = _lines(sim.scene)
    late = lines[2]  # frame 1 again, after frame 3
    lines = lines[:4] + ["\n", "{not json\n", late, json.dumps({"t": 9.0, "detections": [{"camera": "nope"}]}) + "\n"] \
        + lines[4:]
    items = list(track_stream(lines, TrackOptions(solve=SolveOptions(covariance=False), lag=0.5, covariance=False)))
    assert [i.frame for i in items] == list(range(len(items)))
    bad, repeated, unknown = items[3], items[4], items[5]
    assert bad.result is None and bad.line == 6 and "not JSON" in bad.error
    assert repeated.note.startswith("arrived late: t = 0.1 s") and repeated.result.vehicles
    assert all(v.ok for v in repeated.result.vehicles)
    assert unknown.error.startswith("frame.detections[0]") and unknown.to_dict() == {
        "frame": 5, "line": 8, "error": unknown.error}
    assert all(i.result is not None for i in items[6:])  # the tracks go on after the bad lines
    out = items[4].to_dict()
    assert out["frame"] == 4 and out["note"] == repeated.note and out["vehicles"][0]["status"] == "converged"


def test_bad_header_and_no_lag(sim):
    with pytest.raises(InputError, match="header: the stream is empty"):
        list(track_stream([]))
    with pytest.raises(InputError, match="header: the stream's first line is not JSON"):
        list(track_stream(["[1, 2\n"]))
    with pytest.raises(InputError, match="^cameras"):
        list(track_stream(['{"cameras": 3}\n']))
    with pytest.raises(InputError, match="--lag"):
        StreamTracker(sim.scene, TrackOptions(lag=None))


def test_tracks_not_seen_for_max_gap_are_forgotten(sim):
    tracker = Tracker(sim.scene.cameras, TrackOptions(solve=SolveOptions(covariance=False), lag=0.5, max_gap=0.25))
    for i, frame in enumerate(sim.scene.frames[:3]):
        tracker.add_frame(frame, i)
    ids = tracker.track_ids
    assert len(ids) >= 2
    t = sim.scene.frames[2].t
    assert tracker.forget(t + 0.2) == []
    assert sorted(tracker.forget(t + 0.3)) == sorted(ids) and tracker.track_ids == []


def test_follow_reads_a_growing_file(tmp_path, sim):
    path = tmp_path / "live.jsonl"
    lines = _lines(sim.scene)
    path.write_text(lines[0] + lines[1][:20])  # a frame's line half written

    def writer():
        time.sleep(0.3)
        with open(path, "a") as f:
            f.write(lines[1][20:])
            f.flush()
            for line in lines[2:4]:
                time.sleep(0.05)
                f.write(line)
                f.flush()

    thread = threading.Thread(target=writer)
    thread.start()
    got = list(follow_lines(path, poll=0.02, idle_timeout=1.0))
    thread.join()
    assert got == lines[:4]


def test_cli_stream_stdin_to_stdout(sim, monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdin", io.StringIO("".join(_lines(sim.scene)) + "{bad\n"))
    code = main(["track", "-", "--out", "-", "--no-covariance"])
    captured = capsys.readouterr()
    out = [json.loads(line) for line in captured.out.splitlines()]
    assert code == 2  # one line was not a frame
    assert [o["frame"] for o in out] == list(range(len(sim.scene.frames) + 1))
    assert all(v["status"] == "converged" for o in out[:-1] for v in o["vehicles"])
    assert "error" in out[-1] and "fixed lag: 1 s" in captured.err and "1 lines not read" in captured.err


def test_cli_follow_to_file(tmp_path, sim, capsys):
    scene = tmp_path / "live.jsonl"
    scene.write_text("".join(_lines(sim.scene)))
    out = tmp_path / "out.jsonl"
    assert main(["track", str(scene), "--follow", "--idle-timeout", "0.3", "--out", str(out), "--lag", "0.5"]) == 0
    assert len(out.read_text().splitlines()) == len(sim.scene.frames)
    for bad, field in ((["--batch"], "--batch"), (["--workers", "2"], "--workers"), (["--format", "csv"], "--format"),
                       (["--idle-timeout", "-1"], "--idle-timeout")):
        assert main(["track", str(scene), "--follow", "--out", str(out)] + bad) == 2
        assert f"{field}:" in capsys.readouterr().err
    assert main(["track", str(scene), "--out", str(out), "--idle-timeout", "1"]) == 2
    assert "--idle-timeout: only with --follow" in capsys.readouterr().err


def test_a_late_frame_gets_the_covariances_the_tracker_gives(sim):
    lines = _lines(sim.scene)
    items = list(track_stream(lines[:4] + [lines[2]], TrackOptions(solve=SolveOptions(covariance=False), lag=0.5)))
    tracked, late = items[2], items[3]
    assert late.note.startswith("arrived late")
    assert all(v.pose_covariance is not None for v in tracked.result.vehicles if v.ok)
    assert all(v.pose_covariance is not None for v in late.result.vehicles if v.ok) and late.result.vehicles


def test_a_recorded_stream_is_a_scene_file(tmp_path, sim, capsys):
    """scaling.md: "vfactor track on the recorded stream gives the smoothed estimates"; it said "not valid JSON"."""
    from vfactor.errors import SceneError
    from vfactor.scene import load_results, load_scene

    recorded = tmp_path / "live.jsonl"
    recorded.write_text("".join(_lines(sim.scene)))
    scene = load_scene(recorded)
    assert [f.t for f in scene.frames] == [f.t for f in sim.scene.frames]
    assert list(scene.cameras) == list(sim.scene.cameras)
    assert main(["track", str(recorded), "--out", str(tmp_path / "r.json"), "--no-covariance", "-q"]) == 0
    assert len(load_results(tmp_path / "r.json")) == len(sim.scene.frames)
    with_frames = json.loads(_lines(sim.scene)[0])  # a header may hold the first frames, as a live stream's
    with_frames["frames"] = [json.loads(_lines(sim.scene)[1])]
    (tmp_path / "header.jsonl").write_text(json.dumps(with_frames) + "\n" + "".join(_lines(sim.scene)[2:]))
    assert [f.t for f in load_scene(tmp_path / "header.jsonl").frames] == [f.t for f in sim.scene.frames]
    bad = tmp_path / "bad.jsonl"
    bad.write_text("".join(_lines(sim.scene)[:2]) + "{not json\n")
    with pytest.raises(SceneError) as raised:
        load_scene(bad)
    assert raised.value.field == f"{bad}:3"


def test_a_stream_detection_without_its_vehicle_is_named(sim):
    from vfactor.observations import UNASSIGNED

    frame = sim.scene.frames[0]
    unnamed = dataclasses.replace(frame, detections=[frame.detections[0], dataclasses.replace(
        frame.detections[1], vehicle=UNASSIGNED)])
    tracker = StreamTracker(sim.scene, TrackOptions(solve=SolveOptions(covariance=False), lag=0.5, covariance=False))
    with pytest.raises(InputError) as raised:  # it named the field "vehicle", not which detection
        tracker.add(unnamed, 0)
    assert raised.value.field == "frame.detections[1].vehicle"


def test_a_second_header_is_said_to_be_one(sim):
    lines = _lines(sim.scene)
    items = list(track_stream(lines[:3] + [lines[0]] + lines[3:], TrackOptions(
        solve=SolveOptions(covariance=False), lag=0.5, covariance=False)))
    (bad,) = [item for item in items if item.error]
    assert bad.line == 4 and bad.error.startswith("frame: a second header")  # it was "frame.cameras: unknown key"
    assert len([item for item in items if item.result is not None]) == len(sim.scene.frames)


def test_a_stream_refuses_boxes_the_network_would_have_to_read(sim):
    """A stream does not run the keypoint network: its box-only detections came out 'degenerate', no error."""
    frame = sim.scene.frames[0]
    boxed = dataclasses.replace(frame.detections[0], keypoints=np.full((12, 2), np.nan), confidence=np.zeros(12),
                                roi=(10.0, 10.0, 200.0, 120.0), from_image=True)
    tracker = StreamTracker(sim.scene, TrackOptions(solve=SolveOptions(covariance=False), lag=0.5, covariance=False))
    with pytest.raises(InputError) as raised:
        tracker.add(dataclasses.replace(frame, detections=[boxed, *frame.detections[1:]]), 0)
    assert raised.value.field == "frame.detections[0]" and "does not run the keypoint network" in raised.value.problem
