"""Hypothesis profiles of the fuzzing suite (tests/test_fuzz.py), registered by tests/conftest.py.

* ``vfactor-fuzz`` (default): seeded (``derandomize=True``), a few dozen cases
  per property, so the default test run stays fast and deterministic.
* ``vfactor-fuzz-long`` (``pytest --fuzz-long`` or ``VFACTOR_FUZZ=long``): the
  same properties with :data:`LONG_EXAMPLES` cases each (over 5,000 in all);
  with ``VFACTOR_FUZZ_REPORT=FILE`` the outcomes per category are written to FILE
  (JSON), as summarised in docs/reliability.md.
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

__all__ = ["configure", "examples", "LONG", "LONG_EXAMPLES"]

#: Cases per property in the long profile, by property (sum over 5,000).
LONG_EXAMPLES = {"scene_reader": 1500, "calibration_reader": 1000, "result_reader": 600, "cli_solve": 1500,
                 "cli_track": 500}
DEFAULT_EXAMPLES = {"scene_reader": 150, "calibration_reader": 150, "result_reader": 100, "cli_solve": 60,
                    "cli_track": 15}
LONG = False


def configure(long: bool = False) -> None:
    """Registers both profiles and loads the one asked for (the option or ``VFACTOR_FUZZ=long``)."""
    global LONG
    LONG = long or os.environ.get("VFACTOR_FUZZ", "") == "long"
    common = dict(derandomize=True, deadline=None, database=None, print_blob=True,
                  suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                         HealthCheck.function_scoped_fixture])
    settings.register_profile("vfactor-fuzz", **common)
    settings.register_profile("vfactor-fuzz-long", **common)
    settings.load_profile("vfactor-fuzz-long" if LONG else "vfactor-fuzz")


def examples(name: str) -> settings:
    """The settings of one property: its number of cases in the loaded profile."""
    return settings(max_examples=(LONG_EXAMPLES if LONG else DEFAULT_EXAMPLES)[name])
