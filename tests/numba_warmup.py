"""Compile the environments' Numba kernels into their on-disk cache, in one pass over every code path.

``make setup`` runs it (``python -m tests.numba_warmup``) while pip installs the extras, and with ``pytest -n 2``
the conftest runs it again before the workers start (it then only loads the cache, a few seconds, or compiles what
a changed source file needs), so that each kernel is compiled once and the workers load it from ``__pycache__``
instead of compiling it side by side. It only fills
the cache: what a test asserts is unchanged, and a kernel it misses is compiled on first use as before.

The warm-up comes in two ``PARTS`` of about equal compile time (the hexapod's kernels, and everyone else's),
which ``warm_up_in_parallel`` runs in two processes at once. Processes that save into one Numba cache at the
same time need ``lock_numba_cache``: Numba's save is a read-modify-write of the index file, and two processes
saving different signatures of one function would each number its data file 1, so that the index of one
pointed at the code of the other.
"""

from __future__ import annotations

import functools
import os
import pickle
import subprocess
import sys
from pathlib import Path

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
    # force control: the second integrator on each row path (the other force ids share these kernels)
    "Planar3RPRForceReach-v0",
    "StewartGoughForceReach-v0",
    "DeltaForceReach-v0",
)

#: The ids of each part of the warm-up (about 80 s of compiling each on one core): the hexapod's but its Track, and
#: the others with the hexapod's Track last (its step kernels are the Reach ones, in the cache by then).
PARTS = (
    tuple(env_id for env_id in IDS if env_id.startswith("StewartGough") and "Track" not in env_id),
    (*(env_id for env_id in IDS if not env_id.startswith("StewartGough")), "StewartGoughTrack-v0"),
)

#: The ids whose robot as built and as measured (``envs.hardware``) the warm-up compiles.
HARDWARE_IDS = ("Planar3RPRReach-v0", "StewartGoughReach-v0", "DeltaReach-v0", "Planar3RRRReach-v0")


def lock_numba_cache() -> bool:
    """Make Numba's cache saves and loads exclusive between processes (``flock`` on the cache folder).

    A save (read the index, number the data file, write both) and a load (read the index, then the data file)
    then never interleave with another process's save. Idempotent; returns False where ``fcntl`` is missing
    (the caller then must not compile in two processes at once).
    """
    try:
        import fcntl
    except ImportError:
        return False
    from numba.core.caching import IndexDataCacheFile

    if getattr(IndexDataCacheFile, "_locked_between_processes", False):
        return True

    def locked(method):
        @functools.wraps(method)
        def wrapper(self, *args):
            try:
                folder = os.open(self._cache_path, os.O_RDONLY)
            except OSError:  # no folder, so no index to share yet: Numba's own handling
                return method(self, *args)
            try:
                fcntl.flock(folder, fcntl.LOCK_EX)
                return method(self, *args)
            finally:
                os.close(folder)  # releases the lock

        return wrapper

    IndexDataCacheFile.save = locked(IndexDataCacheFile.save)
    IndexDataCacheFile.load = locked(IndexDataCacheFile.load)
    IndexDataCacheFile._locked_between_processes = True
    return True


def warm_up_in_parallel() -> None:
    """``warm_up`` of each part at once: part 0 in a subprocess, the others here (serially where no lock).

    Raises:
        RuntimeError: If the subprocess failed (after this process's parts ran).
    """
    if not lock_numba_cache():
        warm_up()
        return
    root = Path(__file__).resolve().parents[1]
    other = subprocess.Popen(
        [sys.executable, "-m", "tests.numba_warmup", "0"], cwd=root, stdout=subprocess.PIPE, stderr=subprocess.STDOUT
    )
    try:
        for part in range(1, len(PARTS)):
            warm_up(part)
    finally:
        output, _ = other.communicate()
    if other.returncode:
        raise RuntimeError(f"warm-up part 0 failed:\n{output.decode(errors='replace')[-3000:]}")


def warm_up(part: int | None = None) -> None:
    """Reset and step each id's env, a pickled copy of it, and its vector env (one robot, and a multi-core batch).

    Args:
        part: Only the ids of ``PARTS[part]``; default every id.
    """
    import envs  # noqa: F401  (registers the ids)
    from envs.kernels.setup import PARALLEL_MIN_BATCH

    ids = IDS if part is None else PARTS[part]
    for env_id in ids:
        scale = 0.05 if "Force" in env_id else 1.0  # small efforts: a full random push can end the episode at once
        env = gym.make(env_id)
        env.reset(seed=0)
        env.action_space.seed(0)
        env.step(scale * env.action_space.sample())
        clone = pickle.loads(pickle.dumps(env))  # its constants come back read-only: the same specialisations
        for made in (env, clone):
            for _ in range(2):
                _, _, terminated, truncated, _ = made.step(scale * made.action_space.sample())
                if terminated or truncated:
                    made.reset()
            made.reset(seed=1)
            made.close()
        for n in (2, PARALLEL_MIN_BATCH + 1):
            vec = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
            vec.reset(seed=0)
            vec.action_space.seed(0)
            for _ in range(2):
                vec.step((scale * vec.action_space.sample()).astype(np.float32))
            vec.close()
        if "Force" in env_id:  # the transition alone under force control (the oracle tests call it)
            _force_transition(gym.make(env_id).unwrapped)
    # the robot as built and as measured (``envs.hardware``): per-robot constants and the forward kinematics
    hardware = {"observation_source": "encoders", "geometry_tolerance": 0.001}
    for env_id in (env_id for env_id in HARDWARE_IDS if env_id in ids):
        for n in (1, PARALLEL_MIN_BATCH + 1):
            vec = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **hardware)
            vec.reset(seed=0)
            vec.step(np.zeros(vec.action_space.shape, dtype=np.float32))
            vec.close()
    if "Planar3RPRReach-v0" in ids:
        family = gym.make("Planar3RPRReachFamily-v0")
        family.reset(seed=0)
        family.step(np.zeros(3, dtype=np.float32))
    if "StewartGoughReach-v0" in ids:
        _batch_kernels(gym.make("StewartGoughReach-v0").unwrapped)
    if "Planar3RRRReach-v0" in ids:  # the work-array paths of the spaces the register paths serve (compared by a test)
        for env_id in ("Planar3RRRReach-v0", "Planar3PRRReach-v0", "Planar3RPRReach-v0", "DeltaReach-v0"):
            _work_array_transition(gym.make(env_id).unwrapped)
        for env_id in ("Planar3RRRReach-v0", "Planar3PRRReach-v0"):  # force control on planar cranks and sliders
            _force_transition(gym.make(env_id, control="force").unwrapped)


def _force_transition(env: gym.Env) -> None:
    """``physics.transition`` of a force-control env (its entry kernel with the twists)."""
    from envs import physics

    start, reference = env.sample_tasks([np.random.default_rng(i) for i in range(2)], {})
    state = physics.initial_state(env.params, start, reference)
    physics.transition(env.params, state, np.zeros_like(state.q))


def _work_array_transition(env: gym.Env) -> None:
    """The work-array path's transition for a robot that steps on a register path (its pose space's)."""
    from envs import physics
    from envs.kernels import modes, packing, records
    from envs.kernels import step as step_kernels

    start, reference = env.sample_tasks([np.random.default_rng(i) for i in range(2)], {})
    state = physics.initial_state(env.params, start, reference)
    cs = env.params.packed_rows
    work = step_kernels._PATH_KERNELS[packing.WORK_ARRAYS, packing.pose_space_code(cs)]
    motion = records.Motion(state.q, state.x, state.t, state.det_sign, state.residual)
    modes.transition_batch(cs, motion, np.zeros_like(state.q), kernels=work)


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


if __name__ == "__main__":  # python -m tests.numba_warmup [part]: every part at once (make setup), or one part
    if len(sys.argv) > 1:
        lock_numba_cache()
        warm_up(int(sys.argv[1]))
    else:
        warm_up_in_parallel()
