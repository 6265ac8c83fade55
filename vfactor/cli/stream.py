"""``vfactor track -`` and ``vfactor track FILE --follow``: a live stream of frames in, a result line per frame out
(:mod:`vfactor.stream`, docs/scaling.md)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from vfactor.cli.common import EXIT_INPUT, EXIT_OK, EXIT_UNSOLVED, check_out_file, note, say
from vfactor.errors import InputError

__all__ = ["is_stream", "track_stream_command"]


def is_stream(args) -> bool:
    """Whether ``vfactor track`` reads a stream: SCENE ``-`` (standard input) or ``--follow``."""
    return args.scene == "-" or bool(getattr(args, "follow", False))


def track_stream_command(args) -> int:
    """Tracks the stream and writes a JSON line per frame to ``--out`` (``-``: standard output), each flushed as
    it is written. Exit code: 2 when a line was not a valid frame, 3 when a vehicle was not solved, else 0."""
    from vfactor.solve import SolveOptions
    from vfactor.stream import DEFAULT_STREAM_LAG, follow_lines, read_lines, track_stream
    from vfactor.track import TrackOptions

    for option, given in (("--batch", args.batch), ("--plot", args.plot), ("--associate", args.associate),
                          ("--workers", args.workers is not None), ("--scheduler", args.scheduler is not None),
                          ("--save-detections", args.save_detections), ("--camera", args.camera),
                          ("--kitti-frame", args.kitti_frame)):
        if given:
            raise InputError(option, "not for a stream (SCENE '-' or --follow)")
    if args.format != "vfactor":
        raise InputError("--format", "a stream's results are JSON Lines (vfactor's result entries), not "
                         f"{args.format}: track the recorded stream to write other formats")
    if args.idle_timeout is not None and not (args.follow and args.idle_timeout > 0):
        raise InputError("--idle-timeout", "expected a positive number of seconds, with --follow")
    if args.follow and args.scene == "-":
        raise InputError("--follow", "follows a file; standard input ('-') is read to its end anyway")
    if args.out != "-":
        check_out_file(args.out, "--out", [("stream", None if args.scene == "-" else args.scene)])
    lag = args.lag
    if lag is None:
        lag = DEFAULT_STREAM_LAG
        note(f"a stream is tracked with a fixed lag: {lag:g} s (--lag to change it)")
    options = TrackOptions(solve=SolveOptions(covariance=False), lag=lag, covariance=not args.no_covariance,
                           detector_offsets=args.detector_offsets)
    if args.scene == "-":
        lines, base = read_lines(sys.stdin), Path.cwd()
    else:
        lines, base = follow_lines(args.scene, idle_timeout=args.idle_timeout), Path(args.scene).absolute().parent
    out = sys.stdout if args.out == "-" else open(args.out, "w", encoding="utf-8")
    code, frames, unsolved, errors = EXIT_OK, 0, 0, 0
    try:
        for item in track_stream(lines, options, base, args.allow_outside_paths):
            out.write(json.dumps(item.to_dict(), allow_nan=False) + "\n")
            out.flush()
            frames += 1
            if item.error:
                say(f"frame {item.frame} (line {item.line}): {item.error}")
                errors += 1
                continue
            if item.note:
                note(f"frame {item.frame}: {item.note}")
            for v in item.result.vehicles:
                if not v.ok:
                    say(f"frame {item.frame} vehicle '{v.id}': {v.status.value}: {v.message}")
                    unsolved += 1
    finally:
        if out is not sys.stdout:
            out.close()
    if not args.quiet:
        print(f"stream: {frames} frames, {errors} lines not read, {unsolved} vehicles not solved"
              + ("" if args.out == "-" else f"; wrote {args.out}"), file=sys.stderr)
    if errors:
        code = EXIT_INPUT
    elif unsolved:
        code = EXIT_UNSOLVED
    return code
