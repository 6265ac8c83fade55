"""Scale-out: the batch commands' independent units of work on Dask distributed (docs/scaling.md).

:class:`InProcess` runs them in this process (the default; no Dask needed),
:class:`DaskEngine` on a local or remote ``dask.distributed`` cluster, with the
same results. :func:`~vfactor.solve.solve_scene`, :func:`~vfactor.track.track_scene`
and :func:`~vfactor.track.smooth_scene` take an ``engine``; ``vfactor solve`` and
``vfactor track`` build one from ``--workers N`` or ``--scheduler ADDRESS``.
"""

from vfactor.parallel.engine import DaskEngine, Engine, InProcess, check_engine_options, open_engine, warm_up

__all__ = ["Engine", "InProcess", "DaskEngine", "open_engine", "check_engine_options", "warm_up"]
