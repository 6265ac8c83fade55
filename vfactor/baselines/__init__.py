"""Simple baselines to compare the factor graph with, on the same observations.

* :func:`triangulation` — multi-view triangulation of each keypoint; the pose
  by aligning the mean wireframe to the triangulated points.
* :func:`cpo` — the paper's Cross Projection Optimisation with the
  Hierarchical Wireframe Constraint, as written (docs/baselines.md).
* :func:`stereo` — the paper's stereo: two-view triangulation.
* :func:`pnp` — one view, the mean wireframe, the best camera.
* :func:`single_view` — one view with a deformable shape (Pavlakos et al.).
* :func:`known_shape` — the reference: the true wireframe given, only the pose
  solved (from the true pose, with the same robust loss); the best one can hope
  for at a given noise.
"""

from vfactor.baselines.cpo import CpoOptions, cpo
from vfactor.baselines.known_shape import known_shape
from vfactor.baselines.pnp import pnp
from vfactor.baselines.single_view import SingleViewOptions, single_view
from vfactor.baselines.stereo import stereo
from vfactor.baselines.triangulation import triangulation

__all__ = ["triangulation", "known_shape", "cpo", "CpoOptions", "stereo", "pnp", "single_view", "SingleViewOptions"]
