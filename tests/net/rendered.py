"""Rendered scenes shared by the network tests (skipped where no OpenGL context can be made)."""

from __future__ import annotations

import dataclasses

import pytest

from vfactor.render.renderer import RenderingUnavailable, get_context
from vfactor.sim import simulate


def require_rendering() -> None:
    """Skips the calling test where no OpenGL context can be made."""
    try:
        get_context()
    except RenderingUnavailable as exc:
        pytest.skip(f"no OpenGL rendering here: {exc}")


def cut_van_frame():
    """The first frame of ``tracks_3veh`` seed 231 (its van is cut by cam1's image border in every frame), as a
    one-frame simulation."""
    sim = simulate("tracks_3veh", seed=231)
    return dataclasses.replace(sim, scene=dataclasses.replace(sim.scene, frames=sim.scene.frames[:1]),
                               truth=sim.truth[:1])
