"""Other tools' file formats: importing detections into vfactor scene files (and writing results out).

Modules: :mod:`vfactor.formats.keypoint_sets` (other keypoint definitions mapped to
vfactor's 12) and :mod:`vfactor.formats.coco` (COCO-style keypoint results and
annotation files -> scene).
"""

__all__ = []
