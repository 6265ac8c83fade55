"""Command-line front ends of the keypoint network: ``train``, ``detect``, ``calibrate`` and ``score``.

Run as ``python -m vfactor.net train ...`` / ``python -m vfactor.net detect ...`` /
``python -m vfactor.net calibrate ...`` / ``python -m vfactor.net score ...``; ``vfactor train`` and ``vfactor detect``
forward their arguments to :func:`main`.

Exit codes (those of ``vfactor``): 0 success, 2 bad input (the message names
the argument or file), 1 an internal error.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from vfactor.errors import InputError
from vfactor.jsonio import describe, is_number, read_json, write_text_atomic
from vfactor.keypoints import KEYPOINT_NAMES
from vfactor.sanity import one_line

__all__ = ["main", "build_parser", "run_train", "run_detect", "run_calibrate", "run_calibrate_shape",
           "run_calibrate_bias", "run_score"]

EXIT_OK, EXIT_INTERNAL, EXIT_INPUT = 0, 1, 2


def build_parser(prog: str = "python -m vfactor.net") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description="Train the keypoint network, detect keypoints in images "
                                     "or calibrate the keypoint covariances.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    add_train_arguments(sub.add_parser(
        "train", help="train the stacked-hourglass keypoint network (progress bar, checkpoints, resume)",
        description="Train the keypoint network on rendered crops (--render N, or .npz shards with --data) and/or "
        "PASCAL3D+ cars (--pascal3d). Writes OUT/checkpoints/epoch_NNN.pt after every epoch, OUT/history.json "
        "(loss and validation PCK@0.1 per epoch, visible and self-occluded keypoints apart) and OUT/weights.pt. "
        "Deterministic with --seed; --resume continues from the newest checkpoint. Uses CUDA when available.",
    ))
    add_detect_arguments(sub.add_parser(
        "detect", help="12 keypoints, confidences and covariances per vehicle box of an image",
        description="Run the keypoint network on vehicle boxes of images and write, per box, the 12 keypoints in "
        "image pixels, their confidences (heatmap peaks) and 2x2 pixel covariances (the heatmap spread, calibrated "
        "to the network's errors when the weights carry a calibration: see the calibrate command); optionally the "
        "heatmaps (.npz).",
    ))
    add_calibrate_arguments(sub.add_parser(
        "calibrate", help="fit the keypoint covariances to the network's errors on held-out crops",
        description="Run the network on held-out crops with known keypoints (.npz shards), measure its pixel errors "
        "and the decoded heatmap covariances, fit a CovarianceCalibration (vfactor.net.calibrate) on the "
        "even-numbered crops and report, on the odd-numbered ones, the squared Mahalanobis distances before and "
        "after (chi-square(2) if calibrated: median 1.386, mean 2, 95% within 5.99), for visible and "
        "self-occluded keypoints apart. --write stores the calibration in the weights file's metadata (the "
        "weights are unchanged); KeypointDetector then applies it.",
    ))
    add_calibrate_shape_arguments(sub.add_parser(
        "calibrate-shape", help="fit the network's error shaped like a change of shape on solved rendered scenes",
        description="Render the scenes of a scenario (seeds --seed to --seed + --seeds - 1), find the keypoints "
        "with the network, solve every vehicle (each with the shape model learnt without it) and fit the detector "
        "shape error (metres per detection; vfactor.net.shape_error) that gives the world keypoints' covariances "
        "a mean NEES of 3. Prints the keypoint NEES per body type before and after. --write stores it in the "
        "weights file's calibration (the pixel calibration and the weights are kept); the pipeline then gives "
        "every detection that shape_sigma.",
    ))
    add_calibrate_bias_arguments(sub.add_parser(
        "calibrate-bias", help="fit the network's error that repeats over a vehicle's frames and cameras on rendered "
        "tracks",
        description="Render the track scenes of one or more scenarios (seeds --seed to --seed + --seeds - 1), find "
        "the keypoints with the network and, per track, estimate the rigid motion of the vehicle that all its "
        "detections share (every pose held at its truth, the shape free with the shape model learnt without the "
        "vehicle, each camera's own offset tied to it; vfactor.net.bias_error). bias_sigma is the spread of those "
        "motions less the data's own uncertainty of them: [roll, pitch, yaw] radians, [x, y, z] metres, body "
        "frame. --write stores it in the weights file's calibration (the rest is kept); the pipeline then gives "
        "every detection that bias_sigma, and tracks take it into their poses' covariances.",
    ))
    add_score_arguments(sub.add_parser(
        "score", help="PCK@0.1 of weights on crops with known keypoints (e.g. a held-out test set)",
        description="Score weights on rendered crops: PCK@0.1 of the crop side for visible and self-occluded "
        "keypoints, and the heatmap loss. --render-test N renders N held-out crops with --seed into --out first "
        "(a test set apart from the training run's validation crops when the seed differs).",
    ))
    return parser


def add_score_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--weights", help="weights file (default: the shipped weights)")
    p.add_argument("--data", nargs="+", action="extend", default=[], metavar="SHARD",
                   help=".npz shards or folders of shards")
    p.add_argument("--render-test", type=int, metavar="N", help="render N held-out crops first (into --out)")
    p.add_argument("--seed", type=int, default=1, help="seed of the rendered crops (default 1; training uses 0)")
    p.add_argument("--out", default="runs/test", help="folder for the rendered crops (default: runs/test)")
    p.add_argument("--device", help="cuda, cpu, ... (default: cuda when available)")


def add_calibrate_shape_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--weights", help="weights file with a pixel calibration (default: the shipped weights)")
    p.add_argument("--scenario", default="library_2cam", help="scenario to render (default: library_2cam)")
    p.add_argument("--seed", type=int, default=2, help="first seed (default 2)")
    p.add_argument("--seeds", type=int, default=2, help="how many seeds (default 2)")
    p.add_argument("--frames", type=int, help="frames per seed (default: the scenario's)")
    p.add_argument("--write", action="store_true", help="store the fitted shape_sigma in the weights' calibration")
    p.add_argument("--device", help="cuda, cpu, ... (default: cuda when available)")


#: The track scenarios ``calibrate-bias`` renders by default (the shipped calibration's, seeds 231-232).
BIAS_SCENARIOS = ("library_tracks", "tracks_3cam", "library_tracks_2cam", "tracks_3veh")


def add_calibrate_bias_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--weights", help="weights file with a pixel calibration (default: the shipped weights)")
    p.add_argument("--scenario", action="append", metavar="SCENARIO",
                   help="track scenario to render (repeatable; default: library_tracks, tracks_3cam, "
                   "library_tracks_2cam and tracks_3veh: three-camera and two-camera rigs)")
    p.add_argument("--seed", type=int, default=231, help="first seed (default 231)")
    p.add_argument("--seeds", type=int, default=2, help="how many seeds (default 2)")
    p.add_argument("--frames", type=int, help="frames per seed (default: the scenario's)")
    p.add_argument("--write", action="store_true", help="store the fitted bias_sigma in the weights' calibration")
    p.add_argument("--device", help="cuda, cpu, ... (default: cuda when available)")


def add_train_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="runs/keypoints", help="run folder (default: runs/keypoints)")
    p.add_argument("--data", action="append", default=[], metavar="PATH",
                   help="training .npz shards: a shard or a folder of shards (repeatable)")
    p.add_argument("--val", action="append", default=[], metavar="PATH", help="validation .npz shards (repeatable)")
    p.add_argument("--render", type=int, metavar="N", help="render N training crops first (into OUT/data/train)")
    p.add_argument("--render-val", type=int, metavar="N",
                   help="render N held-out validation crops first (into OUT/data/val)")
    p.add_argument("--render-workers", type=int, default=1, metavar="W", help="rendering processes (default 1)")
    p.add_argument("--pascal3d", metavar="ROOT", help="also train on PASCAL3D+ cars (the PASCAL3D+_release1.1 folder)")
    p.add_argument("--config", metavar="JSON", help="TrainConfig fields as a JSON file (flags below override it)")
    for flag, typ, field in [("--epochs", int, "epochs"), ("--batch-size", int, "batch_size"), ("--lr", float, "lr"),
                             ("--seed", int, "seed"), ("--input-size", int, "input_size"),
                             ("--stacks", int, "num_stacks"), ("--channels", int, "channels"),
                             ("--sigma", float, "sigma"), ("--threads", int, "num_threads"),
                             ("--workers", int, "num_workers")]:
        p.add_argument(flag, type=typ, dest=f"cfg_{field}", metavar=flag[2:].upper().replace("-", "_"),
                       help=f"TrainConfig.{field}")
    p.add_argument("--optimizer", choices=("adam", "rmsprop"), dest="cfg_optimizer", help="TrainConfig.optimizer")
    p.add_argument("--resume", action="store_true", help="continue from the newest checkpoint in OUT")
    p.add_argument("--init", metavar="WEIGHTS",
                   help="start from these weights instead of random ones (fine-tuning; the architecture must match)")
    p.add_argument("--library-share", type=float, metavar="P",
                   help="the share of vehicle-library vehicles among the --render training crops (default: the "
                   "training split's, 0.5); the rest are presets and PASCAL3D+ shapes")
    p.add_argument("--clipped-box-share", type=float, metavar="P",
                   help="frame this share of the --render crops' vehicles the image border cuts from their box "
                   "clipped to the image, as a 2D detector gives it (default 0: from the whole vehicle's box)")
    p.add_argument("--library-weight", action="append", default=[], metavar="TYPE=W",
                   help="draw the --render crops' library models of body TYPE W times as often as the others' "
                   "(repeatable; e.g. van=3)")
    p.add_argument("--real-roofs", action=argparse.BooleanOptionalAction, default=True,
                   help="draw the --render crops' vehicles with their roofs at their real heights (the default); "
                   "--no-real-roofs: at their window tops, the renderer's earlier default "
                   "(docs/rendering.md, \"Roofs\")")
    p.add_argument("--shape-stretch", type=float, metavar="S",
                   help="stretch each --render crop's vehicle shape along its length, width and height by independent "
                   "factors in [1 - S, 1 + S] (default 0: the models as they are)")
    p.add_argument("--export", metavar="PATH",
                   help="also copy the weights to PATH: those of the epoch with the best validation PCK when there "
                   "are validation crops (OUT/weights_best.pt), else the final ones")
    p.add_argument("--device", help="cuda, cpu, ... (default: cuda when available)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def add_detect_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("images", nargs="+", metavar="IMAGE", help="image file(s)")
    p.add_argument("--roi", nargs=4, type=float, action="append", default=[], metavar=("X0", "Y0", "X1", "Y1"),
                   help="a vehicle box in pixel edges (repeatable; for a single IMAGE)")
    p.add_argument("--rois", metavar="JSON", help="batch form: a JSON object {image path: [[x0, y0, x1, y1], ...]}")
    p.add_argument("--weights", help="weights file (default: the shipped weights)")
    p.add_argument("--out", help="result JSON (default: standard output)")
    p.add_argument("--heatmaps", metavar="NPZ", help="also write the heatmaps (N x 12 x h x w) with their boxes")
    p.add_argument("--device", help="cuda, cpu, ... (default: cuda when available)")


def add_calibrate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--weights", help="weights file (default: the shipped weights)")
    p.add_argument("--val", nargs="+", action="extend", default=[], metavar="SHARD",
                   help="held-out .npz shards or folders of shards (with the crops' rois for image pixels)")
    p.add_argument("--write", action="store_true",
                   help="store the calibration fitted on the even-numbered crops in the weights file's metadata")
    p.add_argument("--device", help="cuda, cpu, ... (default: cuda when available)")


def main(argv=None, prog: str = "python -m vfactor.net") -> int:
    """``python -m vfactor.net {train,detect,calibrate,calibrate-shape,score} ...`` (``vfactor`` forwards with ``prog="vfactor"``)."""
    args = build_parser(prog).parse_args(argv)
    run = {"train": run_train, "detect": run_detect, "calibrate": run_calibrate, "calibrate-shape": run_calibrate_shape,
           "calibrate-bias": run_calibrate_bias,
           "score": run_score}[args.command]
    try:
        return run(args)
    except (InputError, ValueError, FileNotFoundError) as exc:
        print(one_line(f"error: {exc}", limit=2000), file=sys.stderr)
        return EXIT_INPUT


@contextmanager
def _file_of(option: str):
    """Reports a bad weights or checkpoint file (:class:`vfactor.net.model.WeightsError`) under ``option``."""
    from vfactor.net.model import WeightsError  # noqa: PLC0415

    try:
        yield
    except WeightsError as exc:
        raise InputError(option, str(exc)) from None


# ------------------------------------------------------------------- train
def run_train(args: argparse.Namespace) -> int:
    """The ``train`` command on parsed arguments (see :func:`add_train_arguments`)."""
    from vfactor.net.data import KeypointDataset, as_dataset  # noqa: PLC0415
    from vfactor.net.train import TrainConfig, train  # noqa: PLC0415

    config = _train_config(args)
    out = Path(args.out)
    S = config.input_size
    train_paths, val_paths = [Path(p) for p in args.data], [Path(p) for p in args.val]
    if args.render:
        train_paths.append(_render(out / "data" / "train", args.render, config.seed, S, False, args.render_workers,
                                   not args.quiet, _training_split(args.library_share, args.library_weight,
                                                                   args.shape_stretch),
                                   _sample_options(args.clipped_box_share, args.real_roofs)))
    if args.render_val:
        val_paths.append(_render(out / "data" / "val", args.render_val, config.seed, S, True, args.render_workers,
                                 not args.quiet, None, _sample_options(None, args.real_roofs)))  # roofs as trained
    parts = [_load(p, "--data", S) for p in train_paths]
    if args.pascal3d:
        from vfactor.net.pascal3d import load_pascal3d  # noqa: PLC0415

        parts.append(KeypointDataset.from_samples(load_pascal3d(args.pascal3d, size=S), size=S))
    if not parts:
        raise InputError("--data", "no training data: give --data, --render or --pascal3d")
    data = KeypointDataset.concatenate([p.resized(S) for p in parts])
    val = KeypointDataset.concatenate([_load(p, "--val", S).resized(S) for p in val_paths]) if val_paths else None
    if args.init is not None and not Path(args.init).is_file():
        raise InputError("--init", f"{args.init}: no such weights file")
    with _file_of("--init" if args.init is not None and not args.resume else "--resume"):  # a damaged file
        result = train(config, as_dataset(data), val, out_dir=out, resume=args.resume, progress=not args.quiet,
                       device=args.device, init_weights=args.init)
    exported = result.best_weights_path or result.weights_path
    if args.export:
        dest = Path(args.export)
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_bytes(exported.read_bytes())
    if not args.quiet:
        last = result.history[-1] if result.history else {}
        print(f"weights: {result.weights_path}" + (f" ({exported.name} copied to {args.export})" if args.export else "")
              + (f"; validation PCK@{config.pck_alpha:g} visible {last['pck_visible']:.3f}, self-occluded "
                 f"{last['pck_self_occluded']:.3f}" if last and math.isfinite(last.get("pck_visible", math.nan))
                 else ""), file=sys.stderr)
    return EXIT_OK


def _train_config(args):
    from vfactor.net.train import TrainConfig  # noqa: PLC0415

    base: dict = {}
    if args.config:
        base = read_json(args.config, InputError)
    for key, value in vars(args).items():
        if key.startswith("cfg_") and value is not None:
            base[key[4:]] = value
    try:
        return TrainConfig.from_dict(base)
    except (TypeError, ValueError) as exc:
        raise InputError("--config", str(exc)) from None


#: SplitSpec field -> the train flag that sets it (for its errors).
_SPLIT_FLAGS = {"library_type_weights": "--library-weight", "shape_stretch": "--shape-stretch"}


def _training_split(library_share: float | None, library_weights=(), shape_stretch: float | None = None):
    """The training split with ``library_share`` library vehicles, ``library_weights`` (``TYPE=W`` strings) per
    body type and ``shape_stretch`` (None and none: :data:`vfactor.render.dataset.TRAIN`)."""
    if library_share is None and not library_weights and shape_stretch is None:
        return None
    if library_share is not None and not 0.0 <= library_share <= 1.0:
        raise InputError("--library-share", f"expected a share in [0, 1], got {library_share}")
    from dataclasses import replace  # noqa: PLC0415

    from vfactor.render.dataset import TRAIN  # noqa: PLC0415

    weights = []
    for text in library_weights:
        body_type, _, weight = text.partition("=")
        try:
            weights.append((body_type, float(weight)))
        except ValueError:
            raise InputError("--library-weight", f"expected TYPE=W (e.g. van=3), got {text!r}") from None
    share = TRAIN.library_probability if library_share is None else float(library_share)
    try:
        return replace(TRAIN, library_probability=share, library_type_weights=tuple(weights),
                       shape_stretch=float(shape_stretch or 0.0))
    except ValueError as exc:  # SplitSpec names the field: "<field>: <what is wrong>"
        field, _, message = str(exc).partition(": ")
        raise InputError(_SPLIT_FLAGS.get(field, "--library-weight"), message or str(exc)) from None


def _sample_options(clipped_box_share: float | None, real_roofs: bool = True):
    """The renderer's sample options with ``clipped_box_share`` (None: the default) and ``real_roofs``."""
    from vfactor.render.dataset import SampleOptions  # noqa: PLC0415

    if clipped_box_share is None:
        return SampleOptions(real_roofs=real_roofs)
    if not 0.0 <= clipped_box_share <= 1.0:
        raise InputError("--clipped-box-share", f"expected a share in [0, 1], got {clipped_box_share}")
    return SampleOptions(clipped_box_probability=float(clipped_box_share), real_roofs=real_roofs)


def _render(path: Path, n: int, seed: int, size: int, held_out: bool, workers: int, verbose: bool,
            split=None, options=None) -> Path:
    from vfactor.render import SampleOptions, make_dataset  # noqa: PLC0415

    if any(path.glob("*.npz")):
        if verbose:
            print(f"using the crops already rendered in {path}", file=sys.stderr)
        return path
    if verbose:
        print(f"rendering {n} {'held-out ' if held_out else ''}crops of {size} px into {path}", file=sys.stderr)
    make_dataset(n, seed=seed, size=size, path=path, held_out=held_out, workers=workers, split=split,
                 options=options or SampleOptions())
    return path


def _load(path: Path, flag: str, size: int):
    from vfactor.net.data import as_dataset  # noqa: PLC0415

    try:
        return as_dataset(path, size=size)
    except (ValueError, OSError, KeyError) as exc:
        raise InputError(flag, str(exc)) from None


# ------------------------------------------------------------------ detect
def run_detect(args: argparse.Namespace) -> int:
    """The ``detect`` command on parsed arguments (see :func:`add_detect_arguments`)."""
    from vfactor.images import read_rgb  # noqa: PLC0415
    from vfactor.net.infer import KeypointDetector  # noqa: PLC0415

    boxes = _boxes(args)
    images = []
    for name in args.images:
        try:
            rgb = read_rgb(name)
        except (OSError, ValueError) as exc:
            raise InputError("IMAGE", f"cannot read {name}: {getattr(exc, 'strerror', None) or exc}") from None
        if rgb is None:
            raise InputError("IMAGE", f"cannot read {name}: not an image OpenCV decodes")
        images.append(rgb)
    with _file_of("--weights"):
        detector = KeypointDetector(args.weights, device=args.device)
    results = detector.detect_batch(images, [boxes[name] for name in args.images])
    doc = {"keypoint_names": list(KEYPOINT_NAMES), "images": []}
    heatmaps, rois, crop_rois, owner = [], [], [], []
    for i, (name, dets) in enumerate(zip(args.images, results)):
        entry = {"image": name, "detections": []}
        for roi, d in zip(boxes[name], dets):
            kp = d.keypoints
            entry["detections"].append({
                "roi": [float(v) for v in roi],
                "crop_roi": [float(v) for v in d.roi],
                "keypoints": _nan_to_none(kp.uv),
                "confidence": _nan_to_none(kp.confidence),
                "covariance": _nan_to_none(kp.covariance),
                # what a scene's detection takes as "covariances_calibrated" and "shape_sigma"
                **detector.calibration.detection_fields(),
            })
            heatmaps.append(d.heatmaps)
            rois.append(roi)
            crop_rois.append(d.roi)
            owner.append(i)
        doc["images"].append(entry)
    text = json.dumps(doc, indent=1)
    if args.out:
        write_text_atomic(args.out, text + "\n")
    else:
        print(text)
    if args.heatmaps:
        S4 = detector.input_size // 4
        np.savez_compressed(
            args.heatmaps,
            heatmaps=np.stack(heatmaps) if heatmaps else np.zeros((0, 12, S4, S4), np.float32),
            rois=np.asarray(rois, float).reshape(-1, 4),
            crop_rois=np.asarray(crop_rois, float).reshape(-1, 4),
            image_index=np.asarray(owner, int),
            images=np.asarray(args.images),
            keypoint_names=np.asarray(KEYPOINT_NAMES),
        )
    return EXIT_OK


def _boxes(args) -> dict[str, list]:
    if args.rois and args.roi:
        raise InputError("--roi", "give either --roi boxes or a --rois file, not both")
    if args.rois:
        table = read_json(args.rois, InputError)
        if not isinstance(table, dict):
            raise InputError("--rois", "expected a JSON object {image path: [[x0, y0, x1, y1], ...]}")
        missing = [name for name in args.images if name not in table]
        if missing:
            raise InputError("--rois", f"no boxes for {missing}")
        return {name: _rois_of(table[name], f"--rois[{name!r}]") for name in args.images}
    if not args.roi:
        raise InputError("--roi", "give at least one box: --roi X0 Y0 X1 Y1 (or --rois FILE)")
    if len(args.images) != 1:
        raise InputError("--roi", f"--roi boxes go with a single IMAGE, got {len(args.images)}; use --rois FILE")
    return {args.images[0]: [tuple(b) for b in args.roi]}


def _rois_of(value, where: str) -> list[tuple[float, ...]]:
    """An image's boxes from a --rois file: a list of [x0, y0, x1, y1] (px)."""
    if not isinstance(value, list) or not all(isinstance(b, list) for b in value):
        raise InputError(where, f"expected a list of boxes [[x0, y0, x1, y1], ...], got {describe(value)}")
    for k, box in enumerate(value):
        if len(box) != 4 or not all(is_number(v) and math.isfinite(float(v)) for v in box):
            raise InputError(f"{where}[{k}]", f"expected 4 finite numbers [x0, y0, x1, y1], got {box!r}")
    return [tuple(float(v) for v in box) for box in value]


def _nan_to_none(a):
    arr = np.asarray(a, float)
    if arr.ndim == 0:
        return None if not np.isfinite(arr) else float(arr)
    return [_nan_to_none(x) for x in arr]


# --------------------------------------------------------------- calibrate
def run_calibrate(args: argparse.Namespace) -> int:
    """The ``calibrate`` command on parsed arguments (see :func:`add_calibrate_arguments`).

    Prints markdown tables: the candidate models, the chosen calibration before
    and after on the check half, the error against the box side and ``d2``
    against the confidence.
    """
    from dataclasses import replace  # noqa: PLC0415

    from vfactor.net.calibrate import (  # noqa: PLC0415
        METADATA_KEY, CovarianceCalibration, fit_calibration, measure_errors, summarise, write_calibration)
    from vfactor.net.infer import KeypointDetector, default_weights_path  # noqa: PLC0415

    if not args.val:
        raise InputError("--val", "give the held-out crops: --val SHARD_OR_FOLDER ...")
    weights = Path(args.weights) if args.weights else default_weights_path()
    with _file_of("--weights"):
        detector = KeypointDetector(weights, device=args.device, calibration=CovarianceCalibration())
    try:
        errors = measure_errors(detector, [Path(v) for v in args.val])
    except (ValueError, OSError, KeyError) as exc:
        raise InputError("--val", str(exc)) from None
    crops = np.unique(errors.crop)
    fit_half, check_half = errors.subset(errors.crop % 2 == 0), errors.subset(errors.crop % 2 == 1)
    try:
        models = [
            ("none (heatmap spread)", CovarianceCalibration()),
            ("scale", fit_calibration(fit_half, floor=False, confidence=False)),
            ("scale + floor", fit_calibration(fit_half, floor=True, confidence=False)),
            ("scale + floor + confidence (chosen)", fit_calibration(fit_half)),
        ]
    except ValueError as exc:
        raise InputError("--val", str(exc)) from None
    chosen = models[-1][1]
    summaries = [summarise(check_half, c) for _, c in models]  # models[0] is the identity: the "before"
    before, after = summaries[0], summaries[-1]
    print(f"data: {', '.join(args.val)}: {len(crops)} crops, {len(errors)} keypoints inside them "
          f"({int(errors.found.sum())} found); weights: {weights}")
    print(f"fit on the even-numbered crops ({int(fit_half.found.sum())} found keypoints), checked on the "
          f"odd-numbered ones ({int(check_half.found.sum())}); d2 = e^T S^-1 e, chi-square(2) if calibrated: "
          f"median 1.386, mean 2, 95% within 5.99")
    print("\nmodels (check half):\n")
    _table(["model", "scale", "floor", "confidence_rate", "d2 median", "d2 mean (PCK-correct)", "within 5.99",
            "visible d2 median", "self-occluded d2 median"],
           [[name, f"{c.scale:.4g}", f"{c.floor:.4g}", f"{c.confidence_rate:.3g}"]
            + [_fmt(s["all"][k]) for k in ("d2_median", "d2_mean_correct", "within_95")]
            + [_fmt(s["visible"]["d2_median"]), _fmt(s["self_occluded"]["d2_median"])]
            for (name, c), s in zip(models, summaries)])
    print(f"\ncalibration: S_cal = exp({chosen.confidence_rate:.3f} (1 - confidence)) ({chosen.scale:.4f} S "
          f"+ diag(({chosen.floor:.4f} w)^2, ({chosen.floor:.4f} h)^2)), w, h: the crop box's sides (px)\n")
    rows = []
    for group, label in (("visible", "visible"), ("self_occluded", "self-occluded"), ("all", "all in the crop")):
        for stage, s in (("before", before[group]), ("after", after[group])):
            rows.append([label, stage, str(s["n"]), str(s["found"]), _fmt(s["pck"]), _fmt(s["error_px"], 2),
                         _fmt(s["error_box"], 4)]
                        + [_fmt(s[k]) for k in ("d2_median", "d2_mean", "d2_mean_correct", "within_95",
                                                "within_95_correct")])
    _table(["keypoints", "covariances", "n", "found", "PCK@0.1", "median error px", "median error / box",
            "d2 median", "d2 mean", "d2 mean (PCK-correct)", "within 5.99", "within 5.99 (PCK-correct)"], rows)
    print("\nerror against the box side (check half, quartiles):\n")
    side = check_half.box_size.max(axis=1)
    rows = []
    for lo, hi, mask in _quartiles(side):
        part = check_half.subset(mask)
        b, a = summarise(part), summarise(part, chosen)
        rows.append([f"{lo:.0f}-{hi:.0f}", _fmt(b["visible"]["error_px"], 2), _fmt(b["visible"]["error_box"], 4),
                     _fmt(b["self_occluded"]["error_px"], 2), _fmt(b["self_occluded"]["error_box"], 4),
                     _fmt(a["all"]["d2_median"])])
    _table(["box side px", "visible median error px", "visible error / box", "self-occluded median error px",
            "self-occluded error / box", "d2 median after"], rows)
    print("\nd2 against the confidence (check half, quartiles):\n")
    rows = []
    for lo, hi, mask in _quartiles(check_half.confidence):
        part = check_half.subset(mask)
        stats = [summarise(part, c)["all"] for _, c in models]
        rows.append([f"{lo:.2f}-{hi:.2f}", str(stats[0]["n"]), _fmt(stats[0]["pck"]),
                     _fmt(stats[0]["error_box"], 4)] + [_fmt(s["d2_median"]) for s in stats])
    _table(["confidence", "n", "PCK@0.1", "median error / box"] + [f"d2 median, {name}" for name, _ in models], rows)
    if args.write:
        check = {g: {"n": after[g]["found"], "d2_median_before": before[g]["d2_median"],
                     "d2_median": after[g]["d2_median"], "within_95": after[g]["within_95"]}
                 for g in ("visible", "self_occluded", "all")}
        stored = CovarianceCalibration.from_metadata(detector.metadata) or CovarianceCalibration()
        with _file_of("--weights"):  # calibrate-shape's shape_sigma and calibrate-bias's bias_sigma are kept
            kept = replace(chosen, shape_sigma=stored.shape_sigma, bias_sigma=stored.bias_sigma)
            write_calibration(weights, kept, {f"{METADATA_KEY}_check": {
                "data": [str(v) for v in args.val], "fit": "even-numbered crops", "checked": "odd-numbered crops",
                **check}})
        print(f"\ncalibration written to {weights} (metadata '{METADATA_KEY}'; weights unchanged)", file=sys.stderr)
    return EXIT_OK


def _calibrated_detector(args: argparse.Namespace):
    """``calibrate-shape``'s and ``calibrate-bias``'s inputs checked: ``(weights path, detector, seeds)``.

    Raises:
        InputError: ``--seeds`` below 1, ``--frames`` below 1, unreadable ``--weights`` or weights without a pixel
            calibration.
    """
    from vfactor.net.infer import KeypointDetector, default_weights_path  # noqa: PLC0415

    if args.seeds < 1:
        raise InputError("--seeds", f"expected at least 1, got {args.seeds}")
    if args.frames is not None and args.frames < 1:
        raise InputError("--frames", f"expected at least 1, got {args.frames}")
    weights = Path(args.weights) if args.weights else default_weights_path()
    with _file_of("--weights"):
        detector = KeypointDetector(weights, device=args.device)
    if detector.calibration.is_identity:
        raise InputError("--weights", "no pixel calibration in the weights: run the calibrate command first")
    return weights, detector, list(range(args.seed, args.seed + args.seeds))


def run_calibrate_shape(args: argparse.Namespace) -> int:
    """The ``calibrate-shape`` command on parsed arguments (see :func:`add_calibrate_shape_arguments`)."""
    from dataclasses import replace  # noqa: PLC0415

    from vfactor.errors import ScenarioError  # noqa: PLC0415
    from vfactor.graph import SHAPE_SIGMA_REFERENCE_VOLUME  # noqa: PLC0415
    from vfactor.metrics import CHI2_95  # noqa: PLC0415
    from vfactor.net.calibrate import METADATA_KEY, write_calibration  # noqa: PLC0415
    from vfactor.net.shape_error import (  # noqa: PLC0415
        fit_shape_sigma,
        keypoint_nees_at,
        measure_vehicles,
        pose_nees_at,
    )
    from vfactor.solve import SolveOptions  # noqa: PLC0415
    from vfactor.vehicle_library import BODY_TYPES  # noqa: PLC0415

    weights, detector, seeds = _calibrated_detector(args)
    options = SolveOptions()
    exponent = options.graph.shape_sigma_size_exponent  # the error at the reference size, taken at each vehicle's
    try:
        vehicles = measure_vehicles(args.scenario, seeds, detector, options, frames=args.frames)
    except ScenarioError as exc:
        raise InputError("--scenario", str(exc)) from None
    try:
        sigma = fit_shape_sigma(vehicles, size_exponent=exponent)
    except ValueError as exc:
        raise InputError("--scenario", str(exc)) from None
    print(f"{args.scenario} seeds {seeds[0]}-{seeds[-1]}: {len(vehicles)} vehicles solved from the network's "
          f"keypoints; shape_sigma {sigma:.4f} m per detection at a keypoint box of {SHAPE_SIGMA_REFERENCE_VOLUME:g} "
          f"m^3, times (volume / {SHAPE_SIGMA_REFERENCE_VOLUME:g} m^3) ** {exponent:g} (keypoint NEES: consistent 3, "
          f"95 % under {CHI2_95[3]:.2f})\n")
    before, after = keypoint_nees_at(vehicles, 0.0), keypoint_nees_at(vehicles, sigma, exponent)
    poses = pose_nees_at(vehicles, 0.0), pose_nees_at(vehicles, sigma, exponent)
    classes = [c for c in (*BODY_TYPES, "pascal3d") if any(v.body_type == c for v in vehicles)]
    rows = []
    for name in classes + ["all"]:
        mask = np.array([name == "all" or v.body_type == name for v in vehicles])
        rows.append([name, str(int(mask.sum()))] + [_nees_cell(n[mask], 3) for n in (before, after)] +
                    [_nees_cell(p[mask], 6) for p in poses] +
                    [_own_shape_sigma([v for v, m in zip(vehicles, mask) if m], sigma, exponent)])
    _table(["body type", "vehicles", "keypoint NEES (x 3) / under the bound, without", "with shape_sigma",
            "pose NEES (x 6) / under, without", "with", "shape_sigma fitted to the class alone"], rows)
    if args.write:
        with _file_of("--weights"):
            write_calibration(weights, replace(detector.calibration, shape_sigma=sigma), {
                f"{METADATA_KEY}_shape": {"scenario": args.scenario, "seeds": seeds, "vehicles": len(vehicles)}})
        print(f"\nshape_sigma written to {weights} (metadata '{METADATA_KEY}'; weights unchanged)", file=sys.stderr)
    return EXIT_OK


def _nees_cell(values, dim: int) -> str:
    """``calibrate-shape``'s cell: the mean NEES over ``dim`` and the share under the chi2 95 % bound
    (:func:`vfactor.metrics.nees_summary`; NaN left out)."""
    from vfactor.metrics import nees_summary  # noqa: PLC0415

    summary = nees_summary(values, dim)
    return f"{summary['ratio']:.2f}x / {100 * summary['under_95']:.1f} %"


def _own_shape_sigma(vehicles, pooled: float, exponent: float) -> str:
    """``calibrate-shape``'s column: the ``shape_sigma`` fitted to one class's vehicles alone, and its ratio to the
    pooled fit (a class the network errs on more, or less, than on the others; docs/network.md)."""
    from vfactor.net.shape_error import fit_shape_sigma  # noqa: PLC0415

    try:
        own = fit_shape_sigma(vehicles, size_exponent=exponent)
    except ValueError:
        return "-"
    return f"{100 * own:.1f} cm ({own / pooled:.2f}x)" if pooled > 0 else f"{100 * own:.1f} cm"


def run_calibrate_bias(args: argparse.Namespace) -> int:
    """The ``calibrate-bias`` command on parsed arguments (see :func:`add_calibrate_bias_arguments`)."""
    from dataclasses import replace  # noqa: PLC0415

    from vfactor.errors import ScenarioError  # noqa: PLC0415
    from vfactor.net.bias_error import MIN_FRAMES, fit_bias_sigma, measure_rendered_tracks  # noqa: PLC0415
    from vfactor.net.calibrate import METADATA_KEY, write_calibration  # noqa: PLC0415

    scenarios = args.scenario or list(BIAS_SCENARIOS)
    weights, detector, seeds = _calibrated_detector(args)
    tracks = []
    for scenario in scenarios:
        try:
            tracks += measure_rendered_tracks(scenario, seeds, detector, frames=args.frames)
        except ScenarioError as exc:
            raise InputError("--scenario", str(exc)) from None
    try:
        sigma = fit_bias_sigma(tracks)
    except ValueError as exc:
        raise InputError("--scenario", f"{exc} (no track seen in {MIN_FRAMES} frames or more)") from None
    units = np.r_[np.degrees(np.ones(3)), 100.0 * np.ones(3)]
    bias, variance = np.stack([t.bias for t in tracks]), np.stack([t.variance for t in tracks])
    print(f"{', '.join(scenarios)} seeds {seeds[0]}-{seeds[-1]}: {len(tracks)} tracks from the network's keypoints\n")
    rows = [[name, *(f"{x:.2f}" for x in values * units)] for name, values in (
        ("each track's shared motion, RMS", np.sqrt(np.mean(bias ** 2, axis=0))),
        ("the data's uncertainty of it, RMS", np.sqrt(np.mean(variance, axis=0))),
        ("bias_sigma", sigma))]
    _table(["", "roll (deg)", "pitch (deg)", "yaw (deg)", "x (cm)", "y (cm)", "z (cm)"], rows)
    print(f"\nbias_sigma = {[round(float(x), 5) for x in sigma]} ([roll, pitch, yaw] rad, [x, y, z] m, body frame)")
    if args.write:
        with _file_of("--weights"):
            write_calibration(weights, replace(detector.calibration, bias_sigma=tuple(sigma)), {
                f"{METADATA_KEY}_bias": {"scenarios": scenarios, "seeds": seeds, "tracks": len(tracks)}})
        print(f"\nbias_sigma written to {weights} (metadata '{METADATA_KEY}'; weights unchanged)", file=sys.stderr)
    return EXIT_OK


def _quartiles(values: np.ndarray):
    """``(lo, hi, mask)`` of the four quartile bins of ``values`` (the last bin closed)."""
    if len(values) == 0:
        return []
    edges = np.quantile(values, [0.0, 0.25, 0.5, 0.75, 1.0])
    return [(lo, hi, (values >= lo) & ((values < hi) if k < 3 else (values <= hi)))
            for k, (lo, hi) in enumerate(zip(edges[:-1], edges[1:]))]


def _fmt(value: float, digits: int = 3) -> str:
    return "-" if not np.isfinite(value) else f"{value:.{digits}f}"


def _table(header: list[str], rows: list[list[str]]) -> None:
    print("| " + " | ".join(header) + " |")
    print("| " + " | ".join("---" for _ in header) + " |")
    for row in rows:
        print("| " + " | ".join(row) + " |")


# ------------------------------------------------------------------- score
def run_score(args: argparse.Namespace) -> int:
    """The ``score`` command: PCK of weights on crops with known keypoints (see :func:`add_score_arguments`)."""
    from vfactor.net.infer import default_weights_path  # noqa: PLC0415
    from vfactor.net.model import load_weights  # noqa: PLC0415
    from vfactor.net.train import evaluate_model  # noqa: PLC0415

    weights = Path(args.weights) if args.weights else default_weights_path()
    with _file_of("--weights"):
        model = load_weights(weights)
    size = model.config.input_size
    paths = [Path(p) for p in args.data]
    if args.render_test:
        paths.append(_render(Path(args.out), args.render_test, args.seed, size, True, 1, True))
    if not paths:
        raise InputError("--data", "give crops to score: --data SHARD_OR_FOLDER ... or --render-test N")
    from vfactor.net.data import KeypointDataset  # noqa: PLC0415

    data = KeypointDataset.concatenate([_load(p, "--data", size).resized(size) for p in paths])
    from vfactor.net.model import torch_device  # noqa: PLC0415

    device = torch_device(args.device or "cpu")  # a device the machine lacks: one line naming it, not a crash
    scores = evaluate_model(model.to(device), data, device=device)
    print(f"weights {weights} on {len(data)} crops ({', '.join(str(p) for p in paths)}): PCK@0.1 visible "
          f"{scores['pck_visible']:.3f} ({scores['n_visible']} keypoints), self-occluded "
          f"{scores['pck_self_occluded']:.3f} ({scores['n_self_occluded']}), all {scores['pck_all']:.3f}; "
          f"heatmap loss {scores['val_loss']:.5f}")
    return EXIT_OK
