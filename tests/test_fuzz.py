"""Fuzzing (hypothesis): mutated scene, calibration and result files, and the CLI on mutated scenes.

Properties (docs/reliability.md):

* the scene, calibration and result readers return or raise their
  :class:`~vfactor.errors.InputError`, nothing else;
* ``vfactor solve|track`` on a mutated scene exits 0 or 3 with every vehicle of
  every frame reported in a result file without NaN, no ``converged`` vehicle
  with a non-finite pose or one farther than 1 km from every camera; or exits 2
  with a one-line message; never another code or a traceback.

The default profile is seeded and small (tests/fuzzing.py); ``pytest --fuzz-long``
(or ``VFACTOR_FUZZ=long``) runs over 5,000 cases.
"""

from __future__ import annotations

import collections
import contextlib
import io
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests import fuzzing
from vfactor.camera import Camera
from vfactor.cli import EXIT_INPUT, EXIT_OK, EXIT_UNSOLVED, main
from vfactor.errors import CalibrationError, InputError
from vfactor.sanity import MAX_DISTANCE
from vfactor.scene import load_results, load_scene, save_results, scene_to_dict
from vfactor.sim import load_scenario, simulate
from vfactor.solve import SolveOptions, solve_scene

#: outcomes per category, written to $VFACTOR_FUZZ_REPORT (JSON) at the end of the module
STATS: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)


@pytest.fixture(scope="module", autouse=True)
def report():
    yield
    target = os.environ.get("VFACTOR_FUZZ_REPORT")
    if target:
        Path(target).write_text(json.dumps({k: dict(v) for k, v in sorted(STATS.items())}, indent=1) + "\n")


# ----------------------------------------------------------------------------- base inputs
def _scene_dict(scenario: str, frames: int, seed: int, detector: dict | None = None) -> dict:
    """A simulated scene as its file holds it; ``detector``: fields every detection gets (a learnt detector's)."""
    sim = simulate(load_scenario(scenario), seed=seed, num_frames=frames)
    data = json.loads(json.dumps(scene_to_dict(sim.scene, base_dir=Path.cwd())))
    for frame in data["frames"]:
        for detection in frame["detections"]:
            detection.update(detector or {})
    return data


#: What the keypoint network's calibration gives each detection: its error of the shape and its bias (so that the
#: mutations reach them too).
NETWORK_FIELDS = {"shape_sigma": 0.046, "bias_sigma": [0.0137, 0.0116, 0.0125, 0.0302, 0.0072, 0.0288]}
BASE_SCENE = _scene_dict("intersection_2cam", 1, 3)  # one frame, one vehicle, two cameras
BASE_TRACK = _scene_dict("intersection_2cam_track", 3, 0, NETWORK_FIELDS)  # three frames of one track


def _base_result_text() -> str:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "scene.json"
        path.write_text(json.dumps(BASE_SCENE))
        results = solve_scene(load_scene(path), SolveOptions())
        save_results(results, Path(folder) / "r.json")
        return (Path(folder) / "r.json").read_text()


BASE_RESULT = json.loads(_base_result_text())


def _base_calibration_text() -> str:
    camera = Camera("pole", [[900.0, 0.0, 640.0], [0.0, 900.0, 360.0], [0.0, 0.0, 1.0]],
                    np.array([[1.0, 0, 0, 1], [0, 0, 1, 2], [0, -1, 0, 3], [0, 0, 0, 1]]),
                    dist=[-0.05, 0.01, 0.001, -0.001, 0.0], image_size=(1280, 720))
    with tempfile.TemporaryDirectory() as folder:
        camera.to_opencv_file(Path(folder) / "c.yaml")
        return (Path(folder) / "c.yaml").read_text()


BASE_CALIBRATION = _base_calibration_text()

# ----------------------------------------------------------------------------- mutations
RAW_NUMBERS = ["1" + "0" * 400, "1" + "0" * 5000, "-1e400", "1e-400", "123456789012345678901234567890", "-0",
               "0.1e1", "9" * 30 + ".5"]
_RAW = "__raw_number_{}__"

scalars = (st.none() | st.booleans() | st.integers(-(10**20), 10**20) | st.floats(allow_nan=True, allow_infinity=True)
           | st.text(max_size=6) | st.sampled_from([0, 1, -1, 0.5, 1e-12, 1e12, 1e308, "", "cam0", "cam1", "v1",
                                                   "../x.npy", "/etc/passwd", "\x1b[31m", "\n"]))
json_values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4)
                           | st.dictionaries(st.text(max_size=5), inner, max_size=3), max_leaves=8)


def _paths(value, prefix=()):
    """Every path (tuple of keys / indices) in a JSON value, containers included."""
    yield prefix
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _paths(v, prefix + (i,))


def _get(value, path):
    for key in path:
        value = value[key]
    return value


def _numbers(value):
    return [p for p in _paths(value) if isinstance(_get(value, p), (int, float)) and not isinstance(_get(value, p), bool)]


def mutate(draw, base: dict) -> tuple[str, str]:
    """A mutated JSON text of ``base`` (one to three mutations) and the first one's kind (for the report)."""
    data = json.loads(json.dumps(base))
    raws = []
    kinds = []
    for _ in range(draw(st.integers(1, 3))):
        paths = list(_paths(data))
        kind = draw(st.sampled_from(["replace", "delete", "add_key", "scale_number", "raw_number", "swap", "text"]))
        if kind == "text":
            kinds.append(kind)
            break
        if kind in ("scale_number", "raw_number"):
            numbers = _numbers(data)
            if not numbers:
                continue
            path = draw(st.sampled_from(numbers))
        else:
            path = draw(st.sampled_from(paths))
        if not path:
            continue
        parent, key = _get(data, path[:-1]), path[-1]
        kinds.append(kind)
        if kind == "replace":
            parent[key] = draw(json_values)
        elif kind == "delete":
            del parent[key]
        elif kind == "add_key":
            target = _get(data, path) if isinstance(_get(data, path), dict) else parent
            if isinstance(target, dict):
                target[draw(st.text(max_size=6))] = draw(json_values)
        elif kind == "scale_number":
            factor = draw(st.sampled_from([-1.0, 0.0, 1e-9, 0.5, 1.0001, 2.0, 1e3, 1e9, 1e300]))
            parent[key] = parent[key] * factor + draw(st.sampled_from([0.0, 0.0, 1e-6, 1.0, 100.0]))
        elif kind == "raw_number":
            raws.append(draw(st.sampled_from(RAW_NUMBERS)))
            parent[key] = _RAW.format(len(raws) - 1)
        elif kind == "swap" and isinstance(parent, list) and len(parent) > 1:
            other = draw(st.integers(0, len(parent) - 1))
            parent[key], parent[other] = parent[other], parent[key]
    text = json.dumps(data)
    for i, raw in enumerate(raws):
        text = text.replace(f'"{_RAW.format(i)}"', raw)
    if "text" in kinds:
        cut = draw(st.integers(0, len(text)))
        op = draw(st.sampled_from(["truncate", "insert", "delete"]))
        if op == "truncate":
            text = text[:cut]
        elif op == "insert":
            text = text[:cut] + draw(st.sampled_from(["[", "]", "{", "}", ",", '"', ":", "-", "e", "\\", "\x00",
                                                      "NaN", "Infinity", "1" * 400, "[" * 5000])) + text[cut:]
        else:
            text = text[:cut] + text[cut + 1:]
    return text, (kinds[0] if kinds else "none") + (" (+more)" if len(kinds) > 1 else "")


# ----------------------------------------------------------------------------- CLI runner and checks
def run_cli(argv) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse
            code = exc.code
    return code, err.getvalue()


def check_outcome(code: int, err: str, scene_text: str, out: Path) -> str:
    """Asserts the CLI's contract on one run; returns the outcome's name for the report."""
    assert "Traceback" not in err and "internal error" not in err, err
    assert code in (EXIT_OK, EXIT_INPUT, EXIT_UNSOLVED), (code, err)
    if code == EXIT_INPUT:
        lines = [line for line in err.splitlines() if line.strip()]
        assert len(lines) == 1 and "\x1b" not in err, err
        return "exit 2 (bad input)"
    text = out.read_text()
    json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} in the result file"))
    frames = load_results(out)
    data = json.loads(scene_text)
    assert len(frames) == len(data["frames"])
    cameras = [np.array(c["world_T_camera"], float)[:3, 3] for c in data["cameras"]]
    statuses = collections.Counter()
    for frame, item in zip(frames, data["frames"]):
        ids = {d.get("vehicle") or "vehicle" for d in item["detections"]}
        assert {v.id for v in frame.vehicles} == ids
        for v in frame.vehicles:
            statuses[v.status.value] += 1
            assert "\n" not in v.message
            if v.ok:
                t = np.asarray(v.world_T_vehicle.translation())
                assert np.all(np.isfinite(v.world_T_vehicle.matrix())) and np.all(np.isfinite(v.keypoints_world))
                assert min(np.linalg.norm(t - c) for c in cameras) <= MAX_DISTANCE + 10.0
    solved = statuses["converged"] + statuses["max_iterations"] + statuses["poor_fit"]  # poor_fit: solved, warned
    assert (code == EXIT_UNSOLVED) == (sum(statuses.values()) != solved)
    return f"exit {code}" + ("" if code == EXIT_OK else " (some vehicles not solved)")


# ----------------------------------------------------------------------------- properties
def _read_mutated(data, base: dict, name: str, read):
    """``read`` of a mutated ``base`` file: (the first mutation's kind, "loaded" or "SceneError", what was read or None)."""
    text, kind = mutate(data.draw, base)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / name
        path.write_text(text)
        try:
            return kind, "loaded", read(path)
        except InputError as exc:
            assert "\n" not in exc.field
            return kind, "SceneError", None


@fuzzing.examples("scene_reader")
@given(st.data())
def test_scene_reader_returns_or_raises_a_scene_error(data):
    kind, outcome, _ = _read_mutated(data, BASE_SCENE, "scene.json", load_scene)
    STATS["scene_reader"][outcome] += 1
    STATS["scene_reader (by first mutation)"][f"{kind}: {outcome}"] += 1


def _fuzz_cli(data, base: dict, command: str, options: list[list[str]], fixed: tuple[str, ...] = ()) -> None:
    """One mutated ``base`` scene through ``vfactor COMMAND`` with one of ``options``; the outcome counted."""
    text, kind = mutate(data.draw, base)
    with tempfile.TemporaryDirectory() as folder:
        path, out = Path(folder) / "scene.json", Path(folder) / "result.json"
        path.write_text(text)
        extra = data.draw(st.sampled_from(options))
        code, err = run_cli([command, str(path), "--out", str(out), "--quiet", *fixed, *extra])
        outcome = check_outcome(code, err, text, out)
    STATS[f"cli_{command}"][outcome] += 1
    STATS[f"cli_{command} (by first mutation)"][f"{kind}: {outcome}"] += 1


@fuzzing.examples("cli_solve")
@given(st.data())
def test_cli_solve_on_mutated_scenes(data):
    _fuzz_cli(data, BASE_SCENE, "solve", [[], ["--no-covariance"]])


@fuzzing.examples("cli_track")
@given(st.data())
def test_cli_track_on_mutated_scenes(data):
    _fuzz_cli(data, BASE_TRACK, "track", [[], ["--lag", "0.15"], ["--batch"]], fixed=("--no-covariance",))


@fuzzing.examples("result_reader")
@given(st.data())
def test_result_reader_returns_or_raises_a_scene_error(data):
    _, outcome, frames = _read_mutated(data, BASE_RESULT, "result.json", load_results)
    if frames is not None:
        assert all(np.all(np.isfinite(v.world_T_vehicle.matrix())) for f in frames for v in f.vehicles if v.ok)
    STATS["result_reader"][outcome] += 1


CALIBRATION_TOKENS = ["100000", "-3", "0", "1e309", ".nan", ".inf", '"wide"', "[ 1, 2 ]", "3.5", "!!opencv-matrix",
                      "rows: 3", "data: [ ]", "x", "", "\n", "   ", ":", "[", "dt: q", "999999999999999999999"]


@fuzzing.examples("calibration_reader")
@given(st.data())
def test_calibration_reader_returns_or_raises_a_calibration_error(data):
    lines = BASE_CALIBRATION.splitlines()
    for _ in range(data.draw(st.integers(1, 3))):
        i = data.draw(st.integers(0, len(lines) - 1))
        op = data.draw(st.sampled_from(["value", "delete", "duplicate", "truncate"]))
        if op == "value" and ":" in lines[i]:
            lines[i] = lines[i].split(":", 1)[0] + ": " + data.draw(st.sampled_from(CALIBRATION_TOKENS))
        elif op == "value":
            lines[i] = data.draw(st.sampled_from(CALIBRATION_TOKENS))
        elif op == "delete":
            del lines[i]
        elif op == "duplicate":
            lines.insert(i, lines[i])
        else:
            lines[i] = lines[i][: data.draw(st.integers(0, len(lines[i])))]
        if not lines:
            break
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "calib.yaml"
        path.write_text("\n".join(lines) + "\n")
        try:
            camera = Camera.from_opencv_file(path)
            assert np.all(np.isfinite(camera.K)) and camera.image_size is None or all(
                0 < s <= 1 << 20 for s in camera.image_size)
            outcome = "loaded"
        except CalibrationError:
            outcome = "CalibrationError"
    STATS["calibration_reader"][outcome] += 1


# ----------------------------------------------------------------------------- a few real processes
@pytest.mark.parametrize("content", [
    "[" * 100000 + "]" * 100000,
    b"\xff\xfe not utf-8",
    '{"cameras": [], "frames": 1' + "0" * 5000 + "}",
])
def test_vfactor_process_on_hostile_files_exits_2_with_one_line(tmp_path, content):
    path = tmp_path / "scene.json"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    run = subprocess.run([sys.executable, "-m", "vfactor", "solve", str(path), "--out", str(tmp_path / "r.json")],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == EXIT_INPUT and "Traceback" not in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1, run.stderr
    assert not (tmp_path / "r.json").exists()


def test_long_profile_runs_over_5000_cases():
    assert sum(fuzzing.LONG_EXAMPLES.values()) >= 5000
