"""Certified tasks on a grid: the safe regions of a robot with three pose coordinates, and sampling in them.

``grid`` certifies the grid and labels its connected safe regions; ``grid_kernels`` draws starts, targets and
circle references in one region (compiled). The sampling box's tasks are in ``envs.kernels.generic``.
"""

__all__ = ["grid", "grid_kernels"]
