"""What the ``vfactor`` commands share: exit codes, messages and logging, checks of options, the keypoint network.

Messages: everything the commands say goes to stderr through the ``vfactor``
logger (:func:`say` for errors and the unsolved vehicles, :data:`log` for
notes), one line each, without terminal escapes (:func:`vfactor.sanity.one_line`).
Results and summaries go to stdout, and not at all with ``-q``.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from pathlib import Path

from vfactor.camera import SAME_PLACE, moved
from vfactor.errors import InputError
from vfactor.result import Status
from vfactor.sanity import one_line

__all__ = ["EXIT_OK", "EXIT_INTERNAL", "EXIT_INPUT", "EXIT_UNSOLVED", "EXIT_INTERRUPTED", "EXIT_TERMINATED",
           "configure_logging", "say", "note", "output", "progress", "missing_extra", "check_positive",
           "check_out_file", "check_out_dir", "check_same_rig", "degrees_metres", "rig_scenes", "report_unsolved",
           "detect", "amodal_pass", "check_amodal_pass", "check_outputs", "open_command_engine"]

EXIT_OK, EXIT_INTERNAL, EXIT_INPUT, EXIT_UNSOLVED, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 3, 130, 143

#: The library's logger: modules log under ``vfactor.<module>``; the commands show WARNING and above, INFO
#: with ``-v``, DEBUG with ``-vv``, ERROR only with ``-q``.
log = logging.getLogger("vfactor")


class _OneLine(logging.Formatter):
    """A record as one line without escapes; INFO and DEBUG records name their module."""

    def format(self, record: logging.LogRecord) -> str:
        text = record.getMessage()
        if record.levelno < logging.WARNING:
            text = f"[{record.name}] {text}"
        return one_line(text, limit=2000)


class _StderrHandler(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is when a record comes (tests and callers may swap it)."""

    def __init__(self):
        super().__init__(sys.stderr)

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value):  # StreamHandler sets it; the current sys.stderr is always used
        pass


def configure_logging(verbose: int = 0, quiet: bool = False) -> None:
    """Shows the ``vfactor`` logger's records on stderr: ERROR with ``quiet``, else WARNING, INFO (``verbose``
    1) or DEBUG (2 and more). Idempotent: one handler however often it is called."""
    if quiet:
        level = logging.ERROR
    else:
        level = {0: logging.WARNING, 1: logging.INFO}.get(verbose, logging.DEBUG)
    if not any(isinstance(h, _StderrHandler) for h in log.handlers):
        handler = _StderrHandler()
        handler.setFormatter(_OneLine())
        log.addHandler(handler)
    log.setLevel(level)
    log.propagate = False


def open_command_engine(workers, scheduler):
    """A command's engine (:func:`vfactor.parallel.open_engine`), with Dask's own log records (``distributed``,
    configured when it is imported) shown only at ``-vv``: a lost scheduler is a multi-line traceback there, which
    the command says in one line."""
    from vfactor.parallel import open_engine

    engine = open_engine(workers, scheduler)
    if log.level > logging.DEBUG:
        for name in [n for n in logging.root.manager.loggerDict if n == "distributed" or n.startswith("distributed.")]:
            logging.getLogger(name).setLevel(logging.CRITICAL)
    return engine


def output(args):
    """The ``print`` of a command's results and summaries on stdout: a no-op with ``-q``."""
    return _silent if getattr(args, "quiet", False) else print


def _silent(*args, **kwargs) -> None:
    return None


def say(text: str) -> None:
    """An error or an unsolved vehicle: shown even with ``-q``."""
    log.error(text)


def note(text: str) -> None:
    """A note (``note: ...``) on stderr: hidden by ``-q``."""
    log.warning(f"note: {text}")


def progress(label: str, enabled: bool = True):
    """The progress callback of a command: a bar on a terminal, nothing otherwise."""
    from vfactor.progress import Progress

    return Progress(desc=label, enabled=enabled, tty_only=True)


def missing_extra(field: str, exc: ImportError, extras: str, context: str = "") -> InputError:
    """The error for a command part that needs an optional extra ("net": PyTorch, "render": moderngl)."""
    needs = {"net": "PyTorch", "render": "moderngl"}
    what = " and ".join(needs[e] for e in extras.split(","))
    return InputError(field, f"{context}this needs {what} ({exc}); install with "
                             f"pip install -c constraints.txt -e '.[{extras}]'")


def check_positive(value, name):
    if value is not None and value < 1:
        raise InputError(name, f"expected an integer >= 1, got {value}")
    return value


def check_out_file(value, option: str, inputs=()) -> Path:
    """Checks an output file option before the work starts: not ``-``, not a folder nor another file that is not a
    regular file (a pipe, a device), not a read-only file, not one of ``inputs``, and in a folder that exists (or
    can be made) and is writable. A link is followed: the file written is its target
    (:func:`vfactor.jsonio.write_text_atomic`).

    Raises:
        InputError: (field: ``option``) what is wrong.
    """
    if str(value) == "-":
        raise InputError(option, "'-' (standard output) is only for a stream of frames (vfactor track - --out -, or "
                                 "--follow); give a file name")
    path = Path(value)
    if path.is_dir() or str(value).endswith(("/", os.sep)):
        raise InputError(option, f"{value} is a folder; give a file name")
    if path.exists() and not path.is_file():
        raise InputError(option, f"{value} is not a regular file (a pipe, a device or a socket); results are written "
                                 "to a file, whole or not at all")
    if path.is_file() and not os.access(path, os.W_OK):
        raise InputError(option, f"{value} is read-only; make it writable or give another file")
    for name, given in inputs:
        if given is not None and Path(given).exists() and path.exists() and os.path.samefile(path, given):
            raise InputError(option, f"{value} is the {name} itself; write the output to another file")
    folder = path.absolute().parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise InputError(option, f"cannot create {path.parent}: {folder} is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(option, f"cannot write into {folder}: permission denied")
    return path


def check_out_dir(path: Path) -> Path:
    if path.exists() and not path.is_dir():
        raise InputError("--out", f"{path} exists and is not a folder")
    path.mkdir(parents=True, exist_ok=True)
    return path


def rig_scenes(args, why: str) -> tuple[Path, list[tuple[str, object]]]:
    """The ``--out`` file and the (file name, scene) of SCENE and each ``--traffic`` scene of a command that fits a
    rig to its traffic (fit-ground, fit-extrinsics), each checked to have SCENE's cameras where SCENE has them
    (``why`` says what needs it)."""
    from vfactor.scene import load_scene

    traffic = list(args.traffic or [])
    out = check_out_file(args.out, "--out", [("scene file", args.scene)] + [("--traffic file", t) for t in traffic])
    scenes = [(name, load_scene(name, allow_outside_paths=args.allow_outside_paths)) for name in [args.scene, *traffic]]
    for name, other in scenes[1:]:
        check_same_rig(scenes[0][1], other, name, why)
    return out, scenes


def degrees_metres(text: str, option: str) -> tuple[float, float]:
    """An option's ``DEG,M`` (degrees and metres per camera axis: a camera pose's error) as two numbers.

    Raises:
        InputError: (``option``) not two numbers separated by a comma.
    """
    try:
        rotation, translation = (float(part) for part in text.split(","))
    except ValueError:
        raise InputError(option, f"expected DEG,M (degrees and metres per camera axis), e.g. 0.3,0.05, "
                                 f"got {text!r}") from None
    return rotation, translation


def check_same_rig(scene, other, name: str, why: str) -> None:
    """Raises InputError (``--traffic``) unless ``other`` (the file ``name``) has ``scene``'s cameras where they were:
    one rig (``why`` says what needs it)."""
    if set(other.cameras) != set(scene.cameras):
        raise InputError("--traffic", f"{name} has cameras {sorted(other.cameras)}, the scene {sorted(scene.cameras)}: "
                                      f"{why}")
    for camera, given in scene.cameras.items():
        difference = moved(other.cameras[camera], given)
        if difference > SAME_PLACE:
            raise InputError("--traffic", f"{name}: camera {camera!r} is not where the scene has it "
                                          f"(world_T_camera differs by up to {difference:.3g}): one rig only")


def report_unsolved(results, scene, quiet: bool) -> int:
    """Prints a line per vehicle that was not solved or fits its keypoints poorly (status ``poor_fit``: solved, with a
    warning); returns the exit code (3 when any vehicle was not solved, else 0)."""
    code = EXIT_OK
    camera_index = {name: i for i, name in enumerate(scene.cameras)}
    for f, frame in enumerate(results):
        for v in frame.vehicles:
            if v.status == Status.POOR_FIT:
                say(f"frames[{f}] vehicle '{v.id}': {v.status.value}: {v.message}")
            if v.ok:
                continue
            message = v.message
            for name, i in camera_index.items():
                message = message.replace(f"camera '{name}'", f"camera '{name}' (cameras[{i}])")
            say(f"frames[{f}] vehicle '{v.id}': {v.status.value}: {message}")
            code = EXIT_UNSOLVED
    return code


def detect(scene, args, engine=None):
    """Runs the keypoint network on the scene's box-only detections (if any), on ``engine``
    (:mod:`vfactor.parallel`; default: this process); optionally saves the result."""
    pending = scene.undetected()
    if not pending:
        if args.weights:
            note("every detection gives keypoints; --weights is not used")
        if args.save_detections:
            raise InputError("--save-detections", "no detection of the scene needs the keypoint network")
        return scene
    try:
        from vfactor.net.infer import KeypointDetector
        from vfactor.net.pipeline import detect_scene
    except ImportError as exc:
        f, j = pending[0]
        raise missing_extra(f"frames[{f}].detections[{j}]", exc, "net", "given as an image box: ") from None
    try:
        detector = KeypointDetector(args.weights)
    except Exception as exc:  # noqa: BLE001 - any failure to read the weights file is bad input
        raise InputError("--weights", str(exc)) from None
    t0 = time.perf_counter()
    heatmaps_dir = None
    if args.save_detections:
        out = Path(args.save_detections)
        heatmaps_dir = out.with_name(out.stem + "_heatmaps")
    scene = detect_scene(scene, detector, heatmaps_dir=heatmaps_dir, progress=progress("keypoints", not args.quiet),
                         engine=engine)
    if args.save_detections:
        from vfactor.scene import save_scene

        save_scene(scene, args.save_detections)
    if not args.quiet:
        print(f"keypoint network: {len(pending)} boxes ({time.perf_counter() - t0:.2f} s)"
              + (f"; wrote {args.save_detections} and {heatmaps_dir}/" if args.save_detections else ""))
    return scene


def amodal_pass(scene, results, args, engine=None):
    """``--amodal-pass``: the scene with the keypoints of each vehicle whose box stops at the image border found
    again in the box of the vehicle ``results`` (the first solve's) holds
    (:func:`vfactor.net.amodal.redetect_clipped`), and how many boxes were replaced."""
    from vfactor.net.amodal import redetect_clipped
    from vfactor.net.infer import KeypointDetector

    t0 = time.perf_counter()
    scene, replaced = redetect_clipped(scene, results, KeypointDetector(args.weights), engine=engine)
    if not args.quiet:
        print(f"amodal pass: {replaced} boxes clipped by the image border found again from the first solve's "
              f"vehicles ({time.perf_counter() - t0:.2f} s)")
    return scene, replaced


def check_amodal_pass(raw, args) -> None:
    """``--amodal-pass`` needs detections given as image boxes (found by the network), and writes no first-pass
    detections."""
    if not getattr(args, "amodal_pass", False):
        return
    if not raw.undetected():
        raise InputError("--amodal-pass", "no detection of the scene is given as an image box for the keypoint network")
    if args.save_detections:
        raise InputError("--amodal-pass", "not with --save-detections (which writes the first pass's keypoints)")


def check_outputs(args) -> None:
    """``solve`` and ``track``: --out (a folder for ``--format kitti``) and --save-detections checked before any
    work."""
    if getattr(args, "kitti_frame", None) and getattr(args, "format", "vfactor") != "kitti":
        raise InputError("--kitti-frame", f"only with --format kitti, not {args.format}")
    if getattr(args, "format", "vfactor") == "kitti":
        if Path(args.out).exists() and not Path(args.out).is_dir():
            raise InputError("--out", f"{args.out} exists and is not a folder (--format kitti writes a folder)")
        check_out_file(Path(args.out) / "label.txt", "--out", [("scene file", args.scene)])
    else:
        check_out_file(args.out, "--out", [("scene file", args.scene)])
    if args.save_detections:
        check_out_file(args.save_detections, "--save-detections",
                        [("scene file", args.scene), ("result file --out", args.out)])
        if os.path.abspath(args.save_detections) == os.path.abspath(args.out):
            raise InputError("--save-detections", f"{args.save_detections} is also --out; give another file")

