"""Certified tasks: the family's certificate, tasks drawn in the sampling box, and tasks on a certified grid.

``certificate`` holds the safe set every task is certified on (compiled); ``samplers`` draws certified Reach pairs
and Track references in the sampling box (compiled); ``grid`` certifies a grid over the pose bounds of a robot with
three pose coordinates and labels its connected safe regions; ``grid_kernels`` draws starts, targets and circle
references in one region (compiled).
"""

__all__ = ["certificate", "grid", "grid_kernels", "samplers"]
