"""The output-format tests' fixtures (tests/formats/helpers.py)."""

from tests.formats.helpers import known, real, real_track  # noqa: F401
