"""Tests of the kinematics package: Jacobians, assembly modes, singularities, batching, validation."""
