"""The MJCF export against MuJoCo, an independent engine: assembly, statics and forced motion.

``kinematics.dynamics`` writes the equations of motion in the platform's twist coordinates with q eliminated;
MuJoCo integrates the open chains of ``kinematics.mjcf.to_mjcf`` in its own joint coordinates with the loops
closed by soft equality constraints. Agreement of the two on the holding forces and on forced trajectories checks
the dynamics, the inertial model and the export at once; the last tests plant errors in the exported inertia and
check that these comparisons see them.
"""

from __future__ import annotations

import functools

import mujoco
import numpy as np
import pytest

from kinematics import Delta, DistanceConstraintMechanism, Planar3RPR, StewartGough
from kinematics.dynamics import (
    STANDARD_GRAVITY,
    InertialParameters,
    RobotDynamics,
    default_inertia,
    rod_from_end_masses,
)
from kinematics.mjcf import platform_pose, to_mjcf
from tests.kinematics.helpers import DYNAMICS_PRESETS

PRESETS = DYNAMICS_PRESETS

#: The forced-motion scenarios: number of start poses, size of the random offsets to the holding forces (a
#: fraction of the largest), and the least distance [m] every start must go from its start. The 3-RRR and the 3-PRR
#: have small workspaces: smaller offsets keep them inside for 0.5 s.
SCENARIOS = {
    "3-RPR": (5, 0.3, 0.01),
    "hexapod": (5, 0.3, 0.01),
    "Delta": (5, 0.3, 0.01),
    "3-RRR": (3, 0.05, 0.005),
    "3-PRR": (3, 0.05, 0.005),
}

HOLD_TIME = 0.2  # [s]
SEGMENT = 0.05  # [s], the actuator efforts change every SEGMENT
SEGMENTS = 10  # 0.5 s in all
OUR_SUBSTEPS = 50  # RKMK4 steps of 1 ms per segment

#: Tolerances: the platform's drift under the holding forces [m]; the gap between the two simulations after
#: 0.5 s (position [m], rotation [deg]); MuJoCo's closure violation [m]. MuJoCo (RK4, 0.25 ms, closures with a
#: 0.5 ms time constant) and our RKMK4 at 1 ms agree to about 1e-9 m and 1e-6°, the closures to 2e-8 m.
DRIFT_TOLERANCE = 1e-6
POSITION_TOLERANCE = 1e-5
ANGLE_TOLERANCE = 1e-3
CLOSURE_TOLERANCE = 1e-6


def robot_and_inertia(name: str) -> tuple[object, InertialParameters]:
    """A preset with its default inertia, planar ones stood up (gravity along −y)."""
    robot = PRESETS[name][0]()
    inertia = default_inertia(robot)
    if inertia.point_dim == 2:
        inertia = inertia.replace(gravity=(0.0, -STANDARD_GRAVITY))
    return robot, inertia


def load(robot, inertia: InertialParameters, **options):
    """MuJoCo's model and data of ``to_mjcf(robot, inertia, **options)``."""
    model = mujoco.MjModel.from_xml_string(to_mjcf(robot, inertia, **options))
    return model, mujoco.MjData(model)


def closure_violation(data) -> float:
    """The largest violation [m] of the closures (MuJoCo's equality rows, after a forward pass or a step)."""
    rows = data.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    return float(np.abs(data.efc_pos[rows]).max())


def actuated_qpos(model, data, n: int) -> np.ndarray:
    """The positions of the joints ``actuator{i}``, shape (n,)."""
    return np.array([data.qpos[model.joint(f"actuator{i}").qposadr[0]] for i in range(n)])


def start_poses(robot, name: str, count: int, seed: int = 7) -> np.ndarray:
    """Random poses around the home pose, away from singularities, shape (count, m)."""
    rng = np.random.default_rng(seed)
    _, translation, rotation = PRESETS[name]
    rotations = list(robot.pose_space.rotation_columns)
    kept = []
    while len(kept) < count:
        step = rng.uniform(-translation, translation, robot.n_pose)
        step[rotations] = rng.uniform(-rotation, rotation, len(rotations))
        x = robot.retract(robot.home_pose(), step)
        q = robot.inverse_kinematics(x, validate=False)
        if (
            np.isfinite(q).all()
            and min(robot.inverse_condition_number(q, x), robot.actuator_condition_number(q, x)) > 0.2
        ):
            kept.append(x)
    return np.array(kept)


def efforts(dynamics: RobotDynamics, X0: np.ndarray, fraction: float, seed: int = 11) -> np.ndarray:
    """Holding forces at X0 plus uniform offsets of ± ``fraction`` of the largest, per segment: (SEGMENTS, K, n)."""
    rng = np.random.default_rng(seed)
    hold = dynamics.holding_forces(dynamics.mechanism.inverse_kinematics(X0), X0)
    scale = fraction * np.abs(hold).max(axis=-1, keepdims=True)
    return hold + scale * rng.uniform(-1.0, 1.0, (SEGMENTS,) + hold.shape)


def drift(
    robot, inertia, x: np.ndarray, scale: float = 1.0, exported: InertialParameters | None = None, **options
) -> float:
    """How far [m] the platform's points P_i move in HOLD_TIME from rest at x under our holding forces × scale.

    Args:
        robot: The mechanism.
        inertia: The inertia of our holding forces.
        x: The pose to start from at rest, shape (m,).
        scale: Factor on the holding forces (0: none).
        exported: Inertia written into the MJCF (default ``inertia``).
        **options: Options of ``to_mjcf``.
    """
    tau = scale * RobotDynamics(robot, inertia).holding_forces(robot.inverse_kinematics(x), x)
    model, data = load(robot, inertia if exported is None else exported, x=x, **options)
    data.ctrl[:] = tau
    mujoco.mj_step(model, data, nstep=round(HOLD_TIME / model.opt.timestep))
    end = robot.platform_points_in_base(platform_pose(robot, data.qpos))
    return float(np.linalg.norm(end - robot.platform_points_in_base(x), axis=-1).max())


@functools.cache
def _our_motion(name: str, count: int, fraction: float, damping: float, joint_damping: float) -> tuple:
    """``compare``'s side of our dynamics (the MJCF does not change it): computed once per arguments.

    Returns (X0, τ, x at 0.5 s, the inertia simulated, "moved", "phi"); read-only by convention.
    """
    robot, inertia = robot_and_inertia(name)
    if damping or joint_damping:
        home = robot.home_pose()
        hold = np.abs(RobotDynamics(robot, inertia).holding_forces(robot.inverse_kinematics(home), home)).max()
        inertia = inertia.replace(actuator_damping=damping * hold, joint_damping=joint_damping * hold)
    dynamics = RobotDynamics(robot, inertia)
    X0 = start_poses(robot, name, count)
    tau = efforts(dynamics, X0, fraction)
    d = robot.pose_space.point_dim
    moved = np.zeros(count)
    x, xdot = X0.copy(), np.zeros_like(X0)
    for k in range(SEGMENTS):
        state = dynamics.step(x, xdot, tau[k], SEGMENT, substeps=OUR_SUBSTEPS)
        x, xdot = state.x, state.xdot
        travel = np.linalg.norm(robot.pose_difference(X0, x)[:, :d], axis=-1)
        moved = np.maximum(moved, travel)
    phi = np.abs(robot.constraints(state.q, x)).max(axis=-1)
    return X0, tau, x, inertia, moved, phi


def compare(
    name: str,
    count: int,
    exported: InertialParameters | None = None,
    fraction: float = 0.3,
    damping: float = 0.0,
    joint_damping: float = 0.0,
    **options,
) -> dict[str, np.ndarray]:
    """Both simulations from ``count`` start poses at rest under the same efforts; the gaps at 0.5 s.

    Args:
        name: A key of PRESETS.
        count: Number of start poses.
        exported: Inertia written into the MJCF (default: the one our dynamics uses).
        fraction: Size of the random offsets to the holding forces (see ``efforts``).
        damping: The drives' viscous friction, b_i = ``damping`` × the largest holding force at home [per m/s or
            rad/s], in our dynamics and (unless ``exported``) in the MJCF.
        joint_damping: The passive joints' viscous friction, b = ``joint_damping`` × that force × 1 m [N·m·s/rad].
        **options: Options of ``to_mjcf``.

    Returns:
        Per start: "position" [m] and "angle" [deg] gaps, "closure" (MuJoCo's largest violation [m], sampled
        every 12.5 ms), "moved" (the largest distance [m] of our platform from its start, at the ends of the
        segments), and "phi", our largest |Φ_i| at the end [m²].
    """
    robot, _ = robot_and_inertia(name)
    X0, tau, x, inertia, moved, phi = _our_motion(name, count, fraction, damping, joint_damping)
    d = robot.pose_space.point_dim
    out = {key: np.zeros(count) for key in ("position", "angle", "closure")}
    out["moved"], out["phi"] = moved.copy(), phi.copy()
    for j in range(count):
        model, data = load(robot, inertia if exported is None else exported, x=X0[j], **options)
        steps = round(SEGMENT / model.opt.timestep) // 4
        for k in range(SEGMENTS):
            data.ctrl[:] = tau[k, j]
            for _ in range(4):
                mujoco.mj_step(model, data, nstep=steps)
                out["closure"][j] = max(out["closure"][j], closure_violation(data))
        gap = robot.pose_difference(x[j], platform_pose(robot, data.qpos))
        out["position"][j] = np.linalg.norm(gap[:d])
        out["angle"][j] = np.degrees(np.linalg.norm(gap[d:]))
    return out


# -- the model ------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(PRESETS))
def test_model_loads_closed_with_the_bodies_and_masses(name):
    """Counts, total mass, and at the assembly: zero closure violation, the pose x and the actuators at q."""
    robot, inertia = robot_and_inertia(name)
    model, data = load(robot, inertia)
    n = robot.n_actuators
    spatial, planar = robot.pose_space.name == "spatial", robot.pose_space.name == "planar"
    assert model.nbody == 2 + 2 * n  # world, platform, actuator and distal bodies
    legs = sum(kind == "leg" for kind in robot.actuator_kinds)
    assert model.njnt == (1 if spatial else 3) + 2 * n
    pivot_dofs = 3 if robot.pose_space.point_dim == 3 else 1
    assert model.nv == (6 if spatial else 3) + n * (1 + pivot_dofs)
    assert model.neq == n and model.nu == n
    assert legs in (0, n)
    assert all(model.eq_type[i] == mujoco.mjtEq.mjEQ_CONNECT for i in range(n))
    assert not planar or model.opt.gravity[2] == 0.0
    total = inertia.platform_mass + inertia.actuator_mass.sum() + inertia.distal_mass.sum()
    assert mujoco.mj_getTotalmass(model) == pytest.approx(total, rel=1e-12)
    np.testing.assert_allclose(model.opt.gravity[: robot.pose_space.point_dim], inertia.gravity, rtol=0, atol=0)
    mujoco.mj_forward(model, data)
    assert closure_violation(data) < 1e-12
    x = robot.home_pose()
    np.testing.assert_allclose(platform_pose(robot, data.qpos), x, atol=1e-12)
    np.testing.assert_allclose(actuated_qpos(model, data, n), robot.inverse_kinematics(x), atol=1e-12)


@pytest.mark.parametrize("name", ["hexapod", "3-RRR"])
def test_model_assembles_at_a_given_pose(name):
    """``x=`` assembles elsewhere; ``mechanism.to_mjcf`` is the same document."""
    robot, inertia = robot_and_inertia(name)
    x = start_poses(robot, name, 1)[0]
    model, data = load(robot, inertia, x=x)
    mujoco.mj_forward(model, data)
    assert closure_violation(data) < 1e-12
    np.testing.assert_allclose(platform_pose(robot, data.qpos), x, atol=1e-12)
    np.testing.assert_allclose(actuated_qpos(model, data, 3), robot.inverse_kinematics(x)[:3], atol=1e-12)
    assert robot.to_mjcf(inertia, x=x) == to_mjcf(robot, inertia, x=x)


def test_platform_pose_reads_quaternions_of_both_signs():
    """The rotation vector of q and −q is the same; near zero it is 2 v."""
    robot = StewartGough()
    r = np.array([0.3, -0.2, 0.5])
    angle = np.linalg.norm(r)
    quat = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * r / angle])
    for sign in (1.0, -1.0):
        np.testing.assert_allclose(platform_pose(robot, [1.0, 2.0, 3.0, *(sign * quat)]), [1.0, 2.0, 3.0, *r])
    np.testing.assert_allclose(platform_pose(robot, [0, 0, 0, 1.0, 1e-14, 0, 0])[3:], [2e-14, 0, 0], atol=1e-20)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"timestep": 0.0}, r"timestep must be a finite number > 0.0, got 0.0"),
        ({"integrator": "RK5"}, r"integrator must be one of \['Euler', 'RK4', 'implicit', 'implicitfast'\], got 'RK5'"),
        ({"solref": (0.01,)}, r"solref must be 2 finite numbers, got \(0.01,\)"),
        ({"x": [0.0, 0.0, 0.5, 0.0, 0.0, 0.0], "q": [0.5] * 6}, r"\(q, x\) must be an assembled pose"),
        ({"axial_inertia": -1.0}, r"axial_inertia must be a finite number > 0.0, got -1.0"),
    ],
)
def test_options_are_validated(options, message):
    """Bad options raise ValueErrors that name them and the value."""
    with pytest.raises(ValueError, match=message):
        to_mjcf(StewartGough(), **options)


def test_inertia_must_fit():
    """Planar parameters for a spatial robot, and a crank lighter about its axis than its arm, are refused."""
    with pytest.raises(ValueError, match=r"3 legs with 2-D points do not fit a robot with 6 legs and 3-D points"):
        to_mjcf(StewartGough(), default_inertia(Planar3RPR()))
    delta = Delta()
    with pytest.raises(ValueError, match=r"actuator_inertia of crank 0 must exceed actuator_mass · actuator_com²"):
        to_mjcf(delta, default_inertia(delta).replace(actuator_inertia=0.01))


# -- statics and dynamics against MuJoCo ------------------------------------------------------------


@pytest.mark.parametrize("name", list(PRESETS))
def test_holding_forces_hold_the_platform_in_mujoco(name):
    """Our holding forces as motor controls keep the platform within 1 µm for 0.2 s; without them it falls."""
    robot, inertia = robot_and_inertia(name)
    for x in (robot.home_pose(), start_poses(robot, name, 1)[0]):
        assert drift(robot, inertia, x) < DRIFT_TOLERANCE
    assert drift(robot, inertia, robot.home_pose(), scale=0.0) > 0.02


def off_centre(name: str) -> tuple[object, InertialParameters]:
    """A preset with masses off the symmetric places: the hexapod's payload off-centre, links heavier at A_i."""
    robot, inertia = robot_and_inertia(name)
    if name == "hexapod":
        return robot, inertia.replace(platform_com=(0.03, -0.02, 0.05))
    mass, com, moment = rod_from_end_masses(0.2, 0.1, float(robot.link_lengths[0]))
    return robot, inertia.replace(distal_mass=mass, distal_com=com, distal_inertia=moment)


@pytest.mark.parametrize("name", ["hexapod", "Delta", "3-RRR", "3-PRR"])
def test_holding_forces_hold_off_centre_masses_in_mujoco(name):
    """An off-centre payload, links heavier at the anchor (2:1 end masses): each mass is placed from the right end."""
    robot, inertia = off_centre(name)
    for x in (robot.home_pose(), start_poses(robot, name, 1)[0]):
        assert drift(robot, inertia, x) < DRIFT_TOLERANCE


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_forced_motion_agrees_with_mujoco(name):
    """From start poses at rest, 0.5 s of piecewise-constant efforts: the same pose within 10 µm and 1e-3°."""
    count, fraction, travel = SCENARIOS[name]
    out = compare(name, count, fraction=fraction)
    assert out["moved"].min() > travel  # every start goes somewhere
    assert out["position"].max() < POSITION_TOLERANCE, out["position"]
    assert out["angle"].max() < ANGLE_TOLERANCE, out["angle"]
    assert out["closure"].max() < CLOSURE_TOLERANCE, out["closure"]
    assert out["phi"].max() < 1e-12


@pytest.mark.parametrize("name", list(SCENARIOS))
@pytest.mark.parametrize("where", ["drives", "joints"])
def test_viscous_friction_agrees_with_mujoco_joint_damping(name, where):
    """Viscous friction of the drives or of the passive joints at them: the same forced motion as MuJoCo's.

    MuJoCo: ``damping`` on the actuated joints, or on ``base{i}`` and ``elbow{i}``. Without the damping in the
    MJCF the gap is over ten times the tolerance.
    """
    _, fraction, _ = SCENARIOS[name]
    friction = {"damping": 0.5} if where == "drives" else {"joint_damping": 0.05}
    out = compare(name, 1, fraction=fraction, **friction)
    assert out["position"].max() < POSITION_TOLERANCE, out["position"]
    assert out["angle"].max() < ANGLE_TOLERANCE, out["angle"]
    _, inertia = robot_and_inertia(name)
    undamped = compare(name, 1, exported=inertia, fraction=fraction, **friction)
    assert undamped["position"].max() > 10 * POSITION_TOLERANCE, undamped["position"]


# -- planted errors: the comparisons must see them ---------------------------------------------------


def _planted(name: str, error: str) -> tuple[object, InertialParameters, InertialParameters]:
    robot, inertia = robot_and_inertia(name)
    if error == "rod mass +10 %":
        wrong = inertia.replace(distal_mass=inertia.distal_mass * np.r_[1.1, np.ones(robot.n_actuators - 1)])
    elif error == "rod centre of mass 1 cm off":
        wrong = inertia.replace(distal_com=inertia.distal_com + np.r_[0.01, np.zeros(robot.n_actuators - 1)])
    elif error == "no rotor inertia":
        wrong = inertia.replace(actuator_inertia=inertia.actuator_inertia - 0.01)
    elif error == "cylinder inertia halved":
        wrong = inertia.replace(actuator_inertia=0.5 * inertia.actuator_inertia)
    else:  # pragma: no cover
        raise AssertionError(error)
    return robot, inertia, wrong


@pytest.mark.parametrize(
    ("name", "error"),
    [("hexapod", "rod mass +10 %"), ("hexapod", "rod centre of mass 1 cm off"), ("Delta", "rod mass +10 %")],
)
def test_statics_see_a_wrong_weight(name, error):
    """A wrong rod mass or centre of mass in the MJCF moves the held platform by more than the tolerance."""
    robot, inertia, wrong = _planted(name, error)
    assert drift(robot, inertia, robot.home_pose(), exported=wrong) > 100 * DRIFT_TOLERANCE


@pytest.mark.parametrize(
    ("name", "error"),
    [("Delta", "no rotor inertia"), ("3-RPR", "cylinder inertia halved"), ("hexapod", "rod centre of mass 1 cm off")],
)
def test_dynamics_see_a_wrong_inertia(name, error):
    """Inertia that gravity does not reveal (a rotor, a cylinder's moment) changes the forced motion."""
    _, _, wrong = _planted(name, error)
    out = compare(name, 1, exported=wrong)
    assert out["position"].max() > 10 * POSITION_TOLERANCE


# -- members of the family beyond the presets --------------------------------------------------------


def linear_delta() -> tuple[DistanceConstraintMechanism, InertialParameters]:
    """A linear Delta: three carriages on vertical rails, links to a translating plate; made-up masses."""
    angles = np.radians([0.0, 120.0, 240.0])
    ring = np.stack([np.cos(angles), np.sin(angles), np.zeros(3)], axis=1)
    robot = DistanceConstraintMechanism(
        0.3 * ring, 0.05 * ring, pose_space="translational", actuators="slider", link_lengths=0.4, rails=[0, 0, 1.0]
    )
    inertia = InertialParameters(
        platform_mass=0.4,
        platform_com=(0.0, 0.0, -0.01),
        platform_inertia=np.diag([1e-3, 1e-3, 2e-3]),
        actuator_mass=np.full(3, 0.5),
        actuator_com=0.0,
        actuator_inertia=0.0,
        distal_mass=0.1,
        distal_com=0.25,
        distal_inertia=1e-3,
        gravity=(0.0, 0.0, -STANDARD_GRAVITY),
    )
    return robot, inertia


def six_rus() -> tuple[DistanceConstraintMechanism, InertialParameters]:
    """A 6-RUS on the hexapod's anchors (cranks turning tangent arms in vertical planes), tilted gravity."""
    hexapod = StewartGough()
    base, x = hexapod.base, hexapod.home_pose()
    radial = base / np.linalg.norm(base, axis=1, keepdims=True)
    u = np.stack([(-1.0) ** i * np.cross([0.0, 0.0, 1.0], radial[i]) for i in range(6)])
    v = np.tile([0.0, 0.0, 1.0], (6, 1))
    elbows = base + 0.1 * (np.cos(0.3) * u + np.sin(0.3) * v)
    lengths = np.linalg.norm(hexapod.platform_points_in_base(x) - elbows, axis=1)
    robot = DistanceConstraintMechanism(
        base,
        hexapod.platform,
        actuators="crank",
        crank_radii=0.1,
        link_lengths=lengths,
        crank_axes=np.stack([u, v], axis=1),
        branches=-1,
        home=x,
    )
    inertia = InertialParameters(
        platform_mass=3.0,
        platform_com=(0.01, 0.0, 0.02),
        platform_inertia=np.diag([0.02, 0.03, 0.04]),
        actuator_mass=np.full(6, 0.3),
        actuator_com=0.05,
        actuator_inertia=0.3 * 0.1**2 / 3.0 + 0.002,
        distal_mass=0.2,
        distal_com=0.1,
        distal_inertia=0.2 * 0.35**2 / 12.0,
        gravity=(0.5, -0.3, -STANDARD_GRAVITY),
    )
    return robot, inertia


@pytest.mark.parametrize("build", [linear_delta, six_rus])
def test_other_members_agree_with_mujoco(build):
    """Spatial sliders and spatial cranks: holding forces hold, and 0.3 s under ±20 % offsets ends at one pose."""
    robot, inertia = build()
    x = robot.home_pose()
    assert drift(robot, inertia, x) < DRIFT_TOLERANCE
    assert drift(robot, inertia, x, scale=0.0) > 0.02
    dynamics = RobotDynamics(robot, inertia)
    offsets = 1.0 + 0.2 * np.random.default_rng(3).uniform(-1.0, 1.0, robot.n_actuators)
    tau = offsets * dynamics.holding_forces(robot.inverse_kinematics(x), x)
    ours = dynamics.step(x, np.zeros_like(x), tau, 0.3, substeps=300).x
    model, data = load(robot, inertia)
    data.ctrl[:] = tau
    mujoco.mj_step(model, data, nstep=round(0.3 / model.opt.timestep))
    gap = robot.pose_difference(ours, platform_pose(robot, data.qpos))
    assert np.linalg.norm(robot.pose_difference(x, ours)[:3]) > 0.005
    assert np.linalg.norm(gap[:3]) < POSITION_TOLERANCE
    assert np.degrees(np.linalg.norm(gap[3:])) < ANGLE_TOLERANCE
    assert closure_violation(data) < CLOSURE_TOLERANCE
