"""What a newcomer meets first: --version, help, options anywhere, -q / -v, the licence, py.typed, the package list."""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import pytest

import vfactor
from vfactor.cli import NET_COMMANDS, main

ROOT = Path(__file__).resolve().parents[1]


def test_version_is_the_package_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"vfactor {vfactor.__version__}"
    assert re.fullmatch(r"\d+\.\d+\.\d+", vfactor.__version__)


def test_help_command_shows_a_command_help(capsys):
    assert main(["help", "solve"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: vfactor solve") and "--out" in out
    assert main(["help", "nosuch"]) == 2
    assert "no command 'nosuch'" in capsys.readouterr().err
    assert main(["help"]) == 0
    assert "Start here" in capsys.readouterr().out


def test_help_texts_have_no_literal_percent_escapes(capsys):
    for command in ("eval", "solve", "track", "simulate", "demo", "plot", "schema"):
        assert main(["help", command]) == 0
        assert "%%" not in capsys.readouterr().out, command


def test_eval_help_names_every_noise_level(capsys):
    """The CLI keeps vfactor.evaluation (and GTSAM) out of its import, so the --levels help lists the levels by hand:
    a level added to NOISE_LEVELS must be named there too."""
    from vfactor.evaluation import NOISE_LEVELS

    assert main(["help", "eval"]) == 0
    levels_help = capsys.readouterr().out.split("\n  --levels LEVELS", 1)[1].split("\n  --frames FRAMES", 1)[0]
    named = set(re.findall(r"[a-z_]+", levels_help))
    assert set(NOISE_LEVELS) <= named, sorted(set(NOISE_LEVELS) - named)


@pytest.mark.parametrize("command", sorted(NET_COMMANDS))
def test_network_commands_are_reachable_from_vfactor(command, capsys):
    pytest.importorskip("torch")
    with pytest.raises(SystemExit) as exit_:
        main([command, "--help"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.startswith(f"usage: vfactor {command}")


def test_network_commands_say_what_they_need_without_torch(monkeypatch, capsys):
    import sys

    monkeypatch.setitem(sys.modules, "vfactor.net.commands", None)  # as where torch is not installed
    for argv in (["detect", "--help"], ["help", "detect"]):
        assert main(argv) == 0
        out = capsys.readouterr().out
        assert out.startswith("vfactor detect: keypoints, confidences") and "this needs PyTorch" in out
        assert "pip install -c constraints.txt -e '.[net]'" in out and "vfactor help detect" in out
    assert main(["detect", "image.png", "--roi", "0", "0", "9", "9"]) == 2  # running it is an error
    assert "this needs PyTorch" in capsys.readouterr().err


def test_demo_with_images_without_the_extras_writes_nothing(tmp_path, monkeypatch, capsys):
    import sys

    monkeypatch.setitem(sys.modules, "vfactor.net.pipeline", None)  # as where torch is not installed
    assert main(["demo", "--images", "--out", str(tmp_path / "demo")]) == 2
    assert "--images: this needs PyTorch and moderngl" in capsys.readouterr().err
    assert not (tmp_path / "demo").exists()


def test_a_read_only_out_file_is_not_replaced(tmp_path, monkeypatch, capsys):
    import os

    out = tmp_path / "r.json"
    out.write_text("keep")
    out.chmod(0o444)
    if os.access(out, os.W_OK):  # root may write any file: ask as a user would be answered
        real = os.access
        monkeypatch.setattr(os, "access", lambda p, mode, **k: False if Path(p) == out and mode & os.W_OK
                            else real(p, mode, **k))
    assert main(["simulate", "intersection_2cam", "--out", str(out), "--frames", "1"]) == 2
    assert "read-only" in capsys.readouterr().err and out.read_text() == "keep"


def test_common_options_before_or_after_the_command(tmp_path, capsys):
    scene = tmp_path / "scene.json"
    assert main(["simulate", "intersection_2cam", "--out", str(scene), "--frames", "1", "-q", "--debug"]) == 0
    assert capsys.readouterr().out == ""
    assert main(["-q", "solve", str(scene), "--out", str(tmp_path / "r.json")]) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
    assert main(["solve", str(scene), "--out", str(tmp_path / "r.json"), "-v"]) == 0
    err = capsys.readouterr().err
    assert "[vfactor.solve] solved 1 of 1 vehicles in 1 frames, 2 cameras" in err
    assert main(["solve", str(scene), "--out", str(tmp_path / "r.json"), "-vv"]) == 0
    assert re.search(r"\[vfactor\.solve\] frame 0 \(t = 0 s\) vehicle 'v1': converged after \d+ iterations",
                     capsys.readouterr().err)


def test_errors_still_show_with_quiet(tmp_path, capsys):
    assert main(["solve", str(tmp_path / "missing.json"), "--out", str(tmp_path / "r.json"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("vfactor solve: error:") and "missing.json" in err and "Traceback" not in err


def test_licence_file_matches_the_metadata():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["license"]["text"] == "BSD-3-Clause"
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("BSD 3-Clause License") and "Neither the name of the copyright holder" in text


def test_package_is_typed_and_lists_every_package():
    assert (Path(vfactor.__file__).parent / "py.typed").is_file()
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "vfactor").rglob("__init__.py")}
    mapped = {name: ROOT / folder for name, folder in setuptools["package-dir"].items()}
    assert set(setuptools["packages"]) == found | set(mapped)
    assert all((folder / "__init__.py").is_file() for folder in mapped.values())


def test_scenarios_live_in_the_top_level_graphs_folder():
    from vfactor.sim import list_scenarios

    files = sorted(p.stem for p in (ROOT / "graphs").glob("*.json"))
    assert files and list_scenarios() == files
    assert not (ROOT / "vfactor" / "graphs").exists()


def test_demo_and_simulate_name_the_truth_file_alike(tmp_path, capsys):
    assert main(["simulate", "intersection_2cam", "--out", str(tmp_path / "scene.json"), "--frames", "1"]) == 0
    assert (tmp_path / "scene_truth.json").is_file()
    capsys.readouterr()
    assert main(["demo", "--out", str(tmp_path / "demo"), "--frames", "2", "--frame", "1", "-q"]) == 0
    assert capsys.readouterr().out == ""
    assert {"scene.json", "scene_truth.json"} <= {p.name for p in (tmp_path / "demo").iterdir()}
    assert main(["demo", "--out", str(tmp_path / "demo"), "--frames", "2", "--frame", "2"]) == 2
    assert "--frame: expected a frame index from 0 to 1, got 2" in capsys.readouterr().err


def test_plot_draws_any_frame_of_a_solved_scene(tmp_path, capsys):
    scene, result = tmp_path / "scene.json", tmp_path / "result.json"
    assert main(["simulate", "intersection_multi", "--out", str(scene), "--frames", "2", "-q"]) == 0
    assert main(["solve", str(scene), "--out", str(result), "-q"]) == 0
    truth = tmp_path / "scene_truth.json"
    assert main(["plot", str(scene), str(result), "--out", str(tmp_path / "pics"), "--frame", "1",
                 "--truth", str(truth)]) == 0
    assert "estimate_3d.png" in capsys.readouterr().out
    assert {p.name for p in (tmp_path / "pics").iterdir()} == {"overlay_cam0.png", "overlay_cam1.png",
                                                               "overlay_cam2.png", "estimate_3d.png"}
    assert main(["plot", str(scene), str(result), "--out", str(tmp_path / "pics"), "--frame", "5"]) == 2
    assert "--frame: expected a frame index from 0 to 1" in capsys.readouterr().err
    other = json.loads(result.read_text())
    other["frames"][1]["t"] = 9.0
    (tmp_path / "other.json").write_text(json.dumps(other))
    assert main(["plot", str(scene), str(tmp_path / "other.json"), "--out", str(tmp_path / "pics"), "--frame", "1"]) == 2
    assert "no frame at t = 0.1 s" in capsys.readouterr().err
