"""The default models built once and shipped, so that a fresh process does not rebuild them on its first solve.

vfactor's default vehicle library, PASCAL3D+ wireframes, HWC bounds, body-type
shape model and box model are fixed functions of the packaged data and of the
code that builds them. Built on a process's first solve they cost about 10 ms,
as much as a warm solve (a new Dask worker or CLI call paid it on its first
vehicle). ``vfactor/data/prebuilt_models.pickle`` holds them built, with the
SHA-256 of every file they are built from (:data:`SOURCES`), each model pickled
on its own. A process loads the file only when that digest is its own files'
digest, and unpickles a model when it first uses it (a solve: the shape and box
models, about 0.2 ms); otherwise, or where a model does not unpickle, it is built
as before, so an edited rule or data file is never served stale, and a NumPy
that cannot read the pickle only costs the 10 ms.

``python -m vfactor.prebuilt`` writes the file; ``tests/test_prebuilt.py``
fails when the shipped file is not the one of the sources, and checks that what
it holds equals what the code builds.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import pickle
from collections.abc import Mapping
from pathlib import Path

__all__ = ["SOURCES", "PATH", "source_digest", "shipped", "build", "write", "load", "get"]

_PACKAGE = Path(__file__).resolve().parent
#: The files the models are built from, relative to the package: a change to any of them makes the shipped file stale.
SOURCES = ("vehicle_library.py", "shape_model.py", "box.py", "wireframe.py", "keypoints.py", "prebuilt.py",
           "data/vehicle_dimensions.json", "data/pascal3d_car_shapes.json")
#: The shipped file.
PATH = _PACKAGE / "data" / "prebuilt_models.pickle"

_building = False  # set while build() runs: the builders then build, whatever the shipped file holds
_BUILDERS: dict = {}  # model name -> its builder, decorated by shipped()


def source_digest() -> str:
    """SHA-256 (hex) of the :data:`SOURCES`, each as ``name NUL bytes NUL``."""
    digest = hashlib.sha256()
    for name in SOURCES:
        digest.update(name.encode() + b"\0" + (_PACKAGE / name).read_bytes() + b"\0")
    return digest.hexdigest()


def shipped(name: str):
    """Decorates the builder of a default model: called with every argument at its default, it returns the shipped
    model ``name`` while the file is current (:func:`get`), and otherwise builds; ``wrapper.build`` is the builder
    itself (:func:`build`)."""
    def decorate(builder):
        signature = inspect.signature(builder)
        defaults = {p: parameter.default for p, parameter in signature.parameters.items()}

        @functools.wraps(builder)
        def wrapper(*args, **kwargs):
            bound = signature.bind(*args, **kwargs)
            bound.apply_defaults()
            if bound.arguments == defaults and (model := get(name)) is not None:
                return model
            return builder(*args, **kwargs)

        wrapper.build = builder
        _BUILDERS[name] = wrapper
        return wrapper

    return decorate


def build() -> dict:
    """Every default model, built from the sources (the priors' Cholesky factors included)."""
    global _building
    import vfactor.box  # noqa: F401  the modules whose builders shipped() decorates
    import vfactor.shape_model  # noqa: F401

    _building = True  # the builders' own code, not the shipped models, also where one builder calls another
    try:
        models = {name: builder.build() for name, builder in _BUILDERS.items()}
    finally:
        _building = False
    model = models["shape_model"]
    for body_type in {body_type for body_type, _ in model.components()}:  # each type's prior with its Cholesky
        model.prior(body_type).evidence_terms()  # factor; the wider ones are derived from it on first use
    for body_type in model.types:  # which types a solve starts again from (a process's first solve paid 1 ms)
        model.far_from_pooled(body_type)
    return models


def write(path: Path | str = PATH) -> Path:
    """Builds the models and writes them, with :func:`source_digest`, to ``path`` (default: the shipped file): each
    model pickled on its own, so that a process unpickles only those it uses (:func:`load`)."""
    path = Path(path)
    models = {name: pickle.dumps(model, protocol=4) for name, model in build().items()}
    path.write_bytes(pickle.dumps({"digest": source_digest(), "models": models}, protocol=4))
    return path


class _Shipped(Mapping):
    """The shipped models by name, each unpickled on first use (a solve uses the shape and box models: unpickling
    the vehicle library too cost 0.6 ms of a fresh process's first solve); a model that does not unpickle is
    missing (its builder builds it)."""

    def __init__(self, pickled: dict):
        self._pickled, self._models = dict(pickled), {}

    def __getitem__(self, name):
        if name not in self._models:
            if name not in self._pickled:
                raise KeyError(name)
            try:
                self._models[name] = pickle.loads(self._pickled[name])
            except Exception:  # noqa: BLE001  any failure to read a model means: build it
                raise KeyError(name) from None
        return self._models[name]

    def __iter__(self):
        return iter(self._pickled)

    def __len__(self):
        return len(self._pickled)


@functools.lru_cache(maxsize=1)
def load() -> Mapping:
    """The shipped models by name (unpickled on first use), or an empty mapping when the file is missing, stale or
    unreadable."""
    try:
        payload = pickle.loads(PATH.read_bytes())
        if payload.get("digest") != source_digest() or not isinstance(payload.get("models"), dict):
            return {}
        return _Shipped(payload["models"])
    except Exception:  # noqa: BLE001  any failure to read the cache means: build the models
        return {}


def get(name: str):
    """The shipped model ``name`` (a key of :func:`build`), or None: then the caller builds it."""
    if _building:
        return None
    return load().get(name)


if __name__ == "__main__":
    # `python -m vfactor.prebuilt` runs a second copy of this module; the builders registered with the one vfactor
    # imported
    from vfactor import prebuilt as _imported

    print(f"wrote {_imported.write()} ({_imported.PATH.stat().st_size} bytes, sources {source_digest()[:12]})")
