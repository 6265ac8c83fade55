"""Damaged and hostile weights files for the regression tests of the weights checks (import only with torch).

:func:`bad_weights_files` writes, from a small network's weights file, one file
of every kind that must be refused: truncated, empty, text, a malicious pickle,
a NaN tensor, and bytes flipped inside a tensor's data.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import torch

from vfactor.net.model import StackedHourglass, save_weights

__all__ = ["BAD_KINDS", "small_net", "bad_weights_files", "flip_tensor_bytes"]

#: Every kind of bad file, and a piece of the one-line message it must give.
BAD_KINDS = {
    "truncated": "truncated, or not a weights file",
    "empty": "empty file",
    "text": "not a torch.save archive",
    "malicious": "refused: it holds pickled code",
    "nan": "NaN or infinite",
    "flipped": "do not match the SHA-256 checksum",
}


class _Exploit:
    """Unpickling it would run a shell command."""

    def __reduce__(self):
        return (os.system, ("echo unpickled-code-ran",))


def small_net(input_size: int = 32) -> StackedHourglass:
    """A tiny seeded network (one stack, 8 channels, depth 2): files of about 40 kB."""
    torch.manual_seed(0)
    return StackedHourglass(num_stacks=1, channels=8, depth=2, input_size=input_size).eval()


def flip_tensor_bytes(src: Path, dst: Path) -> None:
    """Copies ``src`` with two bytes flipped in the middle of its largest tensor record (the zip stays valid)."""
    data = bytearray(src.read_bytes())
    with zipfile.ZipFile(src) as archive:
        record = max((i for i in archive.infolist() if "/data/" in i.filename), key=lambda i: i.file_size)
    header = data[record.header_offset:record.header_offset + 30]
    start = (record.header_offset + 30 + int.from_bytes(header[26:28], "little")
             + int.from_bytes(header[28:30], "little"))
    middle = start + record.file_size // 2
    data[middle] ^= 0x40
    data[middle + 1] ^= 0x01
    dst.write_bytes(bytes(data))


def bad_weights_files(folder: Path, input_size: int = 32) -> dict[str, Path]:
    """Writes ``good.pt`` and one file per :data:`BAD_KINDS` key into ``folder``; returns ``{kind: path}`` (and "good")."""
    folder.mkdir(parents=True, exist_ok=True)
    good = save_weights(small_net(input_size), folder / "good.pt", {"crop": {"margin": 0.1, "square": True}})
    data = good.read_bytes()
    files = {"good": good}
    files["truncated"] = folder / "truncated.pt"
    files["truncated"].write_bytes(data[: len(data) // 2])
    files["empty"] = folder / "empty.pt"
    files["empty"].write_bytes(b"")
    files["text"] = folder / "text.pt"
    files["text"].write_text("these are not the weights you are looking for\n")
    files["malicious"] = folder / "malicious.pt"
    torch.save({"format": "vfactor-stacked-hourglass", "version": 1, "exploit": _Exploit()}, files["malicious"])
    nan_net = small_net(input_size)
    with torch.no_grad():
        nan_net.heads[0].weight[0, 0, 0, 0] = float("nan")
    files["nan"] = save_weights(nan_net, folder / "nan.pt")
    files["flipped"] = folder / "flipped.pt"
    flip_tensor_bytes(good, files["flipped"])
    return files
