"""Error types and the shared settings validator."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from vfactor.errors import InputError, SceneError, check_numbers
from vfactor.graph import GraphConfig


def test_check_numbers_bounds_and_types():
    ok = SimpleNamespace(a=1, b=0.5, c=0.0)
    check_numbers("S", ok, ("a", "b"))
    check_numbers("S", ok, ("c",), strict=False)
    with pytest.raises(ValueError, match=r"^S\.c: expected a number > 0, got 0\.0$"):
        check_numbers("S", ok, ("a", "c"))
    for bad in (math.nan, math.inf, True, "1", None, -1.0):
        with pytest.raises(ValueError, match=r"S\.x: expected a number >= 0"):
            check_numbers("S", SimpleNamespace(x=bad), ("x",), strict=False)
    check_numbers("S", SimpleNamespace(x=2.5), ("x",), minimum=2.5, strict=False)
    with pytest.raises(ValueError, match="> 2.5"):
        check_numbers("S", SimpleNamespace(x=2.5), ("x",), minimum=2.5)


def test_settings_name_the_field():
    with pytest.raises(ValueError, match=r"GraphConfig\.hinge_sigma: expected a number > 0, got -1"):
        GraphConfig(hinge_sigma=-1)
    # the part of the hub height's sigma that is each pose's own cannot exceed the whole
    with pytest.raises(ValueError, match=r"GraphConfig\.ground_sigma_road: expected less than ground_sigma_height"):
        GraphConfig(ground_sigma_road=0.06)
    with pytest.raises(ValueError, match=r"GraphConfig\.ground_sigma_road: expected a number > 0"):
        GraphConfig(ground_sigma_road=0.0)


def test_solve_options_name_the_field():
    from vfactor.solve import SolveOptions

    for settings, message in (({"max_iterations": 0}, r"SolveOptions\.max_iterations: expected an integer >= 1"),
                              ({"num_starts": 0}, r"SolveOptions\.num_starts: expected an integer >= 1"),
                              ({"poor_fit_restarts": -1}, r"SolveOptions\.poor_fit_restarts: expected an integer >= 0"),
                              ({"relative_error_tol": math.nan}, r"SolveOptions\.relative_error_tol: expected a"),
                              ({"graph": None}, r"SolveOptions\.graph: expected a GraphConfig"),
                              ({"covariance": 1}, r"SolveOptions\.covariance: expected True or False")):
        with pytest.raises(ValueError, match=message):
            SolveOptions(**settings)
    assert SolveOptions(poor_fit_restarts=0, num_starts=1).poor_fit_restarts == 0


def test_track_options_name_the_field():
    from vfactor.track import TrackOptions

    for settings, message in (({"update_tolerance": -1.0}, r"TrackOptions\.update_tolerance: expected a number >= 0"),
                              ({"relinearize_threshold": math.nan}, r"TrackOptions\.relinearize_threshold"),
                              ({"dogleg_delta": 0.0}, r"TrackOptions\.dogleg_delta: expected a number > 0"),
                              ({"lag": True}, r"TrackOptions\.lag: expected a number > 0"),
                              ({"lag": "1"}, r"TrackOptions\.lag: expected a number > 0"),
                              ({"motion": None}, r"TrackOptions\.motion: expected a MotionModel"),
                              ({"solve": None}, r"TrackOptions\.solve: expected a SolveOptions"),
                              ({"covariance": "no"}, r"TrackOptions\.covariance: expected True or False")):
        with pytest.raises(ValueError, match=message):
            TrackOptions(**settings)
    assert TrackOptions(lag=0.5, max_gap=math.inf).lag == 0.5


def test_a_detection_built_by_hand_is_checked():
    import numpy as np

    from vfactor.observations import Detection

    uv, conf = np.full((12, 2), 100.0), np.ones(12)
    made = Detection("c", "v", uv.tolist(), conf.tolist())  # lists become arrays
    assert isinstance(made.keypoints, np.ndarray) and made.seen.all()
    unseen = uv.copy()
    unseen[3] = np.nan
    assert not Detection("c", "v", unseen, np.r_[conf[:3], 0.0, conf[4:]]).seen[3]  # NaN where unseen: fine
    for keypoints, confidence, field, words in (
            (uv[:11], conf, "keypoints", "(12, 2)"), (uv, conf[:11], "confidence", "(12,)"),
            (np.zeros((12, 3)), conf, "keypoints", "(12, 2)"), (uv, -conf, "confidence", "[0, 1]"),
            (uv, np.full(12, np.nan), "confidence", "[0, 1]"), (unseen, conf, "keypoints", "not finite")):
        with pytest.raises(InputError) as raised:
            Detection("c", "v", keypoints, confidence)
        assert raised.value.field == field and words in raised.value.problem and "'v'" in raised.value.problem
    with pytest.raises(InputError, match="covariance"):
        Detection("c", "v", uv, conf, covariance=np.ones((12, 2)))


def test_input_error_field_and_prefix():
    err = SceneError("K", "singular")
    assert isinstance(err, InputError) and isinstance(err, ValueError)
    moved = err.within("cameras[1]")
    assert moved.field == "cameras[1].K" and str(moved) == "cameras[1].K: singular"


def test_a_message_is_one_line_whatever_the_input_names_hold(tmp_path):
    """A key of the user's file may hold a newline, a tab or a NUL (the long fuzzing profile drew a scene with a key
    ``"\\n"``): the error writes such characters as escapes, so the CLI's message stays one line."""
    import json

    from vfactor.scene import load_scene

    error = InputError("frames[0].a\nb", "unknown key\t\x00")
    assert str(error) == "frames[0].a\\nb: unknown key\\t\\x00" and "\n" not in str(error)
    assert str(error.within("scene")) == str(InputError("scene.frames[0].a\nb", "unknown key\t\x00"))
    path = tmp_path / "scene.json"
    path.write_text(json.dumps({"cameras": [], "frames": [], "\n": 1}))
    with pytest.raises(SceneError) as raised:
        load_scene(path)
    assert "\n" not in str(raised.value) and "\\n" in str(raised.value)
