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


def test_kitti_frame_option(tmp_path, capsys):
    """The level label frame (exact upright boxes for a tilted roadside camera) had no flag."""
    from vfactor.cli import main
    from vfactor.formats import read_kitti
    from vfactor.scene import save_scene
    from vfactor.sim import simulate

    save_scene(simulate("intersection_2cam", seed=0, num_frames=2).scene, tmp_path / "s.json")
    assert main(["solve", str(tmp_path / "s.json"), "--out", str(tmp_path / "camera"), "--format", "kitti", "-q"]) == 0
    assert main(["solve", str(tmp_path / "s.json"), "--out", str(tmp_path / "level"), "--format", "kitti",
                 "--kitti-frame", "level", "-q"]) == 0
    camera, level = (sorted((b.camera, b.frame) for b in read_kitti(tmp_path / n)) for n in ("camera", "level"))
    assert camera == level
    assert (tmp_path / "camera" / "cam0" / "calib" / "000000.txt").read_text() != \
        (tmp_path / "level" / "cam0" / "calib" / "000000.txt").read_text()
    assert main(["solve", str(tmp_path / "s.json"), "--out", str(tmp_path / "r.json"), "--kitti-frame", "level"]) == 2
    assert "--kitti-frame: only with --format kitti" in capsys.readouterr().err
