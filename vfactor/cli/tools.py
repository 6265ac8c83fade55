"""``vfactor schema`` and ``vfactor plot``: the file formats' JSON Schemas, and pictures of a solved frame."""

from __future__ import annotations

import sys
from pathlib import Path

from vfactor.cli.common import EXIT_OK, check_out_dir, check_out_file
from vfactor.errors import InputError
from vfactor.jsonio import write_text_atomic

__all__ = ["schema", "plot"]


def schema(args) -> int:
    """``vfactor schema [scene|result] [--out FILE]``."""
    from vfactor.schema import schema_text

    text = schema_text(args.which)
    if args.out:
        write_text_atomic(check_out_file(args.out, "--out"), text)
        if not args.quiet:
            print(f"wrote {args.out}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    return EXIT_OK


def plot(args) -> int:
    """``vfactor plot SCENE RESULT --out FOLDER [--frame N] [--truth TRUTH]``: overlays and a 3D plot of a frame."""
    from vfactor.scene import load_results, load_scene
    from vfactor.viz import plot_estimates, write_overlays

    scene = load_scene(args.scene, allow_outside_paths=args.allow_outside_paths)
    results = load_results(args.result)
    if not scene.frames:
        raise InputError(args.scene, "the scene has no frames to draw")
    if not 0 <= args.frame < len(scene.frames):
        raise InputError("--frame", f"expected a frame index from 0 to {len(scene.frames) - 1}, got {args.frame}")
    frame = scene.frames[args.frame]
    result = next((r for r in results if abs(r.t - frame.t) <= 1e-9 * max(1.0, abs(frame.t))), None)
    if result is None:
        raise InputError("--frame", f"the result file has no frame at t = {frame.t:g} s (frame {args.frame} of the "
                                    "scene): is it the result of this scene?")
    truth = None
    if args.truth:
        from vfactor.sim import load_truth

        frames_truth = load_truth(args.truth)
        if args.frame >= len(frames_truth):
            raise InputError("--truth", f"has {len(frames_truth)} frames; frame {args.frame} is not among them")
        truth = {vid: (t.world_T_vehicle, t.wireframe) for vid, t in frames_truth[args.frame].items()}
    out = check_out_dir(Path(args.out))
    written = write_overlays(out, scene.cameras, frame, result, truth=truth, base_dir=scene.base_dir)
    written.append(plot_estimates(scene.cameras, result.vehicles, truth, out / "estimate_3d.png",
                                  title=f"{Path(args.scene).name}, frame {args.frame} (t = {frame.t:g} s)"))
    if not args.quiet:
        print("wrote " + ", ".join(str(p) for p in written))
    return EXIT_OK
