"""Tracking vehicles over frames: iSAM2 (optionally fixed-lag) and batch smoothing.

Each track id gets its own incremental smoother, so a track that cannot be
solved never stops the others. Per frame and vehicle there is one new
``world_T_vehicle`` variable; the three shape layers are shared by the whole
track. The factors of a track are those of the one-frame graph (projection,
body frame, symmetry, rectangle, shape prior, lazy HWC) plus, between
consecutive poses, the non-holonomic motion factor and, over three poses, the
acceleration factor (:mod:`vfactor.factors.motion`), and, when the scene
gives a road plane, the ground-plane factor on every pose.

* :class:`Tracker` — online: :meth:`Tracker.add_frame` returns the estimates of
  the frame's vehicles as soon as the frame is in.
* :func:`track_scene` — runs a Tracker over a scene and returns the final
  estimates of every frame (and the online ones).
* :func:`smooth_scene` — offline: Levenberg-Marquardt over every track at once.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import math
from dataclasses import dataclass, field
from functools import partial
from typing import Callable

import gtsam
import numpy as np

from vfactor.box import vehicle_box
from vfactor.camera import Camera
from vfactor.errors import InputError, check_numbers
from vfactor.extrinsics import extrinsic_pose_covariance
from vfactor.factors.body_frame import canonical_gauge
from vfactor.factors.motion import MotionModel, acceleration_factor, nonholonomic_factor
from vfactor.factors.projection import KeypointObservations, whitened_pose_jacobian, whitened_residuals
from vfactor.factors.robust import RobustLoss
from vfactor.graph import (
    COMMON_OFFSET,
    GraphConfig,
    add_observation_factor,
    add_shape_factors,
    detector_bias_prior,
    detector_bias_sigma,
    detector_offset_information,
    detector_offset_prior,
    detector_shape_sigmas,
    ground_factor,
    hub_height,
    hub_prior,
    hwc_factor,
    hwc_terms,
    hwc_violation,
    insert_vehicle_values,
    observations_from_detections,
    resized_observations,
    sized_observations,
    wireframe_from_values,
)
from vfactor.init import StartSearch, best_candidates, cross_projection_cost
from vfactor.keys import KeyScheme
from vfactor.label_swaps import apply_swaps, relabel_swaps, turn_cameras, turned_cameras
from vfactor.observations import Detection, Frame, Scene, class_hints
from vfactor.parallel import InProcess
from vfactor.result import FrameResult, Status, VehicleResult
from vfactor.sanity import checked, summarise_error
from vfactor.shape_evidence import considered_covariance, heavier_kind, median_scale, mixed_kinds, track_shape
from vfactor.shape_model import HwcBounds, ShapeModel, ShapePrior, resolve_shape_prior
from vfactor.solve import GROSS_OUTLIER_SIGMAS, INLIER_BOUND, POOR_FIT_SCALE, SolveOptions, solve_observations
from vfactor.wireframe import Wireframe

log = logging.getLogger(__name__)

__all__ = ["TrackOptions", "Tracker", "TrackRun", "track_scene", "smooth_scene", "scene_notes", "frame_order"]


@dataclass(frozen=True)
class TrackOptions:
    """Settings of tracking and batch smoothing.

    Attributes:
        solve: one-frame settings (graph noise, robust loss, initialisation);
            its ``graph.shape_prior_loss`` is replaced by ``shape_prior_loss``.
        shape_prior_loss: robust loss on the mean-shape prior's Mahalanobis norm
            in tracks (``GraphConfig.shape_prior_loss``). Heavy-tailed by default
            (Cauchy, threshold 6): over a track's many frames the data can show
            a vehicle unlike its type's prior. A threshold of 3 (the default
            before the body-type priors) let two of 30 iSAM2 tracks settle 20 cm
            off while batch smoothing found the shape (docs/results.md).
            ``RobustLoss("none")``: the Gaussian.
        motion: the vehicle motion model.
        lag: fixed lag in seconds (poses older than this are marginalised out,
            so memory and time per frame stay flat); ``None`` keeps every pose.
            A young track (fewer than five frames seen by two cameras) keeps its
            poses until its last re-solve has been read, at most
            ``_YOUNG_HOLD_FRAMES`` (30) of them: its first poses, often seen by
            one camera, are re-solved when the second camera comes in. A track
            that one camera alone sees for longer is no longer young.
        max_gap: seconds between two frames of a track beyond which the motion
            model says nothing (a constant-twist step over more than a few
            seconds is no prediction, and the motion factors' noise grows with the
            step until they hold nothing): a longer gap starts a new segment of the
            track, with no motion factors across the gap (the tracker restarts the
            track's smoother; batch smoothing keeps the shape), and the first
            result after it says so in its message. ``math.inf``: never.
        The road plane of the ground-plane factor is ``solve.ground_plane``
        (``track_scene`` and ``smooth_scene`` fill it from the scene when it gives
        one); its settings are ``solve.graph``'s ``hub_height``,
        ``ground_sigma_height`` and ``ground_sigma_tilt``.
        max_updates: at most this many extra iSAM2 ``update()`` calls per frame,
            until no pose of the track moves more than ``update_tolerance``.
        update_tolerance: metres (and radians) below which extra updates stop.
        relinearize_threshold: iSAM2's relinearisation threshold (metres and
            radians of a variable's step). Small, as a track's cost has flat
            valleys (depth of frames one camera saw, traded against the shape)
            along which each Gauss-Newton step is millimetres: with 0.01 iSAM2
            stopped relinearising there and settled up to 22 cm short of the
            batch minimum (tracks_3veh seed 1); 1e-4 with ``update_tolerance``
            1e-4 reaches it (within 0.4 cm on tracks_3cam and tracks_3veh, seeds
            0-4) at about 1.3x the time per frame.
        covariance: compute each pose's marginal covariance.
        detector_offsets: give each camera's detections of a track their own pose offset (a ``gtsam.Pose3``
            variable: the small rigid motion of the vehicle as that camera's detector sees it, its prior from the
            detections' ``shape_sigma``; detections without one, as the simulator's, get none): the model of a
            detector whose errors repeat from frame to frame (docs/factors.md, "The detector's pose offset in
            tracks"). ``None`` (the default): on where the track has a road plane (``solve.ground_plane``: the
            scene's, or fitted with ``vfactor fit-ground``), off without one; ``True`` / ``False``: always / never.
            With a plane, from the keypoint network's detections, it brings the poses' covariances nearer their
            errors and rotations down (two cameras, twelve scenes, six of them fresh: pose NEES 2.5x -> 1.8x and
            2.7x -> 2.0x, rotation 0.88 -> 0.78 deg; three cameras: NEES 1.1x-2.9x -> 0.86x-2.2x), translations
            -0.2 to +1.2 cm; without a plane, with two cameras of little overlap, rotations are mostly worse
            (docs/results.md, "Tracking from images", "The road plane from the traffic"). It costs 1.2-1.5x per
            frame in iSAM2. Where the detections carry a ``bias_sigma`` (the detector's error that repeats over a
            vehicle's frames and cameras), the track gets one more offset, which every camera's keypoints share,
            with that prior; the cameras' own offsets are then tied to it (docs/factors.md): unless
            ``detector_offsets`` is ``False``, with or without a plane. Off, the smoothed covariances still consider
            each camera's offset (a variable at the identity in the covariances' graph only, docs/factors.md,
            "Covariances of tracks"): the estimate does without it, the covariances do not.
        optimizer: iSAM2's step: ``"auto"`` (the default: Powell's dogleg while
            the track is young, Gauss-Newton from then on), ``"dogleg"`` or
            ``"gn"`` (Gauss-Newton) throughout. The dogleg throughout was the
            default until 2026-12-07: with a fixed lag its steps fell behind and
            the marginals of the poses let go froze that (``long_track``, 1000
            frames, a 1 s lag: online rotation 1.6 -> 3.3 deg and pose NEES
            2.3x -> 14.9x over the run, where Gauss-Newton stays at 0.9 deg and
            0.65x-0.72x); Gauss-Newton throughout diverges by metres to tens of
            metres at some young tracks at hard noise, which the dogleg's trust
            region holds (docs/reliability.md, "Long tracks with a fixed lag drifted").
        dogleg_delta: initial trust-region radius of the dogleg.
    """

    solve: SolveOptions = field(default_factory=SolveOptions)
    shape_prior_loss: RobustLoss = field(default_factory=lambda: RobustLoss("cauchy", 6.0))
    motion: MotionModel = field(default_factory=MotionModel)
    lag: float | None = None
    max_gap: float = 10.0
    max_updates: int = 10
    update_tolerance: float = 1e-4
    relinearize_threshold: float = 1e-4
    covariance: bool = True
    detector_offsets: bool | None = None
    optimizer: str = "auto"
    dogleg_delta: float = 1.0

    def __post_init__(self):  # every field, as SolveOptions and GraphConfig check theirs
        if self.lag is not None:
            check_numbers("TrackOptions", self, ("lag",))
        if not isinstance(self.max_gap, (int, float)) or isinstance(self.max_gap, bool) or not self.max_gap > 0:
            raise ValueError(f"TrackOptions.max_gap: expected a positive number of seconds (inf: never a new "
                             f"segment), got {self.max_gap!r}")
        check_numbers("TrackOptions", self, ("dogleg_delta",))
        check_numbers("TrackOptions", self, ("update_tolerance", "relinearize_threshold"), strict=False)
        for name, kind in (("solve", SolveOptions), ("motion", MotionModel)):
            if not isinstance(getattr(self, name), kind):
                raise ValueError(f"TrackOptions.{name}: expected a {kind.__name__}, got {getattr(self, name)!r}")
        if not isinstance(self.covariance, bool):
            raise ValueError(f"TrackOptions.covariance: expected True or False, got {self.covariance!r}")
        if self.optimizer not in ("auto", "dogleg", "gn"):
            raise ValueError(f"TrackOptions.optimizer: expected 'auto', 'dogleg' or 'gn', got {self.optimizer!r}")
        if not isinstance(self.max_updates, int) or self.max_updates < 0:
            raise ValueError(f"TrackOptions.max_updates: expected an integer >= 0, got {self.max_updates!r}")
        if not isinstance(self.shape_prior_loss, RobustLoss):
            raise ValueError(f"TrackOptions.shape_prior_loss: expected a RobustLoss, got {self.shape_prior_loss!r}")
        if self.detector_offsets not in (None, True, False):
            raise ValueError(f"TrackOptions.detector_offsets: expected True, False or None (on where the track has a "
                             f"road plane), got {self.detector_offsets!r}")
        if self.solve.graph.shape_prior_loss != self.shape_prior_loss:  # the tracks' prior, wherever solve is used
            graph = dataclasses.replace(self.solve.graph, shape_prior_loss=self.shape_prior_loss)
            object.__setattr__(self, "solve", dataclasses.replace(self.solve, graph=graph))

    @property
    def uses_detector_bias(self) -> bool:
        """Whether tracks whose detections carry a ``bias_sigma`` get a common detector offset: unless
        :attr:`detector_offsets` is ``False``."""
        return self.detector_offsets is not False

    @property
    def uses_detector_offsets(self) -> bool:
        """Whether tracks get detector pose offsets: :attr:`detector_offsets`, or where it is ``None`` whether the
        track has a road plane (``solve.ground_plane``)."""
        if self.detector_offsets is None:
            return self.solve.ground_plane is not None
        return bool(self.detector_offsets)


_REANCHOR_FRAMES = 5  # frames seen by two cameras over which a young track is re-solved by LM
#: A track's keypoints "jump" when a pose found from them alone (PnP / triangulation of the track's shape)
#: explains them at under this share of the cost at the motion model's prediction, and lies beyond
#: :func:`_jump`'s gate from it: then they are another vehicle's, and the track starts a new segment.
_JUMP_COST_RATIO = 0.25
#: The tracker's check of its prediction adds RANSAC PnP starts to the SQPnP and triangulation ones where the
#: keypoints cost more than this per keypoint at the prediction (robust cost: about 10 sigma of every keypoint for
#: the Cauchy loss's 2.5), or where one of those starts already explains them better than the prediction.
_RANSAC_COST = 8.0
#: A frame's keypoints that cost more than this per keypoint at the smoother's estimate after its updates (robust
#: cost; on ``long_track``'s 1912 vehicle-frames the median is 1.6, the 99.9th percentile 5.9, and a smoother stalled
#: 1.2-2.5 m off cost 5.5-9.4) send its graph to LM (Tracker._unstuck), whose solution the smoother restarts from where
#: it has less than :data:`_STUCK_GAIN` of the graph's error at the estimate.
_STUCK_COST = 5.0
_STUCK_GAIN = 0.5
#: A pose found from a frame's keypoints alone that lies beyond :func:`_jump`'s gate but is no new segment starts the
#: track's new pose (in place of the motion model's prediction) only where it explains them at under this share of
#: the cost at the prediction: beyond the gate the vehicle cannot be there, unless its keypoints say so clearly (another
#: vehicle under the id, ``intersection_multi``: 0.25-0.43). Such starts at 0.5-1.0 came from a few keypoints' or an
#: outlier's ambiguity (136 of the 162 beyond the gate on 40 simulated scenes tracked with and without a lag); a
#: fixed lag's smoother started there stayed there
#: (``tracks_3veh`` seed 133, 0.56: a start 9.3 m off, the window 2.2 m then 4.5 m off; ``library_tracks_2cam``
#: seed 158, 1.00: 12.7 m off, the window turned by up to 58 deg, then a false new segment 2.9 m off). Of a frame
#: with fewer keypoints than a frame needs alone (``SolveOptions.min_observations``) no such start is taken: four
#: keypoints fit a pose 10.8 m and 148 deg off at 0.29 of the prediction's cost (``tracks_3veh`` seed 174 at hard
#: noise; the window turned by up to 78 deg, 4.3 m off).
_START_COST_RATIO = 0.5
#: A young track's frame beyond the jump gate joins the track (:meth:`Tracker._rejoined`) where the track re-solved
#: with it explains its keypoints at no more than this multiple of the cost of the frame's own best start.
_REJOIN_COST_RATIO = 2.0
#: ... and only a track of at least this many poses (Tracker._rejoined).
_REJOIN_POSES = 5
#: A frame's keypoints that say the vehicle faces the other way are relabelled by half a turn (Tracker._turned) only
#: where the track drives forwards at least this fast, m/s (a vehicle in traffic does not reverse at walking pace):
#: slower, its heading is not its direction of travel, and the track's own heading may be the turned one.
_TURN_MIN_SPEED = 2.0
#: A frame after a jump resumes the segment the jump ended (Tracker._resume) where that segment's prediction
#: explains it at under this share of the cost at the new segment's.
_RESUME_COST_RATIO = 0.5
#: ... while fewer frames than this came after the jump (0.5 s at 10 Hz): a view hidden for a few frames.
_RESUME_FRAMES = 5
#: A young segment of fewer than :data:`_REJOIN_POSES` poses that a jump ended is kept (Tracker._take_back) until the
#: segment after it has this many poses, and is then taken back into it where that segment's motion explains its
#: keypoints (the ended segment's depth, from one camera, may have been what was off, not the id).
_TAKE_BACK_POSES = _REJOIN_POSES
#: What a track's segment is (Tracker._resume holds them for a few frames after a jump ends a segment).
_SEGMENT_STATE = ("smoother", "poses", "hwc_added", "young", "young_frames", "multiview_frames", "reanchored", "prior",
                  "body_type", "body_type_probability", "noise_scale", "camera_factors", "offsets", "offset_priors",
                  "observed")
#: A track's shape choice (Tracker._rechoose): its prior, noise scale, each camera's factor and its body type.
_SHAPE_STATE = ("prior", "noise_scale", "camera_factors", "body_type", "body_type_probability")
#: What a re-solve with a frame that does not join changes and Tracker._rejoined puts back: the shape choice and
#: the detector offsets made for that frame.
_REJOIN_STATE = (*_SHAPE_STATE, "offsets", "offset_priors", "observed")
#: With a fixed lag, a young track's poses stay in its smoother (re-stamped with each new frame) while it has fewer
#: than this many young frames, so that re-anchoring and re-joining can still re-solve them all.
_YOUNG_HOLD_FRAMES = 30
#: The gate of :func:`_jump`: metres beyond the constant-twist prediction (plus what the motion model's
#: acceleration allows over the step), and radians of heading (plus its yaw rate bound over the step). Set on
#: tracks_3veh, tracks_3cam, library_tracks(_2cam) and intersection_2cam_track (no jump on any) and
#: intersection_multi (tests/test_track.py).
_JUMP_DISTANCE, _JUMP_HEADING = 1.5, math.radians(30.0)
#: Speed (m/s) a track of one pose may have had, for the gate of :func:`_jump`: 72 km/h, above urban traffic.
_JUMP_SPEED = 20.0


def _still_held(frames_after: int) -> bool:
    """Whether the segment a jump ended is still held (Tracker._resume) with ``frames_after`` frames after the jump."""
    return frames_after < _RESUME_FRAMES


@dataclass
class _TrackState:
    """One track's smoother and bookkeeping."""

    id: str
    index: int
    smoother: gtsam.IncrementalFixedLagSmoother | None = None
    poses: list = field(default_factory=list)  # (frame index, t, pose key)
    hwc_added: bool = False
    frames_seen: int = 0
    last_seen: float = -math.inf  # time (s) of the last frame that saw the track (Tracker.forget)
    # while the track is young (fewer than _REANCHOR_FRAMES frames seen by two cameras) its observations and
    # motion factors are kept, so that it can be re-solved by Levenberg-Marquardt (see Tracker._reanchor)
    young: bool = False
    # (frame index, observations at nominal sigmas, motion factors, the frame solved alone or None,
    # camera name -> the detector pose offset's key of its keypoints)
    young_frames: list = field(default_factory=list)
    multiview_frames: int = 0  # frames two cameras saw
    reanchored: bool = False
    prior: ShapePrior | None = None  # the track's shape prior (the mixture its frames chose, Tracker._rechoose)
    hints: tuple = ()  # the 2D detector's classes its detections carried (vfactor.observations.class_hints)
    body_type: str | None = None
    body_type_probability: float | None = None
    noise_scale: float = 1.0  # multiplies the detections' pixel sigmas
    camera_factors: dict | None = None  # camera name -> its own factor on top (_camera_factors), or None
    notes: dict = field(default_factory=dict)  # pose key -> message of every result of it (a new segment)
    swaps: dict = field(default_factory=dict)  # pose key -> the frame's relabelled left/right pairs (vfactor.label_swaps)
    jumps: list = field(default_factory=list)  # (frame index, t, what) of each jump beyond the motion model
    # (frame index, id) -> the final result of each pose of the segments the track ended (Tracker._retire)
    retired: dict = field(default_factory=dict)
    # pose key -> (frame index, the result add_frame gave it) of the poses the smoother holds: what a frame that fails
    # leaves them (Tracker.add_frame)
    online: dict = field(default_factory=dict)
    # the detector pose offsets of the smoother (docs/factors.md): camera name -> its current offset's key, and
    # each offset key the smoother was given -> its prior (their count numbers the next key)
    offsets: dict = field(default_factory=dict)
    offset_priors: dict = field(default_factory=dict)
    # the largest bias_sigma of the track's detections (None: none has one; the common offset's prior is made with
    # the one known when the offset is made) and the cameras whose detections carry one
    bias_sigma: np.ndarray | None = None
    bias_cameras: set = field(default_factory=set)
    # pose key -> (frame index, its keypoints as the smoother's projection factors hold them, camera name -> detector
    # offset key): the smoothed covariances' graph takes them as least squares on their inliers (_covariance_graph)
    observed: dict = field(default_factory=dict)
    # the segment a jump ended, held for a few frames (Tracker._resume): its smoother and state, and "bad": the
    # poses of the segments jumps ended since (frame index, t, key), or None
    previous: dict | None = None
    # the young segments of a few poses that jumps ended, kept until the segment after them can take them back
    # (Tracker._take_back): their poses, young frames and where each segment starts among them, or None
    ended_young: dict | None = None
    # the ended poses the segment took back (Tracker._take_back): (their poses, their young frames, the motion
    # factors that join them to the segment's first two poses), solved again when the segment is converged
    taken_back: list = field(default_factory=list)

    def restart(self) -> None:
        """Drops the smoother and the young-track state: the track starts again from its next solvable frame."""
        self.smoother, self.poses, self.hwc_added, self.young, self.young_frames = None, [], False, False, []
        self.offsets, self.offset_priors, self.previous, self.ended_young = {}, {}, None, None
        self.taken_back, self.observed, self.online = [], {}, {}


def frame_order(scene: Scene) -> list[int]:
    """Frame indices in time order.

    Raises:
        InputError: two frames with the same time (tracking needs increasing times).
    """
    order = sorted(range(len(scene.frames)), key=lambda i: scene.frames[i].t)
    for a, b in zip(order, order[1:]):
        if scene.frames[a].t == scene.frames[b].t:
            raise InputError(f"frames[{b}].t", f"same time as frames[{a}] ({scene.frames[b].t} s): tracking needs "
                             "one frame per time")
    return order


class Tracker:
    """Online tracking of every vehicle seen by fixed cameras, one iSAM2 smoother per track.

    Args:
        cameras: camera name -> camera.
        options: tracking settings.
        prior: the body-type shape model (default:
            :func:`~vfactor.shape_model.default_shape_model`): a track starts with
            the prior (the body types' mixture) and noise scale of its first
            frame's own solve (:func:`~vfactor.solve.solve_observations`) and
            chooses them again from all its frames while it is young (its first
            five frames seen by two cameras, :func:`~vfactor.shape_evidence.track_shape`);
            or one :class:`~vfactor.shape_model.ShapePrior` for every track.
        bounds: HWC bounds (default: the model's).
        keys: key scheme of the variables (each track's smoother uses vehicle index
            0..n-1 in order of first appearance).
    """

    def __init__(self, cameras: dict[str, Camera], options: TrackOptions = TrackOptions(),
                 prior: ShapePrior | ShapeModel | None = None, bounds: HwcBounds | None = None,
                 keys: KeyScheme = KeyScheme()):
        self.cameras = cameras
        self.options = options
        self.model, self.prior, self.bounds = resolve_shape_prior(prior, bounds)
        self.keys = keys
        self._terms = hwc_terms(options.solve.graph, self.bounds)
        self._tracks: dict[str, _TrackState] = {}
        self._next_index = 0  # the key scheme's vehicle index of the next new track
        self._frame_counter = 0
        self._last_t: float | None = None

    # ------------------------------------------------------------------ public
    @property
    def track_ids(self) -> list[str]:
        return list(self._tracks)

    @property
    def jumps(self) -> dict[str, list[tuple[int, float, str]]]:
        """Track id -> (frame index, t, what) of each frame whose keypoints lay beyond the motion model's gate
        from the track's prediction (another vehicle under the same id): there the track started a new segment."""
        return {vid: list(track.jumps) for vid, track in self._tracks.items() if track.jumps}

    def add_frame(self, frame: Frame, frame_index: int | None = None) -> FrameResult:
        """Adds a frame and returns the current estimates of its vehicles.

        Args:
            frame: the frame (times must increase from frame to frame).
            frame_index: index used in the pose keys and by :meth:`estimates` (default: a running count); one a
                track still holds for an earlier frame is refused.

        Raises:
            InputError: the frame's time does not follow the previous frame's, or ``frame_index`` is one a track
                still holds.
        """
        if self._last_t is not None and frame.t <= self._last_t:
            raise InputError("t", f"frame at {frame.t} s does not follow the previous frame at {self._last_t} s")
        if frame_index is not None:
            for vid in frame.vehicle_ids():
                held = next((t for i, t, _ in getattr(self._tracks.get(vid), "poses", ()) if i == frame_index), None)
                if held is not None:
                    raise InputError("frame_index", f"{frame_index} already names the frame at {held:g} s of vehicle "
                                                    f"{vid!r}; give each frame its own index")
        self._last_t = frame.t
        index = self._frame_counter if frame_index is None else frame_index
        self._frame_counter = index + 1
        vehicles = []
        for vid in frame.vehicle_ids():
            try:
                result = self._add(vid, index, frame.t, frame.detections_of(vid))
                if result.pose_covariance is not None:
                    result.extras["covariance"] = "filtered"  # from the frames so far
                vehicles.append(checked(result, _seen_by(frame, vid, self.cameras), self.options.covariance))
                failed = result.ok and not vehicles[-1].ok  # garbage (vfactor.sanity): do not track on from it
            except (InputError, RuntimeError, np.linalg.LinAlgError) as exc:
                vehicles.append(VehicleResult(vid, Status.FAILED, message=summarise_error(exc)))
                failed = True
            track = self._tracks.get(vid)
            if failed and track is not None:  # restart this track from its next solvable frame; its earlier poses
                # keep the estimates this method gave them (its smoother may now hold the failed frame too)
                track.retired.update({(i, vid): result for i, result in track.online.values()})
                track.restart()
            elif track is not None and track.smoother is not None:
                track.online[self.keys.pose_key(track.index, index)] = (index, vehicles[-1])
            vehicles[-1].extras["detections"] = frame.indices_of(vid)
        return FrameResult(frame.t, vehicles)

    def estimates(self, covariance: bool = False) -> dict[tuple[int, str], VehicleResult]:
        """Current estimates of every pose still held by the smoothers, and of the segments ended: (frame index,
        id) -> result.

        The poses of a segment a track ended by a jump or a gap beyond ``max_gap`` keep the estimates their
        smoother gave them at that point, smoothed over the whole segment (:meth:`_retire`); those of a segment
        ended by a frame that failed (the sanity check, or an error such as an unknown camera) keep the results
        :meth:`add_frame` gave them (online: ``filtered``). A covariance is labelled ``smoothed`` (from every frame
        the smoother holds) or, with a lag, ``fixed_lag``.

        Args:
            covariance: also compute each pose's marginal covariance (one query per pose; the ended segments'
                poses have one where ``options.covariance`` is set).
        """
        out = {}
        for track in self._tracks.values():
            out.update(track.retired)
            out.update(self._segment_estimates(track, covariance))
        return out

    def _segment_estimates(self, track: _TrackState, covariance: bool) -> dict[tuple[int, str], VehicleResult]:
        """The estimates of every pose the track's smoother holds (none without a smoother): (frame index, id) ->
        result, with its marginal covariance if asked (labelled ``smoothed``: from every frame the smoother holds;
        ``fixed_lag`` with a lag: from the window's frames)."""
        out = {}
        if track.smoother is None:
            return out
        estimate = track.smoother.calculateEstimate()
        wireframe = self._wireframe(estimate, track)
        marginals = self._marginals(track, estimate) if covariance else None
        for frame_index, _, key in track.poses:
            if estimate.exists(key):
                cov = None if not covariance else (marginals.marginalCovariance(key) if marginals is not None
                                                   else track.smoother.marginalCovariance(key))
                out[(frame_index, track.id)] = self._smoothed(track, estimate, key, wireframe, cov,
                                                              "smoothed" if self.options.lag is None else "fixed_lag")
        return out

    def _marginals(self, track: _TrackState, estimate: gtsam.Values) -> gtsam.Marginals | None:
        """The marginals of the track's smoothed poses: those of the smoother's graph with each frame's keypoints as
        least squares on their inliers (:func:`_covariance_graph`, as batch smoothing's); None where that graph
        cannot be solved (the smoother's own marginals are then used)."""
        layer_keys = set(self.keys.layer_keys(track.index))
        observed = {key: entry for key, entry in track.observed.items() if estimate.exists(key)}
        factors = track.smoother.getFactors()
        kept = []
        for j in range(factors.size()):
            factor = factors.at(j)
            if factor is None:
                continue
            factor_keys = set(factor.keys())
            if isinstance(factor, gtsam.CustomFactor) and layer_keys <= factor_keys and factor_keys & observed.keys():
                continue  # a frame's projection factor: replaced below
            kept.append(factor)
        graph, values = _covariance_graph(kept, [(frame, obs, offsets) for frame, obs, offsets in observed.values()],
                                          estimate, self.keys, track.index, self.options.solve.graph)
        try:
            return gtsam.Marginals(graph, values)
        except RuntimeError:
            return None

    def _smoothed(self, track: _TrackState, estimate: gtsam.Values, key: int, wireframe: Wireframe,
                  covariance: np.ndarray | None, kind: str = "smoothed") -> VehicleResult:
        """:meth:`_result` of a pose smoothed over its segment, its covariance (if any) labelled ``kind``."""
        result = self._result(track, estimate, key, wireframe, covariance)
        if covariance is not None:
            result.extras["covariance"] = kind
        return result

    def forget(self, t: float) -> list[str]:
        """Drops every track not seen after ``t - options.max_gap`` (seconds): it would start a new segment, from
        a new smoother, anyway. A stream (:mod:`vfactor.stream`) calls it to hold its memory bounded however many
        vehicles come and go; a forgotten id seen again starts a new track. Returns the ids dropped."""
        gone = [vid for vid, track in self._tracks.items() if track.last_seen < t - self.options.max_gap]
        for vid in gone:
            del self._tracks[vid]
        return gone

    # ----------------------------------------------------------------- private
    def _track(self, vid: str) -> _TrackState:
        if vid not in self._tracks:
            self._tracks[vid] = _TrackState(vid, self._next_index)
            self._next_index += 1
        return self._tracks[vid]

    def _new_smoother(self, young: bool = False) -> gtsam.IncrementalFixedLagSmoother:
        """A smoother with the steps of ``options.optimizer`` (``"auto"``: the dogleg for a ``young`` track)."""
        params = gtsam.ISAM2Params()
        if self.options.optimizer == "dogleg" or (self.options.optimizer == "auto" and young):
            dogleg = gtsam.ISAM2DoglegParams()
            dogleg.setInitialDelta(self.options.dogleg_delta)
            params.setOptimizationParams(dogleg)
        params.setRelinearizeThreshold(self.options.relinearize_threshold)
        params.relinearizeSkip = 1
        lag = self.options.lag if self.options.lag is not None else 1e12
        return gtsam.IncrementalFixedLagSmoother(lag, params)

    def _wireframe(self, estimate: gtsam.Values, track: _TrackState) -> Wireframe:
        return wireframe_from_values(estimate, self.keys, track.index)

    def _result(self, track, estimate, key, wireframe, covariance=None, message="") -> VehicleResult:
        pose = estimate.atPose3(key)
        if covariance is not None and key in track.observed:  # the cameras' declared extrinsic errors
            covariance = covariance + _extrinsic_term(track.observed[key][1], pose, wireframe, self.options)
        result = VehicleResult(track.id, Status.CONVERGED, world_T_vehicle=pose, wireframe=wireframe,
                               pose_covariance=covariance, message=track.notes.get(key, message),
                               body_type=track.body_type, body_type_probability=track.body_type_probability,
                               box=_box(pose, wireframe, track.body_type, self.options.solve.box_model))
        result.extras["noise_scale"] = track.noise_scale
        if track.camera_factors:
            result.extras["camera_noise_factors"] = dict(track.camera_factors)
        hub = self._hub_key(track)
        if hub is not None and estimate.exists(hub):  # the wheel radius the track's poses share (a road plane given)
            result.extras["hub_height"] = float(estimate.atVector(hub)[0])
        if key in track.swaps:
            result.extras["swapped_keypoints"] = track.swaps[key]
        return result

    def _predict(self, poses: list, estimate: gtsam.Values, t: float) -> gtsam.Pose3:
        """Constant-twist prediction of the pose at ``t`` from the last two of a segment's ``poses``."""
        _, t1, k1 = poses[-1]
        T1 = estimate.atPose3(k1)
        if len(poses) < 2:
            return T1
        _, t0, k0 = poses[-2]
        twist = gtsam.Pose3.Logmap(estimate.atPose3(k0).between(T1)) / (t1 - t0)
        return T1.compose(gtsam.Pose3.Expmap(twist * (t - t1)))

    def _start(self, track: _TrackState, frame_index: int, t: float, obs: KeypointObservations,
               detections: list[Detection]) -> VehicleResult:
        """A new segment from this frame's own solve of all its keypoints (``obs``, stacked from ``detections`` at
        their nominal sigmas), their sigmas sized by the vehicle it finds, as :func:`vfactor.solve.solve_vehicle`
        sizes them (a vehicle entering a view, cut by the image border, is what a track often starts from: sized by
        their own small box its few keypoints there were weighed as if several times more precise than they are;
        ``library_tracks`` seed 220's van was failed in its first frame for it)."""
        options = self.options.solve
        first = _solve_alone(obs, dataclasses.replace(options, shape_information=True), track.id,
                             self.model or self.prior, self.bounds, detections, self.cameras, track.hints)
        if not first.ok:
            return first
        # the track's graph keeps the first frame's keypoints as the detector sized them: sized by the vehicle the
        # frame's solve found, a vehicle re-drawn under an id that jumped was merged worse (intersection_multi)
        self._rechoose(track, [first])  # the prior and noise scale the frame's own solve used
        track.smoother = self._new_smoother(young=True)
        track.poses, track.hwc_added = [], False
        key = self.keys.pose_key(track.index, frame_index)
        if first.extras.get("swapped_keypoints"):  # the track's graph takes the labels the frame's solve settled on
            obs = apply_swaps(obs, first.extras["swapped_keypoints"])
            track.swaps[key] = first.extras["swapped_keypoints"]
        motion, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        _add_pose_factors(motion, track.poses, key, t, self.options, self._hub_key(track))
        insert_vehicle_values(values, self.keys, first.world_T_vehicle, first.wireframe, track.index, frame_index)
        if self._hub_key(track) is not None:
            values.insert(self._hub_key(track), np.array([hub_height(self.options.solve.graph, track.prior)]))
        track.offsets, track.offset_priors = {}, {}
        offsets = self._offsets(track, obs, values, gtsam.Values())
        track.young, track.young_frames = True, [(frame_index, obs, motion, first, offsets)]
        stamps = {key: t, **{k: t for k in self._shape_keys(track)}, **{k: t for k in offsets.values()}}
        track.smoother.update(self._young_graph(track), values, stamps)
        track.poses.append((frame_index, t, key))
        track.multiview_frames, track.reanchored = int(_camera_count(obs) >= 2), False
        return self._finish(track, key, t)

    def _hub_key(self, track: _TrackState) -> int | None:
        """The track's hub-height key (:func:`_hub_key`), or None without a road plane."""
        return _hub_key(self.keys, track.index, self.options)

    def _shape_keys(self, track: _TrackState) -> list[int]:
        """The keys of what the track's poses share and its smoother keeps while the track lives: its shape layers
        and, with a road plane, its hub height."""
        hub = self._hub_key(track)
        return [*self.keys.layer_keys(track.index), *([] if hub is None else [hub])]

    def _offsets(self, track: _TrackState, obs: KeypointObservations, values: gtsam.Values,
                 estimate: gtsam.Values, graph: gtsam.NonlinearFactorGraph | None = None) -> dict[str, int]:
        """Camera name -> the key of the detector pose offset of its keypoints in this frame (docs/factors.md, "The
        detector's pose offset in tracks"): with detector offsets, each camera whose detections carry a
        ``shape_sigma`` has its own; where the track's detections carry a ``bias_sigma`` the track has a common
        offset too (under :data:`~vfactor.graph.COMMON_OFFSET`), to which each camera's own offset is tied, and
        which the keypoints of cameras without their own offset move by directly.

        An offset stays while the smoother holds it (``estimate``); a camera new to the track, or an offset the
        fixed lag has marginalised, gets a new one: the identity in ``values``, and its prior (a camera's made at
        the track's shape in ``estimate``, else in ``values``) in ``graph`` (a young track's graph adds the priors
        itself, :meth:`_young_graph`).
        """
        out = {}
        common = None
        if self.options.uses_detector_bias and track.bias_sigma is not None:
            common = track.offsets.get(COMMON_OFFSET)
            if common is None or not (estimate.exists(common) or values.exists(common)):
                common, prior = _new_common_offset(self.keys, track.index, len(track.offset_priors), track.bias_sigma,
                                                   values)
                track.offsets[COMMON_OFFSET], track.offset_priors[common] = common, prior
                if graph is not None:
                    graph.add(prior)
            out[COMMON_OFFSET] = common
        for name, sigma in detector_shape_sigmas(obs).items() if self.options.uses_detector_offsets else ():
            key = track.offsets.get(name)
            if key is None or not (estimate.exists(key) or values.exists(key)):
                shape = estimate if estimate.exists(self.keys.layer_keys(track.index)[0]) else values
                key, prior = _new_offset(self.keys, track.index, len(track.offset_priors), sigma, shape, values,
                                         common, self.options.solve.graph)
                track.offsets[name], track.offset_priors[key] = key, prior
                if graph is not None:
                    graph.add(prior)
            out[name] = key
        return _through_common(out, obs, track.bias_cameras)

    def _young_graph(self, track: _TrackState, frames: list | None = None) -> gtsam.NonlinearFactorGraph:
        """A young track's whole graph (``frames``: its young frames): shape factors (its prior), each frame's
        keypoints (its noise scale, its cameras' detector pose offsets and their priors) and motion."""
        config = self.options.solve.graph
        graph = gtsam.NonlinearFactorGraph()
        add_shape_factors(graph, self.keys, track.index, config, track.prior, self.bounds)
        if self._hub_key(track) is not None:
            graph.add(hub_prior(self._hub_key(track), config, track.prior))
        used = set()
        for frame_index, obs, motion, _, offsets in track.young_frames if frames is None else frames:
            scaled = _track_scaled(obs, track.noise_scale, track.camera_factors)
            add_observation_factor(graph, self.keys, scaled, track.index, frame_index, config, offsets)
            if len(scaled):  # the keypoints as this graph holds them, for the smoothed covariances (_marginals)
                track.observed[self.keys.pose_key(track.index, frame_index)] = (frame_index, scaled, offsets)
            graph.push_back(motion)
            used.update(offsets.values())
        for key in sorted(used):
            graph.add(track.offset_priors[key])
        if track.hwc_added:
            graph.add(hwc_factor(self.keys, track.index, terms=self._terms))
        return graph

    def _rechoose(self, track: _TrackState, alone: list[VehicleResult], far: bool | None = None) -> None:
        """The prior, body type and noise scale of a young track from its frames solved alone (as :func:`smooth_scene`
        does; ``far``: of those of one kind, :func:`~vfactor.shape_evidence.track_shape`)."""
        if not any(r.ok for r in alone):
            return
        shape = track_shape(alone, self.model, self.prior, far=far, hints=track.hints)
        track.prior, track.noise_scale = shape.prior, shape.noise_scale
        track.body_type, track.body_type_probability = shape.body_type, shape.probability
        # a first frame's own cameras' factors (the one-frame rule); over several frames the re-solve's (_solved_young)
        track.camera_factors = alone[0].extras.get("camera_noise_factors") if len(alone) == 1 else None

    def _reanchor(self, track: _TrackState, t: float) -> None:
        """Re-solves a young track by Levenberg-Marquardt over its whole graph.

        In its first frames a track is weakly constrained: one camera fixes a
        vehicle's depth only through the mean shape, and partial views leave the
        robust cost with several minima; iSAM2's incremental steps then may settle
        in a poor one (metres off when a second camera first sees a track started
        by one). So for the first :data:`_REANCHOR_FRAMES` frames that two cameras
        see, the track's whole graph is re-solved by LM, the first time started as
        :func:`smooth_scene` starts (each pose from its own frame's solve, where
        that succeeds), and the smoother restarted from the solution.
        """
        estimate = track.smoother.calculateEstimate()
        held = _held(track)  # its poses stay at least until this re-solve has been read (a fixed lag)
        if not all(estimate.exists(k) for k in self._young_graph(track).keyVector()):  # poses marginalised (lag)
            track.young, track.young_frames = False, []
            self._mature(track, t)
            return
        graph, solved = self._solved_young(track, track.young_frames, estimate, [k for *_, k in track.poses],
                                           fresh=not track.reanchored)
        track.reanchored = True
        if track.multiview_frames >= _REANCHOR_FRAMES:  # well seen now: plain incremental updates from here
            track.young, track.young_frames = False, []
        self._restart_smoother(track, graph, solved, t, held)

    def _solved_young(self, track: _TrackState, frames: list, estimate: gtsam.Values, pose_keys: list,
                      fresh: bool) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
        """LM over a young track's whole graph of ``frames`` from ``estimate``: every frame solved alone (once,
        kept in ``frames``; with ``fresh`` each pose starts from its frame's own solve), the track's prior and noise
        scale chosen again from all of them (:meth:`_rechoose`), and the body frame put back in the convention's
        gauge. Returns the graph and the solution."""
        options = dataclasses.replace(self.options.solve, covariance=False, shape_information=True)
        for i, (index, obs, motion, alone, offsets) in enumerate(frames):
            if alone is None:
                alone = _solve_alone(obs, options, track.id, self.model or self.prior, self.bounds,
                                     hints=track.hints)
                frames[i] = (index, obs, motion, alone, offsets)
        alone = [frame[3] for frame in frames]
        if mixed_kinds(alone, self.model):  # a bus some frames took for a smaller vehicle: each kind solved
            first = heavier_kind(alone, self.model)
            tried = {far: self._solved_as(track, frames, gtsam.Values(estimate), pose_keys, far, alone)
                     for far in (first, not first)}
            keep = not first if tried[not first][0] < _KIND_FIT_SHARE * tried[first][0] else first
            _, state, graph, solved = tried[keep]
            for name, value in state.items():
                setattr(track, name, value)
        else:
            self._rechoose(track, alone)  # all frames so far, not the first alone
            graph, solved = self._young_lm(track, frames, estimate, pose_keys, fresh)
        points = self._wireframe(solved, track).vehicle_p_keypoints
        fits = []  # each frame's keypoints at the track's noise scale, one for all cameras, and their residuals
        for index, obs, _, _, offsets in frames:
            scaled = _track_scaled(obs, track.noise_scale, None)
            if len(scaled):
                fits.append((scaled, _frame_residuals(scaled, solved, self.keys, track.index, index, offsets, points)))
        factors = _camera_factors(fits, _YOUNG_CAMERA_FRAME_SHARE)
        if factors is not None:  # the cameras' keypoints fit at scales far apart: each camera's sigmas its own
            track.camera_factors = factors
            graph = self._young_graph(track, frames)
            solved = gtsam.LevenbergMarquardtOptimizer(graph, solved, self.options.solve.lm_params()).optimize()
        return graph, solved

    def _young_lm(self, track: _TrackState, frames: list, estimate: gtsam.Values, pose_keys: list,
                  fresh: bool) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
        """LM over a young track's graph of ``frames`` at its current prior and noise scale, from ``estimate`` (with
        ``fresh``, each pose from its frame's own solve: :meth:`_young_starts`), the body frame put back in the
        convention's gauge."""
        if fresh:
            for index, pose in self._young_starts(track, frames).items():
                estimate.update(self.keys.pose_key(track.index, index), pose)
        graph = self._young_graph(track, frames)
        solved = gtsam.LevenbergMarquardtOptimizer(graph, estimate, self.options.solve.lm_params()).optimize()
        turned = canonical_gauge(solved, pose_keys, self.keys.layer_keys(track.index), track.offset_priors)
        if turned is not None:  # turned front to back (vfactor.factors.body_frame): again from the convention's gauge
            solved = gtsam.LevenbergMarquardtOptimizer(graph, turned, self.options.solve.lm_params()).optimize()
        return graph, solved

    def _solved_as(self, track: _TrackState, frames: list, estimate: gtsam.Values, pose_keys: list, far: bool,
                   alone: list) -> tuple:
        """A young track whose frames' own solves are of both kinds (:func:`~vfactor.shape_evidence.mixed_kinds`)
        solved as one kind: its prior, body type and noise scale from those frames alone, each pose started from
        its own frame's solve or its nearest frame's of that kind, the shape from the kind's prior mean. Returns
        ``(fit, state, graph, solution)`` with ``fit`` how well every frame's keypoints fit the solution against
        their nominal sigmas (:func:`_fit_scale`) and ``state`` the track's choice for that kind (its prior, noise
        scale, body type and its probability); the caller keeps one by :data:`_KIND_FIT_SHARE`
        (``library_bus_tracks_2cam`` seeds 1-2: the buses were tracked as vans).

        Each kind's frames' Gaussians on the shape are linearised at their own solutions, metres apart, so which
        kind explains the track is told by the joint solution, not by adding them up."""
        self._rechoose(track, alone, far)
        insert_vehicle_values(estimate, self.keys, None, Wireframe(track.prior.mean), track.index)
        graph, solved = self._young_lm(track, frames, estimate, pose_keys, True)
        points = self._wireframe(solved, track).vehicle_p_keypoints
        residuals = [_frame_residuals(obs, solved, self.keys, track.index, index, offsets, points)
                     for index, obs, _, _, offsets in frames if len(obs)]
        state = {name: getattr(track, name) for name in _SHAPE_STATE}
        return _fit_scale(np.concatenate(residuals)) if residuals else np.inf, state, graph, solved

    def _young_starts(self, track: _TrackState, frames: list) -> dict[int, gtsam.Pose3]:
        """Frame index -> the pose a young track's re-solve starts from: each frame's own solve (none for a poor
        fit's, whose pose may be turned over, or a failed one's: the smoother's estimate stays), but where the
        track's body type and the frame's differ and one of them lies far from the model's pooled prior (a bus
        track whose frame came out a car, or the reverse), the pose of the nearest frame whose own solve is of the
        track's kind: such a frame is often the bus taken for a smaller vehicle along the cameras' rays, metres
        off.

        A bus seen by two cameras (``library_bus_tracks_2cam`` seed 13): two of its first five frames solved alone
        were an estate 19 m off and a van 3.4 m off; started there, the re-solve kept the track 135 degrees and
        16 m off for ten frames (docs/results.md)."""
        far = self.model.far_from_pooled if self.model is not None else (lambda body_type: False)

        def usable(alone: VehicleResult) -> bool:
            return alone.ok and alone.status != Status.POOR_FIT

        def other_kind(alone: VehicleResult) -> bool:
            return (alone.body_type != track.body_type and None not in (alone.body_type, track.body_type)
                    and (far(alone.body_type) or far(track.body_type)))

        own = {index: alone.world_T_vehicle for index, _, _, alone, _ in frames
               if usable(alone) and not other_kind(alone)}
        starts = dict(own)
        for index, _, _, alone, _ in frames:
            if usable(alone) and other_kind(alone) and own:
                starts[index] = own[min(own, key=lambda i: abs(i - index))]
        return starts

    def _restart_smoother(self, track: _TrackState, graph: gtsam.NonlinearFactorGraph, solved: gtsam.Values,
                          t: float, held: bool) -> None:
        """A new smoother for the track from a whole-graph solution; with ``held`` every pose is stamped ``t``, so
        that a fixed lag keeps it until this solution has been read."""
        track.smoother = self._new_smoother(track.young)
        stamps = {key: t if held else stamp for _, stamp, key in track.poses}
        stamps.update({k: t for k in self._shape_keys(track)})
        stamps.update({k: t for k in track.offset_priors if solved.exists(k)})
        track.smoother.update(graph, solved, stamps)

    def _mature(self, track: _TrackState, t: float) -> None:
        """A track no longer young: with ``optimizer="auto"`` its smoother restarts with Gauss-Newton steps from its
        own graph (the marginals of the poses it let go included) and estimate (where a re-solve ends the young
        phase, :meth:`_restart_smoother` makes the new smoother so already)."""
        if self.options.optimizer != "auto" or track.smoother is None:
            return
        self._restart_smoother(track, _smoother_graph(track.smoother), track.smoother.calculateEstimate(), t,
                               _held(track))

    def _unstuck(self, track: _TrackState, key: int, t: float, estimate: gtsam.Values,
                 wireframe: Wireframe) -> tuple[gtsam.Values, Wireframe]:
        """Re-solves the smoother's graph by Levenberg-Marquardt where iSAM2 stopped short of its minimum.

        iSAM2's dogleg steps can stall far from the minimum of the smoother's own graph: on ``long_track`` (1000
        frames, a 1 s lag, the road plane) a braking vehicle's filtered pose went 0.6, 1.2, 1.8, 2.5 m off over four
        frames of good keypoints from two cameras, at four times the graph's least error, and the tracker then took
        the next frame for a jump. Where this frame's keypoints cost more than :data:`_STUCK_COST` per keypoint at
        the estimate, the smoother's graph (its factors, the marginals of the poses it let go included) is solved
        by LM from the estimate, and where that lowers the graph's error below :data:`_STUCK_GAIN` of it, the
        smoother restarts from the solution (:meth:`_restart_smoother`). Returns the smoother's estimate and the
        track's wireframe in it: ``estimate`` and ``wireframe`` (its current ones), or the solution's where it
        restarted.
        """
        entry = track.observed.get(key)
        if entry is None:
            return estimate, wireframe
        frame_index, obs, offsets = entry
        smoother = track.smoother
        points = wireframe.vehicle_p_keypoints
        residuals = _frame_residuals(obs, estimate, self.keys, track.index, frame_index, offsets, points)
        loss = self.options.solve.graph.loss
        if not len(obs) or np.sum(loss.rho(np.linalg.norm(residuals, axis=1))) <= _STUCK_COST * len(obs):
            return estimate, wireframe
        graph = _smoother_graph(smoother)
        try:
            solved = gtsam.LevenbergMarquardtOptimizer(graph, estimate, self.options.solve.lm_params()).optimize()
        except RuntimeError:
            return estimate, wireframe
        if graph.error(solved) >= _STUCK_GAIN * graph.error(estimate):
            return estimate, wireframe
        self._restart_smoother(track, graph, solved, t, _held(track))
        estimate = track.smoother.calculateEstimate()
        return estimate, self._wireframe(estimate, track)

    def _rejoined(self, track: _TrackState, frame_index: int, t: float, raw: KeypointObservations,
                  obs: KeypointObservations, start) -> bool:
        """Whether a young track's frame whose keypoints lie beyond the jump gate is the track's own vehicle after
        all, and if so the track re-solved with it.

        A young track may be what is off, not the id: one far camera fixes the depth only through the shape prior,
        and a detector's keypoints of a vehicle cut by the image border can be consistent and wrong, so a track can
        be metres off when good views arrive (``library_tracks_2cam`` from the network's keypoints). So its whole
        graph with this frame is re-solved by LM, every pose from its own frame's solve as :meth:`_reanchor` starts
        (this frame's from ``start``, its best PnP / triangulation pose): where the solution explains this frame's
        keypoints within :data:`_REJOIN_COST_RATIO` of ``start``'s cost, the track goes on from it (re-anchored);
        keypoints of another vehicle cannot be joined to the track's motion at that cost, and the track splits.
        Only for a track of at least :data:`_REJOIN_POSES` poses: with fewer the motion model knows too little of
        the vehicle's speed and turning, and the keypoints of another vehicle within reach joined a track at that
        cost (``intersection_multi`` with its vehicles drawn anew every frame, tests/test_track.py).

        Args:
            raw: the frame's observations at their nominal sigmas; ``obs`` at the track's noise scale, as
                ``start.cost`` was computed.
        """
        estimate = track.smoother.calculateEstimate()
        held = _held(track)
        key = self.keys.pose_key(track.index, frame_index)
        motion = gtsam.NonlinearFactorGraph()
        _add_pose_factors(motion, track.poses, key, t, self.options, self._hub_key(track))
        values = gtsam.Values()
        before = {name: copy.copy(getattr(track, name)) for name in _REJOIN_STATE}
        offsets = self._offsets(track, obs, values, estimate)
        frames = track.young_frames + [(frame_index, raw, motion, None, offsets)]
        values.insert(key, start.world_T_vehicle)
        estimate.insert(values)
        solved = None
        if all(estimate.exists(k) for k in self._young_graph(track, frames).keyVector()):  # else marginalised (lag)
            graph, solved = self._solved_young(track, frames, estimate, [k for *_, k in track.poses] + [key],
                                               fresh=True)
        if solved is None or cross_projection_cost(obs, solved.atPose3(key), wireframe_from_values(
                solved, self.keys, track.index), self.options.solve.graph.loss) > _REJOIN_COST_RATIO * start.cost:
            for name, value in before.items():  # the track as it was: its shape choice and detector offsets
                setattr(track, name, value)
            return False
        track.young_frames, track.reanchored = frames, True
        track.notes[key] = ("the young track re-solved with this frame, whose keypoints lay beyond the motion "
                            "model's gate from its prediction: the track, not the id, was off")
        track.poses.append((frame_index, t, key))
        track.multiview_frames += int(_camera_count(obs) >= 2)
        if track.multiview_frames >= _REANCHOR_FRAMES:
            track.young, track.young_frames = False, []
        self._restart_smoother(track, graph, solved, t, held)
        return True

    def _resume(self, track: _TrackState, t: float, raw: KeypointObservations) -> None:
        """Resumes the segment a jump ended where a frame after the jump follows it.

        A learnt detector now and then gives one frame's keypoints of a vehicle turned round or elsewhere
        (``library_tracks_2cam`` seed 12 from the network's keypoints: both cameras' keypoints of one frame
        165 deg off), or a few frames' where a view is hidden behind another vehicle and the network puts the
        hidden one's keypoints on the one in front (``library_tracks_2cam`` seed 241: a pickup 59-173 deg off in
        three frames of one camera). Such a frame beyond the motion model's gate started a new segment, and the
        next frames, wrong in another way or right again, more. So the segment the first jump ended is held
        (``track.previous``) while the frames after it number fewer than :data:`_RESUME_FRAMES` (a jump from a
        segment begun within them keeps holding it): where a frame's keypoints are explained by the held
        segment's prediction at under :data:`_RESUME_COST_RATIO` of the cost at the current segment's, the
        frames since were bad. The held segment goes on (its poses live again), and the bad frames' poses go back
        into it without their keypoints: where the track's motion puts them, said in their results' messages
        (their online results, given before, were their own solves).
        """
        previous = track.previous
        if previous is None:
            return
        bad = previous["bad"] + track.poses  # every frame since the held segment ended
        if not _still_held(len(bad)):
            track.previous = None  # the segment after the jump holds: the held one is given up
            return
        loss = self.options.solve.graph.loss
        now = track.smoother.calculateEstimate()
        cost_now = cross_projection_cost(_track_scaled(raw, track.noise_scale, track.camera_factors),
                                         self._predict(track.poses, now, t), self._wireframe(now, track), loss)
        before = previous["smoother"].calculateEstimate()  # the held segment (same keys' characters and index)
        cost_before = cross_projection_cost(_track_scaled(raw, previous["noise_scale"], previous["camera_factors"]),
                                            self._predict(previous["poses"], before, t), self._wireframe(before, track),
                                            loss)
        if not cost_before < _RESUME_COST_RATIO * cost_now:
            return
        for name in _SEGMENT_STATE:
            setattr(track, name, previous[name])
        track.previous = None
        track.ended_young = None  # the held segment goes on: nothing to take back
        bad_frames = {index for index, _, _ in bad}
        for index, _, _ in track.poses + bad:  # the held segment's poses are live again; the bad ones join it
            track.retired.pop((index, track.id), None)
        track.jumps = [jump for jump in track.jumps if jump[0] not in bad_frames]
        # the bad frames' poses go back into the track without their keypoints: where its motion puts them
        for frame_index, t_bad, key in bad:
            motion, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
            _add_pose_factors(motion, track.poses, key, t_bad, self.options, self._hub_key(track))
            values.insert(key, self._predict(track.poses, track.smoother.calculateEstimate(), t_bad))
            stamps = {key: t_bad, **({k: t_bad for *_, k in track.poses} if _held(track) else {})}
            track.smoother.update(motion, values, stamps)
            if track.young:  # a frame without keypoints in the young track's graph: its motion factors only
                left_out = VehicleResult(track.id, Status.FAILED, message="keypoints left out")
                track.young_frames.append((frame_index, raw.subset(np.zeros(len(raw), dtype=bool)), motion,
                                           left_out, {}))
            track.poses.append((frame_index, t_bad, key))
            track.notes[key] = ("its keypoints lay beyond the motion model's gate, and a later frame's followed the "
                                "track again: left out of the track, the pose from the track's motion alone")

    def _take_back(self, track: _TrackState) -> None:
        """The poses of the young segment a jump ended, solved again with the segment after it, where its motion
        explains the ended segment's keypoints: the ended poses were this vehicle, off in depth, not another's.

        A track that one far camera starts fixes its depth only through the shape prior, and a vehicle entering a
        view may be solved metres off: the next frame's keypoints then lie beyond the jump gate of a one-pose
        track, and the track split, its first poses left metres off for good (``tracks_3veh`` and
        ``library_tracks_2cam``: 9 of 79 simulated scenes, the first pose of a vehicle entering cam1's view 0.6-6.6 m
        off). With too few poses for :meth:`_rejoined`'s test at the jump, the ended segment (fewer than
        :data:`_TAKE_BACK_POSES` poses) is kept until the new one has :data:`_TAKE_BACK_POSES` poses and so knows
        the vehicle's speed and turning. Then both are solved as one young track by LM: the ended poses start where
        the new segment's motion, run backwards, puts them, motion factors join the two, each camera keeps one
        detector offset. Where the solution explains every ended frame's keypoints within
        :data:`_REJOIN_COST_RATIO` of the cost of that frame's own best start (PnP / triangulation of the solved
        shape), and the new segment's frames within that multiple of their cost before, the ended poses take
        their estimates from it (with their covariances, said in their messages; solved again at the converged
        segment by :meth:`_refit_taken_back`) and the jump is withdrawn; keypoints of another vehicle cannot
        follow the new segment's motion back at that cost. The new segment itself goes on as it was (its
        estimates, shape choice and smoother untouched: a pose off by metres and seen by one camera would only
        drag it).
        """
        ended, track.ended_young = track.ended_young, None
        if [p[0] for p in track.poses] != [f[0] for f in track.young_frames]:
            return
        estimate = track.smoother.calculateEstimate()
        if not all(estimate.exists(k) for k in self._young_graph(track).keyVector()):  # marginalised (lag)
            return
        loss = self.options.solve.graph.loss
        old_poses = ended["poses"]
        before = {name: copy.copy(getattr(track, name)) for name in _REJOIN_STATE}
        values = gtsam.Values()
        backwards = [track.poses[1], track.poses[0]]  # the new segment's motion, run back in time
        for _, t_old, key in old_poses:
            values.insert(key, self._predict(backwards, estimate, t_old))
        frames = [(index, obs, motion, alone, self._offsets(track, obs, values, estimate))
                  for index, obs, motion, alone, _ in ended["young_frames"]] + list(track.young_frames)
        merged = old_poses + track.poses
        for start in ended["starts"][1:] + [len(old_poses)]:  # each segment's first two poses get the motion
            for i in range(start, min(start + 2, len(merged))):  # factors to the poses before it
                motion = gtsam.NonlinearFactorGraph()
                _add_pose_factors(motion, merged[:i], merged[i][2], merged[i][1], self.options,
                                  self._hub_key(track))
                frames[i] = (*frames[i][:2], motion, *frames[i][3:])
        scale, factors = track.noise_scale, track.camera_factors  # costs at the segment's noise scale
        wireframe = self._wireframe(estimate, track)
        cost_before = sum(cross_projection_cost(_track_scaled(obs, scale, factors), estimate.atPose3(key), wireframe,
                                                loss)
                          for (_, obs, *_), (_, _, key) in zip(track.young_frames, track.poses) if len(obs))
        estimate.insert(values)
        try:
            graph, solved = self._solved_young(track, frames, estimate, [k for *_, k in merged], fresh=False)
        except RuntimeError:  # the joint solve failed numerically: the ended segment keeps its own estimates
            return
        finally:
            for name, value in before.items():  # the new segment's shape choice and detector offsets, as they were
                setattr(track, name, value)
        shape = self._wireframe(solved, track)

        def cost(obs, key):
            return cross_projection_cost(_track_scaled(obs, scale, factors), solved.atPose3(key), shape, loss)

        if not cost_before > 0 or sum(cost(obs, key) for (_, obs, *_), (_, _, key) in zip(
                frames[len(old_poses):], track.poses) if len(obs)) > _REJOIN_COST_RATIO * cost_before:
            return
        for (_, obs, *_), (_, _, key) in zip(frames, old_poses):
            if len(obs):
                starts = best_candidates(_track_scaled(obs, scale, factors), shape, loss, 1,
                                         min_keypoints_in_one_view=self.options.solve.min_keypoints_in_one_view)
                if not starts or cost(obs, key) > _REJOIN_COST_RATIO * starts[0].cost:
                    return
        try:
            marginals = gtsam.Marginals(graph, solved) if self.options.covariance else None
        except RuntimeError:
            return
        for index, _, key in old_poses:
            track.notes[key] = ("taken back into the track: the segment a jump ended here was this vehicle, off in "
                                "depth; solved again with the segment after the jump, whose motion leads back to it")
            covariance = marginals.marginalCovariance(key) if marginals is not None else None
            track.retired[(index, track.id)] = self._smoothed(track, solved, key, shape, covariance)
        track.notes.pop(track.poses[0][2], None)
        jumped = {merged[start][0] for start in ended["starts"][1:] + [len(old_poses)]}  # each segment's first frame
        track.jumps = [jump for jump in track.jumps if jump[0] not in jumped]
        if not any(offsets for *_, offsets in frames):
            links = gtsam.NonlinearFactorGraph()
            for frame in frames[len(old_poses):len(old_poses) + 2]:
                links.push_back(frame[2])
            track.taken_back.append((old_poses, frames[:len(old_poses)], links, [p[2] for p in track.poses[:2]]))

    def _refit_taken_back(self, track: _TrackState) -> None:
        """The poses a segment took back (:meth:`_take_back`) solved again at the converged segment: their frames'
        keypoints and motion, joined to the segment's first two poses and its shape, which enter through their
        marginals (each a Gaussian prior at the segment's estimate). At the end of the segment (:meth:`finish`,
        :meth:`_retire`), or with a fixed lag when its poses stop being held (the track grown up), after which
        they keep these estimates; frames with detector pose offsets keep the estimates they were taken back with."""
        if not track.taken_back or track.smoother is None:
            return
        estimate, smoother = track.smoother.calculateEstimate(), track.smoother
        config = self.options.solve.graph
        layer_keys = self._shape_keys(track)
        for old_poses, frames, links, link_keys in track.taken_back:
            if not all(estimate.exists(k) for k in [*link_keys, *layer_keys]):
                continue
            graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
            for (index, obs, motion, *_), (_, _, key) in zip(frames, old_poses):
                if len(obs):
                    add_observation_factor(graph, self.keys, _track_scaled(obs, track.noise_scale,
                                                                           track.camera_factors),
                                           track.index, index, config)
                graph.push_back(motion)
                values.insert(key, track.retired[(index, track.id)].world_T_vehicle)
            graph.push_back(links)
            try:  # a refit that fails numerically leaves the poses as they were taken back
                for key in link_keys:
                    graph.add(gtsam.PriorFactorPose3(key, estimate.atPose3(key), gtsam.noiseModel.Gaussian.Covariance(
                        smoother.marginalCovariance(key))))
                    values.insert(key, estimate.atPose3(key))
                for key in layer_keys:
                    graph.add(gtsam.PriorFactorVector(key, estimate.atVector(key),
                                                      gtsam.noiseModel.Gaussian.Covariance(
                                                          smoother.marginalCovariance(key))))
                    values.insert(key, estimate.atVector(key))
                solved = gtsam.LevenbergMarquardtOptimizer(graph, values, self.options.solve.lm_params()).optimize()
                marginals = gtsam.Marginals(graph, solved) if self.options.covariance else None
            except RuntimeError:
                continue
            wireframe = self._wireframe(estimate, track)
            for index, _, key in old_poses:
                covariance = marginals.marginalCovariance(key) if marginals is not None else None
                track.retired[(index, track.id)] = self._smoothed(track, solved, key, wireframe, covariance)

    def _add(self, vid: str, frame_index: int, t: float, detections: list[Detection]) -> VehicleResult:
        obs = given = observations_from_detections(detections, self.cameras, self.options.solve.graph)
        track = self._track(vid)
        track.last_seen = t
        track.hints = class_hints(detections, track.hints)  # the vehicle's, over its frames
        bias = detector_bias_sigma(detections)
        if bias is not None:  # the detector's bias (the common offset's prior takes what is known when it is made)
            track.bias_sigma = bias if track.bias_sigma is None else np.maximum(track.bias_sigma, bias)
            track.bias_cameras.update(d.camera for d in detections if d.bias_sigma is not None)
        if len(obs) == 0:
            return VehicleResult(vid, Status.DEGENERATE, message="no keypoint seen in this frame")
        track.frames_seen += 1
        gap = t - track.poses[-1][1] if track.smoother is not None and track.poses else 0.0
        if gap > self.options.max_gap:  # beyond the motion model: a new segment, from a new smoother
            self._retire(track)
            track.restart()
            track.notes[self.keys.pose_key(track.index, frame_index)] = _segment_message(gap, self.options.max_gap)
        if track.smoother is None:
            return self._start(track, frame_index, t, given, detections)
        if track.previous is not None:
            self._resume(track, t, obs)
        raw, obs = obs, _track_scaled(obs, track.noise_scale, track.camera_factors)
        options = self.options.solve
        # once both motion factors fix the pose any keypoint helps, as in smooth_scene; a younger track needs three
        fixed_by_motion = _acceleration_applies(track.poses, t, self.options)
        if len(obs) < options.min_observations and len(obs) < 3 and not fixed_by_motion:
            return VehicleResult(vid, Status.DEGENERATE, message=f"only {len(obs)} keypoints seen in this frame")
        estimate = track.smoother.calculateEstimate()
        wireframe = self._wireframe(estimate, track)
        guess = self._predict(track.poses, estimate, t)
        loss = options.graph.loss
        key = self.keys.pose_key(track.index, frame_index)
        # a camera whose detector read the vehicle's front as its back: its keypoints relabelled by half a turn before
        # the prediction is judged, where the track drives forwards (a vehicle does not turn round in one frame)
        turned = self._turned(track, obs, guess, estimate, wireframe)
        if turned:
            raw, obs = turn_cameras(raw, turned), turn_cameras(obs, turned)
            track.notes[key] = (f"the keypoints of camera(s) {', '.join(repr(n) for n in turned)} are those of the "
                                "vehicle turned round (the detector read its front as its back): relabelled")
        # a poor prediction (a long gap, a sharp manoeuvre) is replaced by the best PnP/triangulation start, one beyond
        # the jump gate only where it explains the keypoints clearly better (_START_COST_RATIO) and they are enough
        # for a frame alone
        kept = None
        few = fixed_by_motion and len(obs) < options.min_observations  # fewer keypoints than a frame needs alone
        if few:
            kept = self._gated(track, key, obs, guess, wireframe)
            if kept is not None:
                raw, obs = raw.subset(kept), obs.subset(kept)
        predicted_cost = cross_projection_cost(obs, guess, wireframe, loss)
        if predicted_cost > 2.0 * len(obs):
            # SQPnP and triangulation starts first; OpenCV's RANSAC PnP (a fifth of the tracker's time where it ran
            # at every such frame, about half of them) only where the prediction is clearly poor or a start beats it
            # (docs/performance.md, "The tracker's prediction check: RANSAC where it can matter")
            search = StartSearch(obs, wireframe, loss, options.min_keypoints_in_one_view)
            starts = search.best(1, ransac=False)
            if predicted_cost > _RANSAC_COST * len(obs) or (starts and starts[0].cost < predicted_cost):
                starts = search.best(1)  # RANSAC's poses join the SQPnP and triangulation ones already made
            if starts and starts[0].cost < predicted_cost:
                dt = t - track.poses[-1][1]
                jump = _jump(guess, starts[0].world_T_vehicle, dt, self.options, velocity_known=len(track.poses) >= 2)
                depth = jump and not track.young and _along_one_ray(obs, guess, starts[0].world_T_vehicle, dt,
                                                                    self.options)
                if depth:  # one camera's keypoints put it along that camera's ray: its depth, not another vehicle
                    camera = obs.cameras[int(obs.camera_index[0])].name
                    track.notes[key] = (f"{jump} along the ray of camera {camera!r}, the only one that sees it: taken "
                                        "as that view's depth, not a new segment")
                elif jump and starts[0].cost < _JUMP_COST_RATIO * predicted_cost:
                    if track.young and len(track.poses) >= _REJOIN_POSES and self._rejoined(track, frame_index, t, raw,
                                                                                         obs, starts[0]):
                        return self._finish(track, key, t)  # the track was what was off, not the id
                    # the keypoints are those of a vehicle elsewhere: the id does not follow one vehicle here
                    self._retire(track)
                    ended = {name: getattr(track, name) for name in _SEGMENT_STATE}
                    held = track.previous  # a segment an earlier jump ended, held through the frames after it
                    pending = track.ended_young  # an earlier young segment this one was to take back
                    track.restart()
                    if held is not None and _still_held(len(held["bad"]) + len(ended["poses"])):
                        track.previous = dict(held, bad=held["bad"] + ended["poses"])  # still held: this one was bad
                    else:
                        track.previous = dict(ended, bad=[])
                    if ended["young"] and len(ended["poses"]) < _TAKE_BACK_POSES and \
                            [p[0] for p in ended["poses"]] == [f[0] for f in ended["young_frames"]]:
                        track.ended_young = {"poses": ended["poses"], "young_frames": ended["young_frames"],
                                             "starts": [0]}
                        if pending is not None and len(pending["poses"]) + len(ended["poses"]) < _TAKE_BACK_POSES:
                            # two short segments in a row (a first pose off, then a second): taken back together
                            track.ended_young = {
                                "poses": pending["poses"] + ended["poses"],
                                "young_frames": pending["young_frames"] + ended["young_frames"],
                                "starts": pending["starts"] + [len(pending["poses"])]}
                    track.jumps.append((frame_index, t, jump))
                    track.notes[key] = f"a new segment of the track: {jump}; the detections' id may not follow one vehicle"
                    return self._start(track, frame_index, t, given, detections)
                if not jump or (not few and not depth and starts[0].cost < _START_COST_RATIO * predicted_cost):
                    guess = starts[0].world_T_vehicle
        # the keypoints the track takes (those the gate kept): their sigmas sized by the vehicle where it is taken to be
        raw = turn_cameras(sized_observations(detections, self.cameras, options.graph, guess, wireframe), turned)
        if kept is not None:
            raw = raw.subset(kept)
        obs = _track_scaled(raw, track.noise_scale, track.camera_factors)
        if options.relabel_swaps:  # left/right pairs that the track's shape at the prediction says are swapped
            obs, swaps = relabel_swaps(obs, guess, wireframe.vehicle_p_keypoints, loss)
            if swaps:
                raw = apply_swaps(raw, swaps)
                track.swaps[key] = swaps
        graph, motion, values = gtsam.NonlinearFactorGraph(), gtsam.NonlinearFactorGraph(), gtsam.Values()
        offsets = self._offsets(track, obs, values, estimate, graph)
        add_observation_factor(graph, self.keys, obs, track.index, frame_index, options.graph, offsets)
        track.observed[key] = (frame_index, obs, offsets)
        _add_pose_factors(motion, track.poses, key, t, self.options, self._hub_key(track))
        graph.push_back(motion)
        values.insert(key, guess)
        stamps = {key: t, **{k: t for k in self._shape_keys(track)}, **{k: t for k in offsets.values()}}
        if _held(track):  # a young track's poses stay for its re-solves
            stamps.update({k: t for *_, k in track.poses})
        track.smoother.update(graph, values, stamps)
        track.poses.append((frame_index, t, key))
        if track.young:
            track.young_frames.append((frame_index, raw, motion, None, offsets))
            if track.ended_young is not None and len(track.poses) >= _TAKE_BACK_POSES:
                self._take_back(track)
            if _camera_count(obs) >= 2:
                track.multiview_frames += 1
                self._reanchor(track, t)
            elif self.options.lag is not None and len(track.young_frames) > _YOUNG_HOLD_FRAMES:
                # one camera only for longer than the window holds a young track: its first poses are gone, so it
                # can no longer be re-solved whole (and a stream's memory stays bounded)
                track.young, track.young_frames = False, []
                self._mature(track, t)
        return self._finish(track, key, t)

    def _turned(self, track: _TrackState, obs: KeypointObservations, guess: gtsam.Pose3, estimate: gtsam.Values,
                wireframe: Wireframe) -> list[str]:
        """The cameras whose keypoints are those of the vehicle turned round at the prediction ``guess``
        (:func:`vfactor.label_swaps.turned_cameras`), asked only where the track's last two poses drive forwards at
        :data:`_TURN_MIN_SPEED` or faster: there the track's heading is its direction of travel, and a frame whose
        keypoints say the vehicle faces the other way is the detector's error."""
        if len(track.poses) < 2:
            return []
        (_, t0, k0), (_, t1, k1) = track.poses[-2:]
        world_T_vehicle = estimate.atPose3(k1)
        moved = world_T_vehicle.translation() - estimate.atPose3(k0).translation()
        if not t1 > t0 or world_T_vehicle.rotation().unrotate(moved)[0] / (t1 - t0) < _TURN_MIN_SPEED:
            return []
        return turned_cameras(obs, guess, wireframe.vehicle_p_keypoints, self.options.solve.graph.loss)

    def _gated(self, track: _TrackState, key: int, obs: KeypointObservations, guess: gtsam.Pose3,
               wireframe: Wireframe) -> np.ndarray | None:
        """A frame's few keypoints without those its prediction puts beyond :data:`~vfactor.solve.GROSS_OUTLIER_SIGMAS`.

        With fewer keypoints than a frame needs alone (``SolveOptions.min_observations``: a vehicle leaving a view,
        cut by the image border), a track whose motion fixes the pose still takes them, but the robust loss cannot
        tell one outlier among four from the rest: with a fixed lag the outlier of the fourth last keypoint of a
        van leaving cam1's view turned the window's poses by up to 67 deg, 3 m off, all "converged" (``tracks_3veh``
        seed 39). So such keypoints are gated on the track's prediction, as a tracker gates its measurements:
        those whose whitened residual at the predicted pose and the track's shape (at the track's noise scale) is
        beyond :data:`~vfactor.solve.GROSS_OUTLIER_SIGMAS` are left out, never most of them (a prediction that
        most keypoints disagree with is the jump test's to judge), and the result says so.

        Returns:
            Which of ``obs`` (the frame's observations at the track's noise scale) are kept; None: all of them.
        """
        residual = np.linalg.norm(whitened_residuals(obs, guess, wireframe.vehicle_p_keypoints), axis=1)
        beyond = residual > GROSS_OUTLIER_SIGMAS
        if not beyond.any() or beyond.sum() >= 0.5 * len(obs):
            return None
        labels = ", ".join(f"{obs.cameras[c].name} keypoint {k}"
                           for c, k in zip(obs.camera_index[beyond], obs.keypoint_index[beyond]))
        track.notes[key] = (f"{int(beyond.sum())} of its {len(obs)} keypoints ({labels}) left out: beyond "
                            f"{GROSS_OUTLIER_SIGMAS:g} sigmas of the track's prediction, with too few keypoints for "
                            "the robust loss to outvote them")
        return ~beyond

    def _settle(self, track: _TrackState, max_updates: int, recent: int | None = 20) -> None:
        """Extra iSAM2 updates (relinearisation) until no pose moves more than the tolerance.

        Args:
            recent: check only the track's last poses (their estimates are read one by
                one, so the cost does not grow with the track); None checks them all.
        """
        smoother = track.smoother
        held = smoother.timestamps()  # forget poses the smoother has marginalised (with or without a lag)
        track.poses = [p for p in track.poses if p[2] in held]
        track.observed = {key: entry for key, entry in track.observed.items() if key in held}
        track.online = {key: entry for key, entry in track.online.items() if key in held}
        if track.swaps:
            track.swaps = {key: found for key, found in track.swaps.items() if key in held}
        keys = [key for _, _, key in track.poses[-recent if recent else 0:]]
        before = [smoother.calculateEstimatePose3(k) for k in keys]
        for _ in range(max_updates):
            smoother.update()
            after = [smoother.calculateEstimatePose3(k) for k in keys]
            moved = max(np.linalg.norm(a.localCoordinates(b)) for a, b in zip(before, after))
            before = after
            if moved < self.options.update_tolerance:
                break

    def _retire(self, track: _TrackState, max_updates: int = 50) -> None:
        """Keeps the final results of a track's segment before the track restarts (its smoother is dropped):
        the segment converged fully (as :meth:`finish` does), each of its poses smoothed by all of the segment's
        frames (with its covariance where ``options.covariance``). Without this a restarted segment's poses
        would keep their online (filtered) estimates."""
        if track.smoother is None or not track.poses:
            return
        self._settle(track, max_updates, recent=None)
        self._refit_taken_back(track)
        track.retired.update(self._segment_estimates(track, self.options.covariance))

    def finish(self, max_updates: int = 50) -> None:
        """Converges every track fully (call at the end of a stream before reading :meth:`estimates`)."""
        for track in self._tracks.values():
            if track.smoother is not None and track.poses:
                self._settle(track, max_updates, recent=None)
                self._refit_taken_back(track)

    def _finish(self, track: _TrackState, key: int, t: float) -> VehicleResult:
        """Extra iSAM2 updates until the track settles, lazy HWC, and the frame's result."""
        self._settle(track, self.options.max_updates)
        if track.taken_back and self.options.lag is not None and not _held(track):
            # the poses the taken-back ones are joined to leave the fixed lag from now on: solved again while held
            self._refit_taken_back(track)
            track.taken_back = []
        estimate = track.smoother.calculateEstimate()
        estimate, wireframe = self._unstuck(track, key, t, estimate, self._wireframe(estimate, track))
        smoother = track.smoother
        config = self.options.solve.graph
        if config.hwc == "lazy" and not track.hwc_added and hwc_violation(wireframe, self._terms) > config.hwc_tolerance:
            graph = gtsam.NonlinearFactorGraph()
            graph.add(hwc_factor(self.keys, track.index, terms=self._terms))
            smoother.update(graph, gtsam.Values(), {k: t for k in self._shape_keys(track)})
            track.hwc_added = True
            estimate = smoother.calculateEstimate()
            wireframe = self._wireframe(estimate, track)
        covariance = smoother.marginalCovariance(key) if self.options.covariance else None
        if covariance is not None and key in track.observed:  # the cameras' offsets the track does not estimate
            _, obs, offsets = track.observed[key]
            covariance = covariance + _considered_offsets(obs, offsets, estimate.atPose3(key), wireframe, config)
        message = "" if track.frames_seen > 1 else "first frame of the track: no motion factors yet"
        return self._result(track, estimate, key, wireframe, covariance, message)


def _considered_offsets(obs: KeypointObservations, offsets: dict[str, int], world_T_vehicle: gtsam.Pose3,
                        wireframe: Wireframe, config: GraphConfig) -> np.ndarray:
    """(6, 6) what the online (filtered) covariance of a pose adds for the cameras' detector offsets the track does
    not estimate (docs/factors.md, "Covariances of tracks"): their first-order effect on the frame's pose.

    Camera ``c``'s repeated error moves the pose it sees by a rigid offset ``xi_c`` (covariance ``Sigma_c``, the
    offset prior's: :func:`vfactor.graph.detector_offset_prior` at the detections' ``shape_sigma`` and the track's
    shape); the frame's keypoints then put the pose at ``sum_c S_c xi_c`` from where they would, ``S_c = H^-1 H_c``
    with ``H_c = A_c^T A_c`` camera ``c``'s information on the pose (its inliers' whitened Jacobian) and ``H``
    all cameras'. As the offset is the same in every frame, the motion model that joins
    the frames does not average it away: the term is ``sum_c S_c Sigma_c S_c^T``, whatever the track's length
    (the smoothed covariances consider the offsets in the track's graph instead). Zero where no camera has such an
    offset or the frame's pose information is singular.
    """
    points = wireframe.vehicle_p_keypoints
    sigmas = _unestimated_offsets(obs, offsets)
    if not sigmas:
        return np.zeros((6, 6))
    residuals, jacobian = whitened_pose_jacobian(obs, world_T_vehicle, points)
    inlier = np.sum(residuals ** 2, axis=1) < INLIER_BOUND
    A = jacobian[inlier].reshape(-1, 6)
    try:
        H_inv = np.linalg.inv(A.T @ A)
    except np.linalg.LinAlgError:
        return np.zeros((6, 6))
    names = [camera.name for camera in obs.cameras]
    rows = np.repeat(obs.camera_index[inlier], 2)
    priors: dict[float, np.ndarray] = {}  # sigma -> the offset prior's covariance (cameras of one detector share it)
    for sigma in sigmas.values():
        if sigma not in priors:
            priors[sigma] = np.linalg.inv(detector_offset_information(sigma, points, config.shape_sigma_size_exponent))
    out = considered_covariance(H_inv, A, ((rows == names.index(name), A[rows == names.index(name)], priors[sigma])
                                           for name, sigma in sigmas.items()))  # an offset moves the pose it sees
    return out if np.all(np.isfinite(out)) else np.zeros((6, 6))


def _extrinsic_term(obs: KeypointObservations, world_T_vehicle: gtsam.Pose3, wireframe: Wireframe,
                    options: TrackOptions) -> np.ndarray:
    """(6, 6) what the cameras' declared extrinsic errors add to a track pose's covariance, from its frame's
    observations (:func:`vfactor.extrinsics.extrinsic_pose_covariance`; docs/factors.md, "Covariances of tracks")."""
    return extrinsic_pose_covariance(obs, world_T_vehicle, wireframe.vehicle_p_keypoints, INLIER_BOUND,
                                     options.solve.graph.loss)


def _unestimated_offsets(obs: KeypointObservations, offsets: dict[str, int]) -> dict[str, float]:
    """Camera name -> ``shape_sigma`` of the cameras of a frame (``obs``, seen through ``offsets``, camera name ->
    detector offset key) whose detections carry a ``shape_sigma`` but that have no detector offset of their own in
    the track: the offsets the track's covariances consider (:func:`_covariance_graph`, :func:`_considered_offsets`)."""
    common = offsets.get(COMMON_OFFSET)
    return {name: sigma for name, sigma in detector_shape_sigmas(obs).items() if offsets.get(name, common) == common}


def _hub_key(keys: KeyScheme, index: int, options: TrackOptions) -> int | None:
    """The key of track ``index``'s hub height above the road plane (its wheel radius, one variable its poses share:
    :func:`vfactor.graph.hub_prior`), or None where the track has no road plane (``options.solve.ground_plane``).
    The tracker and batch smoothing both take it from here."""
    return None if options.solve.ground_plane is None else keys.hub_key(index)


def _add_pose_factors(graph: gtsam.NonlinearFactorGraph, poses, key: int, t: float, options: TrackOptions,
                      hub_key: int | None = None) -> None:
    """The factors of a track's new pose ``key`` at time ``t`` (seconds): motion and ground.

    A non-holonomic factor to the previous pose, an acceleration factor over the
    last two (when both are within ``options.lag``), and the ground-plane factor
    when ``options.solve.ground_plane`` is set. ``poses``: the track's earlier
    ``(frame index, t, key)`` in time order; ``hub_key``: the track's hub height
    (:func:`vfactor.graph.hub_prior`), which the ground-plane factors of its poses
    share (None: each pose's factor has the config's hub height). The tracker and
    batch smoothing both build their graphs with it.
    """
    if poses and t - poses[-1][1] <= options.max_gap:
        _, t1, k1 = poses[-1]
        graph.add(nonholonomic_factor(k1, key, t - t1, options.motion))
        if _acceleration_applies(poses, t, options):
            _, t0, k0 = poses[-2]
            graph.add(acceleration_factor(k0, k1, key, t1 - t0, t - t1, options.motion))
    if options.solve.ground_plane is not None:
        graph.add(ground_factor(key, options.solve.ground_plane, options.solve.graph, hub_key))


def _acceleration_applies(poses, t: float, options: TrackOptions) -> bool:
    """Whether a new pose at ``t`` gets both motion factors (two earlier poses, both inside the lag,
    neither step longer than ``options.max_gap``).

    From a track's third pose on these alone fix a pose (lateral, vertical and
    tilt by the non-holonomic factor; speed and yaw rate by the acceleration
    factor).
    """
    if len(poses) < 2 or max(t - poses[-1][1], poses[-1][1] - poses[-2][1]) > options.max_gap:
        return False
    return options.lag is None or t - poses[-2][1] < options.lag


def _jump(predicted: gtsam.Pose3, found: gtsam.Pose3, dt: float, options: TrackOptions,
          velocity_known: bool = True) -> str:
    """What makes ``found`` a jump from the motion model's ``predicted`` pose over ``dt`` seconds, or "".

    A jump: the positions more than ``_JUMP_DISTANCE + sigma_acceleration dt^2`` metres apart (plus
    ``_JUMP_SPEED dt`` when the track has one pose so far, so no velocity), or the headings (body x on the
    road) more than ``_JUMP_HEADING + max_yaw_rate dt`` radians.
    """
    motion = options.motion
    gate = _JUMP_DISTANCE + motion.sigma_acceleration * dt * dt + (0.0 if velocity_known else _JUMP_SPEED * dt)
    distance = float(np.linalg.norm(found.translation() - predicted.translation()))
    if distance > gate:
        return f"its keypoints put it {distance:.1f} m from where its motion predicts"
    a, b = predicted.rotation().matrix()[:2, 0], found.rotation().matrix()[:2, 0]
    heading = abs(math.atan2(a[0] * b[1] - a[1] * b[0], a @ b))
    if heading > _JUMP_HEADING + motion.max_yaw_rate * dt:
        return f"its keypoints turn it {math.degrees(heading):.0f} deg from the heading its motion predicts"
    return ""


def _along_one_ray(obs: KeypointObservations, predicted: gtsam.Pose3, found: gtsam.Pose3, dt: float,
                   options: TrackOptions) -> bool:
    """Whether ``found`` is a jump (:func:`_jump`) from ``predicted`` only along the ray of the one camera whose
    keypoints ``obs`` are: moved back along that ray to ``predicted``'s depth it is within the gate.

    One view fixes a vehicle's depth least of all: a few of its keypoints, one of them an outlier or a swapped pair,
    can fit the track's shape metres along the ray better than at the motion model's prediction (``library_tracks_2cam``
    seed 1115: six keypoints of one camera 4.1 m deeper at 0.13 of the prediction's cost, which started a new segment
    1.6 m off that the track's later one-camera frames kept: its final shape 23 cm off). A mature track's motion
    fixes that depth; another vehicle under the id shows elsewhere in the image, or in another camera.
    """
    cameras = np.unique(obs.camera_index)
    if len(cameras) != 1:
        return False
    center = obs.cameras[int(cameras[0])].center
    ray = predicted.translation() - center
    ray /= np.linalg.norm(ray)
    step = found.translation() - predicted.translation()
    back = gtsam.Pose3(found.rotation(), found.translation() - (step @ ray) * ray)
    return not _jump(predicted, back, dt, options)


def _segment_message(gap: float, max_gap: float) -> str:
    return (f"new segment of the track: {gap:.3g} s since its previous frame exceed the motion model's reach "
            f"(TrackOptions.max_gap = {max_gap:g} s); no motion factors across the gap")


def _held(track: _TrackState) -> bool:
    """Whether a track's poses are held in its smoother whatever the lag (:data:`_YOUNG_HOLD_FRAMES`)."""
    return track.young and len(track.young_frames) < _YOUNG_HOLD_FRAMES


def _seen_by(frame: Frame, vid: str, cameras: dict[str, Camera]) -> list[Camera]:
    """The cameras that see at least one keypoint of vehicle ``vid`` in ``frame`` (for vfactor.sanity)."""
    return [cameras[d.camera] for d in frame.detections_of(vid) if d.camera in cameras and np.any(d.confidence > 0)]


def _camera_count(obs: KeypointObservations) -> int:
    return len(set(obs.camera_index.tolist()))


@dataclass
class TrackRun:
    """What :func:`track_scene` returns.

    Attributes:
        frames: final estimates, one :class:`FrameResult` per scene frame in file
            order (poses still in the smoother at the end are smoothed by every
            later frame; with a lag, older poses keep their estimate from when
            they left the window).
        online: the estimates as each frame arrived (filtered), same layout.
        messages: scene-level notes (frames out of time order, tracks seen once).
    """

    frames: list[FrameResult]
    online: list[FrameResult]
    messages: list[str]


def track_scene(scene: Scene, options: TrackOptions = TrackOptions(),
                progress: Callable[[int, int], None] | None = None, engine=None, **kwargs) -> TrackRun:
    """Tracks every vehicle through a scene (``vfactor track``).

    Frames are processed in time order (out-of-order frames are reported in
    ``messages``); results come back in the scene's order. Each track is its own
    unit of work (one :class:`Tracker` per track id over the frames that see it):
    tracks share nothing, so the results are those of one Tracker over every
    frame, and an ``engine`` can spread the tracks over processes or machines.

    Args:
        scene: the scene.
        options: tracking settings.
        progress: called as ``progress(done, total)`` with the tracks finished so far.
        engine: where the tracks run (:mod:`vfactor.parallel`; default: in this process). The results do not
            depend on it.
        **kwargs: passed to :class:`Tracker` (``prior``, ``bounds``, ``keys``).

    Raises:
        InputError: a detection still waits for the keypoint network
            (:meth:`~vfactor.observations.Scene.require_keypoints`), or two frames have the same time.
    """

    scene.require_keypoints()
    order = frame_order(scene)
    options = dataclasses.replace(options, solve=options.solve.for_scene(scene))
    units = _track_units(scene, order, (scene.cameras, options, kwargs))
    online_of: dict[tuple[int, str], VehicleResult] = {}
    final: dict[tuple[int, str], VehicleResult] = {}
    jumps_of: dict[str, list] = {}
    for (vid, _, _), (online, track_final, jumps) in zip(units, (engine or InProcess()).map(
            _track_unit, units, progress=progress)):
        online_of.update(((i, vid), v) for i, v in online.items())
        final.update(((i, vid), v) for i, v in track_final.items())
        if jumps:
            jumps_of[vid] = jumps
    frames = _frame_results(scene, final, options.covariance)
    messages = scene_notes(scene, frames)
    for vid, jumps in jumps_of.items():
        where = ", ".join(f"frames[{f}]" for f, _, _ in jumps[:5]) + (", ..." if len(jumps) > 5 else "")
        messages.append(f"vehicle '{vid}': {len(jumps)} jumps beyond the motion model ({where}; first: {jumps[0][2]}): "
                        "its id does not follow one vehicle there; tracked as new segments")
    online = [_with_detections(f, [online_of[(i, vid)] for vid in f.vehicle_ids()]) for i, f in enumerate(scene.frames)]
    log.info("tracked %d vehicles over %d frames (%s): %d of %d poses solved", len(units), len(frames),
             "smoothed" if options.lag is None else f"fixed lag {options.lag:g} s",
             sum(v.ok for fr in frames for v in fr.vehicles), sum(len(fr.vehicles) for fr in frames))
    return TrackRun(frames=frames, online=online, messages=messages)


def _track_units(scene: Scene, order: list[int], shared: tuple) -> list[tuple]:
    """The units of work of tracking and batch smoothing: per track id, in order of first appearance (in time
    order), ``(id, index, (shared, [(frame index, the frame with that track's detections only), ...]))``."""
    per_track: dict[str, list] = {}
    for i in order:
        frame = scene.frames[i]
        for vid in frame.vehicle_ids():
            per_track.setdefault(vid, []).append((i, Frame(frame.t, frame.detections_of(vid), frame.images)))
    return [(vid, index, (shared, items)) for index, (vid, items) in enumerate(per_track.items())]


def scene_notes(scene: Scene, frames: list[FrameResult]) -> list[str]:
    """The scene-level notes of a tracking run (:attr:`TrackRun.messages`; ``vfactor track`` prints them, batch
    smoothing's too): frames out of time order, and each vehicle solved in one frame only.

    Args:
        scene: the scene tracked.
        frames: its results, one per scene frame (:func:`track_scene`'s ``frames`` or :func:`smooth_scene`'s).
    """
    notes = []
    order = frame_order(scene)
    if order != sorted(order):
        moved = [i for pos, i in enumerate(order) if i != pos]
        notes.append(f"frames are not in time order (e.g. frames[{moved[0]}]); tracked in time order")
    solved: dict[str, int] = {}
    for frame in frames:
        for v in frame.vehicles:
            solved[v.id] = solved.get(v.id, 0) + int(v.ok)
    notes += [f"vehicle '{vid}' was solved in one frame only: no motion information"
              for vid, count in solved.items() if count == 1]
    return notes


def _track_unit(unit: tuple) -> tuple[dict, dict, list]:
    """Tracks one track (a :func:`_track_units` unit) with its own :class:`Tracker`: its online results and
    final results by frame index, and its jumps."""
    vid, _, ((cameras, options, kwargs), items) = unit
    tracker = Tracker(cameras, options, **kwargs)
    online: dict[int, VehicleResult] = {}
    final: dict[tuple[int, str], VehicleResult] = {}
    for i, frame in items:
        online[i] = final[(i, vid)] = tracker.add_frame(frame, i).vehicles[0]
        if options.lag is not None:  # a pose's final estimate and covariance are its last ones inside the window
            _refresh(final, tracker.estimates(covariance=options.covariance), "fixed_lag")
    tracker.finish()
    _refresh(final, tracker.estimates(covariance=options.covariance), "smoothed" if options.lag is None else "fixed_lag")
    return online, {i: v for (i, _), v in final.items()}, tracker.jumps.get(vid, [])


def _frame_results(scene: Scene, results: dict, covariance: bool) -> list[FrameResult]:
    """The final results of every frame, in the scene's order, from (frame index, id) -> result: each
    sanity-checked against the cameras that saw it (:func:`vfactor.sanity.checked`) and with its
    ``extras["detections"]``."""
    return [_with_detections(f, [checked(results[(i, vid)], _seen_by(f, vid, scene.cameras), covariance)
                                 for vid in f.vehicle_ids()]) for i, f in enumerate(scene.frames)]


def _with_detections(frame: Frame, vehicles: list[VehicleResult]) -> FrameResult:
    """The frame's results, each with ``extras["detections"]``: the indices of its detections in the scene frame
    (a track's unit held only that track's detections)."""
    for v in vehicles:
        v.extras["detections"] = frame.indices_of(v.id)
    return FrameResult(frame.t, vehicles)


def _refresh(final: dict, estimates: dict, kind: str) -> None:
    """Replaces results by the smoothers' current estimates, keeping a covariance that was not recomputed.

    A recomputed covariance is labelled ``kind`` (``extras["covariance"]``); an online result a failed frame left a
    pose (:meth:`Tracker.estimates`) keeps its ``filtered``.
    """
    for key, v in estimates.items():
        old = final.get(key)
        if v.pose_covariance is None and old is not None:
            v.pose_covariance = old.pose_covariance
            if "covariance" in old.extras:
                v.extras["covariance"] = old.extras["covariance"]
        elif v.pose_covariance is not None and v.extras.get("covariance") != "filtered":
            v.extras["covariance"] = kind
        final[key] = v


def _solve_alone(obs: KeypointObservations, options: SolveOptions, vid: str, prior, bounds,
                 detections: list[Detection] | None = None, cameras: dict[str, Camera] | None = None,
                 hints: tuple = ()) -> VehicleResult:
    """One frame of a track solved on its own (with ``detections``, those of ``obs``, as
    :func:`vfactor.solve.solve_vehicle` solves them: the keypoints' sigmas sized by the vehicle it finds), the body
    types weighed by the track's 2D detector classes ``hints``; a numerical failure is a ``failed`` result, not an
    exception."""
    resize = None if detections is None else partial(resized_observations, detections, cameras, options.graph)
    try:
        return solve_observations(obs, options, vid, prior, bounds, hints=hints, resize=resize)
    except (RuntimeError, np.linalg.LinAlgError) as exc:
        return VehicleResult(vid, Status.FAILED, message=summarise_error(exc))


def smooth_scene(scene: Scene, options: TrackOptions = TrackOptions(), prior: ShapePrior | ShapeModel | None = None,
                 bounds: HwcBounds | None = None, progress: Callable[[int, int], None] | None = None,
                 engine=None) -> list[FrameResult]:
    """Batch smoothing: every track's whole graph solved at once by Levenberg-Marquardt.

    Each track starts from its one-frame solves (each frame's pose, the previous
    pose where a frame cannot be solved alone, and the shape of the solved frame
    with the most keypoints: a first frame seen partly can start LM in a worse
    minimum, as on tracks_3cam seed 0). With a shape model (the default) the
    track's body type is chosen from the evidence of all its solved frames
    together (their shape informations add up: they share one shape), and its
    noise scale is the median of theirs.

    Each track is its own unit of work (:func:`track_scene`): ``engine``
    (:mod:`vfactor.parallel`) can spread them, with the same results;
    ``progress(done, total)`` counts the tracks.

    Raises:
        InputError: a detection still waits for the keypoint network.
    """

    scene.require_keypoints()
    order = frame_order(scene)
    options = dataclasses.replace(options, solve=options.solve.for_scene(scene), lag=None)
    units = _track_units(scene, order, (scene.cameras, options, prior, bounds))
    results: dict[tuple[int, str], VehicleResult] = {}
    for (vid, _, _), track_results in zip(units, (engine or InProcess()).map(_smooth_unit, units, progress=progress)):
        results.update(((i, vid), v) for i, v in track_results.items())
    return _frame_results(scene, results, options.covariance)


def _new_offset(keys: KeyScheme, index: int, number: int, sigma: float, shape: gtsam.Values,
                values: gtsam.Values, common: int | None, config: GraphConfig) -> tuple[int, gtsam.NonlinearFactor]:
    """A new detector pose offset of one camera of track ``index`` (docs/factors.md, "The detector's pose offset
    in tracks"): its key (offset ``number``), the identity inserted in ``values``, and its prior made at the
    track's keypoints in ``shape`` with the detections' ``shape_sigma`` ``sigma`` (taken at that shape's size,
    ``config.shape_sigma_size_exponent``): about the identity, or, where the track has a common offset (its key
    ``common``), about that offset (:func:`vfactor.graph.detector_offset_prior`)."""
    key = keys.offset_key(index, number)
    values.insert(key, gtsam.Pose3())
    return key, detector_offset_prior(key, sigma, wireframe_from_values(shape, keys, index).vehicle_p_keypoints,
                                      common, config.shape_sigma_size_exponent)


def _new_common_offset(keys: KeyScheme, index: int, number: int, bias_sigma, values: gtsam.Values
                       ) -> tuple[int, gtsam.NonlinearFactor]:
    """A new common detector offset of track ``index`` (the detector's bias, docs/factors.md, "The detector's pose
    offset in tracks"): its key (offset ``number``), the identity inserted in ``values``, and its prior with the
    detections' ``bias_sigma`` (:func:`vfactor.graph.detector_bias_prior`)."""
    key = keys.offset_key(index, number)
    values.insert(key, gtsam.Pose3())
    return key, detector_bias_prior(key, bias_sigma)


def _through_common(offsets: dict[str, int], obs: KeypointObservations, biased: set) -> dict[str, int]:
    """``offsets`` (camera name -> detector offset key, the track's common one under ``COMMON_OFFSET``) with every
    camera of ``obs`` whose detections carry a ``bias_sigma`` (``biased``) and that has no offset of its own
    moving by the common one; unchanged without a common offset."""
    common = offsets.get(COMMON_OFFSET)
    if common is not None:
        offsets.update({camera.name: common for camera in obs.cameras
                        if camera.name in biased and camera.name not in offsets})
    return offsets


#: Batch smoothing looks for the tracker's jumps in a track (:func:`_smooth_unit`) where at least this many of its
#: frames' keypoints fit a vehicle of their own :data:`~vfactor.solve.POOR_FIT_SCALE` times better than the smoothed
#: track: on 1414 frames of fresh scenes (tracks_3veh, library_tracks_2cam and library_tracks seeds 307-309 at
#: paper-like and hard noise) 9 frames did so, none of them in a wrong track (0.3-1.3 deg, 4-12 cm off), never three
#: in one track (seeds 310-315, 108 tracks: none); of the two ids exchanged half way of an audit's scene, 40 of 79.
_BATCH_SUSPECT_FRAMES = 3
#: The fixed lag (seconds) of the tracker that looks for the jumps of a batch-smoothed track.
_JUMP_SEARCH_LAG = 1.0


def _smooth_unit(unit: tuple) -> dict[int, VehicleResult]:
    """Batch smoothing of one track (a :func:`_track_units` unit): its results by frame index.

    Each frame is solved alone first. The track is cut where the tracker would start a new segment: at a gap beyond
    ``max_gap`` (another vehicle may carry the id after it), and, where the keypoints of
    :data:`_BATCH_SUSPECT_FRAMES` frames or more fit a vehicle of their own at least
    :data:`~vfactor.solve.POOR_FIT_SCALE` times better than the smoothed track, at the jumps the tracker
    (:class:`Tracker`) finds in it: there the id follows another vehicle, which one shape and one motion would bend
    the whole track towards. Each piece is smoothed on its own (:func:`_smooth_piece`).
    """
    vid, index, ((cameras, options, prior, bounds), frames) = unit
    model, prior, bounds = resolve_shape_prior(prior, bounds)
    config = options.solve.graph
    alone = dataclasses.replace(options.solve, shape_information=True)
    hints = class_hints(d for _, frame in frames for d in frame.detections)  # the track's, as the tracker counts them
    firsts = []
    for _, frame in frames:
        obs = observations_from_detections(frame.detections, cameras, config)
        firsts.append(_solve_alone(obs, alone, vid, model or prior, bounds, frame.detections, cameras, hints)
                      if len(obs) else None)
    seen = [(i, frame.t) for (i, frame), first in zip(frames, firsts) if first is not None]
    notes = {i: _segment_message(t - t0, options.max_gap) for (_, t0), (i, t) in zip(seen, seen[1:])
             if t - t0 > options.max_gap}

    def smoothed(starts) -> tuple[dict[int, VehicleResult], int]:
        results, suspect, piece = {}, 0, []
        for item in zip(frames, firsts):
            if item[0][0] in starts and piece:
                done, odd = _smooth_piece(vid, index, cameras, options, model, prior, bounds, piece, hints=hints)
                results, suspect, piece = {**results, **done}, suspect + odd, []
            piece.append(item)
        done, odd = _smooth_piece(vid, index, cameras, options, model, prior, bounds, piece, hints=hints)
        return {**results, **done}, suspect + odd

    results, suspect = smoothed(set(notes))
    if suspect >= _BATCH_SUSPECT_FRAMES:  # the tracker's jumps: where the id follows another vehicle
        # with a fixed lag and no covariances: only its jumps are wanted, and a tracker that keeps every pose costs
        # more with every frame (a 665-frame track took 484 s, 0.7 s a pose; a user's audit)
        tracker = Tracker(cameras, dataclasses.replace(options, lag=_JUMP_SEARCH_LAG, covariance=False),
                          model or prior, bounds)
        for i, frame in frames:
            tracker.add_frame(frame, i)
        jumps = {f: what for f, _, what in tracker.jumps.get(vid, []) if f not in notes}
        if jumps:
            results, _ = smoothed(set(notes) | set(jumps))
            notes.update({f: f"a new segment of the track: {what}; the detections' id may not follow one vehicle"
                          for f, what in jumps.items()})
    for i, note in notes.items():
        if i in results:
            results[i].message = "; ".join(filter(None, [note, results[i].message]))
    return results


def _smooth_piece(vid: str, index: int, cameras: dict[str, Camera], options: TrackOptions, model, prior, bounds,
                  piece: list, camera_factors: dict | None = None,
                  hints: tuple = ()) -> tuple[dict[int, VehicleResult], int]:
    """One piece of a track (``[((frame index, frame), its one-frame solve or None), ...]``) smoothed by
    Levenberg-Marquardt from its frames' own solves, each keypoint's sigma sized by the vehicle its frame's solve
    found (:func:`vfactor.graph.sized_observations`, as the one-frame solve sizes them; a frame whose solve failed
    by the track's pose before it; a frame without keypoints gets no pose). Returns its results by frame index and
    how many of its frames' keypoints fit a vehicle of their own at least :data:`~vfactor.solve.POOR_FIT_SCALE`
    times better than the smoothed track (each result's ``extras["fit_noise_scale"]``: how they fit the track,
    against their sigmas at the track's noise scale).

    Where the cameras' keypoints fit the smoothed track at scales :data:`_CAMERA_SCALE_RATIO` or more apart (a
    detector's scores on another scale in one camera; each camera's median over all the piece's frames), the piece
    is smoothed again with each camera's sigmas times its own factor (``camera_factors``, camera name -> factor;
    the results' ``extras["camera_noise_factors"]``): one scale for all made the other cameras' keypoints too sharp.
    ``hints``: the track's 2D detector classes (all its detections', as the tracker counts them).
    """
    keys = KeyScheme()
    config = options.solve.graph
    results: dict[int, VehicleResult] = {}
    frames = [item[0] for item in piece]
    firsts = [item[1] for item in piece]
    shape = track_shape(firsts, model, prior, hints=hints)
    track_prior, scale, body_type, probability = shape.prior, shape.noise_scale, shape.body_type, shape.probability
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    add_shape_factors(graph, keys, index, config, track_prior, bounds)
    hub = _hub_key(keys, index, options)  # the track's wheel radius
    if hub is not None:
        graph.add(hub_prior(hub, config, track_prior))
        values.insert(hub, np.array([hub_height(config, track_prior)]))
    posed, best = [], -1
    offsets: dict[str, int] = {}  # camera name -> the key of its detector pose offset (one per camera, no lag)
    bias = detector_bias_sigma([d for _, frame in frames for d in frame.detections]) \
        if options.uses_detector_bias else None
    biased = {d.camera for _, frame in frames for d in frame.detections if d.bias_sigma is not None}
    swaps = {}  # frame index -> the left/right pairs that frame's own solve relabelled, taken over by the batch graph
    projections = []  # (the indices of its projection factors in graph, frame index, observations, offsets) per frame
    for (i, frame), first in zip(frames, firsts):
        solved = first is not None and first.ok
        if first is None or (not solved and not posed):  # no keypoint: no pose (the motion model alone would make one)
            results[i] = first or VehicleResult(vid, Status.DEGENERATE, message="no keypoint seen in this frame")
            continue
        trusted = solved and (first.status != Status.POOR_FIT or not posed)  # a poor fit starts no pose but the first
        guess = first.world_T_vehicle if trusted else values.atPose3(posed[-1][2])
        shape_at = first.wireframe if trusted else wireframe_from_values(values, keys, index)
        obs = _track_scaled(sized_observations(frame.detections, cameras, config, guess, shape_at), scale,
                            camera_factors)
        if trusted and first.extras.get("swapped_keypoints"):
            swaps[i] = first.extras["swapped_keypoints"]
            obs = apply_swaps(obs, swaps[i])
        if trusted and len(obs) > best:
            best = len(obs)
            insert_vehicle_values(values, keys, None, first.wireframe, index)
        key = keys.pose_key(index, i)
        if bias is not None and COMMON_OFFSET not in offsets:  # the detector's bias: an offset all cameras share
            offsets[COMMON_OFFSET], bias_prior = _new_common_offset(keys, index, len(offsets), bias, values)
            graph.add(bias_prior)
        for name, sigma in detector_shape_sigmas(obs).items() if options.uses_detector_offsets else ():
            if name not in offsets:
                offsets[name], offset_prior = _new_offset(keys, index, len(offsets), sigma, values, values,
                                                          offsets.get(COMMON_OFFSET), options.solve.graph)
                graph.add(offset_prior)
        frame_offsets = _through_common(dict(offsets), obs, biased)
        first_factor = graph.size()
        add_observation_factor(graph, keys, obs, index, i, config, frame_offsets)
        projections.append((range(first_factor, graph.size()), i, obs, frame_offsets))
        _add_pose_factors(graph, posed, key, frame.t, options, hub)
        values.insert(key, guess)
        posed.append((i, frame.t, key))
    if not posed:
        return results, 0
    try:
        optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, options.solve.lm_params())
        estimate = optimizer.optimize()
        terms = hwc_terms(config, bounds)
        shape = wireframe_from_values(estimate, keys, index)
        if config.hwc == "lazy" and hwc_violation(shape, terms) > config.hwc_tolerance:
            graph.add(hwc_factor(keys, index, terms=terms))
            optimizer = gtsam.LevenbergMarquardtOptimizer(graph, estimate, options.solve.lm_params())
            estimate = optimizer.optimize()
        turned = canonical_gauge(estimate, [key for *_, key in posed], keys.layer_keys(index), offsets.values())
        if turned is not None:  # the body frame turned front to back (vfactor.factors.body_frame): on from the convention's
            optimizer = gtsam.LevenbergMarquardtOptimizer(graph, turned, options.solve.lm_params())
            estimate = optimizer.optimize()
        if options.covariance:
            replaced = {j for rows, *_ in projections for j in rows}
            kept = [graph.at(j) for j in range(graph.size()) if j not in replaced]
            marginals = gtsam.Marginals(*_covariance_graph(kept, [p[1:] for p in projections], estimate, keys, index,
                                                           config))
        else:
            marginals = None
    except RuntimeError as exc:
        for i, _, _ in posed:
            results[i] = VehicleResult(vid, Status.FAILED, message=f"batch smoothing failed: {summarise_error(exc)}")
        return results, 0
    wireframe = wireframe_from_values(estimate, keys, index)
    hit = optimizer.iterations() >= options.solve.max_iterations
    points = wireframe.vehicle_p_keypoints
    residuals = {i: (obs, _frame_residuals(obs, estimate, keys, index, i, frame_offsets, points))
                 for _, i, obs, frame_offsets in projections}
    if camera_factors is None:  # the cameras' own scales over the piece's frames, where they differ that much
        factors = _camera_factors(residuals.values())
        if factors is not None:
            again, suspect_again = _smooth_piece(vid, index, cameras, options, model, prior, bounds, piece, factors,
                                                 hints)
            for result in again.values():
                if result.ok:
                    result.extras["camera_noise_factors"] = factors
            return again, suspect_again
    fits = {i: _fit_scale(r) for i, (_, r) in residuals.items()}
    own = {i: first.extras.get("fit_noise_scale") for (i, _), first in zip(frames, firsts)
           if first is not None and first.ok}  # against the nominal sigmas; the track's fits at scale times them
    suspect = sum(bool(own.get(i)) and own[i] < POOR_FIT_SCALE and fits[i] * scale >= POOR_FIT_SCALE * own[i]
                  for i in fits)
    for i, _, key in posed:
        pose = estimate.atPose3(key)
        covariance = None
        if marginals:  # with the cameras' declared extrinsic errors, from the frame's observations
            covariance = marginals.marginalCovariance(key)
            if i in residuals:
                covariance = covariance + _extrinsic_term(residuals[i][0], pose, wireframe, options)
        results[i] = VehicleResult(
            vid, Status.MAX_ITERATIONS if hit else Status.CONVERGED, world_T_vehicle=pose,
            wireframe=wireframe, pose_covariance=covariance,
            iterations=optimizer.iterations(), final_error=graph.error(estimate),
            body_type=body_type, body_type_probability=probability,
            box=_box(pose, wireframe, body_type, options.solve.box_model))
        results[i].extras["noise_scale"] = scale
        results[i].extras["fit_noise_scale"] = fits[i]
        if hub is not None:  # the wheel radius the track's poses share
            results[i].extras["hub_height"] = float(estimate.atVector(hub)[0])
        if i in swaps:
            results[i].extras["swapped_keypoints"] = swaps[i]
        if marginals:
            results[i].extras["covariance"] = "smoothed"
        if i in residuals:
            odd = _cameras_at_odds(*residuals[i], scale, camera_factors)
            if odd:
                results[i].extras["camera_fit_noise_scale"] = odd
                results[i].message = "; ".join(
                    f"the keypoints of camera {name!r} fit the track {fit:.2g} times worse than their sigmas, the "
                    "other cameras' within them: its detection there is another vehicle's (a 2D tracker's id "
                    "swap) or mostly outliers"
                    for name, fit in odd.items())
    return results, suspect


#: A batch-smoothed track's cameras get a noise scale each where their keypoints' scales over the track differ by
#: this factor or more (:func:`_smooth_piece`; the one-frame solve's rule, ``camera_noise_factors``, has far fewer
#: degrees of freedom per camera and asks the F test too).
_CAMERA_SCALE_RATIO = 3.0
#: ... and each such camera has at least this many keypoints over the track.
_CAMERA_SCALE_MIN_KEYPOINTS = 20
#: A young track whose frames' own solves are of both kinds (a bus some took for a smaller vehicle) is solved as
#: each; the kind its frames' choices weigh more for is kept unless the other's solution fits its keypoints better
#: than this share of its fit (library_bus_tracks_2cam seeds 0-2, looked at: the buses' fits 0.72 and 0.79 of the
#: vans' on seeds 1-2, whose frames weighed for a van on seed 1; 1.01 on seed 0).
_KIND_FIT_SHARE = 0.9
#: A young track's re-solve gives its cameras their own factors only where their scales lie that far apart in at
#: least this share of its frames (:func:`_camera_factors`): over a few frames, a camera's keypoints of another
#: vehicle in three of them would otherwise pass for a camera of its own noise level (tests/test_track.py).
_YOUNG_CAMERA_FRAME_SHARE = 0.8


def _track_scaled(obs: KeypointObservations, noise_scale: float, camera_factors: dict | None) -> KeypointObservations:
    """A track's keypoints at its sigmas: each camera's times its own factor (where the track has them), all times
    the track's noise scale (above the calibrated ones)."""
    return obs.camera_scaled(camera_factors).scaled_above_calibrated(noise_scale)


def _camera_factors(frames, frame_share: float = 0.0) -> dict[str, float] | None:
    """Camera name -> its noise factor over frames of ``(observations, whitened residuals)`` at a track's sigmas
    (its fit scale over the pooled one), where the cameras' fit scales (:func:`_camera_fit_scales`) lie
    :data:`_CAMERA_SCALE_RATIO` or more apart, and, with ``frame_share``, where they do in at least that share of
    the frames in which each of those cameras has 4 keypoints or more (a camera's scale that is its own, not a few
    frames' gross errors); else None. Batch smoothing (:func:`_smooth_piece`, over a whole track) and a young
    track's re-solve (:meth:`Tracker._solved_young`, over its first frames: :data:`_YOUNG_CAMERA_FRAME_SHARE`) take
    it."""
    frames = list(frames)
    own = _camera_fit_scales(frames)
    if len(own) < 2 or max(own.values()) < _CAMERA_SCALE_RATIO * min(own.values()):
        return None
    if frame_share > 0:
        low, high = min(own, key=own.get), max(own, key=own.get)
        apart = []
        for obs, residuals in frames:
            fit = _frame_camera_fits(obs, residuals)
            if low in fit and high in fit:
                apart.append(fit[high] >= _CAMERA_SCALE_RATIO * fit[low])
        if not apart or np.mean(apart) < frame_share:
            return None
    pooled = _fit_scale(np.concatenate([r for _, r in frames]))
    return {name: fit / pooled for name, fit in own.items()}


def _camera_fit_scales(frames) -> dict[str, float]:
    """Camera name -> the scale of its whitened residuals over frames of ``(observations, residuals)``
    (:func:`_fit_scale`), for the cameras with at least :data:`_CAMERA_SCALE_MIN_KEYPOINTS` keypoints."""
    rows: dict[str, list] = {}
    for obs, residuals in frames:
        for c, camera in enumerate(obs.cameras):
            mine = residuals[obs.camera_index == c]
            if len(mine):
                rows.setdefault(camera.name, []).append(mine)
    stacked = {name: np.concatenate(parts) for name, parts in rows.items()}
    return {name: _fit_scale(r) for name, r in stacked.items() if len(r) >= _CAMERA_SCALE_MIN_KEYPOINTS}


def _frame_camera_fits(obs: KeypointObservations, residuals: np.ndarray) -> dict[str, float]:
    """Camera name -> :func:`_fit_scale` of its keypoints' whitened ``residuals`` in one frame, for the cameras with
    at least 4 of them."""
    fits = {}
    for c, camera in enumerate(obs.cameras):
        rows = obs.camera_index == c
        if rows.sum() >= 4:
            fits[camera.name] = _fit_scale(residuals[rows])
    return fits


def _cameras_at_odds(obs: KeypointObservations, residuals: np.ndarray, scale: float,
                     camera_factors: dict | None = None) -> dict[str, float]:
    """The cameras (name -> fit) whose keypoints of a frame fit a smoothed track at least
    :data:`~vfactor.solve.POOR_FIT_SCALE` times worse than their nominal sigmas while another camera's fit within
    them (its keypoints at least 4; ``residuals`` whitened at the track's sigmas, ``scale`` times the nominal ones,
    and each camera's ``camera_factors`` where the track has them):
    a 2D tracker that gave one camera's detections of another vehicle this id (a user's audit: 11 frames whose one
    camera fit 10-83 times worse, all `converged` without a word while the robust loss outvoted that camera)."""
    fit = {name: f * scale * (camera_factors or {}).get(name, 1.0)
           for name, f in _frame_camera_fits(obs, residuals).items()}
    if not any(f < POOR_FIT_SCALE for f in fit.values()):
        return {}
    return {name: f for name, f in fit.items() if f >= POOR_FIT_SCALE}


def _frame_residuals(obs: KeypointObservations, values: gtsam.Values, keys: KeyScheme, index: int, frame: int,
                     offsets: dict[str, int], points: np.ndarray) -> np.ndarray:
    """(n, 2) whitened residuals of a frame's keypoints at a track's pose of that frame in ``values`` and its shape
    ``points``, each camera's through its detector offset (in ``values``) where ``offsets`` names one, as the
    track's projection factors take them."""
    world_T_vehicle = values.atPose3(keys.pose_key(index, frame))
    residuals = whitened_residuals(obs, world_T_vehicle, points)
    for c, camera in enumerate(obs.cameras):  # a camera's detector offset moves the vehicle as its factor does
        rows = obs.camera_index == c
        if camera.name in offsets and rows.any():
            residuals[rows] = whitened_residuals(
                obs.subset(rows), world_T_vehicle.compose(values.atPose3(offsets[camera.name])), points)
    return residuals


def _fit_scale(residuals: np.ndarray) -> float:
    """How many times worse than their sigmas keypoints fit: :func:`~vfactor.shape_evidence.median_scale` of their
    whitened residuals' squares, the one-frame solve's ``fit_noise_scale`` without its leverages (a track's frames
    share the shape, so each frame's own leverage is small); 0 without any."""
    if not len(residuals):
        return 0.0
    return median_scale(np.sum(residuals ** 2, axis=1))


def _smoother_graph(smoother) -> gtsam.NonlinearFactorGraph:
    """A smoother's factors (the marginals of the poses it let go included) as one graph, for LM or a restart."""
    factors = smoother.getFactors()
    graph = gtsam.NonlinearFactorGraph()
    for j in range(factors.size()):
        if factors.at(j) is not None:
            graph.add(factors.at(j))
    return graph


def _covariance_graph(factors: list, projections: list, estimate: gtsam.Values, keys: KeyScheme, index: int,
                      config: GraphConfig) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """The graph whose marginals are a track's covariances, and the values to take them at: its factors but the
    keypoints', each frame's keypoints as least squares on its inliers (docs/factors.md, "Covariances of tracks"),
    as the one-frame solve's covariances take them, and each camera's detector error considered where the track
    does not estimate it.

    * **Inliers at full weight.** The robust loss's Gauss-Newton information down-weights every keypoint by its
      residual, inliers too (the Cauchy loss gives one 1.5 sigmas off 63 % of its information), so the marginals of
      the solved graph are too wide where the keypoints are good. Here each frame's projection factors are replaced by
      factors without the loss on its observations whose whitened residual's square at ``estimate`` is within
      :data:`~vfactor.solve.INLIER_BOUND` (at the track's noise scale, which the observations carry); the motion,
      ground-plane, hub-height, shape, HWC and offset factors stay.
    * **The cameras' offsets considered.** A camera whose detections carry a ``shape_sigma`` and that has no
      detector offset of its own in the track (``TrackOptions.detector_offsets`` off, as without a road plane)
      repeats its error in every frame all the same; the track's estimate does without the offset, its covariances
      do not: that camera's keypoints move through an offset variable at the identity with the offset prior
      (:func:`vfactor.graph.detector_offset_prior`, tied to the track's common offset where it has one), added to
      the returned values only ("consider" parameters: the estimate stays that of the graph without them).

    Args:
        factors: the solved track graph's factors without its projection factors.
        projections: per frame, ``(frame index, its observations (as in the solved graph), camera name ->
            detector offset key)``.
        estimate: the solution.
        index: the track's vehicle index in ``keys``.

    Returns:
        (the graph, the values to take its marginals at: ``estimate``, with the considered offsets at the identity
        where there are any).
    """
    out = gtsam.NonlinearFactorGraph()
    for factor in factors:
        out.add(factor)
    values = estimate  # copied when a considered offset is first added
    least_squares = dataclasses.replace(config, loss=RobustLoss("none"))
    points = wireframe_from_values(estimate, keys, index).vehicle_p_keypoints
    considered: dict[str, int] = {}
    for frame, obs, offsets in projections:
        offsets = dict(offsets)
        common = offsets.get(COMMON_OFFSET)
        for name, sigma in _unestimated_offsets(obs, offsets).items():
            if name not in considered:  # numbered from the top: the track numbers its own offsets from 0
                considered[name] = keys.offset_key(index, keys.frame_stride - 1 - len(considered))
                if values is estimate:
                    values = gtsam.Values(estimate)
                values.insert(considered[name], gtsam.Pose3())
                out.add(detector_offset_prior(considered[name], sigma, points, common,
                                              config.shape_sigma_size_exponent))
            offsets[name] = considered[name]
        residuals = _frame_residuals(obs, values, keys, index, frame, offsets, points)
        inlier = np.sum(residuals ** 2, axis=1) < INLIER_BOUND
        if inlier.any():
            add_observation_factor(out, keys, obs.subset(inlier), index, frame, least_squares, offsets)
    return out, values


def _box(world_T_vehicle: gtsam.Pose3, wireframe: Wireframe, body_type: str | None, model=None):
    """A track's box, without sigmas (the tracker keeps the poses' covariances only), with the box ``model``
    (``SolveOptions.box_model``; None: the default one)."""
    return vehicle_box(world_T_vehicle, wireframe, None, {body_type: 1.0} if body_type else None, model)
