"""Compile the environments' Numba kernels into their on-disk cache, in one pass over every code path.

With ``pytest -n 2`` the conftest runs ``warm_up`` in the controller before the workers start, so on a fresh
clone each kernel is compiled once and the workers load it from ``__pycache__`` instead of compiling it side
by side. It only fills the cache: what a test asserts is unchanged, and a kernel it misses is compiled on
first use as before.
"""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np

#: One id per pose space and actuator kind (planar legs, spatial legs, translational cranks, planar cranks,
#: planar sliders), with the 3-RPR's grid tasks, hard targets and a Track reference.
IDS = (
    "Planar3RPRReach-v0",
    "Planar3RPRReachHard-v0",
    "Planar3RPRTrack-v0",
    "StewartGoughReach-v0",
    "StewartGoughReachHard-v0",
    "StewartGoughTrack-v0",
    "DeltaReach-v0",
    "DeltaTrack-v0",
    "Planar3RRRReach-v0",
    "Planar3PRRReach-v0",
)


def warm_up() -> None:
    """Reset and step each id's env, a pickled copy of it, and its vector env (one robot, and a multi-core batch)."""
    import envs  # noqa: F401  (registers the ids)
    from envs.kernels.setup import PARALLEL_MIN_BATCH

    for env_id in IDS:
        env = gym.make(env_id)
        env.reset(seed=0)
        env.action_space.seed(0)
        env.step(env.action_space.sample())
        clone = pickle.loads(pickle.dumps(env))  # its constants come back read-only: the same specialisations
        for made in (env, clone):
            for _ in range(2):
                made.step(made.action_space.sample())
            made.reset(seed=1)
            made.close()
        for n in (2, PARALLEL_MIN_BATCH + 1):
            vec = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
            vec.reset(seed=0)
            vec.action_space.seed(0)
            for _ in range(2):
                vec.step(vec.action_space.sample().astype(np.float32))
            vec.close()
    # the robot as built and as measured (``envs.hardware``): per-robot constants and the forward kinematics
    hardware = {"observation_source": "encoders", "geometry_tolerance": 0.001}
    for env_id in ("Planar3RPRReach-v0", "StewartGoughReach-v0", "DeltaReach-v0", "Planar3RRRReach-v0"):
        for n in (1, PARALLEL_MIN_BATCH + 1):
            vec = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **hardware)
            vec.reset(seed=0)
            vec.step(np.zeros(vec.action_space.shape, dtype=np.float32))
            vec.close()
    family = gym.make("Planar3RPRReachFamily-v0")
    family.reset(seed=0)
    family.step(np.zeros(3, dtype=np.float32))
    _batch_kernels(gym.make("StewartGoughReach-v0").unwrapped)


def _batch_kernels(env: gym.Env) -> None:
    """The batch kernels the tests call without an env: transition, safe set, segments, singularity measures."""
    from envs import physics
    from envs.kernels import generic as fk

    params = env.params
    start, reference = env.sample_tasks([np.random.default_rng(i) for i in range(4)], {})
    state = physics.initial_state(params, start, reference)
    physics.transition(params, state, np.zeros_like(state.q))
    fk.safe_batch(params.packed, start)
    fk.segment_batch(params.packed, start, start[::-1].copy())
    fk.safety_batch(params.packed, start)  # the planners' certificate (segment_min_safety_batch shares the loop)
    fk.singularity_batch(params.packed, state.q, start)


if __name__ == "__main__":
    warm_up()
