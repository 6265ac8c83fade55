"""vfactor's compiled kernels: a C extension built ahead of time from ``kernels/`` (numba.pycc; kernels/build.py).

Each function is the numba function of the same name in ``kernels/``, whose
docstring gives its arguments and units. The arrays are taken as they are:
float64 (int64 for ``keypoint_index`` and ``lens``), of the documented number of
dimensions, any strides; the compiled wrapper checks only the item size.
"""

import numpy as np

__all__ = ["projection_kernel", "robust_cost_kernel", "robust_scale", "truncated_means_kernel", "step_twist_kernel",
           "nonholonomic_kernel", "acceleration_kernel", "ground_plane_kernel", "layer_plane_kernel",
           "trapezoid_kernel", "distance_bounds_kernel", "layer_offset_kernel", "fit_at_scale_kernel",
           "log_evidence_kernel", "symmetric_eigen_kernel", "source_digest"]

def projection_kernel(R: np.ndarray, t: np.ndarray, points: np.ndarray, keypoint_index: np.ndarray, R_cw: np.ndarray,
                      t_cw: np.ndarray, intrinsics: np.ndarray, lens: np.ndarray, dist: np.ndarray, uv: np.ndarray,
                      L: np.ndarray, window: np.ndarray, sigma: np.ndarray, loss_id: int, k: float, min_depth: float,
                      want_jacobians: bool, r_out: np.ndarray, H_pose: np.ndarray, H_shape: np.ndarray) -> None:
    """kernels.projection.projection_kernel."""

def robust_cost_kernel(R: np.ndarray, t: np.ndarray, points: np.ndarray, keypoint_index: np.ndarray, R_cw: np.ndarray,
                       t_cw: np.ndarray, intrinsics: np.ndarray, lens: np.ndarray, dist: np.ndarray, uv: np.ndarray,
                       L: np.ndarray, window: np.ndarray, sigma: np.ndarray, loss_id: int, k: float, min_depth: float,
                       costs: np.ndarray) -> None:
    """kernels.projection.robust_cost_kernel."""

def robust_scale(loss_id: int, k: float, n: float) -> tuple[float, float]:
    """kernels.robust.robust_scale."""

def truncated_means_kernel(mu: np.ndarray, sigma: np.ndarray, lo: np.ndarray, hi: np.ndarray, m: np.ndarray,
                           slope: np.ndarray) -> None:
    """kernels.truncation.truncated_means_kernel."""

def step_twist_kernel(M1: np.ndarray, M2: np.ndarray, want_jacobians: bool, xi: np.ndarray, J1: np.ndarray,
                      J2: np.ndarray) -> None:
    """kernels.motion.step_twist_kernel."""

def nonholonomic_kernel(M1: np.ndarray, M2: np.ndarray, params: np.ndarray, want_jacobians: bool, r: np.ndarray,
                        H1: np.ndarray, H2: np.ndarray) -> None:
    """kernels.motion.nonholonomic_kernel."""

def acceleration_kernel(M0: np.ndarray, M1: np.ndarray, M2: np.ndarray, params: np.ndarray, want_jacobians: bool,
                        r: np.ndarray, H0: np.ndarray, H1: np.ndarray, H2: np.ndarray) -> None:
    """kernels.motion.acceleration_kernel."""

def ground_plane_kernel(M: np.ndarray, params: np.ndarray, want_jacobian: bool, r: np.ndarray, J: np.ndarray) -> None:
    """kernels.ground_plane.ground_plane_kernel."""

def layer_plane_kernel(points: np.ndarray, indices: np.ndarray, sigma_m: float, sigma_rad: float,
                       want_jacobian: bool, r: np.ndarray, J: np.ndarray) -> None:
    """kernels.hwc.layer_plane_kernel."""

def trapezoid_kernel(points: np.ndarray, indices: np.ndarray, lo: np.ndarray, hi: np.ndarray, sigma_rad: float,
                     sigma_ratio: float, want_jacobian: bool, r: np.ndarray, J: np.ndarray) -> None:
    """kernels.hwc.trapezoid_kernel."""

def distance_bounds_kernel(points: np.ndarray, pairs: np.ndarray, lo: np.ndarray, hi: np.ndarray, sigma: float,
                           want_jacobian: bool, r: np.ndarray, J: np.ndarray) -> None:
    """kernels.hwc.distance_bounds_kernel."""

def layer_offset_kernel(points: np.ndarray, indices: np.ndarray, lo: np.ndarray, hi: np.ndarray, sigma: float,
                        want_jacobian: bool, r: np.ndarray, J: np.ndarray) -> None:
    """kernels.hwc.layer_offset_kernel."""

def fit_at_scale_kernel(total: np.ndarray, projection: np.ndarray, total_eta: np.ndarray, projection_eta: np.ndarray,
                        jacobian: np.ndarray, rhs: np.ndarray, w: float, max_leverage: float, q_out: np.ndarray,
                        freedom_out: np.ndarray) -> float:
    """kernels.shape_evidence.fit_at_scale_kernel."""

def log_evidence_kernel(information: np.ndarray, eta: np.ndarray, precisions: np.ndarray, precision_means: np.ndarray,
                        quadratic_out: np.ndarray, logdet_out: np.ndarray) -> None:
    """kernels.shape_evidence.log_evidence_kernel."""

def symmetric_eigen_kernel(A: np.ndarray, w_out: np.ndarray, V_out: np.ndarray) -> int:
    """kernels.linalg.symmetric_eigen_kernel."""

def source_digest() -> int:
    """kernels.source_digest() of the sources this module was built from."""
