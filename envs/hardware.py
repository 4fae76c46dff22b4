"""The robot as built and as measured: geometry tolerances, encoders with a forward-kinematics estimate, drives.

Four parts of a real parallel robot that the ideal simulation leaves out, each an option of
``envs.params.FamilyParams`` and off by default; ``envs.physics`` calls the functions below, so the single env, the
vector env and the evaluation share them.

* **Model mismatch** (``geometry_tolerance`` δ [m]): the robot that is integrated (the *plant*) differs from the
  nominal one every controller knows. Each episode draws, from the reset generator, every coordinate of every base
  anchor B_i and platform point P_i (in the pose space's d dimensions), and for cranks and sliders every link length
  l_i and crank radius a_i, uniformly within ±δ (``perturbed_plants``). The robot starts at the strokes the nominal
  inverse kinematics gives for the start pose, so its true start pose is the plant's forward kinematics there.
* **Encoders** (``observation_source="encoders"``): the policy sees what a real controller has: measured actuator
  coordinates q̃ = res · round((q + σ ε) / res) (ε standard normal, from the env's generator; ``encoder_resolution``
  and ``encoder_noise`` per actuator) and the pose x̂ estimated by Newton's method on the *nominal* constraints
  Φ(q̃, x̂) = 0, warm-started from the previous estimate (``sense``), with the estimate's own k. Near a Type II
  singularity the pose is ill-determined by q̃ and the estimate's error grows as 1/k. The true pose stays in
  ``info["pose"]``; ``info["estimated_pose"]`` is the estimate.
* **A family of geometries** (``geometry_variation`` ν, Reach with box tasks): each episode's robot is drawn with
  its base and platform scaled and sheared by up to ±ν (``varied_plants``), and it is *known*: its tasks are
  certified on its own geometry, the observation and the reward use it, and the observation ends with the 2 d²
  codes of the draw, so that one policy can learn the family.
* **Drives** (``max_acceleration`` per actuator, ``action_delay`` whole control steps): an action takes effect
  ``action_delay`` steps after it is given, and the stroke rate changes by at most ``max_acceleration`` · dt per
  step (``drive``). ``max_rate`` is the rate limit. The rate is constant within a step.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from envs.kernels import force
from envs.kernels import generic as fk
from envs.kernels.layout import C_A, C_B, C_ELL, C_P
from envs.kernels.setup import random_streams, uniform_batch
from kinematics import DistanceConstraintMechanism

__all__ = [
    "OBSERVATION_SOURCES",
    "Measurement",
    "check_tolerance",
    "drive",
    "encoders",
    "known_holding_actions",
    "perturbed_plants",
    "perturbed_robot",
    "plant_columns",
    "sense",
    "sensed_motion",
    "varied_plants",
]

OBSERVATION_SOURCES = ("pose", "encoders")
#: Default encoder resolution by actuator kind: 10 µm of a leg's or a slider's stroke, 0.01° of a crank.
ENCODER_RESOLUTION = {"leg": 1e-5, "slider": 1e-5, "crank": math.radians(0.01)}


class Measurement(NamedTuple):
    """What the controller of N robots knows of them: encoder readings and the pose estimated from them.

    Attributes:
        q: Measured actuator coordinates q̃ [m, or rad for cranks], shape (N, n).
        x: Estimated poses x̂ (nominal forward kinematics of q̃), shape (N, m).
        k: Inverse condition number at (q̃, x̂) on the nominal model, shape (N,).
        k1: Actuator condition number there (1 for legs), shape (N,).
        residual: max_i |Φ_i(q̃, x̂)| [m²], shape (N,); NaN where the estimate did not converge (x̂ is then the
            previous estimate).
    """

    q: np.ndarray
    x: np.ndarray
    k: np.ndarray
    k1: np.ndarray
    residual: np.ndarray


def encoders(params) -> tuple[np.ndarray, np.ndarray]:
    """(resolution, noise standard deviation) of each actuator's encoder [m, or rad for cranks], each shape (n,).

    ``params.encoder_resolution`` or, if (), ``ENCODER_RESOLUTION`` by actuator kind; ``params.encoder_noise`` or,
    if (), one count.
    """
    resolution = params.encoder_resolution or tuple(ENCODER_RESOLUTION[kind] for kind in params.robot.actuator_kinds)
    return np.asarray(resolution), np.asarray(params.encoder_noise or resolution)


def plant_columns(robot) -> np.ndarray:
    """Indices into the packed constants of the geometry a tolerance perturbs (see the module docstring), shape (K,).

    Every coordinate of B_i and P_i in the pose space's d dimensions; l_i and a_i of cranks, l_i of sliders.
    """
    d = robot.base.shape[1]
    columns = [C_B + 3 * i + j for i in range(robot.n_actuators) for j in range(d)]
    columns += [C_P + 3 * i + j for i in range(robot.n_actuators) for j in range(d)]
    for i, kind in enumerate(robot.actuator_kinds):
        if kind != "leg":
            columns.append(C_ELL + i)
        if kind == "crank":
            columns.append(C_A + i)
    return np.asarray(columns, dtype=np.int64)


def perturbed_plants(params, streams: np.ndarray) -> np.ndarray:
    """Packed constants of N robots as built, each drawn from its stream: nominal ± ``geometry_tolerance``.

    Args:
        params: ``envs.params.FamilyParams``.
        streams: ``envs.kernels.setup.random_streams`` of the N generators, shape (N, 2); each gives K uniform
            draws (K = ``len(plant_columns(robot))``), in ``plant_columns`` order.

    Returns:
        float64 array (N, C_SIZE): the nominal ``params.packed`` with the perturbed geometry.
    """
    columns = plant_columns(params.robot)
    u = uniform_batch(streams, len(columns))
    plants = np.repeat(params.packed[None], len(streams), axis=0)
    plants[:, columns] += params.geometry_tolerance * (2.0 * u - 1.0)
    return plants


def varied_plants(params, streams: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Robots of a family of geometries, each drawn from its stream, and the codes the policy observes.

    Base anchors B_i' = c_B + S_B (B_i − c_B) about their centroid c_B, platform points P_i' = S_P P_i, with
    S = I + ν U and the d × d entries of U uniform in [−1, 1] (ν = ``geometry_variation``: scalings and shears of
    up to ±ν). Crank radii, link lengths, axes and rails stay nominal.

    Args:
        params: ``envs.params.FamilyParams``.
        streams: ``random_streams`` of the N generators, shape (N, 2); each gives 2 d² uniform draws (U_B, then
            U_P, row by row).

    Returns:
        (plants: packed constants (N, C_SIZE); codes: (U_B, U_P) flattened, (N, 2 d²), in [−1, 1]).
    """
    robot = params.robot
    n, d = robot.n_actuators, robot.base.shape[1]
    codes = 2.0 * uniform_batch(streams, 2 * d * d) - 1.0
    eye = np.eye(d)
    s_base = eye + params.geometry_variation * codes[:, : d * d].reshape(-1, d, d)
    s_platform = eye + params.geometry_variation * codes[:, d * d :].reshape(-1, d, d)
    centre = robot.base.mean(axis=0)
    base = centre + np.einsum("nij,kj->nki", s_base, robot.base - centre)
    platform = np.einsum("nij,kj->nki", s_platform, robot.platform)
    plants = np.repeat(params.packed[None], len(streams), axis=0)
    for i in range(n):
        plants[:, C_B + 3 * i : C_B + 3 * i + d] = base[:, i]
        plants[:, C_P + 3 * i : C_P + 3 * i + d] = platform[:, i]
    return plants, codes


def perturbed_robot(params, plant: np.ndarray):
    """The ``kinematics.DistanceConstraintMechanism`` of one plant row (the robot that was integrated).

    Args:
        params: ``envs.params.FamilyParams`` (the nominal robot: pose space, actuation, axes, rails, branches).
        plant: One row of ``perturbed_plants`` (or of ``FamilyState.plant``), shape (C_SIZE,).
    """
    robot = params.robot
    n, d = robot.n_actuators, robot.base.shape[1]
    return DistanceConstraintMechanism(
        plant[C_B : C_B + 3 * n].reshape(n, 3)[:, :d],
        plant[C_P : C_P + 3 * n].reshape(n, 3)[:, :d],
        pose_space=robot.pose_space.name,
        actuators=robot.actuator_kinds,
        link_lengths=plant[C_ELL : C_ELL + n],
        crank_radii=plant[C_A : C_A + n],
        crank_axes=robot.crank_axes,
        rails=robot.rails,
        branches=robot.branches,
        characteristic_length=robot.characteristic_length,
        check_architecture=False,
    )


def check_tolerance(params, draws: int = 64) -> None:
    """Refuse a ``geometry_tolerance`` at which the robot as built may not assemble near its home pose.

    Draws ``draws`` plants (from a fixed seed) and solves each one's forward kinematics at the strokes the nominal
    inverse kinematics gives for the centre of the task box; every one must converge, keep its working mode
    (sign(det J_x)) and stay above the hard threshold k_hard.

    Raises:
        ValueError: Naming the tolerance and what failed.
    """
    tolerance = params.geometry_tolerance
    if tolerance == 0.0:
        return
    centre = 0.5 * (np.asarray(params.sample_low) + np.asarray(params.sample_high))
    q = params.robot.inverse_kinematics(centre[None], validate=False)  # the nominal strokes
    if not np.isfinite(q).all():
        return  # the nominal robot does not reach there; the tasks (drawn safe) decide
    _, residual, k, _, sign = fk.forward_batch(params.packed_rows, q, centre[None], 50)  # the nominal robot there
    if not np.isfinite(residual[0]) or not k[0] >= params.hard_threshold:
        return  # the nominal robot itself is singular there
    generators = [np.random.default_rng([0, i]) for i in range(draws)]
    plants = perturbed_plants(params, random_streams(generators))
    plants.setflags(write=False)
    _, residual, k_plant, _, sign_plant = fk.forward_batch(
        plants, np.repeat(q, draws, axis=0), np.repeat(centre[None], draws, axis=0), 50
    )
    bad = ~np.isfinite(residual) | (sign_plant != sign[0]) | ~(k_plant >= params.hard_threshold)
    if bad.any():
        raise ValueError(
            f"geometry_tolerance={tolerance} m makes the robot unassemblable or singular near the centre of its "
            f"task box: {int(bad.sum())} of {draws} robots drawn within ±{tolerance} m do not assemble in the nominal "
            f"working mode above k_hard={params.hard_threshold} at its nominal strokes; give a smaller tolerance"
        )


def sense(
    params, q: np.ndarray, guess: np.ndarray, streams: np.ndarray, model: np.ndarray | None = None
) -> Measurement:
    """Encoder readings of N robots and the pose their controller estimates from them (see the module docstring).

    Args:
        params: ``envs.params.FamilyParams`` (encoder resolution and noise, the nominal model).
        q: True actuator coordinates [m, or rad for cranks], shape (N, n).
        guess: The previous estimates the forward kinematics starts from, shape (N, m).
        streams: ``random_streams`` of the N generators, shape (N, 2); each gives 2n uniform draws (Box–Muller).
        model: Read-only packed constants of the model the controllers know, (N or 1, C_SIZE); None: the nominal.

    Returns:
        The measurement.
    """
    n = q.shape[1]
    u = uniform_batch(streams, 2 * n)
    eps = np.sqrt(-2.0 * np.log1p(-u[:, :n])) * np.cos(2.0 * np.pi * u[:, n:])
    resolution, noise = encoders(params)
    measured = np.round((q + noise * eps) / resolution) * resolution
    model = params.packed_rows if model is None else model
    x, residual, k, k1, _ = fk.forward_batch(model, measured, guess, params.estimator_iterations)
    return Measurement(measured, x, k, k1, residual)


def drive(params, state: np.ndarray, action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The actions the drives apply this step, and their new state.

    Args:
        params: ``envs.params.FamilyParams`` (``action_delay``, ``max_acceleration``, ``max_rate``, ``dt``).
        state: The drives of N robots, shape (N, 1 + delay, n): row 0 the action applied last step, then the
            actions given but not yet applied, oldest first.
        action: The actions given now, normalised rates, shape (N, n), finite.

    Returns:
        (applied actions (N, n) in [−1, 1], the new state (N, 1 + delay, n)).
    """
    given = np.clip(action, -1.0, 1.0)
    new = np.empty_like(state)
    if params.action_delay:
        applied = state[:, 1].copy()
        new[:, 1:-1] = state[:, 2:]
        new[:, -1] = given
    else:
        applied = given
    if params.max_acceleration:
        change = np.asarray(params.max_acceleration) * params.dt / params.max_rate  # per step, normalised
        applied = np.clip(applied, state[:, 0] - change, state[:, 0] + change)
    new[:, 0] = applied
    return applied, new


def sensed_motion(params, before: Measurement, after: Measurement) -> tuple[np.ndarray, np.ndarray]:
    """What a controller knows of the motion under force control: the period's differences of its measurements.

    Returns:
        (twist estimate (x̂′ ⊖ x̂) / dt (N, m), measured actuator rates (q̃′ − q̃) / dt (N, n)).
    """
    dt = params.dt
    step = params.robot.pose_difference(after.x, before.x, validate=False)
    return step / dt, (after.q - before.q) / dt


def known_holding_actions(params, q, x, sensed, plant, action, parallel: bool = False) -> np.ndarray:
    """Force control on a robot the controller does not know exactly (a geometry tolerance, encoders).

    The action is an offset from the holding forces the controller computes: the nominal model's at the pose it
    knows (its estimate with encoders, else the true pose). The compiled step offsets it from the plant's at the
    true pose, so each action is turned into the one whose efforts there are the same
    (``envs.kernels.force.efforts_of_actions`` and its inverse).

    Args:
        params: ``envs.params.FamilyParams`` (force control).
        q: True actuator coordinates, shape (N, n).
        x: True poses, shape (N, m).
        sensed: The controllers' ``Measurement``, or None (they know the true pose).
        plant: Read-only packed constants of the robots as built, (N or 1, C_SIZE).
        action: The actions given, shape (N, n).
        parallel: Solve the holding forces on the multi-core step's kernel (``envs.kernels.modes``), as a vector
            env that steps on every core passes.

    Returns:
        The actions for the compiled step, shape (N, n); rows where a holding force is not finite (a singular
        J_x) or the action is not are passed through.
    """
    limits = params.force_limit_array
    if sensed is not None:
        q_known, x_known = sensed.q, sensed.x
    else:
        q_known, x_known = params.robot.inverse_kinematics(x, validate=False), x
    known = fk.holding_batch(params.packed_rows, params.packed_inertia, q_known, x_known, parallel)
    true = fk.holding_batch(plant, params.packed_inertia, q, x, parallel)
    clean = (np.isfinite(known).all(axis=-1) & np.isfinite(true).all(axis=-1))[:, None]
    effort = force.efforts_of_actions(np.where(clean, known, 0.0), action, limits)
    converted = force.actions_of_efforts(np.where(clean, true, 0.0), effort, limits)
    return np.where(clean & np.isfinite(action), converted, action)
