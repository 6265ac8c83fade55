"""CSV read with Python's csv module; the write_results dispatcher; every format on a real solve."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from tests.formats.helpers import DEG, MM, assert_same_box, rotation_error
from vfactor.errors import InputError
from vfactor.formats import (
    CSV_COLUMNS,
    FORMATS,
    read_csv,
    read_kitti,
    read_nuscenes,
    read_openlabel,
    write_csv,
    write_results,
)
from vfactor.scene import load_results


def test_csv_rows_by_the_csv_module(known, tmp_path):
    _, results = known
    report = write_csv(tmp_path / "r.csv", results)
    with open(tmp_path / "r.csv", newline="") as f:
        reader = csv.DictReader(f)
        assert tuple(reader.fieldnames) == CSV_COLUMNS
        rows = list(reader)
    assert [(r["frame"], r["id"]) for r in rows] == [("0", "a"), ("0", "b"), ("0", "c"), ("1", "a"), ("1", "b"),
                                                    ("1", "d"), ("2", "a")]
    c = rows[2]
    assert c["status"] == "failed" and c["message"] == "LM raised on every start"
    assert all(c[k] == "" for k in CSV_COLUMNS[4:22])  # no numbers for an unsolved vehicle
    assert report.skipped == [] and report.unsolved == [(0, "c", "failed")]
    a, b = rows[0], rows[1]
    assert [float(a[k]) for k in ("x", "y", "z")] == pytest.approx([10.0, 2.0, 0.75], abs=MM)  # box centre
    assert math.degrees(float(a["yaw"])) == pytest.approx(90.0, abs=0.1)
    assert [math.degrees(float(b[k])) for k in ("yaw", "pitch", "roll")] == pytest.approx([0.0, 5.0, -3.0], abs=0.1)
    y, p, r = (float(b[k]) for k in ("yaw", "pitch", "roll"))  # Z-Y-X: R = Rz(yaw) Ry(pitch) Rx(roll)
    Rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    Ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    Rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    box = results[0].vehicles[1].box
    assert rotation_error(Rz @ Ry @ Rx, box.world_T_box.rotation().matrix()) < DEG
    assert [float(b[k]) for k in ("length", "width", "height")] == pytest.approx([4.8, 1.9, 1.6], abs=MM)
    assert [float(b[k]) for k in ("x_sigma", "yaw_sigma", "length_sigma")] == pytest.approx([0.1, 0.03, 0.2])
    assert b["body_type"] == "sedan" and float(b["body_type_probability"]) == pytest.approx(0.9)
    back = read_csv(tmp_path / "r.csv")
    assert back[2].box is None and back[2].status == "failed"
    assert_same_box(back[1].box, box)
    assert back[1].box.size_sigma == pytest.approx(box.size_sigma)


def test_dispatcher_formats_and_errors(known, tmp_path):
    scene, results = known
    assert set(FORMATS) == {"vfactor", "openlabel", "kitti", "nuscenes", "csv"}
    with pytest.raises(InputError, match="^format:"):
        write_results(tmp_path / "x", results, scene, "yolo")
    with pytest.raises(InputError, match="^format: 'csv' takes the options none"):
        write_results(tmp_path / "x.csv", results, scene, "csv", frame="level")
    with pytest.raises(InputError, match="^scene:"):
        write_results(tmp_path / "x.json", results, None, "openlabel")
    with pytest.raises(InputError, match="^scene:"):
        write_results(tmp_path / "x.csv", results[:1], scene, "csv")
    assert list(tmp_path.iterdir()) == []
    report = write_results(tmp_path / "k", results, scene, "kitti", frame="level", cameras=["tilted"])
    assert {p.parent.name for p in report.paths} == {"label_2", "calib"} and (tmp_path / "k" / "tilted").is_dir()


def test_a_failed_write_leaves_the_old_file(known, tmp_path):
    scene, results = known
    path = tmp_path / "r.json"
    write_results(path, results, scene, "nuscenes")
    before = path.read_text()
    bad = [*results[:1], "not a frame"]
    with pytest.raises(InputError, match="^results:"):
        write_results(path, bad, None, "nuscenes")
    assert path.read_text() == before and [p.name for p in tmp_path.iterdir()] == ["r.json"]


@pytest.mark.parametrize("run", ["real", "real_track"])
def test_every_format_gives_a_real_solve_back(run, request, tmp_path):
    scene, results = request.getfixturevalue(run)
    boxes = {(f, v.id): v.box for f, frame in enumerate(results) for v in frame.vehicles}
    assert all(b is not None for b in boxes.values()) and len(boxes) == len(results)
    for name in FORMATS:
        report = write_results(tmp_path / name, results, scene, name)
        assert report.unsolved == [] and report.note() == ""
    assert [v.box.size.tolist() for f in load_results(tmp_path / "vfactor") for v in f.vehicles] == [
        b.size.tolist() for b in boxes.values()]
    for r in [*read_openlabel(tmp_path / "openlabel"), *read_csv(tmp_path / "csv")]:
        assert_same_box(r.box, boxes[(r.frame, r.id)])
    for r in read_nuscenes(tmp_path / "nuscenes"):
        assert_same_box(r.box, boxes[(r.frame, "v1")])
    kitti = read_kitti(tmp_path / "kitti")
    assert {r.camera for r in kitti} == set(scene.cameras)
    for r in kitti:  # camera frame: centre and size exact, heading as seen along the tilted camera's y axis
        box = boxes[(r.frame, "v1")]
        assert np.allclose(r.box.world_T_box.translation(), box.world_T_box.translation(), atol=MM)
        assert np.allclose(r.box.size, box.size, atol=MM)


def test_readers_refuse_rows_and_boxes_that_are_not_boxes(known, tmp_path):
    """A short CSV row raised a TypeError; NaN centres and negative sizes were read as boxes; a nuScenes entry filed
    under another sample's token was taken as that sample's."""
    import json

    scene, results = known
    write_csv(tmp_path / "r.csv", results)
    header, first, *_ = (tmp_path / "r.csv").read_text().splitlines()
    (tmp_path / "short.csv").write_text(header + "\n" + ",".join(first.split(",")[:5]) + "\n")
    with pytest.raises(InputError, match="row 1: expected the header's"):
        read_csv(tmp_path / "short.csv")
    fields = first.split(",")
    for column, value, words in (("length", "-5", "must be positive"), ("x", "nan", "must be finite")):
        bad = list(fields)
        bad[CSV_COLUMNS.index(column)] = value
        (tmp_path / "bad.csv").write_text(header + "\n" + ",".join(bad) + "\n")
        with pytest.raises(InputError, match=words):
            read_csv(tmp_path / "bad.csv")
    write_results(tmp_path / "n.json", results, scene, "nuscenes")
    data = json.loads((tmp_path / "n.json").read_text())
    token, entries = next((t, e) for t, e in data["results"].items() if e)
    entries[0]["sample_token"] = "another"
    (tmp_path / "n.json").write_text(json.dumps(data))
    with pytest.raises(InputError, match="sample_token"):
        read_nuscenes(tmp_path / "n.json")
