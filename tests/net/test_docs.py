"""The inference example of docs/network.md runs as written."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

pytest.importorskip("torch")

PAGE = Path(__file__).resolve().parents[2] / "docs" / "network.md"


def test_inference_example_runs():
    blocks = [b for b in re.findall(r"```python\n(.*?)```", PAGE.read_text(encoding="utf-8"), flags=re.S)
              if "KeypointDetector" in b]
    assert blocks, "docs/network.md has no inference example"
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, str(PAGE), "exec"), namespace)  # noqa: S102 - our own documentation
    assert namespace["heatmaps"].shape == (1, 12, 24, 24)
