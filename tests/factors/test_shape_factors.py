"""Symmetry, body frame, shape prior and the nonlinear HWC factors."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from vfactor.factors.body_frame import body_frame_factor
from vfactor.factors.distance_bounds import distance_bounds_term
from vfactor.factors.layer_offset import layer_offset_term
from vfactor.factors.planarity import layer_plane_term
from vfactor.factors.rectangle import rectangle_factor
from vfactor.factors.robust import RobustLoss
from vfactor.factors.shape_prior import shape_prior_factor
from vfactor.factors.shape_terms import evaluate_terms, hinge, shape_terms_factor
from vfactor.factors.symmetry import symmetry_factor
from vfactor.factors.trapezoid import trapezoid_term
from vfactor.graph import GraphConfig, hwc_terms
from vfactor.keys import KeyScheme
from vfactor.shape_model import default_hwc_bounds, default_shape_prior
from vfactor.wireframe import PRESETS, Wireframe

from .contract import FactorContract

KEYS = KeyScheme().layer_keys(0)


def layer_values(wireframe: Wireframe, noise: float = 0.0, rng=None) -> gtsam.Values:
    values = gtsam.Values()
    for key, vec in zip(KEYS, wireframe.layer_vectors().values()):
        values.insert(key, vec + (rng.normal(0, noise, 12) if noise else 0.0))
    return values


class ShapeFactorContract(FactorContract):
    truth = PRESETS["bmw_x5"].wireframe()

    def make_values(self, rng):
        return layer_values(self.truth, 0.15, rng)

    def make_truth_values(self):
        return layer_values(self.truth)


class TestSymmetry(ShapeFactorContract):
    def make_factor(self):
        return symmetry_factor(KEYS[1], sigma=0.01)

    def test_mirror_violation_is_measured_in_metres(self):
        values = self.make_truth_values()
        vec = values.atVector(KEYS[1]).copy()
        vec[1] += 0.02  # left front light 2 cm further left
        values.update(KEYS[1], vec)
        assert np.isclose(self.make_factor().error(values), 0.5 * (0.02 / 0.01) ** 2)


class TestBodyFrame(ShapeFactorContract):
    def make_factor(self):
        return body_frame_factor(KEYS[0])

    def test_shifted_wheels_cost(self):
        shifted = Wireframe(self.truth.vehicle_p_keypoints + [0.1, 0, 0])
        assert self.make_factor().error(layer_values(shifted)) > 1e3


class TestShapePrior(ShapeFactorContract):
    truth = Wireframe(default_shape_prior().mean)

    def make_factor(self):
        return shape_prior_factor(KEYS, default_shape_prior())


class TestShapePriorCauchy(ShapeFactorContract):
    """The heavy-tailed prior: a Cauchy loss on the Mahalanobis norm."""

    truth = Wireframe(default_shape_prior().mean)

    def make_factor(self):
        return shape_prior_factor(KEYS, default_shape_prior(), loss=RobustLoss("cauchy", 3.0))

    def test_error_is_the_loss_of_the_mahalanobis_norm(self):
        prior = default_shape_prior()
        van = PRESETS["van"].wireframe()
        values = layer_values(van)
        d = np.linalg.norm(prior.sqrt_information() @ (van.vehicle_p_keypoints - prior.mean).ravel())
        gaussian = shape_prior_factor(KEYS, prior).error(values)
        assert np.isclose(gaussian, 0.5 * d * d)
        assert np.isclose(self.make_factor().error(values), RobustLoss("cauchy", 3.0).rho(np.array([d]))[0])
        # the van is far outside the cars the prior is learnt from (d^2 about 76): its pull is cut by 1 + d^2 / 9

        def pull(factor):
            A, b = factor.linearize(values).jacobian()
            return np.linalg.norm(A.T @ b)

        ratio = pull(self.make_factor()) / pull(shape_prior_factor(KEYS, prior))
        assert d > 8 and np.isclose(ratio, 1 / (1 + d * d / 9.0))


@pytest.mark.parametrize("name", ["huber", "geman_mcclure"])
def test_robust_shape_prior_jacobians(name):
    from vfactor.testing import check_factor_jacobians

    factor = shape_prior_factor(KEYS, default_shape_prior(), 0.5, RobustLoss(name, 2.0))
    for seed in (0, 1):
        check_factor_jacobians(factor, layer_values(PRESETS["van"].wireframe(), 0.1, np.random.default_rng(seed)))


class TestLayerPlane(ShapeFactorContract):
    def make_factor(self):
        return shape_terms_factor(KEYS, [layer_plane_term()])

    def test_lifting_one_corner_breaks_planarity(self):
        p = self.truth.vehicle_p_keypoints.copy()
        p[11, 2] += 0.1
        assert self.make_factor().error(layer_values(Wireframe(p))) > 1.0


class TestRectangle(ShapeFactorContract):
    def make_factor(self):
        return rectangle_factor(KEYS[0])

    def test_skewed_wheels_cost(self):
        p = self.truth.vehicle_p_keypoints.copy()
        p[0, 0] += 0.1
        assert self.make_factor().error(layer_values(Wireframe(p))) > 1.0


class TestTrapezoid(ShapeFactorContract):
    def make_factor(self):
        return shape_terms_factor(KEYS, [trapezoid_term(default_hwc_bounds().width_ratio)])

    def make_values(self, rng):
        # also outside the width-ratio range, so that the hinge branch is exercised
        p = self.truth.vehicle_p_keypoints.copy()
        p[[4, 5], 1] *= 1.8
        return layer_values(Wireframe(p), 0.1, rng)


class TestDistanceBounds(ShapeFactorContract):
    def make_factor(self):
        return shape_terms_factor(KEYS, [distance_bounds_term(default_hwc_bounds().distance)])

    def make_values(self, rng):
        return layer_values(self.truth.scaled(1.6), 0.1, rng)


class TestLayerOffset(ShapeFactorContract):
    def make_factor(self):
        return shape_terms_factor(KEYS, [layer_offset_term(default_hwc_bounds().layer_offset)])

    def make_values(self, rng):
        p = self.truth.vehicle_p_keypoints.copy()
        p[8:, 2] += 3.0  # roof far too high (above a 4 m coach's: the bounds admit buses)
        return layer_values(Wireframe(p), 0.1, rng)


class TestFusedHwc(ShapeFactorContract):
    def make_factor(self):
        return shape_terms_factor(KEYS, hwc_terms(GraphConfig()))

    def make_values(self, rng):
        return layer_values(self.truth.scaled(1.5), 0.1, rng)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_preset_satisfies_hwc(name):
    points = PRESETS[name].wireframe().vehicle_p_keypoints
    r = evaluate_terms(hwc_terms(GraphConfig()), points)
    assert np.abs(r).max() < 1e-6


def _reference_hwc(points, config, bounds):
    """The four HWC terms as docs/factors.md writes them, in plain NumPy (the oracle of the compiled kernels)."""
    from vfactor.keypoints import LAYER_NAMES, LAYERS
    from vfactor.shape_model import DISTANCE_PAIRS

    def hinge_(q, lo, hi):
        return np.where(q < lo, q - lo, np.where(q > hi, q - hi, 0.0))

    rows = []
    for name in LAYER_NAMES:
        lf, rf, lb, rb = points[list(LAYERS[name])]
        n = np.cross(rb - lf, lb - rf)
        n = n / np.linalg.norm(n)
        rows += [n @ (rf - lf) / config.plane_sigma_m, n[1] / config.plane_sigma_rad]
    for name, (lo, hi) in bounds.width_ratio.items():
        lf, rf, lb, rb = points[list(LAYERS[name])]
        f, b = lf - rf, lb - rb
        rows += list(np.cross(f / np.linalg.norm(f), b / np.linalg.norm(b)) / config.trapezoid_sigma_rad)
        rows.append(hinge_(np.linalg.norm(f) / np.linalg.norm(b), lo, hi) / config.width_ratio_sigma)
    d = np.linalg.norm(points[DISTANCE_PAIRS[:, 0]] - points[DISTANCE_PAIRS[:, 1]], axis=1)
    distance = np.asarray(bounds.distance)
    rows += list(hinge_(d, distance[:, 0], distance[:, 1]) / config.hinge_sigma)
    wheels = points[list(LAYERS["wheel"])].mean(axis=0)
    for name, box in bounds.layer_offset.items():
        offset = (points[list(LAYERS[name])].mean(axis=0) - wheels)[[0, 2]]
        box = np.asarray(box)
        rows += list(hinge_(offset, box[:, 0], box[:, 1]) / config.hinge_sigma)
    return np.array(rows)


def test_the_compiled_hwc_terms_are_the_documented_maths():
    """The HWC terms fill their rows in compiled kernels (kernels/hwc.py); against the formulas of docs/factors.md
    on shapes inside and far outside the bounds, and their Jacobians against central differences."""
    config, bounds = GraphConfig(), default_hwc_bounds()
    terms = hwc_terms(config, bounds)
    rng = np.random.default_rng(3)
    for trial in range(40):
        base = PRESETS[sorted(PRESETS)[trial % len(PRESETS)]].wireframe().vehicle_p_keypoints
        points = base * rng.uniform(0.6, 1.8) + rng.normal(0, (0.02, 0.1, 0.3)[trial % 3], base.shape)
        r = evaluate_terms(terms, points)
        assert np.allclose(r, _reference_hwc(points, config, bounds), rtol=1e-12, atol=1e-12)
        if trial % 3 == 2:
            assert np.abs(r).max() > 1.0  # the bounds' side of the hinges is exercised
        J = np.concatenate([t.jacobian_at(points.ravel()) for t in terms])
        x = points.ravel()

        def at(shift):
            return evaluate_terms(terms, (x + shift).reshape(12, 3))

        numeric = np.stack([(at(h) - at(-h)) / 2e-7 for h in 1e-7 * np.eye(36)], axis=1)
        assert np.allclose(J, numeric, atol=1e-4 * (1 + np.abs(J).max()))
    batched = evaluate_terms(terms, np.stack([base, 1.7 * base]))
    assert batched.shape == (2, 84) and np.allclose(batched[1], evaluate_terms(terms, 1.7 * base))
    with pytest.raises(TypeError, match="real points"):
        terms[0].residual(base + 1e-30j)


def test_a_degenerate_wireframe_gives_nan_rows_not_an_error():
    """The NumPy terms gave NaN for a collapsed layer or coincident points (0 / 0); the first compiled kernels
    raised ZeroDivisionError out of the HWC check and the factor."""
    terms = hwc_terms(GraphConfig(), default_hwc_bounds())
    collapsed = np.zeros((12, 3))
    r = evaluate_terms(terms, collapsed)
    assert np.isnan(r[:14]).all()  # the layers' planes and the trapezoids' directions
    lo = np.asarray(default_hwc_bounds().distance)[:, 0]  # every distance 0: below each positive lower bound
    assert np.allclose(r[14:80], -np.maximum(lo, 0.0) / GraphConfig().hinge_sigma)
    for t in terms:
        t.jacobian_at(collapsed.ravel())
    assert np.isnan(evaluate_terms(terms, np.full((12, 3), np.nan))).all()


def test_a_terms_sigma_must_be_positive():
    bounds = default_hwc_bounds()
    for make, name in (
            (lambda: layer_plane_term(sigma_m=0.0), "layer_plane_term.sigma_m"),
            (lambda: trapezoid_term(bounds.width_ratio, sigma_ratio=-1.0), "trapezoid_term.sigma_ratio"),
            (lambda: distance_bounds_term(bounds.distance, sigma=float("nan")), "distance_bounds_term.sigma"),
            (lambda: layer_offset_term(bounds.layer_offset, sigma="1"), "layer_offset_term.sigma")):
        with pytest.raises(ValueError, match=f"{name}: expected a number > 0"):
            make()


def test_hinge_is_zero_inside_and_linear_outside():
    q = np.array([0.5, 1.0, 1.5, 2.5])
    assert np.allclose(hinge(q, 1.0, 2.0), [-0.5, 0.0, 0.0, 0.5])


def test_a_priors_factor_is_made_once_and_stays_out_of_its_pickle():
    """shape_prior_factor keeps the factor on its prior (a solve builds its graph several times); a pickled prior, as
    Dask sends it to a worker, carries no GTSAM object."""
    import pickle

    from vfactor.shape_model import ShapePrior

    prior = ShapePrior(default_shape_prior().mean, default_shape_prior().covariance)
    first = shape_prior_factor(KEYS, prior, 1.0)
    assert shape_prior_factor(list(KEYS), prior, 1.0) is first
    assert shape_prior_factor(KEYS, prior, 2.0) is not first
    assert shape_prior_factor(KEYS, prior, 1.0, RobustLoss("cauchy", 6.0)) is not first
    copy = pickle.loads(pickle.dumps(prior))
    assert "_factors" not in copy.__dict__
    values = layer_values(PRESETS["bmw_x5"].wireframe())
    assert shape_prior_factor(KEYS, copy, 1.0).error(values) == pytest.approx(first.error(values), rel=1e-12)


def test_the_short_median_is_numpys_to_the_bit():
    from vfactor.shape_evidence import _median

    rng = np.random.default_rng(11)
    for n in range(1, 80):
        q = rng.gamma(1.0, 2.0, n) * 10.0 ** rng.uniform(-6, 6)
        assert _median(q) == float(np.median(q))
    assert np.isnan(_median(np.array([1.0, np.nan, 2.0])))
