"""Actuator kinds of the distance-constraint family: each leg's anchor A_i(q_i) and length ℓ_i(q_i), as arrays."""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from kinematics._validation import FloatArray, as_float_array, check_finite, per_leg

__all__ = ["ACTUATOR_KINDS", "LegActuation", "leg_actuation"]

#: Actuator kinds: extensible leg, rotary crank, linear slider (see ``kinematics.family``).
ACTUATOR_KINDS = ("leg", "crank", "slider")


def _unit_vectors(name: str, value: Any, n: int, d: int) -> FloatArray:
    """A (d,) vector for every leg or an (n, d) array of unit vectors (norm 1 within 1e-9)."""
    arr = as_float_array(name, value)
    if arr.shape == (d,):
        arr = np.broadcast_to(arr, (n, d))
    if arr.shape != (n, d):
        raise ValueError(f"{name} must have shape ({d},) or ({n}, {d}), got shape {arr.shape}")
    check_finite(name, arr)
    norms = np.linalg.norm(arr, axis=-1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > 1e-9)
    if bad.size:
        raise ValueError(f"{name} must be unit vectors: row {bad[0] + 1} has norm {norms[bad[0]]!r}")
    return np.array(arr, dtype=np.float64)


def _readonly(*arrays: FloatArray) -> None:
    for arr in arrays:
        arr.setflags(write=False)


class LegActuation(NamedTuple):
    """Each leg's actuation A_i(q) = B_i + a_i (cos q u_i + sin q v_i) + q e_i, ℓ_i = λ_i q + l_i (read-only arrays).

    Attributes:
        crank_radii: a_i [m] (0 but for cranks), shape (n,).
        u: u_i, where a crank's arm points at q_i = 0 (zero but for cranks), shape (n, d).
        v: v_i, towards which a crank's arm turns (zero but for cranks), shape (n, d).
        rails: e_i of the sliders (zero for other kinds), shape (n, d).
        length_rate: λ_i, 1 for a leg (ℓ_i = q_i) and 0 for other kinds, shape (n,).
        link_lengths: l_i [m] of the cranks and sliders (0 for legs), shape (n,).
        branches: The inverse-kinematics branch, +1 or −1, shape (n,).
        q_description: Human-readable description of q, for error messages.
    """

    crank_radii: FloatArray
    u: FloatArray
    v: FloatArray
    rails: FloatArray
    length_rate: FloatArray
    link_lengths: FloatArray
    branches: FloatArray
    q_description: str


def leg_actuation(
    kinds: tuple[str, ...], d: int, link_lengths: Any, radii: Any, axes: Any, rails: Any, branches: Any
) -> LegActuation:
    """Validate the actuation arguments of ``DistanceConstraintMechanism`` and return them as per-leg arrays.

    Args:
        kinds: The actuator kind of each leg (``ACTUATOR_KINDS``), length n.
        d: Dimension of the points (2 or 3).
        link_lengths: l_i [m] of the crank and slider legs, a number or shape (n,); None if every leg is a leg.
        radii: a_i [m] of the crank legs, a number or shape (n,).
        axes: (u_i, v_i) of the crank legs, orthonormal, shape (2, d) or (n, 2, d); None: x̂, ŷ (planar only).
        rails: e_i of the slider legs, unit, shape (d,) or (n, d).
        branches: +1 or −1 for each leg, or None (+1).

    Returns:
        The actuation; its arrays are read-only.

    Raises:
        ValueError: On a missing or refused argument of the kinds present, naming it.
    """
    n = len(kinds)
    crank = np.array([kind == "crank" for kind in kinds])
    slider = np.array([kind == "slider" for kind in kinds])
    leg = ~(crank | slider)
    crank_radii = np.zeros(n)
    U = np.zeros((n, d))
    V = np.zeros((n, d))
    E = np.zeros((n, d))
    lam = leg.astype(np.float64)  # ℓ_i = λ_i q_i + l_i: λ = 1, l = 0 for a leg
    ell = np.zeros(n)
    branch = np.ones(n)
    if not leg.all():
        if link_lengths is None:
            raise ValueError("link_lengths are required for crank and slider legs")
        lengths = per_leg("link_lengths", link_lengths, n)
        if not (lengths[~leg] > 0).all():
            raise ValueError(f"link_lengths must be > 0 [m], got {lengths.tolist()}")
        ell[~leg] = lengths[~leg]
        if branches is not None:
            signs = per_leg("branches", branches, n)
            if not np.isin(signs, (-1.0, 1.0)).all():
                raise ValueError(f"branches must be +1 or −1, got {signs.tolist()}")
            branch = signs
    if crank.any():
        if radii is None:
            raise ValueError("crank_radii are required for crank legs")
        a = per_leg("crank_radii", radii, n)
        if not (a[crank] > 0).all():
            raise ValueError(f"crank_radii must be > 0 [m], got {a.tolist()}")
        crank_radii[crank] = a[crank]
        if axes is None:
            if d != 2:
                raise ValueError("crank_axes (u_i, v_i) are required for the cranks of a 3-D robot")
            axes = np.eye(2)
        axes_arr = as_float_array("crank_axes", axes)
        if axes_arr.shape == (2, d):
            axes_arr = np.broadcast_to(axes_arr, (n, 2, d))
        if axes_arr.shape != (n, 2, d):
            raise ValueError(f"crank_axes must have shape (2, {d}) or ({n}, 2, {d}), got {axes_arr.shape}")
        u = _unit_vectors("crank_axes u", axes_arr[:, 0], n, d)
        v = _unit_vectors("crank_axes v", axes_arr[:, 1], n, d)
        dots = np.abs(np.einsum("ij,ij->i", u, v))
        if (dots[crank] > 1e-9).any():
            i = int(np.flatnonzero(crank & (dots > 1e-9))[0])
            raise ValueError(f"crank_axes u and v must be orthogonal: leg {i + 1} has u·v = {dots[i]!r}")
        U[crank], V[crank] = u[crank], v[crank]
    if slider.any():
        if rails is None:
            raise ValueError("rails (unit directions e_i) are required for slider legs")
        E[slider] = _unit_vectors("rails", rails, n, d)[slider]
    _readonly(crank_radii, U, V, E, lam, ell, branch)
    names = {"leg": "leg lengths", "crank": "crank angles", "slider": "slider positions"}
    units = {"leg": "[m]", "crank": "[rad]", "slider": "[m]"}
    if len(set(kinds)) == 1:
        description = f"{names[kinds[0]]} (q_1, …, q_{n}) {units[kinds[0]]}"
    else:
        description = (
            "actuator coordinates (" + ", ".join(f"q_{i + 1} {units[kind]}" for i, kind in enumerate(kinds)) + ")"
        )
    return LegActuation(crank_radii, U, V, E, lam, ell, branch, description)
