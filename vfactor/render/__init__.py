"""Rendering of vehicles for keypoint-network training data (moderngl, headless EGL).

* :mod:`vfactor.render.mesh`: textured low-poly vehicle meshes built around a
  12-keypoint wireframe, and simple props (NumPy only).
* :mod:`vfactor.render.renderer`: :class:`Renderer` (OpenGL via moderngl) drawing
  vehicles, occluders and the road for a :class:`vfactor.camera.Camera`, with
  exact keypoint annotations (pixels, self-occlusion, occlusion by others).
* :mod:`vfactor.render.dataset`: random surveillance-style training crops,
  ``.npz`` shards, and a held-out split.

Importing this package does not import moderngl; the first :class:`Renderer`
does (``pip install 'vfactor[render]'``). See ``docs/rendering.md``.
"""

from vfactor.render.dataset import (
    HELD_OUT,
    TRAIN,
    RenderedDataset,
    Sample,
    SampleOptions,
    SplitSpec,
    crop_camera,
    load_dataset,
    make_dataset,
    random_training_sample,
    roi_from_box,
    sample_rng,
)
from vfactor.render.mesh import Appearance, Mesh, Part, VehicleGeometry, vehicle_geometry, vehicle_mesh
from vfactor.render.renderer import (
    Ground,
    Light,
    Renderer,
    RenderingUnavailable,
    RenderResult,
    VehicleAnnotation,
    VehicleInstance,
    keypoint_annotations,
)

__all__ = [
    "Appearance",
    "Mesh",
    "Part",
    "VehicleGeometry",
    "vehicle_geometry",
    "vehicle_mesh",
    "Ground",
    "Light",
    "Renderer",
    "RenderingUnavailable",
    "RenderResult",
    "VehicleAnnotation",
    "VehicleInstance",
    "keypoint_annotations",
    "HELD_OUT",
    "TRAIN",
    "RenderedDataset",
    "Sample",
    "SampleOptions",
    "SplitSpec",
    "crop_camera",
    "load_dataset",
    "make_dataset",
    "random_training_sample",
    "roi_from_box",
    "sample_rng",
]
