"""vfactor.parallel: the batch commands on Dask distributed give exactly the serial results, in order, also when a
worker is killed mid-job; many scenes as one job (docs/scaling.md)."""

from __future__ import annotations

import json
import os
import signal
import time

import numpy as np
import pytest

pytest.importorskip("distributed")

from vfactor.cli import main  # noqa: E402
from vfactor.parallel import DaskEngine, InProcess, open_engine  # noqa: E402
from vfactor.scene import results_to_dict, save_scene  # noqa: E402
from vfactor.errors import InputError  # noqa: E402
from vfactor.sim import simulate  # noqa: E402
from vfactor.solve import SolveOptions, solve_scene  # noqa: E402
from vfactor.track import TrackOptions, smooth_scene, track_scene  # noqa: E402


def _slow_square(x):
    time.sleep(0.002 * (x % 5))  # later units often finish first
    return x * x


def _fails_on_three(x):
    if x == 3:
        raise ZeroDivisionError("three")
    return x


@pytest.fixture(scope="module")
def engine():
    with DaskEngine(workers=2) as e:
        yield e


@pytest.fixture(scope="module")
def multi_scene():
    return simulate("intersection_multi", seed=1, num_frames=5).scene


@pytest.fixture(scope="module")
def track_scene_3veh():
    return simulate("tracks_3veh", seed=3, num_frames=10).scene


def test_map_keeps_the_units_order_and_streams(engine):
    seen = []
    out = list(engine.map(_slow_square, iter(range(40)), progress=lambda done, total: seen.append((done, total)),
                          total=40))
    assert out == [x * x for x in range(40)]
    assert seen[-1] == (40, 40) and [d for d, _ in seen] == list(range(1, 41))
    assert engine.workers == 2


def test_map_with_small_window_and_chunks(engine):
    e = DaskEngine(client=engine.client, chunk=3, in_flight=2, warm=False)
    assert list(e.map(_slow_square, range(25))) == [x * x for x in range(25)]
    e.close()  # a given client stays open
    assert engine.client.status == "running"


def test_task_exception_reaches_the_caller(engine):
    with pytest.raises(ZeroDivisionError, match="three"):
        list(engine.map(_fails_on_three, range(6)))


def test_solve_scene_on_dask_equals_serial(engine, multi_scene):
    options = SolveOptions()
    serial = solve_scene(multi_scene, options)
    distributed = solve_scene(multi_scene, options, engine=engine)
    assert results_to_dict(distributed) == results_to_dict(serial)
    assert sum(len(f.vehicles) for f in serial) >= 10


def test_track_and_smooth_on_dask_equal_serial(engine, track_scene_3veh):
    for lag in (None, 0.5):
        options = TrackOptions(solve=SolveOptions(covariance=False), lag=lag)
        serial, distributed = track_scene(track_scene_3veh, options), track_scene(track_scene_3veh, options, engine=engine)
        assert results_to_dict(distributed.frames) == results_to_dict(serial.frames)
        assert results_to_dict(distributed.online) == results_to_dict(serial.online)
        assert distributed.messages == serial.messages
    options = TrackOptions(solve=SolveOptions(covariance=False))
    assert results_to_dict(smooth_scene(track_scene_3veh, options, engine=engine)) == \
        results_to_dict(smooth_scene(track_scene_3veh, options))


@pytest.mark.parametrize("tracks", [True, False])
def test_associate_scene_on_dask_equals_serial(engine, monkeypatch, tracks):
    """The frames' pair tests on the workers, the grouping (with the cameras' track ids as hints) and the linking
    here, or without track ids each frame's grouping on the workers too: the same association as in one process,
    and no pair test (and without track ids no grouping) made here."""
    import vfactor.association as association
    from vfactor.sim import anonymise

    # three vehicles driving past two cameras, a tracker's id switches and false detections
    anonymous = anonymise(simulate("tracks_3veh", seed=4, num_frames=6), seed=4, track_switch_rate=0.2,
                          false_rate=0.3, keep_tracks=tracks).scene
    assert any(d.track is not None for f in anonymous.frames for d in f.detections) == tracks  # the trackers' hints
    here, grouped = [], []
    tests, group = association.pair_tests, association.group_detections
    monkeypatch.setattr(association, "pair_tests", lambda *args: here.append(args) or tests(*args))
    monkeypatch.setattr(association, "group_detections", lambda *args: grouped.append(args) or group(*args))
    serial = association.associate_scene(anonymous)
    assert len(here) == len(grouped) == 6
    here.clear()
    grouped.clear()
    on_dask = association.associate_scene(anonymous, engine=engine)
    assert not here and len(grouped) == (6 if tracks else 0)  # the tests (and the groups) made on the workers
    assert on_dask.groups == serial.groups and on_dask.kept == serial.kept
    assert on_dask.left_out == serial.left_out and on_dask.messages == serial.messages
    assert [[d.vehicle for d in f.detections] for f in on_dask.scene.frames] == \
        [[d.vehicle for d in f.detections] for f in serial.scene.frames]
    assert sum(len(g) > 1 for frame in serial.groups for g in frame.values()) >= 12 and serial.left_out


def test_killed_worker_loses_nothing(multi_scene):
    options = SolveOptions(covariance=False)
    serial = results_to_dict(solve_scene(multi_scene, options))
    with DaskEngine(workers=2, chunk=1) as e:
        pids = e.client.run(os.getpid)
        frames = []
        from vfactor.solve import iter_solve_scene

        for k, frame in enumerate(iter_solve_scene(multi_scene, options, engine=e)):
            if k == 0:  # mid-job: the other frames' vehicles are queued or running on both workers
                os.kill(next(iter(pids.values())), signal.SIGKILL)
            frames.append(frame)
        assert results_to_dict(frames) == serial
        # Whether and when Dask's nanny restarts the killed worker is Dask's: it took over 30 s once in a full run


def test_open_engine_and_bad_options(monkeypatch):
    import vfactor.parallel.engine as engine

    monkeypatch.setattr(engine, "CONNECT_TIMEOUT", 1.0)  # Dask tries a refused port again until half of it
    assert isinstance(open_engine(), InProcess)
    with pytest.raises(InputError, match="--workers"):
        open_engine(workers=0)
    with pytest.raises(InputError, match="not both"):
        open_engine(workers=1, scheduler="tcp://127.0.0.1:1")
    with pytest.raises(InputError, match="--scheduler: cannot reach"):
        open_engine(scheduler="tcp://127.0.0.1:1")
    for address in ("nonsense", "", "tcp://host"):  # Dask's own ValueError was an 'internal error', exit 1
        with pytest.raises(InputError, match="--scheduler: expected the scheduler's address"):
            open_engine(scheduler=address)


def test_a_scheduler_port_that_never_answers_is_an_error_not_a_hang(monkeypatch):
    """A port that takes the connection and never answers as Dask does (the dashboard's HTTP port) held the
    command for ever."""
    import socket

    import vfactor.parallel.engine as engine

    monkeypatch.setattr(engine, "CONNECT_TIMEOUT", 1.0)
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        start = time.perf_counter()
        with pytest.raises(InputError, match="--scheduler: no answer from a Dask scheduler"):
            open_engine(scheduler=f"tcp://127.0.0.1:{server.getsockname()[1]}")
        assert time.perf_counter() - start < 10.0


def test_cli_many_scenes_with_workers_equal_serial(tmp_path, capsys, multi_scene):
    sites = tmp_path / "sites"
    for name, seed in (("north", 1), ("south", 2)):
        save_scene(simulate("intersection_multi", seed=seed, num_frames=3).scene, sites / name / "scene.json")
    (sites / "broken").mkdir()
    (sites / "broken" / "scene.json").write_text('{"cameras": []}')
    glob = str(sites / "*" / "scene.json")
    code = main(["solve", glob, "--out", str(tmp_path / "serial"), "-q"])
    assert code == 2  # the broken scene; the others are written
    err = capsys.readouterr().err
    assert "broken/scene.json: frames: missing" in err and len(err.strip().splitlines()) == 1
    code = main(["solve", glob, "--out", str(tmp_path / "dask"), "--workers", "2", "-q"])
    assert code == 2
    for name in ("north", "south"):
        serial = (tmp_path / "serial" / name / "scene.json").read_bytes()
        assert serial == (tmp_path / "dask" / name / "scene.json").read_bytes()
        assert json.loads(serial)["frames"]
    assert not (tmp_path / "serial" / "broken").exists()


def test_cli_many_scenes_options(tmp_path, capsys):
    folder = tmp_path / "scenes"
    sim = simulate("intersection_2cam", seed=0, num_frames=2)
    save_scene(sim.scene, folder / "a.json")
    (folder / "a_truth.json").write_text("{}")
    assert main(["track", str(folder), "--out", str(tmp_path / "out")]) == 0
    captured = capsys.readouterr()
    assert "1 ground-truth files" in captured.err and "1 scenes: 1 done" in captured.out
    assert (tmp_path / "out" / "a.json").exists() and not (tmp_path / "out" / "a_truth.json").exists()
    assert main(["track", str(folder / "*.json"), "--out", str(tmp_path / "glob")]) == 0  # a glob skips them too
    captured = capsys.readouterr()
    assert "1 ground-truth files" in captured.err and "1 scenes: 1 done" in captured.out
    assert main(["track", str(folder), "--out", str(tmp_path / "x"), "--plot", str(tmp_path / "p.png")]) == 2
    assert "--plot: names one file: not for many scenes" in capsys.readouterr().err
    (tmp_path / "file.json").write_text("{}")
    assert main(["solve", str(folder), "--out", str(tmp_path / "file.json")]) == 2
    assert "--out: " in capsys.readouterr().err
    assert main(["solve", str(tmp_path / "nothing*.json"), "--out", str(tmp_path / "o")]) == 2
    assert "scene: no scene file matches" in capsys.readouterr().err
    assert main(["solve", str(folder / "a.json"), "--out", str(tmp_path / "o.json"), "--workers", "0"]) == 2
    assert "--workers: expected an integer >= 1" in capsys.readouterr().err


def test_eval_on_dask_equals_serial(engine):
    from vfactor.evaluation import run_accuracy

    def rows(runs):  # every figure but the times
        return [(variant.name, {m: [{k: np.asarray(v).tolist() for k, v in r.items() if k != "seconds"} for r in rs]
                                for m, rs in pooled.items()}) for variant, pooled in runs]

    kwargs = dict(frames=2, levels=("paper",), seeds=2, methods=("factor_graph", "triangulation"))
    serial = run_accuracy("library_2cam", **kwargs)
    assert rows(run_accuracy("library_2cam", engine=engine, **kwargs)) == rows(serial)
    assert {r["seed"] for r in serial[0][1]["factor_graph"]} == {0, 1}
