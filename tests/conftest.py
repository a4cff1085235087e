"""Fixtures shared by the test modules."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def cruise_identification():
    """One :func:`livesweep.identify` of the shipped XV-15 cruise case (every stage), shared."""
    import livesweep

    return livesweep.identify(ROOT / "config" / "xv15_cruise_lateral.toml")
