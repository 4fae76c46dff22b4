"""Batched calls equal stacked single calls, and properties of the math over random poses (Hypothesis)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from kinematics import Planar3RPR

X0 = np.array([0.5, 0.3, 0.1])

Method = Callable[[Planar3RPR, np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, ...]]

#: Every public method, as (robot, q, x, v) → tuple of arrays; v is the wrench or τ where one is taken.
METHODS: dict[str, Method] = {
    "constraints": lambda r, q, x, v: (r.constraints(q, x),),
    "jacobians": lambda r, q, x, v: r.jacobians(q, x),
    "forward_jacobian": lambda r, q, x, v: (r.forward_jacobian(q, x),),
    "inverse_jacobian": lambda r, q, x, v: (r.inverse_jacobian(q, x),),
    "homogeneous_jacobian": lambda r, q, x, v: (r.homogeneous_jacobian(q, x),),
    "inverse_kinematics": lambda r, q, x, v: (r.inverse_kinematics(x),),
    "leg_vectors": lambda r, q, x, v: (r.leg_vectors(x),),
    "platform_points_in_base": lambda r, q, x, v: (r.platform_points_in_base(x),),
    "forward_kinematics": lambda r, q, x, v: tuple(np.asarray(a) for a in vars(r.forward_kinematics(q, x)).values()),
    "instantaneous_dof": lambda r, q, x, v: (np.asarray(r.instantaneous_dof(q, x)),),
    "platform_mobility": lambda r, q, x, v: (np.asarray(r.platform_mobility(q, x)),),
    "actuator_forces": lambda r, q, x, v: (r.actuator_forces(q, x, v),),
    "platform_wrench": lambda r, q, x, v: (r.platform_wrench(q, x, v),),
    "inverse_condition_number": lambda r, q, x, v: (np.asarray(r.inverse_condition_number(q, x)),),
    "raw_condition_number": lambda r, q, x, v: (np.asarray(r.raw_condition_number(q, x)),),
}

#: The arguments each method reads, which set its batch shape.
ARGUMENTS = dict.fromkeys(METHODS, "qx") | {
    "inverse_kinematics": "x",
    "leg_vectors": "x",
    "platform_points_in_base": "x",
    "actuator_forces": "qxv",
    "platform_wrench": "qxv",
}

#: Batch shapes of (q, x, v); ``None`` means a single vector of shape (3,) broadcast against the rest.
LAYOUTS = {
    "N=20 (closed-form 3x3 solves)": ((20,), (20,), (20,)),
    "N=5 (LAPACK solves)": ((5,), (5,), (5,)),
    "q (3,) against x (N, 3)": (None, (20,), (20,)),
    "x (3,) against q (N, 3)": ((20,), None, (20,)),
    "v (3,) against (N, 3)": ((20,), (20,), None),
    "2-D batch (4, 5)": ((4, 5), (4, 5), (4, 5)),
    "2-D broadcast (5,) against (4, 5)": ((5,), (4, 5), (4, 1)),
}


def layout_inputs(
    robot: Planar3RPR, layout: tuple, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q, x, v of the given batch shapes around the regular pose X0, with q close to IK(x)."""
    q_shape, x_shape, v_shape = layout

    def poses(shape: tuple | None) -> np.ndarray:
        if shape is None:
            return X0.copy()
        return X0 + rng.uniform(-1.0, 1.0, (*shape, 3)) * [0.03, 0.03, 0.05]

    q = robot.inverse_kinematics(poses(q_shape))
    x = poses(x_shape) + (0.0 if x_shape is None else rng.normal(size=(*x_shape, 3)) * 1e-3)
    v = rng.normal(size=(3,) if v_shape is None else (*v_shape, 3)) * 10.0
    return q, x, v


def assert_batch_equals_stacked_singles(robot: Planar3RPR, name: str, q, x, v) -> None:
    """method(batch)[k] == method(single k) for every index k of the broadcast batch."""
    method = METHODS[name]
    inputs = dict(zip("qxv", (q, x, v), strict=True))
    batch = np.broadcast_shapes(*(inputs[key].shape[:-1] for key in ARGUMENTS[name]))
    batched = method(robot, q, x, v)
    stacked = {key: np.broadcast_to(inputs[key], (*batch, 3)) for key in ARGUMENTS[name]}
    for index in np.ndindex(*batch):
        # Arguments a method does not read are passed as one arbitrary vector.
        singles = method(robot, *(stacked[k][index] if k in stacked else inputs[k].reshape(-1, 3)[0] for k in "qxv"))
        for got, expected in zip(batched, singles, strict=True):
            assert got.shape == batch + expected.shape
            if expected.dtype.kind in "biu":
                np.testing.assert_array_equal(got[index], expected)
            else:
                atol = 1e-12 * max(1.0, float(np.max(np.abs(expected), initial=0.0)))
                np.testing.assert_allclose(got[index], expected, rtol=1e-9, atol=atol)


@pytest.mark.parametrize("layout", LAYOUTS.values(), ids=list(LAYOUTS))
@pytest.mark.parametrize("name", sorted(METHODS))
def test_batched_equals_stacked_single_results(name, layout, robot, rng):
    """Every public method broadcasts over leading axes exactly like a loop over single calls."""
    q, x, v = layout_inputs(robot, layout, rng)
    assert_batch_equals_stacked_singles(robot, name, q, x, v)


@pytest.mark.parametrize("name", sorted(METHODS))
def test_single_configuration_shapes(name, robot):
    """A single configuration gives unbatched outputs (scalars for the scalar measures)."""
    q = robot.inverse_kinematics(X0)
    outputs = METHODS[name](robot, q, X0, np.ones(3))
    batched = METHODS[name](robot, q[None], X0[None], np.ones((1, 3)))
    for single, one in zip(outputs, batched, strict=True):
        assert one.shape == (1, *single.shape)
        assert single.ndim <= 2


@pytest.mark.parametrize("name", sorted(METHODS))
def test_empty_batch(name, robot):
    """A batch of zero configurations gives empty outputs of the right shape, not an error."""
    q = robot.inverse_kinematics(X0)
    singles = METHODS[name](robot, q, X0, np.ones(3))
    empty = np.empty((0, 3))
    for single, out in zip(singles, METHODS[name](robot, empty, empty, empty), strict=True):
        assert out.shape == (0, *single.shape)


@pytest.mark.parametrize("name", sorted(METHODS))
def test_validate_false_gives_the_same_results(name, robot, rng):
    """The unvalidated fast path computes exactly what the validated path does."""
    q, x, v = layout_inputs(robot, LAYOUTS["N=20 (closed-form 3x3 solves)"], rng)
    checked = METHODS[name](robot, q, x, v)
    unchecked = {
        "constraints": lambda: (robot.constraints(q, x, validate=False),),
        "jacobians": lambda: robot.jacobians(q, x, validate=False),
        "forward_jacobian": lambda: (robot.forward_jacobian(q, x, validate=False),),
        "inverse_jacobian": lambda: (robot.inverse_jacobian(q, x, validate=False),),
        "homogeneous_jacobian": lambda: (robot.homogeneous_jacobian(q, x, validate=False),),
        "inverse_kinematics": lambda: (robot.inverse_kinematics(x, validate=False),),
        "leg_vectors": lambda: (robot.leg_vectors(x, validate=False),),
        "platform_points_in_base": lambda: (robot.platform_points_in_base(x, validate=False),),
        "forward_kinematics": lambda: tuple(
            np.asarray(a) for a in vars(robot.forward_kinematics(q, x, validate=False)).values()
        ),
        "instantaneous_dof": lambda: (np.asarray(robot.instantaneous_dof(q, x, validate=False)),),
        "platform_mobility": lambda: (np.asarray(robot.platform_mobility(q, x, validate=False)),),
        "actuator_forces": lambda: (robot.actuator_forces(q, x, v, validate=False),),
        "platform_wrench": lambda: (robot.platform_wrench(q, x, v, validate=False),),
        "inverse_condition_number": lambda: (np.asarray(robot.inverse_condition_number(q, x, validate=False)),),
        "raw_condition_number": lambda: (np.asarray(robot.raw_condition_number(q, x, validate=False)),),
    }[name]()
    for a, b in zip(checked, unchecked, strict=True):
        np.testing.assert_array_equal(a, b)


# -- properties over random poses (Hypothesis) ------------------------------------------------------

ROBOT = Planar3RPR()

poses = st.tuples(
    st.floats(0.2, 0.8, allow_nan=False),
    st.floats(0.1, 0.6, allow_nan=False),
    st.floats(-1.0, 1.0, allow_nan=False),
).map(np.array)


def assume_regular(x: np.ndarray) -> np.ndarray:
    """Skip near-singular poses (inverse condition number ≤ 1e-3); return q = IK(x)."""
    q = ROBOT.inverse_kinematics(x)
    assume(ROBOT.inverse_condition_number(q, x) > 1e-3)
    return q


@settings(max_examples=400, deadline=None)
@given(x=poses)
def test_constraints_vanish_at_inverse_kinematics(x):
    """Φ(IK(x), x) = 0."""
    q = ROBOT.inverse_kinematics(x)
    np.testing.assert_allclose(ROBOT.constraints(q, x), 0.0, atol=1e-14)


@settings(max_examples=400, deadline=None)
@given(
    x=poses,
    offset=st.tuples(*[st.floats(-1.0, 1.0, allow_nan=False)] * 3).map(np.array),
)
def test_forward_kinematics_inverts_inverse_kinematics(x, offset):
    """FK(IK(x)) from a guess near x returns x (same assembly mode); IK of that gives q back."""
    q = assume_regular(x)
    icn = ROBOT.inverse_condition_number(q, x)
    guess = x + offset * [1e-2, 1e-2, 2e-2] * icn  # closer to the singularity, a closer guess
    result = ROBOT.forward_kinematics(q, guess)
    assert result.converged
    assert result.residual <= 1e-12
    np.testing.assert_allclose(result.x, x, rtol=0, atol=1e-8)
    # |Φ_i| = |L_i(x)² − L_i²| ≤ 1e-12 m² bounds the leg-length error by 1e-12 / (2 L_i).
    np.testing.assert_allclose(ROBOT.inverse_kinematics(result.x), q, rtol=0, atol=1e-12 / q.min())


@settings(max_examples=400, deadline=None)
@given(x=poses)
def test_forward_times_inverse_jacobian_is_identity(x):
    """J_f J_i = I and J_i J_f = I away from singularities."""
    q = assume_regular(x)
    J_f, J_i = ROBOT.forward_jacobian(q, x), ROBOT.inverse_jacobian(q, x)
    atol = 1e-13 / ROBOT.inverse_condition_number(q, x)
    np.testing.assert_allclose(J_f @ J_i, np.eye(3), rtol=0, atol=atol)
    np.testing.assert_allclose(J_i @ J_f, np.eye(3), rtol=0, atol=atol)


@settings(max_examples=400, deadline=None)
@given(x=poses, q_offset=st.tuples(*[st.floats(-0.05, 0.05)] * 3).map(np.array))
def test_inverse_condition_number_is_in_unit_interval(x, q_offset):
    """0 ≤ σ_min/σ_max ≤ 1 for any admissible (q, x), on or off the constraint manifold."""
    q = ROBOT.inverse_kinematics(x) + q_offset
    assume(np.all(q > 0))
    icn = ROBOT.inverse_condition_number(q, x)
    assert 0.0 <= icn <= 1.0
