"""The default models shipped built (vfactor.prebuilt): current, equal to what the code builds, never served stale."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest

from vfactor import prebuilt
from vfactor.box import default_box_model
from vfactor.shape_model import _shape_model, default_hwc_bounds, default_shape_model, pascal3d_wireframes
from vfactor.vehicle_library import vehicle_library
from vfactor.wireframe import Wireframe


_RTOL, _ATOL = 1e-12, 1e-15  # a few ulps of the models' metres and square metres


def _same(a, b, where="") -> None:
    """Asserts that two models are equal: arrays to the last few bits, dataclasses and containers field by field.

    Not bit for bit: NumPy's OpenBLAS picks its kernels by the CPU (``DYNAMIC_ARCH``), so the same build on
    another machine differs in the last bit (a 1e-16 relative difference in 48 of a prior covariance's 1296 entries
    was seen); a stale model differs by many orders more.
    """
    if isinstance(a, Wireframe):
        np.testing.assert_allclose(a.vehicle_p_keypoints, b.vehicle_p_keypoints, rtol=_RTOL, atol=_ATOL, err_msg=where)
    elif dataclasses.is_dataclass(a):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            if not f.name.startswith("_"):  # private fields are caches that solves fill (ShapeModel._variants)
                _same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, dict):
        assert list(a) == list(b), where
        for key in a:
            _same(a[key], b[key], f"{where}[{key!r}]")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray) and a.dtype.kind == "f":
        np.testing.assert_allclose(a, b, rtol=_RTOL, atol=_ATOL, err_msg=where)
    elif isinstance(a, np.ndarray):
        np.testing.assert_array_equal(a, b, err_msg=where)
    elif isinstance(a, float):
        assert a == pytest.approx(b, rel=_RTOL, abs=_ATOL), where
    else:
        assert a == b, where


def test_the_shipped_file_is_that_of_the_sources():
    payload = pickle.loads(prebuilt.PATH.read_bytes())
    assert payload["digest"] == prebuilt.source_digest(), (
        "vfactor/data/prebuilt_models.pickle is stale: run `python -m vfactor.prebuilt` and commit the file")
    assert set(prebuilt.load()) == {"vehicle_library", "pascal3d_wireframes", "hwc_bounds", "box_model", "shape_model"}


def test_the_shipped_models_equal_what_the_code_builds():
    shipped, built = prebuilt.load(), prebuilt.build()
    for name in built:
        _same(shipped[name], built[name], name)
    model = shipped["shape_model"]  # the priors' Cholesky factors travel with them
    assert all("_evidence_terms" in p.__dict__ for p in (*model.types.values(), model.pooled))


def test_the_default_models_come_from_the_file():
    for cached in (vehicle_library, pascal3d_wireframes, default_hwc_bounds, default_box_model, _shape_model):
        cached.cache_clear()
    try:
        shipped = prebuilt.load()
        assert vehicle_library() is shipped["vehicle_library"]
        assert pascal3d_wireframes() is shipped["pascal3d_wireframes"]
        assert default_hwc_bounds() is shipped["hwc_bounds"]
        assert default_box_model() is shipped["box_model"]
        assert default_shape_model() is shipped["shape_model"]
        # a held-out model is built, not shipped
        held_out = default_shape_model(frozenset({next(iter(vehicle_library()))}))
        assert held_out is not shipped["shape_model"] and held_out.bounds is not shipped["hwc_bounds"]
    finally:
        for cached in (vehicle_library, pascal3d_wireframes, default_hwc_bounds, default_box_model, _shape_model):
            cached.cache_clear()


@pytest.mark.parametrize("content", ["stale", "garbage"])
def test_a_stale_or_unreadable_file_is_not_used(tmp_path, monkeypatch, content):
    path = tmp_path / "prebuilt_models.pickle"
    if content == "stale":
        path.write_bytes(pickle.dumps({"digest": "0" * 64, "models": {"vehicle_library": {"not": "it"}}}))
    else:
        path.write_bytes(b"not a pickle")
    monkeypatch.setattr(prebuilt, "PATH", path)
    prebuilt.load.cache_clear()
    vehicle_library.cache_clear()
    try:
        assert prebuilt.load() == {} and prebuilt.get("vehicle_library") is None
        library = vehicle_library()
        assert "not" not in library and len(library) == len(prebuilt.build()["vehicle_library"])
    finally:
        monkeypatch.undo()
        prebuilt.load.cache_clear()
        vehicle_library.cache_clear()
