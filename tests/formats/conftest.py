"""The output-format tests' fixtures (tests/formats/helpers.py)."""

from tests.formats.helpers import known, real  # noqa: F401
