"""The stacked hourglass: output shapes and count per stack, config checks, weights round trip (weights_only)."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from vfactor.net.model import (  # noqa: E402
    ModelConfig,
    StackedHourglass,
    count_parameters,
    load_weights,
    save_weights,
)


@pytest.mark.parametrize(
    "num_stacks, channels, depth, input_size",
    [(1, 16, 4, 128), (2, 16, 4, 96), (3, 8, 3, 64), (2, 32, 3, 32)],
)
def test_one_heatmap_stack_per_hourglass(num_stacks, channels, depth, input_size):
    torch.manual_seed(0)
    net = StackedHourglass(num_stacks=num_stacks, channels=channels, depth=depth, input_size=input_size).eval()
    with torch.no_grad():
        out = net(torch.rand(2, 3, input_size, input_size))
    assert isinstance(out, list) and len(out) == num_stacks
    for h in out:
        assert h.shape == (2, 12, input_size // 4, input_size // 4)
        assert torch.isfinite(h).all()


def test_default_is_the_papers_layout_and_small():
    net = StackedHourglass()
    assert net.config == ModelConfig(num_stacks=2, num_keypoints=12, channels=64, depth=4, input_size=128)
    assert 300_000 < count_parameters(net) < 600_000  # ~1.7 MB of float32 weights


def test_gradients_reach_every_stack():
    torch.manual_seed(0)
    net = StackedHourglass(num_stacks=2, channels=16, depth=2, input_size=32)
    out = net(torch.rand(2, 3, 32, 32))
    out[0].sum().backward()  # the first stack's loss alone trains the stem and the first hourglass
    assert net.stem[0].weight.grad.abs().sum() > 0
    assert net.heads[1].weight.grad is None


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"input_size": 30}, "input_size"),
        ({"input_size": 16, "depth": 4}, "input_size"),
        ({"channels": 7}, "channels"),
        ({"num_stacks": 0}, "num_stacks"),
        ({"depth": 1.5}, "depth"),
    ],
)
def test_bad_configs_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        StackedHourglass(**kwargs)


def test_wrong_input_shape_is_reported():
    net = StackedHourglass(num_stacks=1, channels=8, depth=2, input_size=32)
    with pytest.raises(ValueError, match=r"\(B, 3, 32, 32\)"):
        net(torch.zeros(1, 3, 64, 64))


def test_weights_round_trip_with_weights_only(tmp_path):
    torch.manual_seed(1)
    net = StackedHourglass(num_stacks=2, channels=16, depth=3, input_size=64)
    net.train()
    net(torch.rand(4, 3, 64, 64))  # moves the BatchNorm running statistics off their defaults
    net.eval()
    path = save_weights(net, tmp_path / "w.pt", {"crop": {"margin": 0.1, "square": True}, "note": "test"})
    payload = torch.load(path, weights_only=True)  # plain types and tensors only
    assert payload["format"] == "vfactor-stacked-hourglass"
    assert payload["model"] == net.config.to_dict()
    loaded, meta = load_weights(path, with_config=True)
    assert meta == {"crop": {"margin": 0.1, "square": True}, "note": "test"}
    assert loaded.config == net.config and not loaded.training
    x = torch.rand(3, 3, 64, 64)
    with torch.no_grad():
        for a, b in zip(net(x), loaded(x)):
            assert torch.equal(a, b)


def test_load_rejects_other_files(tmp_path):
    torch.save({"state_dict": {}}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not a vfactor"):
        load_weights(tmp_path / "other.pt")


def test_save_rejects_metadata_that_needs_pickle(tmp_path):
    net = StackedHourglass(num_stacks=1, channels=8, depth=2, input_size=32)
    with pytest.raises(TypeError, match="config.when"):
        save_weights(net, tmp_path / "w.pt", {"when": object()})
