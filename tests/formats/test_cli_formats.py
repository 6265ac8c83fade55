"""``vfactor solve|track --format``: every output format from the command line, read back to the same boxes."""

from __future__ import annotations

import numpy as np
import pytest

from vfactor.cli import main
from vfactor.formats import read_csv, read_kitti, read_nuscenes, read_openlabel
from vfactor.scene import load_results

READERS = {"openlabel": read_openlabel, "kitti": read_kitti, "nuscenes": read_nuscenes, "csv": read_csv}


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli_formats")
    scene = folder / "scene.json"
    assert main(["simulate", "intersection_2cam", "--out", str(scene), "--frames", "2", "--seed", "3", "-q"]) == 0
    assert main(["solve", str(scene), "--out", str(folder / "result.json"), "-q"]) == 0
    return folder, scene, load_results(folder / "result.json")


def _centres(boxes):
    return sorted(tuple(np.round(b.box.world_T_box.translation(), 4)) for b in boxes if b.box is not None)


@pytest.mark.parametrize("fmt", sorted(READERS))
def test_solve_writes_each_format_with_the_result_files_boxes(solved, fmt):
    folder, scene, results = solved
    out = folder / f"out_{fmt}"
    assert main(["solve", str(scene), "--out", str(out), "--format", fmt, "-q"]) == 0
    boxes = READERS[fmt](out)
    want = sorted(tuple(np.round(v.box.world_T_box.translation(), 4)) for fr in results for v in fr.vehicles)
    got = _centres(boxes)
    if fmt == "kitti":  # one label per camera that sees the box
        got = sorted(set(got))
    np.testing.assert_allclose(got, want, atol=2e-3)


def test_track_writes_csv_and_kitti_out_must_be_a_folder(solved, capsys):
    folder, scene, _ = solved
    assert main(["track", str(scene), "--out", str(folder / "tracks.csv"), "--format", "csv", "-q"]) == 0
    assert len(read_csv(folder / "tracks.csv")) == 2
    (folder / "a_file").write_text("x")
    assert main(["solve", str(scene), "--out", str(folder / "a_file"), "--format", "kitti"]) == 2
    assert "--out: " in capsys.readouterr().err
