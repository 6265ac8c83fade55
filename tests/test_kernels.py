"""The compiled kernels: one extension module, built ahead of time from kernels/, loaded without numba."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(not (ROOT / "kernels").is_dir(), reason="the kernels' sources are not here (an installed wheel)")
def test_the_extension_is_built_from_the_current_kernel_sources():
    """Fails after an edit of kernels/ until the extension is rebuilt (pip install -e ., or setup.py build_ext)."""
    from kernels import source_digest
    from vfactor import _kernels

    assert _kernels.source_digest() == source_digest()


def test_a_solve_loads_no_numba_and_no_scipy_special(tmp_path):
    """A fresh process imports vfactor and solves a vehicle from a scene file without numba (nothing is compiled at
    run time) and without scipy.special (a 0.3 s import)."""
    from vfactor.scene import save_scene
    from vfactor.sim import simulate

    scene_file = tmp_path / "scene.json"
    save_scene(simulate("intersection_2cam", seed=0, num_frames=1).scene, scene_file)
    code = (
        "import sys, vfactor\n"
        "from vfactor.scene import load_scene\n"
        "from vfactor.solve import solve_scene\n"
        f"assert solve_scene(load_scene({str(scene_file)!r}))[0].vehicles[0].ok\n"
        "print(sorted(m for m in ('numba', 'llvmlite', 'scipy.special') if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"
