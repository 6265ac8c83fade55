"""``vfactor import``: detections of other tools into a scene file; the ``NAME=FILE`` options they share."""

from __future__ import annotations

from pathlib import Path

from vfactor.cli.common import EXIT_OK, check_out_file, note, output
from vfactor.errors import InputError

__all__ = ["import_detections", "name_file_pairs"]


def name_file_pairs(values: list[str] | None, option: str) -> dict[str, str]:
    """``NAME=FILE`` options (repeatable) as a dict; the error names the option.

    Raises:
        InputError: (field: ``option``) a value without ``=``, an empty name or file, or a name given twice.
    """
    out: dict[str, str] = {}
    for value in values or []:
        name, sep, path = value.partition("=")
        if not sep or not name or not path:
            raise InputError(option, f"expected CAMERA=FILE, got {value!r}")
        if name in out:
            raise InputError(option, f"camera {name!r} is given twice ({out[name]} and {path})")
        out[name] = path
    return out


def import_detections(args) -> int:
    """``vfactor import coco --cameras CAMERAS --results CAM=FILE ... --keypoints SET --out SCENE``."""
    from vfactor.formats.coco import import_coco

    results = name_file_pairs(args.results, "--results")
    if not results:
        raise InputError("--results", "give at least one CAMERA=FILE (a COCO keypoint file of that camera)")
    images = name_file_pairs(args.images, "--images") or None
    out = check_out_file(args.out, "--out", [("cameras file --cameras", args.cameras),
                                             *((f"COCO file of {name}", path) for name, path in results.items())])
    skipped: dict[str, int] = {}
    try:
        scene = import_coco(args.cameras, results, args.keypoints, out, values=args.values, min_score=args.min_score,
                            min_confidence=args.min_confidence, frames=args.frames, images=images, fps=args.fps,
                            pixel_origin=args.pixel_origin, track_ids=args.track_ids, skipped=skipped)
    except InputError as exc:  # the API's option names as the command's flags
        flag = {"min_score": "--min-score", "min_confidence": "--min-confidence"}.get(exc.field)
        if flag is None:
            raise
        raise InputError(flag, exc.problem) from None
    if skipped:
        note(f"left out {sum(skipped.values())} detections: " + ", ".join(
            f"{n} {reason}" for reason, n in skipped.items()) + " (crowd: iscrowd 1; score: under --min-score; "
            "no keypoint: none of the 12 seen after --min-confidence)")
    detections = sum(len(f.detections) for f in scene.frames)
    output(args)(f"wrote {Path(out)} ({len(scene.frames)} frames, {detections} detections, "
                 f"{len(scene.cameras)} cameras; keypoints {args.keypoints})")
    return EXIT_OK
