"""The classical controllers of the evaluation harness, by command-line name.

They are NumPy only and live in ``envs.controllers`` (the residual wrapper ``envs.PlannerResidualWrapper``
builds on the planner controller); this module is where the training side finds them.
"""

from __future__ import annotations

from envs import controllers as _controllers
from envs.controllers import *  # noqa: F403  (the names of envs.controllers.__all__)

__all__ = list(_controllers.__all__)
