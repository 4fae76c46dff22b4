"""Compiled (Numba) kernels of the family: one packed layout, the step over any pose space, and its set-up.

``layout`` holds the offsets of the packed constants; ``packing`` packs them; ``pose`` the rotations and
pose-space operations; ``constraints`` Φ, the Jacobians, the kinematics and k over work arrays; ``step`` the
transition and the fused step of any robot; ``evaluation`` its reference, reward and observation; ``modes``
the step's kernel in its other roles (evaluation at rest, transition, assembly, strokes); ``generic`` gathers
the public kernels (with the certificate and the samplers of ``envs.tasks``); ``paths`` the step's operations
on each row path (vectors in registers or in work arrays); ``three`` the algebra of three actuators in
registers; ``dynamics`` the equations of motion (mass matrix, velocity-product and gravity terms, forward
dynamics) on each row path, with the packed inertia of ``dynamics_layout`` (its table and ``pack_inertia``) and
N robots' batches in ``dynamics_batch``; ``linalg`` the small dense linear algebra; ``setup`` the threads,
borrowed arrays and NumPy's random streams; ``cache`` keeps Numba's on-disk cache true.
"""

__all__ = [
    "cache",
    "constraints",
    "dynamics",
    "dynamics_batch",
    "dynamics_layout",
    "evaluation",
    "generic",
    "layout",
    "linalg",
    "modes",
    "packing",
    "paths",
    "pose",
    "setup",
    "step",
    "three",
]
