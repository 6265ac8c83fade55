"""Statistics of vehicle shapes: shape priors, the body-type shape model and the HWC bounds.

* :func:`default_shape_prior`: the paper's car prior, learnt from the nine
  PASCAL3D+ car CAD models scaled to metres by a wheelbase (the baselines use it).
* :class:`ShapeModel` / :func:`default_shape_model`: one Gaussian prior per body
  type (sedan, hatchback, estate, SUV, pickup, van, bus) and a pooled prior over
  the light vehicles (all but the bus), learnt from the vehicle library (:mod:`vfactor.vehicle_library`),
  optionally without some vehicles (leave-one-model-out evaluation). The solver
  picks the body type by its Laplace evidence (:meth:`ShapeModel.type_log_evidence`).
* :func:`default_hwc_bounds`: bounds spanning every library vehicle, the
  PASCAL3D+ cars and the presets, widened: HWC says what is physically a
  vehicle, not what a car looks like.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from itertools import combinations

import numpy as np

from vfactor import prebuilt
from vfactor._kernels import log_evidence_kernel
from vfactor.errors import InputError
from vfactor.jsonio import is_number
from vfactor.stats import chi2_quantile
from vfactor.keypoints import LAYERS
from vfactor.wireframe import PRESETS, Wireframe, pascal3d_shapes, symmetrised

__all__ = ["ShapePrior", "ShapeModel", "HwcBounds", "default_shape_prior", "default_shape_model", "default_hwc_bounds",
           "car_hwc_bounds", "resolve_shape_prior", "pascal3d_wireframes", "PASCAL3D_WHEELBASE", "DISTANCE_PAIRS",
           "CLASS_HINTS", "ANY", "HEAVY_PRIOR_WEIGHT"]

#: All 66 keypoint pairs (i < j) whose distance the HWC distance factor bounds.
DISTANCE_PAIRS: np.ndarray = np.array(list(combinations(range(12), 2)))
DISTANCE_PAIRS.setflags(write=False)


@dataclass(frozen=True)
class ShapePrior:
    """Gaussian prior on the 36 body-frame keypoint coordinates (metres).

    Attributes:
        mean: (12, 3) mean shape, exactly left/right symmetric.
        covariance: (36, 36) covariance of the flattened shape (row-major
            ``[x0, y0, z0, x1, ...]``), positive definite.
        hub_height: the wheel radius of such vehicles, metres: where a road plane is given, the ground-plane
            factor holds the hubs this far above it (:func:`vfactor.graph.hub_height`; None:
            :data:`vfactor.graph.DEFAULT_HUB_HEIGHT`; a ``GraphConfig.hub_height`` the user sets overrides it).
            The default model's is each body type's mean over the library (a bus's hubs are 0.48 m up, a
            hatchback's 0.32 m).
    """

    mean: np.ndarray
    covariance: np.ndarray
    hub_height: float | None = None

    def __post_init__(self):
        """Read-only float copies (a prior is shared by every solve that uses it), checked.

        Raises:
            InputError: (field ``ShapePrior.mean``, ``ShapePrior.covariance`` or ``ShapePrior.hub_height``) not
                numbers of that shape, not finite, a covariance that is not symmetric positive definite, a hub
                height that is not a number > 0.
        """
        if self.hub_height is not None:
            if not _finite_number(self.hub_height) or self.hub_height <= 0:
                raise InputError("ShapePrior.hub_height", f"expected a number of metres > 0 or None, got "
                                                          f"{self.hub_height!r}")
            object.__setattr__(self, "hub_height", float(self.hub_height))
        for name, shape in (("mean", (12, 3)), ("covariance", (36, 36))):
            field_name = f"ShapePrior.{name}"
            try:
                value = np.array(getattr(self, name), dtype=float)
            except (TypeError, ValueError):
                raise InputError(field_name, f"expected {shape} numbers (metres), got "
                                             f"{type(getattr(self, name)).__name__}") from None
            if value.size != np.prod(shape):
                raise InputError(field_name, f"expected {shape} numbers (metres), got shape {value.shape}")
            value = value.reshape(shape)
            if not np.all(np.isfinite(value)):
                raise InputError(field_name, "expected finite numbers, got NaN or infinity")
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        cov = self.covariance
        if np.abs(cov - cov.T).max() > 1e-9 * np.abs(cov).max():
            raise InputError("ShapePrior.covariance", "expected a symmetric matrix")
        try:
            np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            raise InputError("ShapePrior.covariance", "expected a positive-definite matrix (every direction of the "
                                                      "shape some variance: add a floor, ShapePrior.from_wireframes)"
                             ) from None

    @classmethod
    def trusted(cls, mean: np.ndarray, covariance: np.ndarray, hub_height: float | None = None) -> "ShapePrior":
        """A prior made by vfactor from priors already checked (a type's at another spread, a mixture's moments):
        read-only float copies without the checks of a prior built by hand (a Cholesky factor per solve)."""
        prior = object.__new__(cls)
        object.__setattr__(prior, "hub_height", None if hub_height is None else float(hub_height))
        for name, value, shape in (("mean", mean, (12, 3)), ("covariance", covariance, (36, 36))):
            value = np.array(value, dtype=float).reshape(shape)
            value.setflags(write=False)
            object.__setattr__(prior, name, value)
        return prior

    @classmethod
    def from_wireframes(cls, wireframes, floor_sigma=0.04, inflation: float = 1.5,
                        hub_height: float | None = None) -> "ShapePrior":
        """Mean and covariance of metric shapes, symmetrised.

        ``cov = inflation * S + diag(floor^2)`` with ``S`` the sample covariance
        (``n - 1`` in the denominator): a handful of vehicles spans few
        directions, and a vehicle not among them lies further from their mean
        than they do (the inflation), in every direction a little (the floor).

        Args:
            wireframes: at least two shapes, body frame, metres.
            floor_sigma: standard deviation added to every coordinate, metres: one
                number, or one per keypoint (12,).
            inflation: multiplies the sample covariance.
            hub_height: the prior's :attr:`hub_height` (metres, or None).
        """
        pts = np.array([w.vehicle_p_keypoints for w in wireframes], dtype=float)
        if len(pts) < 2:
            raise ValueError(f"ShapePrior.from_wireframes: expected at least 2 shapes, got {len(pts)}")
        flat = symmetrised(pts).reshape(len(pts), 36)
        mean = flat.mean(0).reshape(12, 3)
        floor = np.repeat(np.broadcast_to(np.asarray(floor_sigma, dtype=float), (12,)), 3)
        return cls(mean=mean, covariance=inflation * np.cov(flat, rowvar=False) + np.diag(floor**2),
                   hub_height=hub_height)

    def __getstate__(self):  # the factors made from it (vfactor.factors.shape_prior) stay in their process
        return {k: v for k, v in self.__dict__.items() if k != "_factors"}

    @property
    def wireframe(self) -> Wireframe:
        return Wireframe(self.mean)

    def evidence_terms(self) -> tuple[np.ndarray, np.ndarray, float, float]:
        """``(P, P mu, mu^T P mu, log|Sigma|)`` with ``P = Sigma^-1`` (computed once; for the Laplace evidence)."""
        cached = self.__dict__.get("_evidence_terms")
        if cached is None:
            R = self.sqrt_information()
            P = R.T @ R
            mu = np.asarray(self.mean).ravel()
            Pmu = P @ mu
            cached = (P, Pmu, float(mu @ Pmu), float(-2 * np.log(np.abs(np.diag(R))).sum()))
            self.__dict__["_evidence_terms"] = cached
        return cached

    def widened(self, spread: float) -> "ShapePrior":
        """This prior with its covariance times ``spread``; its square-root information and evidence terms are this
        one's scaled (``R / sqrt(spread)``, ``P / spread``, ``log|Sigma| + 36 log(spread)``), with no factorisation
        (a body type's wider priors, :meth:`ShapeModel.prior`)."""
        wide = ShapePrior.trusted(self.mean, self.covariance * spread, self.hub_height)
        R = self.sqrt_information() / math.sqrt(spread)
        R.setflags(write=False)
        wide.__dict__["_sqrt_information"] = R
        P, Pmu, quadratic, logdet = self.evidence_terms()
        wide.__dict__["_evidence_terms"] = (P / spread, Pmu / spread, quadratic / spread,
                                            logdet + P.shape[0] * math.log(spread))
        return wide

    def sqrt_information(self) -> np.ndarray:
        """(36, 36) upper-triangular R with ``R^T R = covariance^-1`` (computed once, read-only)."""
        cached = self.__dict__.get("_sqrt_information")
        if cached is None:
            cached = np.linalg.cholesky(np.linalg.inv(self.covariance)).T
            cached.setflags(write=False)
            self.__dict__["_sqrt_information"] = cached
        return cached


@lru_cache(maxsize=32)
def default_shape_prior(
    wheelbase: float = 2.75, wheelbase_sigma: float = 0.20, floor_sigma: float = 0.04,
    exclude: frozenset = frozenset(),
) -> ShapePrior:
    """Mean shape and spread from the nine PASCAL3D+ cars.

    The normalised shapes (wheelbase units) are symmetrised, their mean and
    covariance are scaled by a wheelbase ``s ~ N(wheelbase, wheelbase_sigma^2)``:
    ``cov = E[s^2] cov_n + var(s) mean_n mean_n^T``, and an isotropic floor
    ``floor_sigma^2`` keeps the matrix positive definite (nine samples span at
    most eight directions).

    Args:
        wheelbase: mean wheelbase, metres.
        wheelbase_sigma: standard deviation of the wheelbase, metres.
        floor_sigma: isotropic standard deviation added to every coordinate, metres.
        exclude: ``pascal3d_<index>`` ids of cars left out (the evaluation's ``car_prior`` baseline solves a
            PASCAL3D+ car with the prior of the other eight, as the body-type model is learnt without it).
    """
    shapes = [s for i, s in enumerate(pascal3d_shapes()) if f"pascal3d_{i}" not in exclude]
    if len(shapes) < 2:
        raise ValueError(f"default_shape_prior: exclude leaves {len(shapes)} of the nine cars; at least 2 are needed")
    flat = symmetrised(np.array(shapes)).reshape(-1, 36)
    mean_n = flat.mean(0)
    cov_n = np.cov(flat, rowvar=False)
    second = wheelbase**2 + wheelbase_sigma**2
    cov = second * cov_n + wheelbase_sigma**2 * np.outer(mean_n, mean_n) + floor_sigma**2 * np.eye(36)
    return ShapePrior(mean=wheelbase * mean_n, covariance=cov)


@dataclass(frozen=True)
class HwcBounds:
    """Bounds of the hierarchical wireframe constraint (metres, or ratios).

    Attributes:
        distance: (66, 2) ``[min, max]`` for every pair in :data:`DISTANCE_PAIRS`.
        width_ratio: layer name -> ``(min, max)`` of front width / back width
            (the trapezoid of the light and roof layers).
        layer_offset: layer name -> (2, 2) ``[[x_min, x_max], [z_min, z_max]]``
            of the layer centroid relative to the wheel-layer centroid.
    """

    distance: np.ndarray
    width_ratio: dict
    layer_offset: dict

    @classmethod
    def from_wireframes(cls, wireframes, margin: float = 0.15) -> "HwcBounds":
        """Bounds spanning ``wireframes``, widened by ``margin`` of each range's size (at least 5 cm)."""
        pts = np.array([w.vehicle_p_keypoints for w in wireframes])
        d = np.linalg.norm(pts[:, DISTANCE_PAIRS[:, 0]] - pts[:, DISTANCE_PAIRS[:, 1]], axis=2)
        distance = _widen(d.min(0), d.max(0), margin, 0.05)
        width_ratio, layer_offset = {}, {}
        wheel_centroid = pts[:, list(LAYERS["wheel"])].mean(1)
        for name in ("light", "roof"):
            lf, rf, lb, rb = LAYERS[name]
            ratio = np.linalg.norm(pts[:, lf] - pts[:, rf], axis=1) / np.linalg.norm(pts[:, lb] - pts[:, rb], axis=1)
            lo, hi = _widen(ratio.min(), ratio.max(), margin, 0.05)
            width_ratio[name] = (float(lo), float(hi))
            off = pts[:, list(LAYERS[name])].mean(1) - wheel_centroid
            # (2 axes, [min, max]); until 2026-12-07 stored transposed, which made the x range [x_min, z_min] and
            # the z range [x_max, z_max] (tests/test_vehicle_library.py)
            layer_offset[name] = _widen(off[:, [0, 2]].min(0), off[:, [0, 2]].max(0), margin, 0.10)
        distance.setflags(write=False)
        return cls(distance=distance, width_ratio=width_ratio, layer_offset=layer_offset)


    def spanning(self, wireframes, margin: float = 0.0) -> "HwcBounds":
        """These bounds extended just enough to admit ``wireframes`` too (5 cm on the distances, 0.05 on the width
        ratios, 10 cm on the layer offsets beyond them): a few vehicles far from the sample (a city bus) widen the
        bounds on their side only, where :meth:`from_wireframes`' margin, a share of each range, would also drop
        the other side (a car squashed to a third of its height would pass).

        Args:
            wireframes: the vehicles to admit, body frame, metres.
            margin: their own ranges widened by this share first (:meth:`from_wireframes`), so that a vehicle
                like them but not among them passes too (the library's buses: 0.5, as for the light vehicles).
        """
        other = HwcBounds.from_wireframes(wireframes, margin=margin)

        def union(a, b, pad):
            a, b = np.asarray(a, float), np.asarray(b, float)
            return np.stack([np.minimum(a[..., 0], b[..., 0] - pad), np.maximum(a[..., 1], b[..., 1] + pad)], axis=-1)

        distance = union(self.distance, other.distance, 0.05)
        distance.setflags(write=False)
        width_ratio = {k: tuple(float(x) for x in union(v, other.width_ratio[k], 0.05))
                       for k, v in self.width_ratio.items()}
        layer_offset = {k: union(v, other.layer_offset[k], 0.10) for k, v in self.layer_offset.items()}
        return HwcBounds(distance=distance, width_ratio=width_ratio, layer_offset=layer_offset)


def _widen(lo, hi, margin, minimum):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    pad = np.maximum(margin * (hi - lo), minimum)
    return np.stack([lo - pad, hi + pad], axis=-1)


def _car_wireframes(exclude: frozenset = frozenset()) -> list[Wireframe]:
    """The PASCAL3D+ cars at wheelbases 2.4 and 3.1 m, and the presets; those named in ``exclude`` left out."""
    wireframes = [Wireframe(s * wb) for i, s in enumerate(pascal3d_shapes()) if f"pascal3d_{i}" not in exclude
                  for wb in (2.4, 3.1)]
    return wireframes + [p.wireframe() for name, p in PRESETS.items() if name not in exclude]


@lru_cache(maxsize=64)
@prebuilt.shipped("hwc_bounds")
def default_hwc_bounds(exclude: frozenset = frozenset(), road_extremes: bool = True) -> HwcBounds:
    """HWC bounds spanning every vehicle of the library, the PASCAL3D+ cars at wheelbases 2.4-3.1 m, the presets
    and the road's extremes beyond the library (a microcar, the largest two-axle bus EU rules allow:
    :func:`vfactor.vehicle_library.bounds_vehicles`).

    The ranges of the cars and of the library's light vehicles
    (:data:`~vfactor.vehicle_library.LIGHT_TYPES`) widened by 50 % (at least 5 cm, 10 cm
    for the layer offsets) so that a vehicle outside the sample is still a
    vehicle to HWC, then extended to admit the library's heavy vehicles (buses) and the extremes
    (:meth:`HwcBounds.spanning`: on their own side only).
    HWC says what is physically a vehicle: without the extremes a 12 m bus was
    held to a 7 m shape and solved 1.8 m off, `converged` (docs/vehicles.md).

    Args:
        exclude: library ids and ``pascal3d_<index>`` ids left out (leave-one-model-out evaluation).
        road_extremes: span the road's extremes too (False: the bounds of the cars and the library alone, which the
            simulator's random PASCAL3D+ cars are drawn within, as before 2026-12-07, so that seeds keep their
            scenes).
    """
    from vfactor.vehicle_library import HEAVY_TYPES, LIGHT_TYPES, bounds_vehicles, vehicle_library

    library = [v for v in vehicle_library().values() if v.id not in exclude]
    wireframes = _car_wireframes(exclude) + [v.wireframe for v in library if v.body_type in LIGHT_TYPES]
    bounds = HwcBounds.from_wireframes(wireframes, margin=0.5)
    if not road_extremes:
        return bounds
    heavy = [v.wireframe for v in library if v.body_type in HEAVY_TYPES]
    if heavy:  # the buses, and buses like them
        bounds = bounds.spanning(heavy, margin=0.5)
    return bounds.spanning([v.wireframe for v in bounds_vehicles().values()])


@lru_cache(maxsize=32)
def car_hwc_bounds(exclude: frozenset = frozenset()) -> HwcBounds:
    """The HWC bounds of the paper's car prior: the PASCAL3D+ cars at wheelbases 2.4-3.1 m and the presets, 15 %.

    vfactor's own bounds until issue 10; the paper's CPO + HWC reproduction
    (:mod:`vfactor.baselines.cpo`) and the ``car_prior`` evaluation method keep them. ``exclude``: PASCAL3D+ ids
    (``pascal3d_<index>``) and preset names left out.
    """
    return HwcBounds.from_wireframes(_car_wireframes(exclude), margin=0.15)


#: The component of a :class:`ShapeModel` that is no body type: the pooled prior.
ANY = "any"

#: A 2D detector's class -> the body types it suggests (``"class"`` of a detection):
#: COCO / YOLO names and vfactor's own body types.
CLASS_HINTS: dict[str, tuple[str, ...]] = {
    "car": ("sedan", "hatchback", "estate", "suv"),
    "truck": ("pickup", "van"),
    "bus": ("bus",),
    "sedan": ("sedan",),
    "hatchback": ("hatchback",),
    "estate": ("estate",),
    "wagon": ("estate",),
    "suv": ("suv",),
    "pickup": ("pickup",),
    "van": ("van",),
}


@dataclass(frozen=True)
class ShapeModel:
    """One shape prior per body type, a pooled prior, and the HWC bounds.

    Attributes:
        types: body type -> :class:`ShapePrior` (metres).
        pooled: a broad prior over vehicles of several types together (the first solve's,
            and the mean shape that initialisation aligns; the default model's: the light
            vehicles').
        bounds: the HWC bounds.
        prior_probability: body type -> probability before any observation.
        hint_weight: probability mass that a detection's ``class`` puts on the
            body types it suggests (:data:`CLASS_HINTS`); the rest stays on the
            other types, so a hint is never a hard rule.
        spreads: multipliers of each type's covariance among which the
            evidence chooses too (empirical Bayes on the prior's width): a
            vehicle unlike the library's of its type gets a wider prior rather
            than being pulled to their mean.
        pooled_probability: probability, before any observation, that the vehicle
            is of none of the types (its prior then is :attr:`pooled`, key
            :data:`ANY`): a vehicle unlike every type's vehicles (another
            keypoint convention, a body the library lacks) is held by the broad
            pooled prior instead of a wrong type's.
        class_hints: a 2D detector's class name (lower case) -> the body types it
            suggests (:data:`CLASS_HINTS` by default; a model with a body type of
            its own maps its detector's classes to it: ``{**CLASS_HINTS, "truck":
            ("truck",)}``). A class that names one of :attr:`types` suggests that type.
    """

    types: dict
    pooled: ShapePrior
    bounds: HwcBounds
    prior_probability: dict
    hint_weight: float = 0.8
    spreads: tuple = (1.0, 4.0, 16.0)
    pooled_probability: float = 1.0 / 7.0
    class_hints: dict = field(default_factory=lambda: dict(CLASS_HINTS))
    # caches filled by solves; init=False: a model made by dataclasses.replace starts with its own (it shared the
    # original's and served the original's priors, and wrote its own into the original's)
    _variants: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    _evidence_stack: dict = field(default_factory=dict, init=False, repr=False, compare=False)
    _far: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self):
        """Checks a model built by hand (the one place a user's priors enter the solve).

        Raises:
            InputError: (field ``ShapeModel.<attribute>``, or ``ShapeModel.types[<name>]``) a type that is not a
                :class:`ShapePrior` or has no probability, a probability that is not a finite number >= 0 (or
                all of them 0), no spread or one that is not a finite number > 0, ``hint_weight`` or
                ``pooled_probability`` outside [0, 1), a pooled prior that is not a :class:`ShapePrior`, bounds that
                are not :class:`HwcBounds`, class hints that are not a mapping of names to body types.
        """
        if not isinstance(self.types, dict) or not self.types:
            raise InputError("ShapeModel.types", "expected a dict of body type -> ShapePrior, at least one")
        for name, prior in self.types.items():
            if not isinstance(name, str) or not name or name == ANY:
                raise InputError("ShapeModel.types", f"expected body type names (strings, not {ANY!r}), got {name!r}")
            if not isinstance(prior, ShapePrior):
                raise InputError(f"ShapeModel.types[{name}]", f"expected a ShapePrior, got {type(prior).__name__}")
        if not isinstance(self.pooled, ShapePrior):
            raise InputError("ShapeModel.pooled", f"expected a ShapePrior, got {type(self.pooled).__name__}")
        if not isinstance(self.bounds, HwcBounds):
            raise InputError("ShapeModel.bounds", f"expected HwcBounds, got {type(self.bounds).__name__}")
        probability = self.prior_probability if isinstance(self.prior_probability, dict) else {}
        for name in self.types:
            p = probability.get(name)
            if not _finite_number(p) or p < 0:
                raise InputError(f"ShapeModel.prior_probability[{name}]",
                                 f"expected a number >= 0 for every body type of types, got {p!r}")
        if not sum(probability[t] for t in self.types) > 0:
            raise InputError("ShapeModel.prior_probability", "expected some body type a probability above 0")
        spreads = tuple(self.spreads) if isinstance(self.spreads, (tuple, list)) else ()
        if not spreads or not all(_finite_number(k) and k > 0 for k in spreads):
            raise InputError("ShapeModel.spreads", f"expected one or more numbers > 0, got {self.spreads!r}")
        for name in ("hint_weight", "pooled_probability"):
            value = getattr(self, name)
            if not _finite_number(value) or not 0 <= value < 1:
                raise InputError(f"ShapeModel.{name}", f"expected a number in [0, 1), got {value!r}")
        hints = self.class_hints
        if not isinstance(hints, dict) or not all(
                isinstance(k, str) and isinstance(v, (tuple, list)) and all(isinstance(t, str) for t in v)
                for k, v in hints.items()):
            raise InputError("ShapeModel.class_hints", "expected a dict of class name -> tuple of body types")

    def components(self) -> list[tuple[str, float]]:
        """The (body type, spread) priors the evidence weighs, and ``(ANY, 1.0)``: the pooled prior."""
        typed = [(t, float(k)) for t in self.types for k in self.spreads]
        return typed + [(ANY, 1.0)] if self.pooled_probability > 0 else typed

    def prior(self, body_type: str, spread: float = 1.0) -> ShapePrior:
        """The prior of ``body_type`` (or :data:`ANY`: the pooled prior) with its covariance times ``spread`` (cached)."""
        key = (body_type, float(spread))
        if key not in self._variants:
            base = self.pooled if body_type == ANY else self.types[body_type]
            self._variants[key] = base if spread == 1.0 else base.widened(spread)
        return self._variants[key]

    def far_from_pooled(self, body_type: str) -> bool:
        """Whether ``body_type``'s mean shape lies beyond the pooled prior's 99.9 % region (chi2, 36 dof): a solve
        that starts from the pooled mean shape and prior starts far from such a vehicle (a bus, to the light
        vehicles' pooled prior: squared Mahalanobis distance 1417 against at most 3 for the light types), and
        :func:`vfactor.solve.solve_observations` solves it again from its type's own."""
        if body_type == ANY or body_type not in self.types:
            return False
        if body_type not in self._far:  # once per model and type (36: a shape's 12 x 3 coordinates)
            self._far[body_type] = (_mahalanobis2(self.pooled, Wireframe(self.types[body_type].mean))
                                    > chi2_quantile(36, 0.999))
        return self._far[body_type]

    def suggested_types(self, hints=()) -> tuple[str, ...]:
        """The body types a vehicle's detections' class ``hints`` suggest together (empty: no suggestion).

        Each hint (case and surrounding spaces ignored) suggests the types :attr:`class_hints` maps it to, or the
        type it names; unknown classes and types the model lacks are ignored. However many detections carry them,
        the hints count once: the types every hint suggests, or, where they disagree (``car`` and ``truck``), the
        types any suggests.
        """
        lower = {t.lower(): t for t in self.types}
        sets = []
        for hint in hints:
            name = str(hint).strip().lower()
            named = (lower[name],) if name in lower else self.class_hints.get(name, ())
            suggested = {lower[t.lower()] for t in named if t.lower() in lower}
            if suggested:
                sets.append(suggested)
        if not sets:
            return ()
        common = set.intersection(*sets)
        chosen = common or set.union(*sets)
        return tuple(t for t in self.types if t in chosen)

    def log_prior(self, hints=()) -> dict[str, float]:
        """Body type -> log probability given the detections' class ``hints`` (:meth:`suggested_types`; normalised).

        The suggested types share :attr:`hint_weight` of the probability (in proportion to
        :attr:`prior_probability`), the others the rest: a hint, never a hard rule.
        """
        with np.errstate(divide="ignore"):
            logp = {t: float(np.log(self.prior_probability[t])) for t in self.types}
        suggested = self.suggested_types(hints)
        if suggested and len(suggested) < len(self.types):
            inside = _log_sum([logp[t] for t in suggested])
            outside = _log_sum([logp[t] for t in self.types if t not in suggested])
            for t in self.types:
                logp[t] += (np.log(self.hint_weight) - inside if t in suggested
                            else np.log(1.0 - self.hint_weight) - outside)
        norm = _log_sum(list(logp.values()))
        return {t: float(v - norm) for t, v in logp.items()}

    def type_log_evidence(self, information: np.ndarray, eta: np.ndarray) -> dict[tuple[str, float], float]:
        """Log marginal likelihood of the observations under each body type's prior and spread (Laplace), up to a constant.

        The observations (the pose marginalised out) are summarised by a
        Gaussian in the 36 shape coordinates, ``exp(-x^T Lambda x / 2 + eta^T x)``
        (information form; ``Lambda`` may be singular: directions the views do
        not see). With the type's prior ``N(mu, Sigma)``, ``P = Sigma^-1``::

            log p(z | type) = -1/2 [mu^T P mu - b^T (Lambda + P)^-1 b + log|Sigma| + log|Lambda + P|] + c,
            b = eta + P mu

        with ``c`` the same for every type (docs/factors.md).

        Args:
            information: (36, 36) ``Lambda``, 1/m^2.
            eta: (36,) information vector, 1/m.

        Returns:
            (body type or :data:`ANY`, spread) -> log evidence.
        """
        keys = self.components()
        stacked = self._evidence_stack.get(tuple(keys))  # every component's terms, stacked once per model
        if stacked is None:
            terms = [self.prior(name, spread).evidence_terms() for name, spread in keys]
            stacked = (np.ascontiguousarray(np.stack([t[0] for t in terms])),
                       np.ascontiguousarray(np.stack([t[1] for t in terms])), np.array([t[2] + t[3] for t in terms]))
            self._evidence_stack[tuple(keys)] = stacked
        precisions, precision_means, constants = stacked
        quadratic, logdet_A = np.empty(len(keys)), np.empty(len(keys))
        log_evidence_kernel(np.ascontiguousarray(information, dtype=float), np.ascontiguousarray(eta, dtype=float),
                            precisions, precision_means, quadratic, logdet_A)  # one Cholesky per component, compiled
        if not np.all(np.isfinite(logdet_A)):
            raise np.linalg.LinAlgError("the information plus a prior's precision is not positive definite")
        value = -0.5 * (constants - quadratic + logdet_A)
        return {key: float(v) for key, v in zip(keys, value)}


def _log_sum(values) -> float:
    """``log(sum(exp(values)))``, stably (-inf entries: probability 0)."""
    values = np.asarray(values, dtype=float)
    top = values.max()
    return float(top + np.log(np.exp(values - top).sum())) if np.isfinite(top) else float(top)


def _finite_number(value) -> bool:
    return is_number(value) and math.isfinite(value)


def resolve_shape_prior(prior: "ShapePrior | ShapeModel | None",
                        bounds: HwcBounds | None = None) -> tuple["ShapeModel | None", "ShapePrior | None", HwcBounds]:
    """What a solver's ``prior`` argument means: (the shape model or None, the single prior or None, the bounds).

    ``None`` is :func:`default_shape_model`; a :class:`ShapeModel` is used as it
    is; a :class:`ShapePrior` is that one prior for every vehicle. The bounds
    default to the model's (the default model's with a single prior).
    """
    model = default_shape_model() if prior is None else (prior if isinstance(prior, ShapeModel) else None)
    single = None if model is not None else prior
    return model, single, bounds or (model or default_shape_model()).bounds


#: Wheelbase (metres) at which the PASCAL3D+ car CAD models enter the body-type priors.
PASCAL3D_WHEELBASE = 2.75


@lru_cache(maxsize=1)
@prebuilt.shipped("pascal3d_wireframes")
def pascal3d_wireframes() -> dict[str, Wireframe]:
    """The nine PASCAL3D+ car CAD models at :data:`PASCAL3D_WHEELBASE`, symmetrised, by id ``pascal3d_<index>`` (made once)."""
    out = {}
    for i, shape in enumerate(symmetrised(pascal3d_shapes() * PASCAL3D_WHEELBASE)):
        out[f"pascal3d_{i}"] = Wireframe(shape - shape[list(LAYERS["wheel"])].mean(axis=0))
    return out


#: The default model's prior probability of a heavy body type (a bus) against a light one's: buses are a small
#: share of road traffic (of the order of one vehicle in a hundred); the views' evidence for a bus outweighs this
#: many times over (docs/vehicles.md).
HEAVY_PRIOR_WEIGHT = 0.1

def _mahalanobis2(prior: ShapePrior, wireframe: Wireframe) -> float:
    r = prior.sqrt_information() @ (wireframe.vehicle_p_keypoints.ravel() - np.asarray(prior.mean).ravel())
    return float(r @ r)


@prebuilt.shipped("shape_model")
def default_shape_model(exclude=frozenset(), hub_sigma: float = 0.02, rule_sigma: float = 0.08,
                        inflation: float = 1.5) -> ShapeModel:
    """The body-type shape model learnt from the vehicle library and the PASCAL3D+ cars.

    The light body types are equally likely before the views, a bus :data:`HEAVY_PRIOR_WEIGHT` times as likely as
    one of them; the pooled prior is the light vehicles' (:data:`~vfactor.vehicle_library.LIGHT_TYPES`).

    Each body type's prior is learnt from the library's vehicles of that type
    and from the PASCAL3D+ car CAD models nearest to it (Mahalanobis distance
    to the library-only priors; at :data:`PASCAL3D_WHEELBASE`). The CAD models
    are real car shapes annotated by hand, where the library's lamps and
    window tops are placed by rules (docs/vehicles.md). The library's hubs come
    from published dimensions, the rest from those rules that a real vehicle
    departs from: the priors' floor is ``hub_sigma`` on the hubs and
    ``rule_sigma`` on the other eight keypoints. Each prior's hub height
    (:attr:`ShapePrior.hub_height`) is the mean wheel radius of its library
    vehicles.

    Args:
        exclude: library ids and ``pascal3d_<index>`` ids left out of every
            prior and of the bounds (leave-one-model-out evaluation: the solved
            vehicle is never in the prior).
        hub_sigma, rule_sigma: the floor (:meth:`ShapePrior.from_wireframes`), metres.
        inflation: see :meth:`ShapePrior.from_wireframes`.
    """
    return _shape_model(frozenset(exclude), float(hub_sigma), float(rule_sigma), float(inflation))


@lru_cache(maxsize=128)
def _shape_model(exclude: frozenset, hub_sigma: float, rule_sigma: float, inflation: float) -> ShapeModel:
    """:func:`default_shape_model`, made once per set of arguments."""
    from vfactor.vehicle_library import BODY_TYPES, LIGHT_TYPES, vehicle_library

    floor_sigma = np.array([hub_sigma] * 4 + [rule_sigma] * 8)
    shapes = {t: [] for t in BODY_TYPES}
    radii = {t: [] for t in BODY_TYPES}  # the library's wheel radii (the PASCAL3D+ models give none)
    for v in vehicle_library().values():
        if v.id not in exclude:
            shapes[v.body_type].append(v.wireframe)
            radii[v.body_type].append(v.wheel_radius)
    library_only = {t: ShapePrior.from_wireframes(shapes[t], floor_sigma, inflation) for t in LIGHT_TYPES
                    if len(shapes[t]) >= 2}
    for cad_id, wireframe in pascal3d_wireframes().items():
        if cad_id not in exclude and library_only:
            nearest = min(library_only, key=lambda t: _mahalanobis2(library_only[t], wireframe))
            shapes[nearest].append(wireframe)
    types = {t: ShapePrior.from_wireframes(w, floor_sigma, inflation, float(np.mean(radii[t])) if radii[t] else None)
             for t, w in shapes.items() if len(w) >= 2}
    light_radii = [r for t in LIGHT_TYPES for r in radii[t]]
    pooled = ShapePrior.from_wireframes([w for t in LIGHT_TYPES for w in shapes[t]], floor_sigma, inflation,
                                        float(np.mean(light_radii)) if light_radii else None)
    weight = {t: 1.0 if t in LIGHT_TYPES else HEAVY_PRIOR_WEIGHT for t in types}
    return ShapeModel(types=types, pooled=pooled, bounds=default_hwc_bounds(exclude),
                      prior_probability={t: w / sum(weight.values()) for t, w in weight.items()})
