"""Weights and checkpoint files: every damaged or hostile file is refused with one line naming the option.

Regression tests of docs/reliability.md ("Weights files"): a truncated, empty,
text or malicious file, a NaN tensor and bytes flipped inside a tensor, in every
command that reads weights (``detect``, ``score``, ``calibrate``, ``solve`` /
``track`` on a scene of image boxes) and in ``train --resume``'s checkpoints.
Before, these gave exit 1 ("internal error: EOFError", "KeyError: 101", an
``UnpicklingError`` of several lines) or, for flipped bytes, loaded silently.
"""

from __future__ import annotations

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from tests.net.bad_weights import BAD_KINDS, bad_weights_files, flip_tensor_bytes, small_net  # noqa: E402
from tests.net.synthetic import blob_dataset  # noqa: E402
from vfactor.cli import main as vfactor_main  # noqa: E402
from vfactor.net.commands import main as net_main  # noqa: E402
from vfactor.net.data import KeypointDataset  # noqa: E402
from vfactor.net.infer import KeypointDetector  # noqa: E402
from vfactor.net.model import (  # noqa: E402
    SHIPPED_WEIGHTS_SHA256,
    WeightsError,
    check_state_dict,
    default_weights_path,
    load_weights,
    read_torch_file,
    weights_digest,
)
from vfactor.net.train import TrainConfig, latest_checkpoint, train  # noqa: E402

KINDS = sorted(BAD_KINDS)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return bad_weights_files(tmp_path_factory.mktemp("weights"))


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """An image with a box, held-out crops (.npz) and a one-frame scene of image boxes, for the commands."""
    folder = tmp_path_factory.mktemp("inputs")
    cv2.imwrite(str(folder / "image.png"), np.zeros((72, 128, 3), np.uint8))
    images, kp, vis, occ = blob_dataset(4, 32, seed=0)
    np.savez_compressed(folder / "val.npz", images=images, keypoints=kp, visible=vis, self_occluded=occ,
                        rois=np.tile([10.0, 20.0, 106.0, 116.0], (4, 1)))
    assert vfactor_main(["simulate", "intersection_2cam", "--out", str(folder / "sim.json"), "--frames", "1",
                         "--seed", "2"]) == 0
    doc = json.loads((folder / "sim.json").read_text())
    frame = doc["frames"][0]
    frame["images"] = {}
    for det in frame["detections"]:
        det.pop("keypoints", None)
        det.pop("keypoint_covariances", None)
        det["roi"] = [100.0, 100.0, 300.0, 260.0]
        frame["images"][det["camera"]] = f"{det['camera']}.png"
    for camera in doc["cameras"]:
        w, h = camera["image_size"]
        cv2.imwrite(str(folder / f"{camera['name']}.png"), np.zeros((h, w, 3), np.uint8))
    (folder / "scene.json").write_text(json.dumps(doc))
    return folder


def one_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert "\x1b" not in lines[0] and "Traceback" not in err
    return lines[0]


# ------------------------------------------------------------------ the reader
@pytest.mark.parametrize("kind", KINDS)
def test_load_weights_refuses_every_bad_file_with_one_line(files, kind, capfd):
    with pytest.raises(WeightsError) as info:
        load_weights(files[kind])
    assert info.value.field == str(files[kind]) and BAD_KINDS[kind] in str(info.value)
    assert "\n" not in str(info.value) and "\x1b" not in str(info.value)
    with pytest.raises(WeightsError, match=BAD_KINDS[kind].replace("(", r"\(")):
        KeypointDetector(files[kind])
    assert "unpickled-code-ran" not in capfd.readouterr().out  # the malicious pickle never ran


def test_good_weights_carry_the_checksum_of_their_tensors(files):
    payload = read_torch_file(files["good"])
    assert payload["sha256"] == weights_digest(payload["state_dict"], payload["model"])
    model, meta = load_weights(files["good"], with_config=True)
    assert meta == {"crop": {"margin": 0.1, "square": True}}
    # the digest covers the architecture and every tensor, not the free-form metadata
    assert weights_digest(payload["state_dict"], payload["model"]) != weights_digest(payload["state_dict"], None)
    state = dict(payload["state_dict"], **{"heads.0.bias": payload["state_dict"]["heads.0.bias"] + 1e-7})
    assert weights_digest(state, payload["model"]) != payload["sha256"]


def test_files_without_a_checksum_still_load(tmp_path):
    """Weights written before the checksum was stored: only the finite-values check applies."""
    net = small_net()
    payload = {"format": "vfactor-stacked-hourglass", "version": 1, "model": net.config.to_dict(), "config": {},
               "state_dict": net.state_dict()}
    torch.save(payload, tmp_path / "old.pt")
    loaded = load_weights(tmp_path / "old.pt")
    assert all(torch.equal(a, b) for a, b in zip(loaded.state_dict().values(), net.state_dict().values()))


def test_shipped_weights_match_the_checksum_in_the_package(tmp_path):
    payload = read_torch_file(default_weights_path())
    assert weights_digest(payload["state_dict"], payload["model"]) == SHIPPED_WEIGHTS_SHA256
    load_weights(default_weights_path())  # verified on load
    flip_tensor_bytes(default_weights_path(), tmp_path / "keypoints.pt")  # a damaged copy of the shipped file
    damaged = read_torch_file(tmp_path / "keypoints.pt")
    with pytest.raises(WeightsError, match="do not match the SHA-256 checksum"):
        check_state_dict(damaged["state_dict"], "shipped", SHIPPED_WEIGHTS_SHA256, damaged["model"])


# ------------------------------------------------------------------ every command that reads weights
def net_command(command: str, inputs, weights) -> list[str]:
    if command == "detect":
        return ["detect", str(inputs / "image.png"), "--roi", "10", "10", "60", "60", "--weights", str(weights)]
    if command == "score":
        return ["score", "--data", str(inputs / "val.npz"), "--weights", str(weights)]
    return ["calibrate", "--val", str(inputs / "val.npz"), "--weights", str(weights)]


@pytest.mark.parametrize("command", ["detect", "score", "calibrate"])
@pytest.mark.parametrize("kind", KINDS)
def test_network_commands_refuse_a_bad_weights_file(files, inputs, capsys, command, kind):
    assert net_main(net_command(command, inputs, files[kind])) == 2
    line = one_line(capsys.readouterr().err)
    assert "--weights" in line and str(files[kind]) in line and BAD_KINDS[kind] in line


@pytest.mark.parametrize("command", ["detect", "score", "calibrate"])
def test_network_commands_run_with_the_good_file(files, inputs, capsys, command):
    assert net_main(net_command(command, inputs, files["good"])) == 0


@pytest.mark.parametrize("command", ["solve", "track"])
@pytest.mark.parametrize("kind", KINDS)
def test_solve_and_track_of_image_boxes_refuse_a_bad_weights_file(files, inputs, tmp_path, capsys, command, kind):
    code = vfactor_main([command, str(inputs / "scene.json"), "--out", str(tmp_path / "r.json"), "--weights",
                         str(files[kind])])
    line = one_line(capsys.readouterr().err)
    assert code == 2 and line.startswith(f"vfactor {command}: error: --weights: ") and BAD_KINDS[kind] in line


def test_vfactor_detect_refuses_a_malicious_file_without_a_traceback(files, inputs):
    """The real entry point: exit 2, one line, and the pickled command never runs."""
    done = subprocess.run([sys.executable, "-m", "vfactor", *net_command("detect", inputs, files["malicious"])],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "unpickled-code-ran" not in done.stdout
    assert "refused" in one_line(done.stderr)


# ------------------------------------------------------------------ train --resume
TINY = dict(num_stacks=1, channels=8, depth=2, input_size=32, batch_size=8, num_threads=1)


@pytest.mark.parametrize("kind", ["truncated", "text", "nan", "flipped"])
def test_train_resume_refuses_a_damaged_checkpoint(tmp_path, capsys, kind):
    KeypointDataset(*blob_dataset(8, 32, seed=0)).save_npz(tmp_path / "train" / "shard_00000.npz")
    train(TrainConfig(epochs=1, **TINY), KeypointDataset(*blob_dataset(8, 32, seed=0)), out_dir=tmp_path / "run",
          progress=False)
    ckpt = latest_checkpoint(tmp_path / "run")
    data = ckpt.read_bytes()
    if kind == "truncated":
        ckpt.write_bytes(data[: len(data) // 2])
    elif kind == "text":
        ckpt.write_text("not a checkpoint")
    elif kind == "nan":
        payload = torch.load(ckpt, weights_only=True)
        payload["state_dict"]["heads.0.weight"][0, 0, 0, 0] = float("nan")
        torch.save(payload, ckpt)
    else:
        intact = tmp_path / "intact.pt"
        intact.write_bytes(data)
        flip_tensor_bytes(intact, ckpt)
    (tmp_path / "tiny.json").write_text(json.dumps(TINY))
    code = net_main(["train", "--data", str(tmp_path / "train"), "--config", str(tmp_path / "tiny.json"),
                     "--epochs", "2", "--out", str(tmp_path / "run"), "--resume", "--quiet"])
    line = one_line(capsys.readouterr().err)
    assert code == 2 and "--resume" in line and ckpt.name in line
    assert {"truncated": "truncated", "text": "truncated", "nan": "NaN", "flipped": "SHA-256"}[kind] in line

