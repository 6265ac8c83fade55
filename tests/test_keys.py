"""Key scheme."""

from __future__ import annotations

import gtsam
import pytest

from vfactor.keys import KeyScheme


def test_default_scheme_is_documented_symbols():
    keys = KeyScheme()
    assert keys.pose_key(2, 5) == gtsam.symbol("x", 2_000_005)
    assert keys.layer_keys(3) == (gtsam.symbol("w", 3), gtsam.symbol("l", 3), gtsam.symbol("r", 3))


def test_custom_characters_avoid_collisions():
    keys = KeyScheme(pose="v", wheel="a", light="b", roof="c")
    assert gtsam.Symbol(keys.pose_key(0, 1)).chr() == ord("v")


@pytest.mark.parametrize("kw", [dict(pose="xx"), dict(pose="w"), dict(frame_stride=0)])
def test_bad_schemes_raise(kw):
    with pytest.raises(ValueError, match="KeyScheme"):
        KeyScheme(**kw)


def test_frame_index_must_fit_the_stride():
    with pytest.raises(ValueError, match="frame"):
        KeyScheme(frame_stride=10).pose_key(0, 10)


def test_keys_that_would_collide_or_fail_in_gtsam_are_refused():
    for settings in ({"pose": "\x00"}, {"pose": "é"}, {"pose": " "}, {"frame_stride": True},
                     {"frame_stride": 2 ** 60}):
        with pytest.raises(ValueError, match="KeyScheme"):
            KeyScheme(**settings)  # "\x00" made plain integer keys, which a user's own graph uses
    keys = KeyScheme()
    for make in (lambda: keys.pose_key(-1, 0), lambda: keys.layer_key("wheel", -1), lambda: keys.hub_key(-1),
                 lambda: keys.pose_key(2 ** 40, 0)):
        with pytest.raises(ValueError, match="^vehicle: expected an index from 0"):
            make()
