"""vfactor's factors, one per module (their maths: docs/factors.md).

* :mod:`~vfactor.factors.projection` — keypoint projection (pose and shape against pixels)
* :mod:`~vfactor.factors.symmetry`, :mod:`~vfactor.factors.body_frame`, :mod:`~vfactor.factors.rectangle`,
  :mod:`~vfactor.factors.shape_prior` — native linear shape factors
* :mod:`~vfactor.factors.planarity`, :mod:`~vfactor.factors.trapezoid`, :mod:`~vfactor.factors.distance_bounds`,
  :mod:`~vfactor.factors.layer_offset` — HWC terms, fused by :mod:`~vfactor.factors.shape_terms`
* :mod:`~vfactor.factors.motion`, :mod:`~vfactor.factors.ground_plane` — tracking
"""

__all__: list[str] = []
