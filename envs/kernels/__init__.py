"""Compiled (Numba) kernels of the family: one packed layout, the step over any pose space, and its set-up.

``layout`` holds the offsets of the packed constants; ``generic`` the step, evaluation and certified task
sampling of any robot over work arrays; ``planar`` and ``three`` the same step in registers for three legs on
the planar pose space and for three actuators of any kind; ``linalg`` the small dense linear algebra;
``setup`` the threading layer and NumPy's random streams; ``cache`` keeps Numba's on-disk cache true.
"""

__all__ = ["cache", "generic", "layout", "linalg", "planar", "setup", "three"]
