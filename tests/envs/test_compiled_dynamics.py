"""The compiled equations of motion (``envs.kernels.dynamics``) against ``kinematics.dynamics.RobotDynamics``."""

from __future__ import annotations

import functools

import numba
import numpy as np
import pytest

from envs.kernels import dynamics, dynamics_batch
from envs.kernels.dynamics_layout import C_INERTIA_SIZE
from envs.kernels.packing import PLANAR_LEGS, THREE, WORK_ARRAYS, pack_family, row_path
from envs.presets import build_family_params
from kinematics.dynamics import STANDARD_GRAVITY, RobotDynamics, default_inertia

#: Every preset robot and the row path its kernels take.
PRESETS = {
    "planar_3rpr": PLANAR_LEGS,
    "stewart_gough": WORK_ARRAYS,
    "delta": THREE,
    "planar_3rrr": THREE,
    "planar_3prr": THREE,
}
RTOL = 1e-10


@functools.cache
def _robot(name: str):
    """(params, packed constants, packed inertia, reference) of a preset with every inertial term switched on.

    The default inertia moved off its symmetric values: the platform's centre of mass off its origin, a full
    inertia tensor and a tilted gravity (planar robots stand in a vertical plane), so that no term vanishes.
    """
    params = build_family_params(name)
    robot = params.robot
    inertia = default_inertia(robot)
    if robot.pose_space.point_dim == 2:
        inertia = inertia.replace(platform_com=inertia.platform_com + (0.02, -0.01), gravity=(0.3, -STANDARD_GRAVITY))
    else:
        tensor = np.diag([0.3, 0.4, 0.5]) + 0.05 * np.array([[0.0, 1.0, 0.5], [1.0, 0.0, 0.2], [0.5, 0.2, 0.0]])
        inertia = inertia.replace(
            platform_com=(0.01, -0.02, 0.03), platform_inertia=tensor, gravity=(0.5, -0.3, -STANDARD_GRAVITY)
        )
    packed = pack_family(params)
    return params, packed, dynamics.pack_inertia(robot, inertia), RobotDynamics(robot, inertia)


def _states(name: str, count: int, seed: int = 0):
    """``count`` random states (q, x, ẋ, τ) in the preset's task box, each on the robot's own branch."""
    params, _, _, _ = _robot(name)
    robot = params.robot
    rng = np.random.default_rng(seed)
    x = rng.uniform(params.sample_low, params.sample_high, size=(8 * count, robot.n_pose))
    q = robot.inverse_kinematics(x, validate=False)
    reached = np.isfinite(q).all(axis=1)
    x, q = x[reached][:count], q[reached][:count]
    assert len(x) == count, f"{name}: only {len(x)} reachable poses"
    xdot = 0.5 * rng.standard_normal(x.shape)
    tau = 5.0 * rng.standard_normal(q.shape)
    return q, x, xdot, tau


def _close(actual: np.ndarray, expected: np.ndarray, what: str) -> None:
    np.testing.assert_allclose(actual, expected, rtol=RTOL, atol=RTOL * np.abs(expected).max(), err_msg=what)


@pytest.mark.parametrize("name", list(PRESETS))
def test_equations_of_motion_match_the_reference(name):
    """M, c + G and ẍ of every preset equal ``RobotDynamics``'s at random states, on the robot's own path."""
    _, c, ci, reference = _robot(name)
    assert row_path(c) == PRESETS[name]
    q, x, xdot, tau = _states(name, 16)
    _close(dynamics_batch.mass_matrix_batch(c, ci, q, x), reference.mass_matrix(q, x), f"{name}: M")
    _close(dynamics_batch.bias_batch(c, ci, q, x, xdot), reference.bias_forces(q, x, xdot), f"{name}: c + G")
    _close(
        dynamics_batch.forward_dynamics_batch(c, ci, q, x, xdot, tau),
        reference.forward_dynamics(q, x, xdot, tau),
        f"{name}: ẍ",
    )


@pytest.mark.parametrize("name", ["planar_3rpr", "delta", "planar_3prr"])
def test_work_path_matches_the_reference_on_three_actuators(name):
    """The work-array path, written for any pose space, gives the reference's terms for planar and Delta robots too."""
    _, c, ci, reference = _robot(name)
    q, x, xdot, tau = _states(name, 6, seed=1)
    M, bias, acc = dynamics_batch._PATH_KERNELS[WORK_ARRAYS].dynamics(c, ci, q, x, xdot, tau)
    _close(M, reference.mass_matrix(q, x), f"{name}: M")
    _close(bias, reference.bias_forces(q, x, xdot), f"{name}: c + G")
    _close(acc, reference.forward_dynamics(q, x, xdot, tau), f"{name}: ẍ")


# Not cached on disk: a test module's cache would outlive a change to the kernels it calls (``envs.kernels.cache``).
@numba.njit(cache=False)
def _accelerations_planar_legs(c, ci, q, x, xdot, tau):
    """``dynamics.acceleration`` on the register path of three legs, robot by robot (as an integrator calls it)."""
    out = np.empty(x.shape)
    wd = dynamics._dynamics_work()
    for i in range(x.shape[0]):
        acc = dynamics.acceleration(
            PLANAR_LEGS,
            c,
            ci,
            (q[i, 0], q[i, 1], q[i, 2]),
            (x[i, 0], x[i, 1], x[i, 2]),
            (xdot[i, 0], xdot[i, 1], xdot[i, 2]),
            (tau[i, 0], tau[i, 1], tau[i, 2]),
            wd,
            wd[0],
        )
        out[i, 0], out[i, 1], out[i, 2] = acc
    return out


def test_the_acceleration_operation_matches_the_reference():
    """``acceleration``, the operation a compiled integrator calls with the path's vectors, gives the reference's ẍ."""
    _, c, ci, reference = _robot("planar_3rpr")
    q, x, xdot, tau = _states("planar_3rpr", 4, seed=2)
    _close(_accelerations_planar_legs(c, ci, q, x, xdot, tau), reference.forward_dynamics(q, x, xdot, tau), "ẍ")


def test_pack_inertia_layout():
    """The packed inertia has its table's size, is read-only, and refuses parameters of another robot."""
    params, _, ci, _ = _robot("planar_3rpr")
    assert ci.shape == (C_INERTIA_SIZE,)
    assert not ci.flags.writeable
    hexapod = _robot("stewart_gough")[0].robot
    with pytest.raises(ValueError, match=r"inertial parameters for 6 legs with 3-D points do not fit a robot"):
        dynamics.pack_inertia(params.robot, default_inertia(hexapod))
    with pytest.raises(TypeError, match=r"inertia must be a kinematics\.InertialParameters, got dict"):
        dynamics.pack_inertia(params.robot, {})


def test_bad_arguments_raise_value_errors_naming_them():
    """A misshapen inertia vector, inertia of another robot or a misshapen state is refused, naming the value."""
    _, c, ci, _ = _robot("planar_3rpr")
    _, _, ci_hexapod, _ = _robot("stewart_gough")
    q, x, xdot, tau = _states("planar_3rpr", 2)
    size = C_INERTIA_SIZE
    with pytest.raises(ValueError, match=rf"ci \(packed inertia, pack_inertia\) must have shape \({size},\), got "):
        dynamics_batch.mass_matrix_batch(c, ci[:-1], q, x)
    with pytest.raises(ValueError, match=rf"must have shape \({size},\), got shape \(2, {size}\)"):
        dynamics_batch.forward_dynamics_batch(c, np.stack([ci, ci]), q, x, xdot, tau)
    with pytest.raises(ValueError, match="ci packs the inertia of 6 legs, but c is a robot with 3 legs"):
        dynamics_batch.bias_batch(c, ci_hexapod, q, x, xdot)
    with pytest.raises(ValueError, match=r"c \(packed constants, pack_family\) must have shape"):
        dynamics_batch.mass_matrix_batch(c[:-1], ci, q, x)
    with pytest.raises(ValueError, match=r"tau must have shape \(2, 3\) holding actuator efforts, got shape \(2, 2\)"):
        dynamics_batch.forward_dynamics_batch(c, ci, q, x, xdot, tau[:, :2])
    with pytest.raises(ValueError, match=r"xdot must have shape \(2, 3\) holding platform twists, got shape \(3,\)"):
        dynamics_batch.bias_batch(c, ci, q, x, xdot[0])
