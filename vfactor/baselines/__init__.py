"""Simple baselines to compare the factor graph with, on the same observations.

* :func:`triangulation` — multi-view triangulation of each keypoint; the pose
  by aligning the mean wireframe to the triangulated points.
* :func:`known_shape` — the reference: the true wireframe given, only the pose
  solved (from the true pose, with the same robust loss); the best one can hope
  for at a given noise.
"""

from vfactor.baselines.known_shape import known_shape
from vfactor.baselines.triangulation import triangulation

__all__ = ["triangulation", "known_shape"]
