"""Fixtures shared by the kinematics tests."""

import numpy as np
import pytest

from kinematics import Planar3RPR


@pytest.fixture
def robot() -> Planar3RPR:
    """The lesson's planar 3-RPR (default geometry)."""
    return Planar3RPR()


@pytest.fixture
def rng() -> np.random.Generator:
    """A fixed-seed generator, so that every test is reproducible."""
    return np.random.default_rng(20240607)
