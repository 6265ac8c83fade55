"""The Python examples in README.md, docs/tutorial.md, docs/output-formats.md and docs/vehicles.md run as written."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def python_blocks(path: Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", path.read_text(encoding="utf-8"), flags=re.S)


@pytest.mark.parametrize("page", ["README.md", "docs/tutorial.md", "docs/output-formats.md", "docs/vehicles.md"])
def test_examples_run(page, tmp_path, monkeypatch):
    path = ROOT / page
    if not path.exists():
        pytest.fail(f"{page} is missing")
    blocks = python_blocks(path)
    assert blocks, f"{page} has no Python example"
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, str(path), "exec"), namespace)  # noqa: S102 - our own documentation
