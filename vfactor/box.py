"""A vehicle's 3D box from its wireframe and body type, with the standard deviations of its size and heading.

The 12 keypoints do not reach the vehicle's outer surface: the lamps sit
behind its ends and inside its sides, the window tops below its roof, and
the road is a wheel radius below the hubs. The box adds to five features of
the wireframe (body frame, metres) what the vehicle library says lies
beyond them, per body type (:class:`BoxModel`, learnt from
``vfactor/data/vehicle_dimensions.json``):

============  =====================================================  ==========================================
box           feature of the keypoints                               offset (per body type: mean, sigma)
============  =====================================================  ==========================================
length        front lamps' x minus tail lamps' x (means of pairs)    length minus that
width         lamp pairs' left-right spacing (mean of front, back)   width minus that
top (z)       higher of the windshield and rear-window tops' z       roof above it
bottom (z)    the hubs (z = 0)                                       minus the tyre radius
centre x      mid-point of the front and tail lamps' x               overall centre minus that
============  =====================================================  ==========================================

With several body types possible the offsets are the mixture over the
solve's posterior (``body_type_posterior``); a vehicle with none uses all
library vehicles. The sigmas add the keypoints' uncertainty (the joint
marginal of pose and shape, propagated through the linear map from the
keypoints to the box) and the offsets' spread; docs/factors.md gives the
maths. The box frame has the body frame's axes (x forward, y left, z up)
and its origin at the box centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import gtsam
import numpy as np

from vfactor import prebuilt
from vfactor.vehicle_library import BODY_TYPES, VehicleDimensions, vehicle_library
from vfactor.wireframe import Wireframe

__all__ = ["Box", "BoxModel", "OFFSET_NAMES", "MODEL_SIGMA", "box_features", "published_box", "default_box_model",
           "predictive_factor", "vehicle_box"]

#: The offsets of :class:`BoxModel`, in order (metres).
OFFSET_NAMES = ("length", "width", "roof", "tyre_radius", "centre_x")

#: Spread added to each offset's library spread (metres): the library places the lamps and the window tops by
#: one rule per body type (docs/vehicles.md), which real vehicles follow only to a few centimetres.
MODEL_SIGMA = np.array([0.05, 0.03, 0.03, 0.0, 0.03])

# keypoint indices (vfactor.keypoints order)
_FRONT_LIGHTS, _BACK_LIGHTS = (4, 5), (6, 7)
_WINDSHIELD, _REAR_WINDOW = (8, 9), (10, 11)


@dataclass(frozen=True)
class Box:
    """A vehicle's 3D box (the result file's ``box``).

    Attributes:
        world_T_box: pose of the box frame in the world: the body frame's axes, origin at the box centre.
        size: (3,) length, width, height, metres.
        size_sigma: (3,) their standard deviations, metres; None without covariances.
        heading: yaw of the box's x axis from the world x axis about the world z axis, radians in (-pi, pi].
        heading_sigma: its standard deviation, radians; None without covariances.
        centre_sigma: (3,) standard deviations of the box centre along the world x, y, z axes, metres; None
            without covariances.
    """

    world_T_box: gtsam.Pose3
    size: np.ndarray
    size_sigma: np.ndarray | None = None
    heading: float = 0.0
    heading_sigma: float | None = None
    centre_sigma: np.ndarray | None = None


@dataclass(frozen=True)
class BoxModel:
    """The offsets from the wireframe's features to the box, per body type (:data:`OFFSET_NAMES`, metres).

    Attributes:
        mean: body type -> (5,) mean offsets; ``"any"``: over every library vehicle.
        covariance: body type -> (5, 5) their covariance for a vehicle not among those they are learnt from (the
            library's sample covariance times :func:`predictive_factor`, plus :data:`MODEL_SIGMA` squared).
    """

    mean: dict = field(default_factory=dict)
    covariance: dict = field(default_factory=dict)

    def offsets(self, posterior: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Mean and covariance of the offsets under body-type probabilities (None or empty: ``"any"``).

        The mixture's moments: ``mu = sum w_t mu_t``, ``Sigma = sum w_t (Sigma_t + (mu_t - mu)(mu_t - mu)^T)``;
        probabilities of types the model does not know go to ``"any"``.
        """
        weights = {}
        for body_type, w in (posterior or {}).items():
            key = body_type if body_type in self.mean else "any"
            weights[key] = weights.get(key, 0.0) + float(w)
        total = sum(weights.values())
        if not total > 0:
            return self.mean["any"].copy(), self.covariance["any"].copy()
        mu = sum(w / total * self.mean[t] for t, w in weights.items())
        cov = sum(w / total * (self.covariance[t] + np.outer(self.mean[t] - mu, self.mean[t] - mu))
                  for t, w in weights.items())
        return mu, cov


def box_features(vehicle_p_keypoints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The wireframe's five box features (:data:`OFFSET_NAMES` order; the fourth is 0) and their (5, 36) Jacobian.

    Args:
        vehicle_p_keypoints: (12, 3) keypoints in the body frame, metres; the Jacobian is with respect to
            their keypoint-major flattening (the graph's layer order).
    """
    p = np.asarray(vehicle_p_keypoints, dtype=float)
    J = np.zeros((5, 36))

    def mean_of(indices, axis, row, sign=1.0):
        for k in indices:
            J[row, 3 * k + axis] += sign / len(indices)
        return float(np.mean(p[list(indices), axis]))

    front = mean_of(_FRONT_LIGHTS, 0, 0)
    back = mean_of(_BACK_LIGHTS, 0, 0, -1.0)
    J[4] = 0.5 * np.abs(J[0])  # the mid-point: a quarter of each lamp's x
    width = 0.0
    for left, right in (_FRONT_LIGHTS, _BACK_LIGHTS):
        width += 0.5 * (p[left, 1] - p[right, 1])
        J[1, 3 * left + 1] += 0.5
        J[1, 3 * right + 1] -= 0.5
    windshield, rear_window = p[list(_WINDSHIELD), 2].mean(), p[list(_REAR_WINDOW), 2].mean()
    top_pair = _WINDSHIELD if windshield >= rear_window else _REAR_WINDOW
    top = mean_of(top_pair, 2, 2)
    return np.array([front - back, width, top, 0.0, 0.5 * (front + back)]), J


def published_box(dimensions: VehicleDimensions) -> tuple[np.ndarray, np.ndarray]:
    """A library vehicle's true box from its published dimensions: (size (3,), centre (3,) in the body frame), metres.

    The ends at ``+-(wheelbase / 2 + overhang)``, the road a tyre radius below
    the hubs (docs/vehicles.md).
    """
    front, rear = dimensions.overhangs()
    centre = np.array([0.5 * (front - rear), 0.0, 0.5 * dimensions.height - dimensions.wheel_radius])
    return np.array([dimensions.length, dimensions.width, dimensions.height]), centre


@lru_cache(maxsize=16)
@prebuilt.shipped("box_model")
def default_box_model(exclude: frozenset = frozenset()) -> BoxModel:
    """The box offsets learnt from the vehicle library, without the vehicles ``exclude`` (ids).

    Per body type and over all (``"any"``): the mean and covariance of each
    library vehicle's offsets (its published length, width, height, tyre
    radius and overhangs against its keypoints' features), the covariance
    times :func:`predictive_factor` (a vehicle solved is not among them) plus
    :data:`MODEL_SIGMA` squared.
    """
    rows: dict[str, list] = {t: [] for t in BODY_TYPES}
    for vehicle_id, vehicle in vehicle_library().items():
        if vehicle_id in exclude:
            continue
        d = vehicle.dimensions
        features, _ = box_features(vehicle.wireframe.vehicle_p_keypoints)
        (length, width, height), centre = published_box(d)
        r = d.wheel_radius
        rows[d.body_type].append([length - features[0], width - features[1], height - r - features[2], r,
                                  centre[0] - features[4]])
    extra = np.diag(MODEL_SIGMA**2)
    mean, cov = {}, {}
    for key, values in [*rows.items(), ("any", [v for vs in rows.values() for v in vs])]:
        if len(values) < 2:
            continue
        values = np.asarray(values)
        mean[key] = values.mean(axis=0)
        cov[key] = predictive_factor(len(values)) * np.cov(values, rowvar=False) + extra
    return BoxModel(mean, cov)


def predictive_factor(n: int) -> float:
    """What the sample covariance of ``n`` vehicles' offsets is multiplied by to be the covariance of the offsets of
    a vehicle that is not among them: ``(1 + 1 / n)`` for the error of their mean, times ``(n - 1) / (n - 3)``, the
    variance of the Student t with ``n - 1`` degrees of freedom that such a vehicle's offset follows (2, that of 4
    degrees of freedom, for ``n <= 5``). 1.32 (sigmas 1.15x) for the dozen vans of the library, whose roofs sit
    0.10-0.56 m above their window tops."""
    return (1.0 + 1.0 / n) * ((n - 1.0) / (n - 3.0) if n > 5 else 2.0)


def vehicle_box(world_T_vehicle: gtsam.Pose3, wireframe: Wireframe, covariance: np.ndarray | None = None,
                posterior: dict | None = None, model: BoxModel | None = None) -> Box:
    """The box of an estimated vehicle.

    Args:
        world_T_vehicle: its pose.
        wireframe: its shape (body frame, metres).
        covariance: (42, 42) joint covariance of the pose (GTSAM tangent, body frame) and the 36 shape
            coordinates (keypoint-major; wheel, light, roof layers); None: no sigmas.
        posterior: body type -> probability (``VehicleResult.extras["body_type_posterior"]``); None: any type.
        model: the offsets (default :func:`default_box_model`).

    Returns:
        The :class:`Box`; with ``covariance``, its sigmas.
    """
    model = model or default_box_model()
    features, G = box_features(wireframe.vehicle_p_keypoints)
    mu, offset_cov = model.offsets(posterior)
    length, width = features[0] + mu[0], features[1] + mu[1]
    top, bottom = features[2] + mu[2], -mu[3]
    size = np.array([length, width, top - bottom])
    centre = np.array([features[4] + mu[4], 0.0, 0.5 * (top + bottom)])
    world_T_box = world_T_vehicle.compose(gtsam.Pose3(gtsam.Rot3(), centre))
    R = world_T_vehicle.rotation().matrix()
    heading = math.atan2(R[1, 0], R[0, 0])
    if covariance is None:
        return Box(world_T_box, size, heading=heading)
    covariance = np.asarray(covariance, dtype=float)
    if covariance.shape != (42, 42):
        raise ValueError(f"covariance: expected shape (42, 42) (pose and shape), got {covariance.shape}")
    # size and centre (body) as linear maps of [pose (6), shape (36), offsets (5)]
    S = np.zeros((3, 47))
    S[0, 6:42], S[0, 42] = G[0], 1.0
    S[1, 6:42], S[1, 43] = G[1], 1.0
    S[2, 6:42], S[2, 44], S[2, 45] = G[2], 1.0, 1.0
    C = np.zeros((3, 47))  # body-frame centre
    C[0, 6:42], C[0, 46] = G[4], 1.0
    C[2, 6:42], C[2, 44], C[2, 45] = 0.5 * G[2], 0.5, -0.5
    full = np.zeros((47, 47))
    full[:42, :42], full[42:, 42:] = covariance, offset_cov
    # world centre = t + R c: d/d(rotation) = -R [c]x, d/d(translation) = R, d/dc = R (right perturbation)
    W = R @ C
    W[:, :3] += -R @ _skew(centre)
    W[:, 3:6] += R
    # heading: the body x axis moves by R (omega x e_x) = R[:, 1] omega_z - R[:, 2] omega_y
    across = np.array([-math.sin(heading), math.cos(heading), 0.0])
    horizontal = math.hypot(R[0, 0], R[1, 0])
    H = np.zeros(47)
    H[1], H[2] = -(across @ R[:, 2]) / horizontal, (across @ R[:, 1]) / horizontal
    size_sigma = np.sqrt(np.maximum(np.diag(S @ full @ S.T), 0.0))
    centre_sigma = np.sqrt(np.maximum(np.diag(W @ full @ W.T), 0.0))
    heading_sigma = float(math.sqrt(max(H @ full @ H, 0.0)))
    return Box(world_T_box, size, size_sigma, heading, heading_sigma, centre_sigma)


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
