"""Sanity checks of a solved vehicle, and one-line messages.

An optimiser "converges" on garbage when the views do not constrain the
vehicle: one camera seeing all 12 keypoints at one pixel let Levenberg-Marquardt
walk the vehicle 1e15 m away and still stop on a small cost. So a vehicle is
reported ``converged`` (or ``max_iterations``) only when :func:`check_estimate`
finds its estimate

* finite (pose and wireframe),
* within :data:`MAX_DISTANCE` of the nearest camera that sees it,
* in front of every camera that sees it (the keypoints' centroid at a positive
  depth), and not wholly outside the image of one whose keypoints it keeps (every keypoint more than
  :data:`OUTSIDE_IMAGE` image sizes beyond the border),
* upright: its body's z axis within 90 degrees of the world's (world z is up,
  docs/conventions.md; no vehicle in traffic is upside down, and a solution
  that is explains its pixels with the wheels where the roof is, from a start
  turned over: batch smoothing of ``tracks_3veh`` seed 169 at hard noise),
* tilted less than :data:`MAX_TILT_DEG` from the world's up (else ``poor_fit``, its estimate kept: no road is that
  steep; a two-camera rig given ``camera_T_world`` for ``world_T_camera`` fits its keypoints with a vehicle tilted
  35-49 degrees, 11-13 m above the road, about as well as their sigmas say),
* with its front hubs ahead of its back hubs (body x forward: a shape turned
  front to back explains the same pixels, :mod:`vfactor.factors.body_frame`;
  the solvers turn such a solution back, so this catches what they could not), and
* with a pose covariance when one was asked for (GTSAM's marginals fail only
  when the linear system is indeterminate: some direction is not observed);

otherwise it is ``failed`` (non-finite, behind or outside the image of a camera that sees it, upside down or
turned front to back) or
``degenerate`` (too far, or no covariance), with a one-line message. The
solvers call :func:`checked` on every result they return (``solve_observations``,
the tracker, batch smoothing).

:func:`summarise_error` turns GTSAM's multi-line exception texts into one line;
:func:`one_line` is the one sanitiser of text for a terminal (one line, no
control characters or escape sequences), used by the CLI for everything it prints.
"""

from __future__ import annotations

import dataclasses
import re
from typing import Iterable

import numpy as np

from vfactor.camera import Camera, project_pinhole
from vfactor.factors.body_frame import turned_front_to_back, upright
from vfactor.result import Status, VehicleResult

__all__ = ["MAX_DISTANCE", "MAX_TILT_DEG", "OUTSIDE_IMAGE", "check_estimate", "checked", "summarise_error", "one_line"]

#: Farthest a solved vehicle may be from the nearest camera that sees it, metres. Fixed traffic
#: cameras see vehicles at tens of metres; at 1 km a 4.5 m car spans about 4 pixels at a focal
#: length of 900 px, too few to place keypoints, so an estimate farther away is not a measurement.
MAX_DISTANCE = 1000.0

#: Largest angle, degrees, between a solved vehicle's up (body z) and the world's (z) that is not reported
#: ``poor_fit``: the steepest public roads climb about 19 degrees (35 %), a banked curve leans a few.
MAX_TILT_DEG = 30.0

#: A solved vehicle whose every keypoint projects more than this many image sizes (widths sideways, heights up and
#: down) outside the image of a camera that sees it explains none of that camera's keypoints: the image-border
#: truncation's expected pixel of a keypoint predicted far outside sits at the border, where a cut view's keypoints
#: are, so Levenberg-Marquardt could walk a one-camera vehicle 210 m off along the border
#: (``association_3cam``, a view of six keypoints cut by the image's left edge).
OUTSIDE_IMAGE = 1.0
_MESSAGE_LIMIT = 300
_ESCAPES = re.compile(r"\x1b\[[0-?]*[ -/]*[@-~]|\x1b\][^\x07\x1b]*(?:\x07|\x1b\\)?|\x1b.?")
_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]+")
_SYMBOL = re.compile(r"Symbol:\s*([A-Za-z])(\d+)")
_VARIABLES = {"x": "pose", "w": "wheel layer of the shape", "l": "light layer of the shape",
              "r": "roof layer of the shape"}


def one_line(text, limit: int = _MESSAGE_LIMIT) -> str:
    """``text`` as one printable line: escape sequences dropped, line breaks and control characters
    made spaces, runs of spaces collapsed, at most ``limit`` characters (then ``...``)."""
    text = _ESCAPES.sub("", str(text))
    text = " ".join(_CONTROL.sub(" ", text).split())
    return text if len(text) <= limit else text[: limit - 3].rstrip() + "..."


def summarise_error(text) -> str:
    """One line for a GTSAM (or other) exception text.

    GTSAM's ``IndeterminateLinearSystemException`` (a dozen lines with a link)
    becomes ``indeterminate linear system at the pose: the views do not
    constrain it`` (the variable named from its ``gtsam.Symbol`` character under
    the default :class:`~vfactor.keys.KeyScheme`); anything else its first
    non-empty line, through :func:`one_line`. Text before GTSAM's is kept (``"covariance unavailable: "``).
    """
    text = str(text)
    start = text.find("Indeterminate linear system")
    if start >= 0:
        match = _SYMBOL.search(text)
        what = _VARIABLES.get(match.group(1), f"variable {match.group(1)}{match.group(2)}") if match else "a variable"
        return one_line(f"{text[:start]} indeterminate linear system at the {what}: the views do not constrain it")
    lines = [line for line in text.splitlines() if line.strip()]
    return one_line(lines[0] if lines else text)


def check_estimate(result: VehicleResult, cameras: Iterable[Camera], covariance: bool = False,
                   max_distance: float = MAX_DISTANCE, in_image: Iterable[str] | None = None) -> tuple[Status, str]:
    """The status and one-line message a solved vehicle deserves.

    Args:
        result: the solver's result.
        cameras: the cameras that see the vehicle (in this frame).
        covariance: a pose covariance was asked for.
        max_distance: see :data:`MAX_DISTANCE`, metres.
        in_image: the names of those cameras in whose image the estimate must lie (:data:`OUTSIDE_IMAGE`); None:
            every one. A solve names those whose keypoints it keeps: a camera whose every keypoint it takes for
            an outlier (a calibration that is wrong) does not fail it.

    Returns:
        ``(status, message)``: the result's own status (and its message made one
        line) when it is not solved or passes every check; else ``FAILED`` or
        ``DEGENERATE`` and what is wrong (see the module's docstring).
    """
    message = summarise_error(result.message) if result.message else ""
    if not result.ok:
        return result.status, message or "not solved"
    if result.world_T_vehicle is None or result.wireframe is None:
        return Status.FAILED, "no estimate"
    T = np.asarray(result.world_T_vehicle.matrix(), dtype=float)
    world_p = np.asarray(result.wireframe.vehicle_p_keypoints, dtype=float)
    if not (np.all(np.isfinite(T)) and np.all(np.isfinite(world_p))):
        return Status.FAILED, "the estimate is not finite (NaN or infinity in the pose or the shape)"
    if not upright(T[:3, :3]):
        return Status.FAILED, ("the estimate is upside down (its roof below its wheels in the world frame, whose z "
                               "is up): the views did not tell the vehicle's top from its bottom, or the cameras' "
                               "frames are not OpenCV's (x right, y down, z forward) or the world's z is not up")
    if turned_front_to_back(world_p[:4].ravel()):
        return Status.FAILED, ("the shape is turned front to back (its front hubs behind its back hubs): the views "
                               "did not tell the vehicle's front from its back")
    tilted = None
    tilt = float(np.degrees(np.arccos(np.clip(T[2, 2], -1.0, 1.0))))
    if tilt > MAX_TILT_DEG:
        tilted = (f"the estimate is tilted {tilt:.0f} deg from the world's up (no road is that steep; more than "
                  f"{MAX_TILT_DEG:g} deg): check each camera's world_T_camera (camera_T_world given for it?) and "
                  "that the world's z is up")
    world_p = world_p @ T[:3, :3].T + T[:3, 3]
    centre = world_p.mean(axis=0)
    cameras = list(cameras)
    if cameras:
        distances = [float(np.linalg.norm(centre - camera.center)) for camera in cameras]
        nearest = int(np.argmin(distances))
        if distances[nearest] > max_distance:
            return Status.DEGENERATE, (f"the estimate lies {distances[nearest]:.3g} m from camera "
                                       f"'{cameras[nearest].name}', farther than {max_distance:g} m: the views do "
                                       "not fix the vehicle's position")
        for camera in cameras:
            camera_p = camera.to_camera(world_p)
            if camera_p.mean(axis=0)[2] <= 0:
                return Status.FAILED, f"the estimate lies behind camera '{camera.name}', which sees the vehicle"
            away = _outside_image(camera, camera_p) if in_image is None or camera.name in in_image else None
            if away is not None:
                return Status.FAILED, (f"the estimate lies outside the image of camera '{camera.name}', which sees "
                                       f"the vehicle (every keypoint {away:.1f} image sizes or more beyond the "
                                       "border): its keypoints there do not fix it (a view cut by the border?)")
    if covariance and result.pose_covariance is None:
        why = message.removeprefix("covariance unavailable: ") if message else "not computed"
        return Status.DEGENERATE, f"no pose covariance ({summarise_error(why)})"
    if covariance and not np.all(np.isfinite(result.pose_covariance)):
        return Status.DEGENERATE, "the pose covariance is not finite: the views do not constrain the pose"
    if tilted:
        return Status.POOR_FIT, f"{message}; {tilted}" if message else tilted
    return result.status, message


def checked(result: VehicleResult, cameras: Iterable[Camera], covariance: bool = False,
            max_distance: float = MAX_DISTANCE, in_image: Iterable[str] | None = None) -> VehicleResult:
    """``result`` after :func:`check_estimate`: unchanged but for a one-line message when it
    passes; ``poor_fit`` with its estimate when tilted; a ``degenerate`` or ``failed`` result without pose, shape or
    covariances when not."""
    status, message = check_estimate(result, cameras, covariance, max_distance, in_image)
    if status == result.status or status == Status.POOR_FIT:
        return result if (status, message) == (result.status, result.message) else dataclasses.replace(
            result, status=status, message=message)
    return VehicleResult(result.id, status, iterations=result.iterations, final_error=result.final_error,
                         message=message)


def _outside_image(camera: Camera, camera_p: np.ndarray) -> float | None:
    """How far (in image sizes: widths sideways, heights up and down) the nearest of the keypoints ``camera_p``
    (camera frame, metres) projects beyond ``camera``'s image where every one projects farther than
    :data:`OUTSIDE_IMAGE` image sizes outside it (the ideal pinhole: far outside the image a lens's polynomial is no
    guide); None where one is nearer, or the image size is unknown."""
    if camera.image_size is None:
        return None
    width, height = camera.image_size
    if np.any(camera_p[:, 2] <= 0):  # a keypoint at or behind the camera's plane projects anywhere: not judged
        return None
    K = np.asarray(camera.K, dtype=float)
    uv, _ = project_pinhole(camera_p, K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2], jacobian=False)
    u, v = uv[:, 0], uv[:, 1]
    beyond = np.maximum.reduce([-u / width, (u - width) / width, -v / height, (v - height) / height])
    nearest = float(beyond.min())
    return nearest if nearest > OUTSIDE_IMAGE else None
