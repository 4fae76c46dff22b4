"""Benchmark force control: single steps against Pendulum-v1, the vector env, and MuJoCo on the exported models.

Run with ``python -m benchmarks.bench_force_step [--steps 500] [--rounds 21] [--sizes 16384] [--vector-rounds 5]
[--mujoco-robots 64]``.

1. Single steps through ``gym.make`` (``bench_env_step``'s protocol: default wrappers, actions drawn in advance,
   resets inside the timed loop, 500 warm-up steps, the environments taking turns with the order reversed every
   other round) of ``Planar3RPRForceReach-v0``, ``DeltaForceReach-v0`` and ``StewartGoughForceReach-v0`` against
   ``Pendulum-v1``. The ratio is taken round by round, each id against the Pendulum of the same round, and the
   table gives the median and the quartiles of the rounds' ratios (a drift of the machine's speed slower than a
   round cancels in that round's ratio). Actions are uniform in ±0.05 (offsets from the holding forces of 5 % of the
   drive limits; full-scale random efforts fling the platform out in a few steps, and the loop would time resets).
   Targets: planar and Delta / Pendulum ≤ 1.5, hexapod / Pendulum ≤ 2.
2. The native vector env (``gym.make_vec``, ``vector_entry_point``) at each size: env-steps per second of
   ``--vector-rounds`` samples of ``--vector-steps`` steps each, fresh uniform ±0.05 actions, autoreset included,
   after 3 warm-up steps; the median and the range of the samples. Targets at N = 16384: ≥ 1 M env-steps/s
   (planar), ≥ 0.3 M (hexapod).
3. MuJoCo (the ``test``/``bench`` extra) on the robot exported by ``robot.to_mjcf`` with the same inertia: the
   time of one 50 ms control period (``dt / timestep`` calls of ``mj_step`` at MuJoCo's default 2 ms and at 0.25 ms,
   the step at which its soft loop closures stay within µm; closures' time constant 2 timesteps, at least 0.5 ms)
   per robot, single thread, and batched over
   ``--mujoco-robots`` robots with ``mujoco.rollout`` on every core. Ours for comparison is the vector env's
   time per env-step (one control period) at the largest size.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
from benchmarks.bench_env_step import SteppedEnv

PLANAR, DELTA, HEXAPOD, PENDULUM = (
    "Planar3RPRForceReach-v0",
    "DeltaForceReach-v0",
    "StewartGoughForceReach-v0",
    "Pendulum-v1",
)
#: (subject, largest ratio to Pendulum-v1 of the median time per step).
STEP_TARGETS = ((PLANAR, 1.5), (DELTA, 1.5), (HEXAPOD, 2.0))
#: (subject, least env-steps per second of the vector env at N = 16384).
VECTOR_TARGETS = ((PLANAR, 1.0e6), (DELTA, 1.0e6), (HEXAPOD, 0.3e6))
ACTION_SCALE = 0.05
WARM_UP_STEPS = 500


def single_steps(steps: int, rounds: int, seed: int) -> dict[str, list[float]]:
    """µs per ``env.step`` of the force ids and Pendulum-v1 in each of the alternating rounds."""
    steppers = [SteppedEnv(env_id, steps, seed) for env_id in (PLANAR, DELTA, HEXAPOD, PENDULUM)]
    for stepper in steppers[:3]:
        stepper.actions = [(ACTION_SCALE * a).astype(np.float32) for a in stepper.actions]
    for stepper in steppers:
        for action in stepper.actions[: min(steps, WARM_UP_STEPS)]:
            _, _, terminated, truncated, _ = stepper.env.step(action)
            if terminated or truncated:
                stepper.env.reset()
    samples: dict[str, list[float]] = {s.env_id: [] for s in steppers}
    for index in range(rounds):
        for stepper in steppers if index % 2 == 0 else steppers[::-1]:
            samples[stepper.env_id].append(stepper.run() / steps * 1e6)
    return samples


def vector_rates(env_id: str, n: int, steps: int, rounds: int, seed: int) -> list[float]:
    """Env-steps per second of the native vector env of ``n`` robots in each of ``rounds`` samples of ``steps``."""
    env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    actions = [
        rng.uniform(-ACTION_SCALE, ACTION_SCALE, env.action_space.shape).astype(np.float32) for _ in range(steps)
    ]
    for action in actions[:3]:
        env.step(action)
    rates = []
    for _ in range(rounds):
        start = time.perf_counter()
        for action in actions:
            env.step(action)
        rates.append(n * steps / (time.perf_counter() - start))
    env.close()
    return rates


def mujoco_period(env_id: str, timestep: float, robots: int, seed: int) -> tuple[float, float] | None:
    """MuJoCo's µs per robot per control period of the exported robot: (single thread, ``rollout`` on every core)."""
    try:
        import mujoco
        from mujoco import rollout
    except ImportError:
        return None
    params = gym.make(env_id).unwrapped.params
    inertia = params.dynamics.inertia
    solref = (max(0.0005, 2.0 * timestep), 1.0)  # a time constant of two steps at least keeps the loops stable
    model = mujoco.MjModel.from_xml_string(params.robot.to_mjcf(inertia, timestep=timestep, solref=solref))
    data = mujoco.MjData(model)
    steps = round(params.dt / timestep)
    home = params.robot.home_pose()
    hold = params.dynamics.holding_forces(params.robot.inverse_kinematics(home), home)
    data.ctrl[:] = hold
    start = time.perf_counter()
    periods = 20
    for _ in range(periods * steps):
        mujoco.mj_step(model, data)
    single = (time.perf_counter() - start) / periods * 1e6
    mujoco.mj_resetData(model, data)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, state, spec)
    initial = np.tile(state, (robots, 1))
    rng = np.random.default_rng(seed)
    control = np.tile(hold, (robots, steps, 1)) * (1.0 + 0.01 * rng.standard_normal((robots, 1, 1)))
    datas = [mujoco.MjData(model) for _ in range(os.cpu_count() or 1)]
    rollout.rollout(model, datas, initial, control)  # warm-up (thread pool)
    start = time.perf_counter()
    rollout.rollout(model, datas, initial, control)
    batched = (time.perf_counter() - start) / robots * 1e6
    return single, batched


def main(argv: list[str] | None = None) -> None:
    """Print the three tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=500, help="steps per round of the single envs")
    parser.add_argument("--rounds", type=int, default=21, help="rounds of the single envs")
    parser.add_argument("--sizes", type=int, nargs="+", default=[16384], help="vector env sizes")
    parser.add_argument("--vector-steps", type=int, default=10, help="timed steps of a sample of the vector env")
    parser.add_argument("--vector-rounds", type=int, default=5, help="samples of the vector env")
    parser.add_argument("--mujoco-robots", type=int, default=64, help="robots of MuJoCo's batched rollout")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    print(f"python {platform.python_version()}, {os.cpu_count()} cores, numpy {np.__version__}")
    print(f"\n1. Single env.step, {args.rounds} alternating rounds of {args.steps} steps (actions ±{ACTION_SCALE})")
    samples = single_steps(args.steps, args.rounds, args.seed)
    print("| env | µs/step (median) | / Pendulum-v1, median of the rounds | quartiles of the rounds | target |")
    print("|---|---|---|---|---|")
    for env_id, target in STEP_TARGETS:
        ratios = [ours / anchor for ours, anchor in zip(samples[env_id], samples[PENDULUM])]
        low, middle, high = statistics.quantiles(ratios, n=4) if len(ratios) > 1 else ratios * 3
        print(
            f"| {env_id} | {statistics.median(samples[env_id]):.1f} | {middle:.2f} | {low:.2f}–{high:.2f} "
            f"| ≤ {target} |"
        )
    print(f"| {PENDULUM} | {statistics.median(samples[PENDULUM]):.1f} | 1.00 | | |")
    print(f"\n2. Native vector env, {args.vector_rounds} samples of {args.vector_steps} steps, env-steps/s")
    print("| env | N | M env-steps/s (median) | range | µs per env-step (median) | target at N = 16384 |")
    print("|---|---|---|---|---|---|")
    ours = {}
    for env_id, target in VECTOR_TARGETS:
        for n in args.sizes:
            rates = vector_rates(env_id, n, args.vector_steps, args.vector_rounds, args.seed)
            rate = statistics.median(rates)
            ours[env_id] = 1e6 / rate
            print(
                f"| {env_id} | {n} | {rate / 1e6:.2f} | {min(rates) / 1e6:.2f}–{max(rates) / 1e6:.2f} "
                f"| {1e6 / rate:.3f} | ≥ {target / 1e6:g} M |"
            )
    print(f"\n3. MuJoCo on the exported robot, µs per robot per {0.05 * 1e3:g} ms control period")
    print("| robot | MuJoCo timestep | single thread | rollout, every core | ours, vector env |")
    print("|---|---|---|---|---|")
    for env_id, _ in VECTOR_TARGETS:
        for timestep in (0.002, 0.00025):
            result = mujoco_period(env_id, timestep, args.mujoco_robots, args.seed)
            if result is None:
                print("MuJoCo is not installed: pip install -e '.[bench]'")
                return
            print(f"| {env_id} | {timestep * 1e3:g} ms | {result[0]:.1f} | {result[1]:.1f} | {ours[env_id]:.3f} |")


if __name__ == "__main__":
    main()
