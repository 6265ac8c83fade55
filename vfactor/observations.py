"""What the cameras saw: detections of vehicles' keypoints, frames and scenes.

These are plain containers; :mod:`vfactor.scene` loads and validates them from
scene files, :mod:`vfactor.sim` makes them, the solvers read them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vfactor.camera import Camera
from vfactor.errors import InputError
from vfactor.factors.ground_plane import GroundPlane

__all__ = ["DEFAULT_VEHICLE_ID", "UNASSIGNED", "Detection", "Frame", "Scene", "resolve_path", "covariance_problem",
           "class_hints"]

#: Relative asymmetry a covariance matrix may have (rounding): keypoints' 2x2 blocks, results' covariances.
SYMMETRY_RTOL = 1e-9


def covariance_problem(S: np.ndarray) -> str | None:
    """What is wrong with a keypoint's 2x2 pixel covariance (not symmetric, not positive definite), or None."""
    S = np.asarray(S, dtype=float)
    if abs(S[0, 1] - S[1, 0]) > SYMMETRY_RTOL * np.abs(S).max():
        return f"expected a symmetric matrix, got {S.tolist()}"
    if not (S[0, 0] > 0 and np.linalg.det(S) > 0):
        return f"expected a positive-definite matrix, got {S.tolist()}"
    return None

#: Track id given to the vehicle of a detection that names none (allowed when
#: its frame holds a single vehicle).
DEFAULT_VEHICLE_ID = "vehicle"
#: Vehicle id of a detection whose vehicle is not known yet: its frame names no vehicle but holds several
#: detections of one camera, or per-camera track ids. :func:`vfactor.association.associate_scene` gives such
#: detections their vehicles (``vfactor solve`` and ``vfactor track`` run it themselves).
UNASSIGNED = "?"


def resolve_path(path: str | Path, base_dir: str | Path | None = None) -> Path:
    """An absolute path for a path of a scene (heatmaps, images): relative ones start at ``base_dir``
    (the scene file's folder; the current directory when None)."""
    p = Path(path)
    if not p.is_absolute():
        p = Path(base_dir if base_dir is not None else Path.cwd()) / p
    return Path(os.path.abspath(p))


@dataclass
class Detection:
    """The 12 keypoints of one vehicle seen by one camera.

    Attributes:
        camera: name of the camera.
        vehicle: track id of the vehicle.
        keypoints: (12, 2) pixels ``(u, v)`` in the fixed keypoint order; NaN where unseen.
        confidence: (12,) in [0, 1]; 0 means not seen.
        covariance: optional (12, 2, 2) pixel covariances (px^2), e.g. from a
            heatmap's spread; NaN blocks where unknown. When given, it replaces the
            confidence-derived noise of the projection factor.
        heatmaps: optional path of a (12, H, W) ``.npy`` heatmap stack covering ``heatmaps_roi`` (else ``roi``).
        roi: optional box ``(x0, y0, x1, y1)`` in pixels: the 2D detector's box of the vehicle.
        heatmaps_roi: optional box the ``heatmaps`` cover, where it is not ``roi`` (the keypoint network's crop
            of ``roi``, grown and squared: :func:`vfactor.net.pipeline.detect_scene`); ``roi`` stays the
            detector's box, which says whether the image border cuts the view.
        from_image: the keypoints are still to be found by the keypoint network
            in the frame's image of this camera, inside ``roi`` (a detection given
            as a box only); until then ``keypoints`` are NaN and ``confidence`` 0.
            :func:`vfactor.net.pipeline.detect_scene` fills them in; the solvers
            refuse such a detection with an :class:`~vfactor.errors.InputError`.
        vehicle_class: optional class from the 2D detector (the scene's
            ``"class"``: COCO / YOLO ``car``, ``truck``, ``bus`` or a vfactor
            body type), a hint for the body type, never a hard rule
            (:data:`vfactor.shape_model.CLASS_HINTS`).
        track: optional per-camera track id (the scene's ``"track"``): the id a camera's own 2D tracker gave
            this detection, evidence for the association across frames (it may switch; it is never a
            vehicle id shared between cameras).
        covariance_calibrated: ``covariance`` is calibrated against the detector's true pixel errors
            (:func:`vfactor.net.pipeline.detect_scene` sets it when the keypoint network's calibration is
            applied; the scene's ``"covariances_calibrated"``). The result's covariances are then computed at
            no less than these covariances: the residuals' noise scale may widen them, never narrow them
            (docs/factors.md, "Covariances").
        shape_sigma: optional standard deviation (metres, per axis) of the detector's error that is shaped like a
            change of the vehicle's shape: the keypoints of one detection err together, as if the camera saw a
            slightly other vehicle, so the fit takes the error into the shape and the residuals never show it
            (the keypoint network's, calibrated with ``python -m vfactor.net calibrate-shape``; the scene's
            ``"shape_sigma"``), for a vehicle whose keypoints span a box of 9 m^3: the solver takes it at the
            vehicle's size (:func:`vfactor.graph.shape_sigma_at_size`, ``GraphConfig.shape_sigma_size_exponent``).
            The one-frame result's pose, shape and keypoint covariances are widened by it (docs/factors.md,
            "Covariances", item 6); None or 0: no such error.
        bias_sigma: optional standard deviations of the detector's error that repeats over a vehicle's frames and
            cameras, as a rigid motion of the vehicle in its body frame: ``(roll, pitch, yaw)`` radians about its
            x, y, z axes, ``(x, y, z)`` metres along them (the keypoint network's, calibrated with ``python -m
            vfactor.net calibrate-bias``; the scene's ``"bias_sigma"``). A track with detector offsets takes it as
            the prior of one pose offset that all its cameras share (docs/factors.md, "The detector's pose offset
            in tracks"), so that its poses' covariances keep what no number of frames averages away; None: none.
    """

    camera: str
    vehicle: str
    keypoints: np.ndarray
    confidence: np.ndarray
    covariance: np.ndarray | None = None
    heatmaps: str | None = None
    roi: tuple[float, float, float, float] | None = None
    from_image: bool = False
    heatmaps_roi: tuple[float, float, float, float] | None = None
    vehicle_class: str | None = None
    track: str | None = None
    covariance_calibrated: bool = False
    shape_sigma: float | None = None
    bias_sigma: tuple[float, ...] | None = None

    def __post_init__(self):
        """Checks what a user builds by hand as a scene file's reader checks it (the reader's fields name where).

        Raises:
            InputError: (field ``keypoints``, ``confidence`` or ``covariance``) a wrong shape, a confidence outside
                [0, 1] or not a number, a seen keypoint (confidence > 0) that is not finite, a finite covariance
                block that is not symmetric positive definite (NaN blocks: none of its own).
        """
        try:
            keypoints = np.asarray(self.keypoints, dtype=float)
            confidence = np.asarray(self.confidence, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InputError("keypoints", f"expected (12, 2) pixels and (12,) confidences: {exc}") from None
        where = f"detection of vehicle {self.vehicle!r} by camera {self.camera!r}: "
        if keypoints.shape != (12, 2):
            raise InputError("keypoints", f"{where}expected (12, 2) pixels (u, v), got shape {keypoints.shape}")
        if confidence.shape != (12,):
            raise InputError("confidence", f"{where}expected (12,) confidences, got shape {confidence.shape}")
        if not np.all((confidence >= 0.0) & (confidence <= 1.0)):  # NaN fails too
            raise InputError("confidence", f"{where}expected numbers in [0, 1] (0: not seen), got "
                                           f"{confidence[~((confidence >= 0.0) & (confidence <= 1.0))][0]!r}")
        if not np.all(np.isfinite(keypoints[confidence > 0])):
            raise InputError("keypoints", f"{where}a seen keypoint (confidence > 0) is not finite")
        if self.covariance is not None:
            covariance = np.asarray(self.covariance, dtype=float)
            if covariance.shape != (12, 2, 2):
                raise InputError("covariance", f"{where}expected (12, 2, 2) px^2, got shape {covariance.shape}")
            for k in np.flatnonzero(np.isfinite(covariance).all(axis=(1, 2))):  # NaN (or inf): none of its own
                problem = covariance_problem(covariance[k])
                if problem:
                    raise InputError("covariance", f"{where}keypoint {k}: {problem}")
            object.__setattr__(self, "covariance", covariance)
        object.__setattr__(self, "keypoints", keypoints)
        object.__setattr__(self, "confidence", confidence)

    @property
    def seen(self) -> np.ndarray:
        """(12,) boolean mask of keypoints with confidence > 0."""
        return self.confidence > 0

    def box_diagonal(self) -> float:
        """Diagonal of the box around the seen keypoints (or of the ROI), pixels."""
        if self.roi is not None:
            x0, y0, x1, y1 = self.roi
            return float(np.hypot(x1 - x0, y1 - y0))
        uv = self.keypoints[self.seen]
        if len(uv) < 2:
            return 0.0
        return float(np.linalg.norm(uv.max(0) - uv.min(0)))


def class_hints(detections, known: tuple[str, ...] = ()) -> tuple[str, ...]:
    """The 2D detector's classes of ``detections`` (``Detection.vehicle_class``) after those ``known`` already (a
    track's so far), each once, in the order first met: the hints of a vehicle's body-type choice
    (:meth:`vfactor.shape_model.ShapeModel.suggested_types`), whether its detections are one frame's
    (:func:`vfactor.solve.solve_vehicle`), a track's (:mod:`vfactor.track`) or those the association solves together
    (:mod:`vfactor.association`)."""
    return tuple(dict.fromkeys((*known, *(d.vehicle_class for d in detections if d.vehicle_class))))


@dataclass
class Frame:
    """One time step: every detection of every camera at time ``t`` (seconds)."""

    t: float
    detections: list[Detection] = field(default_factory=list)
    images: dict[str, str] | None = None

    def vehicle_ids(self) -> list[str]:
        """Track ids in the order they first appear in this frame."""
        return list(dict.fromkeys(d.vehicle for d in self.detections))

    def detections_of(self, vehicle: str) -> list[Detection]:
        return [d for d in self.detections if d.vehicle == vehicle]

    def indices_of(self, vehicle: str) -> list[int]:
        """The indices in :attr:`detections` of a vehicle's detections."""
        return [j for j, d in enumerate(self.detections) if d.vehicle == vehicle]


@dataclass
class Scene:
    """Cameras and frames of a scene file.

    Attributes:
        cameras: camera name -> :class:`Camera`, in file order.
        frames: frames in file order.
        base_dir: folder that relative paths in the scene (heatmaps, images) start from.
        ground_plane: the road plane when the scene gives one (``solve_scene`` and
            ``track_scene`` then add a ground-plane factor per pose); ``None`` otherwise.
    """

    cameras: dict[str, Camera]
    frames: list[Frame]
    base_dir: Path | None = None
    ground_plane: GroundPlane | None = None

    def unassigned(self) -> list[tuple[int, int]]:
        """``(frame index, detection index)`` of every detection whose vehicle is not known yet (:data:`UNASSIGNED`)."""
        return [(f, j) for f, frame in enumerate(self.frames) for j, det in enumerate(frame.detections)
                if det.vehicle == UNASSIGNED]

    def undetected(self) -> list[tuple[int, int]]:
        """``(frame index, detection index)`` of every detection still waiting for the keypoint network."""
        return [(f, j) for f, frame in enumerate(self.frames) for j, det in enumerate(frame.detections)
                if det.from_image]

    def require_detected(self) -> None:
        """Raises :class:`~vfactor.errors.InputError` naming the first detection still waiting for the keypoint
        network (an image box only, ``from_image``): :func:`vfactor.net.pipeline.detect_scene` first
        (``vfactor solve`` and ``vfactor track`` run it themselves)."""
        _require(self.undetected(), "keypoints", "not detected yet: {n} detection(s) give only an image box ('roi'); "
                 "run the keypoint network first (vfactor.net.pipeline.detect_scene, which needs the 'net' extra)")

    def require_keypoints(self) -> None:
        """Raises :class:`~vfactor.errors.InputError` naming the first detection the solvers cannot take: one
        without keypoints yet (:meth:`require_detected`), or one whose vehicle is not known yet
        (:data:`UNASSIGNED`: :func:`vfactor.association.associate_scene` first; ``vfactor solve`` and ``vfactor
        track`` run it themselves)."""
        self.require_detected()
        _require(self.unassigned(), "vehicle", "not known: {n} detection(s) name no vehicle in frames of several "
                 "vehicles; associate them first (vfactor.association.associate_scene; vfactor solve and track do)")


def _require(pending: list[tuple[int, int]], field: str, problem: str) -> None:
    """Raises an InputError at the first of ``pending`` (frame, detection) naming ``field``; ``{n}``: how many."""
    if pending:
        f, j = pending[0]
        raise InputError(f"frames[{f}].detections[{j}].{field}", problem.format(n=len(pending)))
