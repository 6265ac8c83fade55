"""Association metrics on hand-made cases whose answers are worked out by hand."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

from vfactor.association_metrics import (
    MOT_METRICS,
    assigned_ids_from_results,
    association_table,
    clear_mot,
    cross_camera_pairs,
    positions_from_results,
)
from vfactor.result import FrameResult, Status, VehicleResult

# One frame: vehicle A seen by cam0, cam1, cam2; B by cam0, cam1.
TRUTH = [["A", "A", "A", "B", "B"]]
CAMS = [["cam0", "cam1", "cam2", "cam0", "cam1"]]


def test_a_perfect_association_scores_one():
    s = cross_camera_pairs(TRUTH, [["x", "x", "x", "y", "y"]], CAMS)  # any names: only the grouping counts
    assert (s.precision, s.recall) == (1.0, 1.0)
    assert (s.predicted, s.true, s.correct, s.same_camera) == (4, 4, 4, 0)  # A: 3 pairs, B: 1


def test_one_wrong_merge():
    # B's cam1 detection given to A: pairs A0-B1 and A2-B1 are wrong (A1-B1 is of one camera), B0-B1 is lost.
    s = cross_camera_pairs(TRUTH, [["x", "x", "x", "y", "x"]], CAMS)
    assert (s.predicted, s.correct, s.true, s.same_camera) == (5, 3, 4, 1)
    assert (s.precision, s.recall) == (3 / 5, 3 / 4)


def test_one_split():
    # A's cam2 detection made a vehicle of its own: pairs A0-A2 and A1-A2 are lost.
    s = cross_camera_pairs(TRUTH, [["x", "x", "z", "y", "y"]], CAMS)
    assert (s.predicted, s.correct, s.true) == (2, 2, 4)
    assert (s.precision, s.recall) == (1.0, 0.5)


def test_everything_merged_counts_same_camera_pairs_apart():
    s = cross_camera_pairs(TRUTH, [["x"] * 5], CAMS)
    assert (s.predicted, s.correct, s.same_camera) == (8, 4, 2)  # 10 pairs, 2 of them within a camera
    assert (s.precision, s.recall) == (0.5, 1.0)


def test_a_false_detection_attached():
    truth = [["A", "A", None]]
    cams = [["cam0", "cam1", "cam2"]]
    s = cross_camera_pairs(truth, [["x", "x", "x"]], cams)
    assert (s.predicted, s.correct, s.true) == (3, 1, 1)
    assert (s.false_detections, s.false_attached, s.real_unassigned) == (1, 1, 0)
    left = cross_camera_pairs(truth, [["x", "x", None]], cams)
    assert (left.precision, left.recall, left.false_attached) == (1.0, 1.0, 0)
    none = cross_camera_pairs(truth, [[None, None, None]], cams)
    assert math.isnan(none.precision) and none.recall == 0.0 and none.real_unassigned == 2


def test_pairs_are_pooled_over_frames_and_never_across_them():
    truth = [["A", "A"], ["A", "A", "B", "B"]]
    cams = [["cam0", "cam1"], ["cam0", "cam1", "cam0", "cam1"]]
    # the same name "x" in both frames, and B's pair split in frame 1
    s = cross_camera_pairs(truth, [["x", "x"], ["x", "x", "p", "q"]], cams)
    assert (s.predicted, s.correct, s.true) == (2, 2, 3)
    assert (s.precision, s.recall) == (1.0, 2 / 3)
    with pytest.raises(ValueError, match="frame 0"):
        cross_camera_pairs([["A"]], [["x", "y"]], [["cam0"]])
    with pytest.raises(ValueError, match="as many frames"):
        cross_camera_pairs([["A"]], [], [["cam0"]])


def test_clear_mot_of_a_perfect_tracker():
    truth = [{"A": (0.0, 0.0), "B": (0.0, 5.0)}, {"A": (1.0, 0.0), "B": (1.0, 5.0)}]
    est = [{"1": (0.1, 0.0), "2": (0.0, 5.0)}, {"1": (1.0, 0.1), "2": (1.0, 5.3)}]
    m = clear_mot(truth, est)
    assert set(m) == set(MOT_METRICS)
    assert m["mota"] == 1.0 and m["idf1"] == 1.0 and m["num_switches"] == 0
    assert m["motp"] == pytest.approx((0.1 + 0.0 + 0.1 + 0.3) / 4)


def test_an_id_switch_is_counted_once():
    # A is followed by estimate 1 in frames 0-1 and by estimate 2 in frames 2-3; B by 3 throughout.
    truth = [{"A": (float(f), 0.0), "B": (float(f), 5.0)} for f in range(4)]
    est = [{("1" if f < 2 else "2"): (float(f), 0.0), "3": (float(f), 5.0)} for f in range(4)]
    m = clear_mot(truth, est)
    assert m["num_switches"] == 1 and m["num_misses"] == 0 and m["num_false_positives"] == 0
    assert m["mota"] == pytest.approx(1 - 1 / 8)
    # IDF1: A maps to 1 or 2 (2 frames each): IDTP = 2 + 4, IDFP = 2, IDFN = 2
    assert m["idf1"] == pytest.approx(2 * 6 / (2 * 6 + 2 + 2))


def test_clear_mot_of_a_small_case_worked_by_hand():
    # frame 0: A-1 at 0.5 m, B-2 at 0.3 m.
    # frame 1: A-1 at 0.2 m; estimate 2 is 3 m from B (beyond the 2 m gate): B missed, 2 a false positive.
    # frame 2: A-1 at 0 m; B-3 at 0.4 m: an ID switch (B was 2's).
    truth = [{"A": (0, 0), "B": (0, 5)}, {"A": (1, 0), "B": (1, 5)}, {"A": (2, 0), "B": (2, 5)}]
    est = [{"1": (0.5, 0), "2": (0, 5.3)}, {"1": (1, 0.2), "2": (4, 5)}, {"1": (2, 0), "3": (2, 5.4)}]
    m = clear_mot(truth, est)
    assert (m["num_objects"], m["num_misses"], m["num_false_positives"], m["num_switches"]) == (6, 1, 1, 1)
    assert m["num_matches"] + m["num_switches"] == 5
    assert m["mota"] == pytest.approx(1 - (1 + 1 + 1) / 6)
    assert m["motp"] == pytest.approx((0.5 + 0.3 + 0.2 + 0.0 + 0.4) / 5)
    assert m["num_fragmentations"] == 1  # B: matched, lost, matched
    # IDF1: A <-> 1 (3 frames); B <-> 2 or 3 (1 frame each). IDTP = 4 of 6 true and 6 estimated vehicle-frames.
    assert m["idf1"] == pytest.approx(2 * 4 / (2 * 4 + 2 + 2))
    # a wider gate matches B with 2 in frame 1: no miss, no false positive
    wide = clear_mot(truth, est, max_distance=3.5)
    assert (wide["num_misses"], wide["num_false_positives"]) == (0, 0)


def test_clear_mot_takes_poses_and_skips_unsolved_vehicles():
    pose = gtsam.Pose3(gtsam.Rot3.Yaw(0.3), np.array([2.0, 3.0, 0.35]))
    m = clear_mot([{"A": pose}], [{"1": (2.0, 3.0, 0.0), "2": None}])
    assert m["mota"] == 1.0 and m["num_false_positives"] == 0 and m["motp"] == 0.0
    empty = clear_mot([{"A": (0, 0)}], [{}])
    assert empty["num_misses"] == 1 and empty["mota"] == 0.0 and math.isnan(empty["motp"])
    with pytest.raises(ValueError, match="as many frames"):
        clear_mot([{}], [])
    with pytest.raises(ValueError, match="max_distance"):
        clear_mot([{}], [{}], max_distance=0.0)


def _vehicle(vid, detections, xy=None):
    pose = None if xy is None else gtsam.Pose3(gtsam.Rot3(), np.array([xy[0], xy[1], 0.3]))
    status = Status.FAILED if xy is None else Status.CONVERGED
    return VehicleResult(vid, status, world_T_vehicle=pose, extras={"detections": detections})


def test_ids_and_positions_from_frame_results():
    results = [FrameResult(0.0, [_vehicle("x", [0, 2], (1.0, 2.0)), _vehicle("y", [3], None)])]
    assert assigned_ids_from_results(results, [4]) == [["x", None, "x", "y"]]
    positions = positions_from_results(results)
    np.testing.assert_allclose(positions[0]["x"], [1.0, 2.0])
    assert positions[0]["y"] is None
    with pytest.raises(ValueError, match="used by vehicles x and z"):
        assigned_ids_from_results([FrameResult(0.0, [_vehicle("x", [0]), _vehicle("z", [0])])], [1])
    with pytest.raises(ValueError, match="uses detection 5 of 2"):
        assigned_ids_from_results([FrameResult(0.0, [_vehicle("x", [5])])], [2])


def test_association_table():
    pairs = cross_camera_pairs(TRUTH, [["x", "x", "x", "y", "x"]], CAMS)
    mot = clear_mot([{"A": (0, 0)}], [{"1": (0.5, 0)}])
    table = association_table({"ours": {"pairs": pairs, "mot": mot}, "pairs only": {"pairs": pairs}})
    lines = table.splitlines()
    assert lines[0].startswith("| method | pair precision | pair recall |") and len(lines) == 4
    assert lines[2] == "| ours | 0.600 | 0.750 | 1 | 0 / 0 | 1.000 | 0.500 | 1.000 | 0 | 0 | 0 | 0 |"
    assert lines[3].endswith("| - | - | - | - | - | - | - |")
