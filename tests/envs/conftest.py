"""Fixtures shared by the environment tests."""

from __future__ import annotations

import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)


@pytest.fixture
def rng() -> np.random.Generator:
    """A fixed-seed generator, so that every test is reproducible."""
    return np.random.default_rng(20240607)
