"""Live streams: frames as JSON Lines in, one result per frame out, with the fixed-lag smoother.

``vfactor track - --out -`` reads standard input, ``vfactor track FILE --follow``
a file that another program is still writing (docs/scaling.md). The stream's
**first line** is its header: a scene file without frames (``cameras``, and
``ground_plane`` when the scene has one; a ``frames`` list there is read first).
**Every later line** is one frame, as in a scene file's ``frames`` list
(docs/scene-format.md); blank lines are skipped. Detections must name their
vehicle (a per-camera ``track`` alone is not enough: cross-camera association
needs the scene's frames around each frame, see docs/association.md).

For each frame, in arrival order, one JSON line comes out::

    {"frame": n, "t": ..., "vehicles": [...], "note"?: "..."}

``n`` counts the stream's frames from 0 (header frames included), ``vehicles``
are result-file vehicles (docs/scene-format.md) holding each vehicle's
estimate as that frame arrived (``filtered``: the smoother's estimate from the
frames so far; ``vfactor track`` on the recorded stream gives the smoothed
ones). A frame that arrives late (its time not after the last frame's) cannot
join the tracks: it is solved on its own (one-frame solve) and its line says so
in ``note``. A line that is not a valid frame gives ``{"frame": n, "line": k,
"error": "field: problem"}`` and the stream goes on; nothing is dropped
unsaid.

Memory stays bounded over any number of frames: each track's smoother holds
only its lag (:attr:`~vfactor.track.TrackOptions.lag`), and a track not seen for
:attr:`~vfactor.track.TrackOptions.max_gap` seconds is forgotten
(:meth:`~vfactor.track.Tracker.forget`).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from vfactor.errors import InputError, SceneError
from vfactor.observations import UNASSIGNED, Frame, Scene
from vfactor.result import FrameResult
from vfactor.solve import solve_frame
from vfactor.track import Tracker, TrackOptions

__all__ = ["StreamTracker", "StreamItem", "read_lines", "follow_lines", "stream_header", "track_stream",
           "DEFAULT_STREAM_LAG"]

log = logging.getLogger(__name__)

#: The fixed lag (seconds) of a stream whose command gives none.
DEFAULT_STREAM_LAG = 1.0


@dataclass
class StreamItem:
    """What a stream gives for one input line: a frame's result, or the error of a line that is not a frame.

    Attributes:
        frame: the frame's number in the stream (from 0).
        line: the input line it came from (from 1).
        result: the frame's result (None for an error).
        note: why the frame was not tracked (``""`` when it was).
        error: ``field: problem`` of a line that is not a valid frame (``""`` otherwise).
    """

    frame: int
    line: int
    result: FrameResult | None = None
    note: str = ""
    error: str = ""

    def to_dict(self) -> dict:
        """The item's output line (module docstring) as a JSON-serialisable dictionary."""
        from vfactor.scene import frame_result_to_dict

        if self.result is None:
            return {"frame": self.frame, "line": self.line, "error": self.error}
        out = {"frame": self.frame, **frame_result_to_dict(self.result, self.frame)}
        if self.note:
            out["note"] = self.note
        return out


class StreamTracker:
    """Tracks frames as they arrive (a :class:`~vfactor.track.Tracker` with a fixed lag), bounded in memory, for
    any number of frames (the pose keys take the stream's frame number modulo ``KeyScheme.frame_stride``).

    Args:
        scene: the stream's header (its cameras and ground plane; its frames are not used).
        options: tracking settings; a ``lag`` is required (bounded memory).

    Raises:
        InputError: (field ``--lag``) no lag.
    """

    def __init__(self, scene: Scene, options: TrackOptions):
        if options.lag is None:
            raise InputError("--lag", "a stream needs a fixed lag (bounded memory); give --lag SECONDS")
        self.scene = scene
        self.options = dataclasses.replace(options, solve=options.solve.for_scene(scene))
        self.tracker = Tracker(scene.cameras, self.options)
        # a late frame's own solve gives the covariances the tracker gives (options.covariance)
        self._alone = dataclasses.replace(self.options.solve, covariance=self.options.covariance)
        self.last_t: float | None = None

    def add(self, frame: Frame, index: int) -> tuple[FrameResult, str]:
        """The result of the stream's frame ``index`` (each vehicle's filtered estimate) and a note when it could not
        be tracked.

        Raises:
            InputError: a detection names no vehicle.
        """
        boxed = next((j for j, d in enumerate(frame.detections) if d.from_image), None)
        if boxed is not None:  # they came out "degenerate: no keypoint seen", the network never run
            raise InputError(f"frame.detections[{boxed}]", "a box without keypoints: a stream does not run the "
                             "keypoint network; give its keypoints (vfactor detect), or track the recorded stream as "
                             "a scene file (vfactor track live.jsonl --out r.json)")
        unnamed = next((j for j, d in enumerate(frame.detections) if d.vehicle == UNASSIGNED), None)
        if unnamed is not None:
            raise InputError(f"frame.detections[{unnamed}].vehicle",
                             "missing: the detections of a stream must name their vehicle (no association)")
        if self.last_t is not None and frame.t <= self.last_t:
            note = (f"arrived late: t = {frame.t:g} s is not after the last frame's {self.last_t:g} s; solved on its "
                    "own (one-frame solve), not tracked")
            return solve_frame(frame, self.scene.cameras, self._alone), note
        self.last_t = frame.t
        # the pose keys number a vehicle's frames below KeyScheme.frame_stride (10^6: 28 h at 10 Hz); a stream runs
        # longer, and its lag lets a frame's key go long before the number comes round again
        result = self.tracker.add_frame(frame, index % self.tracker.keys.frame_stride)
        self.tracker.forget(frame.t)
        return result, ""


def stream_header(line: str, base_dir: Path | None = None, allow_outside_paths: bool = False) -> Scene:
    """The stream's first line as a :class:`~vfactor.observations.Scene` (its ``frames`` optional).

    Raises:
        InputError: (field ``header`` or the header's field) not JSON or not a valid scene header.
    """
    from vfactor.scene import scene_from_dict

    try:
        data = json.loads(line)
    except json.JSONDecodeError as exc:
        raise InputError("header", f"the stream's first line is not JSON ({exc.msg} at column {exc.colno})") from None
    if isinstance(data, dict) and "frames" not in data:
        data = {**data, "frames": []}
    return scene_from_dict(data, base_dir=base_dir, allow_outside_paths=allow_outside_paths)


def read_lines(stream: IO[str]) -> Iterator[str]:
    """The lines of a text stream (standard input) as they come, until its end."""
    while True:
        line = stream.readline()
        if not line:
            return
        yield line


def follow_lines(path: str | Path, poll: float = 0.1, idle_timeout: float | None = None,
                 sleep: Callable[[float], None] = time.sleep) -> Iterator[str]:
    """The lines of a file that another program is still writing (``tail -f``): each whole line once it ends
    with a newline; at the end of the file, waits ``poll`` seconds and looks again.

    Args:
        idle_timeout: stop after this many seconds without a new line (default: follow until interrupted).

    Raises:
        InputError: (field ``scene``) the file cannot be opened.
    """
    try:
        handle = open(path, encoding="utf-8")
    except OSError as exc:
        raise InputError("scene", f"cannot read {path}: {exc.strerror}") from None
    with handle:
        partial, idle = "", 0.0
        while True:
            piece = handle.readline()
            if piece:
                partial += piece
                if partial.endswith("\n"):
                    yield partial
                    partial, idle = "", 0.0
                continue
            if idle_timeout is not None and idle >= idle_timeout:
                if partial.strip():
                    yield partial  # the writer stopped without a last newline
                return
            sleep(poll)
            idle += poll


def track_stream(lines: Iterable[str], options: TrackOptions = TrackOptions(lag=DEFAULT_STREAM_LAG),
                 base_dir: Path | None = None, allow_outside_paths: bool = False) -> Iterator[StreamItem]:
    """Tracks a stream (module docstring): yields one :class:`StreamItem` per frame line, as it arrives.

    Raises:
        InputError: an empty stream, or a header that is not a valid scene header (the error names the field).
    """
    from vfactor.scene import frame_from_dict

    numbered = ((k, line) for k, line in enumerate(lines, 1) if line.strip())
    first = next(numbered, None)
    if first is None:
        raise InputError("header", "the stream is empty: its first line must be the header (the cameras)")
    header = stream_header(first[1], base_dir, allow_outside_paths)
    tracker = StreamTracker(header, options)
    n = -1  # the stream's frame number
    for n, frame in enumerate(header.frames):
        yield StreamItem(n, first[0], *tracker.add(frame, n))
    for k, line in numbered:
        n += 1
        try:
            data = json.loads(line)
            if isinstance(data, dict) and "cameras" in data:  # it read "frame.cameras: unknown key"
                raise InputError("frame", "a second header: a stream's cameras are its first line's and stay; "
                                          "start a new stream for other cameras")
            frame = frame_from_dict(data, header, "frame", allow_outside_paths)
            yield StreamItem(n, k, *tracker.add(frame, n))
        except json.JSONDecodeError as exc:
            yield StreamItem(n, k, error=f"not JSON ({exc.msg} at column {exc.colno})")
        except (InputError, SceneError) as exc:
            yield StreamItem(n, k, error=str(exc))
