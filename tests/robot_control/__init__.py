"""Tests of the baselines: controllers, the planner and its wrappers."""
