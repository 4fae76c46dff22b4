"""Native vector environments: N robots of the family stepped at once by the single env's batched functions."""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from envs import physics
from envs.arguments import Parameter, Range, table
from envs.env import TRAIL_LENGTH, FamilyEnvBase, FamilyReachEnv, FamilyTrackEnv, render_frames
from envs.info import step_info
from envs.kernels.setup import random_streams, uses_every_core
from envs.physics import NonFiniteActionError, StepBuffers, evaluate
from envs.state import FamilyState, copy_state, put_rows, state_arrays

__all__ = ["FamilyReachVectorEnv", "FamilyTrackVectorEnv", "FamilyVectorEnv", "episode_starts"]


def episode_starts(mode: AutoresetMode, ended: np.ndarray, terminated: np.ndarray, truncated: np.ndarray) -> np.ndarray:
    """Rows whose observation from this ``step`` is the first of their next episode, shape (N,) bool.

    Args:
        mode: The vector env's ``autoreset_mode``.
        ended: Rows that had ended at the previous step (terminated or truncated), shape (N,) bool.
        terminated: This step's terminations, shape (N,) bool.
        truncated: This step's truncations, shape (N,) bool.

    Returns:
        With ``NEXT_STEP`` the rows in ``ended`` (this step reset them and ignored their action); with
        ``SAME_STEP`` the rows ending now (their observation is already the next episode's); with ``DISABLED``
        none.
    """
    if mode == AutoresetMode.NEXT_STEP:
        return np.asarray(ended, dtype=bool).copy()
    if mode == AutoresetMode.SAME_STEP:
        return np.asarray(terminated, dtype=bool) | np.asarray(truncated, dtype=bool)
    return np.zeros(np.shape(ended), dtype=bool)


#: The vector env's own keyword arguments (its Arguments table); every other one is the single env's.
NUM_ENVS = Parameter("num_envs", 1, "number of robots N", check=Range(1, integer=True))
MAX_EPISODE_STEPS = Parameter(
    "max_episode_steps", None, "truncation length; None: the registered one", check=Range(1, integer=True),
    type="int or None",
)  # fmt: skip
VECTOR_ARGUMENTS = (
    NUM_ENVS,
    MAX_EPISODE_STEPS,
    Parameter("autoreset_mode", AutoresetMode.NEXT_STEP, "see Episode End", type="AutoresetMode or str"),
    Parameter("render_mode", None, '"rgb_array": `render()` returns the N frames', type="str or None"),
)


def _count(parameter: Parameter, value: Any) -> int:
    """``value`` as an int in the range of ``parameter.check``, or a TypeError / ValueError naming it."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{parameter.name} must be an int, got {type(value).__name__} {value!r}")
    if not parameter.check.contains(value):
        raise ValueError(f"{parameter.name} must be {parameter.check.text}, got {value}")
    return int(value)


class FamilyVectorEnv(VectorEnv):
    """N robots of the family in one batch: the native vector form of a single environment.

    ## Description
    Every sub-environment is exactly the single environment of the same id (``envs.env.FamilyReachEnv`` or
    ``FamilyTrackEnv`` with that id's preset, see their docstrings); this class holds the state of the N robots
    as arrays with a leading dimension N and advances them with the very functions the single environment
    calls with N = 1 (``envs.physics.step`` and ``evaluate``, whose compiled kernels do the dynamics, reward and
    observation robot by robot, on every core for large N; ``initial_state``, ``envs.info.step_info``, and the single
    environment's own task sampling). Nothing of the dynamics, reward, sampling or info is copied here, so the
    two cannot drift apart: sub-environment i of `reset(seed=s)` behaves exactly as `gym.make(id)` reset with
    seed s + i, to the last bit.

    The step is one compiled pass over the robots; only starting new episodes loops in Python over the
    robots that start one (each draws its task from its own generator, as the single env does).

    ## Action Space
    `Box(-1, 1, (N, n), float32)`: row i is the action of sub-environment i (actuator rates
    q̇_j / max_rate). `single_action_space` is the single env's `Box(-1, 1, (n,), float32)`.

    ## Observation Space
    `Box(low, high, (N, D), float32)`: row i is the single env's observation; `single_observation_space` is
    the single env's.

    ## Rewards
    Row i is the single env's reward; every reward term is in the infos and the reward is their sum.

    ## Starting State
    As the single env; `reset(options=...)` accepts the single env's options (given to every
    sub-environment), and `options["reset_mask"]` (bool array (N,)) resets only the masked ones.

    ## Episode End
    Termination as the single env. Truncation after `max_episode_steps` steps (the registered
    value by default), counted here instead of by a `TimeLimit` wrapper: `truncated` is True on the
    step that reaches it, even if `terminated` is True too (as `TimeLimit` does). Sub-environments
    that end are reset automatically, following Gymnasium 1.x's `autoreset_mode`
    (https://farama.org/Vector-Autoreset-Mode):

    * `NEXT_STEP` (default): the step after the end resets the sub-environment and ignores its
      action; it returns the first observation, reward 0, `terminated = truncated = False` and the
      reset info.
    * `SAME_STEP`: the ending step resets it at once and returns the new episode's first
      observation and its reset info, with the reward and flags of the ending step;
      `infos["final_obs"]` (object array, the last observation of the ended episodes) and
      `infos["final_info"]` (their step infos, in the vector layout) are set where
      `infos["_final_obs"]` / `infos["_final_info"]` are True.
    * `DISABLED`: no autoreset; stepping an ended sub-environment raises `ResetNeeded`, reset it
      with `reset(options={"reset_mask": mask})`.

    Infos use Gymnasium's vector layout: `infos[key]` is an array with a leading dimension N and
    `infos["_" + key]` a boolean mask of the sub-environments that report it
    (`termination_reason` is an object array of strings).

    ## Arguments
    {arguments}

    ## Memory
    Memory grows linearly with N (`benchmarks.bench_vector_env` prints the figures): the state arrays (q, x,
    t, det sign, k, k_I, residual and the reference: centre, amplitude, phase, target strokes), the kept
    observations, each sub-environment's `np.random.Generator` (about 860 bytes), and two sets of step
    outputs reused in turn.

    ## Version History
    * v0: Initial version.
    """

    metadata: ClassVar[dict[str, Any]] = {
        "render_modes": ["rgb_array"],
        "render_fps": 20,
        "autoreset_mode": AutoresetMode.NEXT_STEP,
    }
    #: The single environment this class vectorises (set by the concrete classes).
    single_env_class: ClassVar[type[FamilyEnvBase] | None] = None
    #: Truncation length of the registered ids of this class.
    default_max_episode_steps: ClassVar[int] = 200

    def __init__(
        self,
        num_envs: int = 1,
        *,
        max_episode_steps: int | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        cls = type(self).single_env_class
        if cls is None:
            raise TypeError("FamilyVectorEnv is abstract; use FamilyReachVectorEnv or FamilyTrackVectorEnv")
        self.num_envs = _count(NUM_ENVS, num_envs)
        if max_episode_steps is None:
            max_episode_steps = type(self).default_max_episode_steps
        self.max_episode_steps = _count(MAX_EPISODE_STEPS, max_episode_steps)
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError as exc:
            valid = [mode.value for mode in AutoresetMode]
            raise ValueError(
                f"autoreset_mode must be an AutoresetMode or one of {valid}, got {autoreset_mode!r}"
            ) from exc
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.render_mode = render_mode
        # One single env validates the keyword arguments (build_family_params, same errors) and draws the tasks
        # of every sub-environment, each with that sub-environment's generator.
        self._sampler = cls(render_mode=None, **kwargs)
        self.params = self._sampler.params
        self.with_velocity = cls.with_velocity
        self.metadata = {
            **type(self).metadata,
            "render_fps": 1.0 / self.params.dt,
            "autoreset_mode": self.autoreset_mode,
        }

        self.single_action_space = self._sampler.action_space
        self.single_observation_space = self._sampler.observation_space
        self._n_actions = self.single_action_space.shape[0]
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)

        self._generators: list[np.random.Generator | None] = [None] * self.num_envs
        # The kernels' handle on each generator (``envs.kernels.setup.random_streams``), made once per generator:
        # an episode start then costs no Python work per robot beyond its task's compiled draw.
        self._streams = np.zeros((self.num_envs, 2), dtype=np.uint64)
        self._scratch_generator = np.random.default_rng(0)  # draws thrown away (see ``step``)
        self._scratch_stream = random_streams([self._scratch_generator])[0]
        self._seeds: list[int | None] = [None] * self.num_envs
        self._state: FamilyState | None = None
        self._observations: np.ndarray | None = None
        # Two sets of step outputs, used in turn (a step never writes over the state it starts from),
        # so that stepping allocates no large arrays.
        self._buffers = tuple(StepBuffers(self.params, self.num_envs, self.with_velocity) for _ in range(2))
        self._next = 0
        self._ended = np.zeros(self.num_envs, dtype=bool)
        self._trails: list[deque[np.ndarray]] = []

    # -- the Gymnasium vector API -----------------------------------------------------------------

    def reset(
        self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start new episodes in every sub-environment (or in those of ``options["reset_mask"]``).

        Args:
            seed: None (keep each sub-environment's generator, or draw one at the first reset), an
                int s (sub-environment i is seeded s + i), or a sequence of N ints or Nones.
            options: The single env's reset options, given to every sub-environment, plus
                ``"reset_mask"``: a bool array of shape (N,) selecting the sub-environments to reset.

        Returns:
            (observations (N, obs_dim) float32, infos in the vector layout). With a mask, the other
            rows of the observations are their latest ones and their info masks are False.
        """
        seeds = self._seed_list(seed)
        options = {} if options is None else options
        if not isinstance(options, dict):
            raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
        options = dict(options)
        mask = options.pop("reset_mask", None)
        rows = np.arange(self.num_envs) if mask is None else self._mask_rows(mask)
        if mask is not None and self._state is None:
            raise gym.error.ResetNeeded("reset with a reset_mask needs a first reset of every sub-environment")
        unknown = set(options) - set(self._sampler.reset_options)
        if unknown:
            raise ValueError(
                f"unknown reset option(s) {sorted(unknown)}; valid options are "
                f"{[*self._sampler.reset_options, 'reset_mask']}"
            )
        for i in rows:
            if seeds[i] is not None or self._generators[i] is None:
                self._new_generator(i, seeds[i])
        fresh = self._start_episodes(rows, options)
        if mask is None:
            self._state = fresh
            self._trails = [deque(maxlen=TRAIL_LENGTH) for _ in range(self.num_envs)]
        else:
            put_rows(self._state, rows, fresh)
        self._ended[rows] = False
        observations, info = self._evaluate(fresh)
        if self._observations is None:
            self._observations = observations
        else:
            self._observations[rows] = observations
        self._restart_trails(rows)
        return self._observations.copy(), self._vector_info(info, None if mask is None else rows)

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Advance every robot by one control period dt (ended ones are reset per ``autoreset_mode``).

        Args:
            actions: Normalised stroke rates, shape (N, 3), finite; out-of-range values are clipped.

        Returns:
            (observations (N, obs_dim) float32, rewards (N,) float64, terminations (N,) bool,
            truncations (N,) bool, infos in the vector layout).
        """
        if self._state is None:
            raise gym.error.ResetNeeded("Cannot call step() before reset()")
        a = self._check_actions(actions)
        if self.autoreset_mode == AutoresetMode.DISABLED and self._ended.any():
            ended = np.flatnonzero(self._ended).tolist()
            raise gym.error.ResetNeeded(
                f"sub-environment(s) {ended[:10]} have ended and autoreset_mode is DISABLED; "
                "reset them with reset(options={'reset_mask': mask})"
            )
        out = self._buffers[self._next]  # not the one holding self._state
        streams = None
        if self.params.observation_source == "encoders":
            streams = self._streams
            if self.autoreset_mode == AutoresetMode.NEXT_STEP and self._ended.any():
                # Robots that restart this step draw no encoder noise from their own generators (a single env
                # that has ended is not stepped), so their next task is the one the single env would draw.
                streams = streams.copy()
                streams[self._ended] = self._scratch_stream
        try:
            state, outcome, evaluation, observations = physics.step(
                self.params, self._state, a, self.with_velocity, out, validate=False, streams=streams
            )
        except NonFiniteActionError as exc:  # checked inside the compiled pass; no robot has moved
            bad = exc.rows
            raise ValueError(
                f"actions must be finite; sub-environment(s) {bad[:10].tolist()} got e.g. {a[bad[0]].tolist()}"
            ) from None
        self._next ^= 1
        self._state = state
        info = step_info(self.params, evaluation, outcome.reason, state, outcome)
        rewards = evaluation[self.params.evaluation_rows["reward"]].copy()
        terminations = outcome.reason != 0
        truncations = state.t >= self.max_episode_steps
        extra: dict[str, Any] = {}
        restarted = np.empty(0, dtype=np.int64)
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            restarted = np.flatnonzero(self._ended)
            if restarted.size:
                rewards[restarted] = 0.0
                terminations[restarted] = False
                truncations[restarted] = False
                self._restart(restarted, observations, info)
            self._ended = terminations | truncations
        elif self.autoreset_mode == AutoresetMode.SAME_STEP:
            ended = terminations | truncations
            restarted = np.flatnonzero(ended)
            if restarted.size:
                final_obs = np.full(self.num_envs, None, dtype=object)
                for i in restarted:
                    final_obs[i] = observations[i].copy()
                extra = {
                    "final_obs": final_obs,
                    "_final_obs": ended.copy(),
                    "final_info": self._vector_info({k: v[restarted] for k, v in info.items()}, restarted),
                    "_final_info": ended.copy(),
                }
                self._restart(restarted, observations, info)
        else:
            self._ended = terminations | truncations
        self._extend_trails(restarted)
        self._observations = observations
        infos = self._vector_info(info, None)
        infos.update(extra)
        return observations.copy(), rewards, terminations, truncations, infos

    def render(self) -> tuple[np.ndarray, ...] | None:
        """The frames of the N sub-environments (``rgb_array``); None without a render mode.

        Returns:
            A tuple of N uint8 arrays, as the single env's ``render()``.
        """
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        if self._state is None:
            raise gym.error.ResetNeeded("Cannot call render() before reset()")
        return tuple(render_frames(self.params, self._state, self._trails))

    def _trail_point(self, i: int) -> np.ndarray:
        return self.params.robot.pose_space.position(self._state.x[i]).copy()

    def close_extras(self, **kwargs: Any) -> None:
        """Release the task sampler (nothing else holds resources)."""
        self._sampler.close()

    # -- attributes -------------------------------------------------------------------------------

    @property
    def state(self) -> FamilyState | None:
        """A copy of the batched state of the N robots, or None before the first reset.

        The environment reuses its own arrays from step to step; the copy is yours to keep.
        """
        state = self._state
        return None if state is None else copy_state(state)

    @property
    def np_random(self) -> tuple[np.random.Generator, ...]:
        """The generators of the sub-environments (drawn from a random seed if not yet seeded)."""
        for i, generator in enumerate(self._generators):
            if generator is None:
                self._new_generator(i, None)
        return tuple(self._generators)

    @property
    def np_random_seed(self) -> tuple[int | None, ...]:
        """The seeds of the sub-environments' generators (None before their first reset)."""
        return tuple(self._seeds)

    def get_attr(self, name: str) -> tuple[Any, ...]:
        """An attribute of each sub-environment, as ``SyncVectorEnv.get_attr``.

        The spaces are the single ones, ``np_random`` / ``np_random_seed`` are per sub-environment and
        ``render_mode`` is this env's; anything else (``params``, ``workspace``, ``targets``, ...) is
        the single env's attribute, shared by every sub-environment.

        Args:
            name: A public attribute name.

        Returns:
            A tuple of N values.

        Raises:
            AttributeError: If the single env has no such public attribute.
        """
        if name in ("np_random", "np_random_seed"):
            return getattr(self, name)
        if name == "observation_space":
            value = self.single_observation_space
        elif name == "action_space":
            value = self.single_action_space
        elif name == "render_mode":
            value = self.render_mode
        elif name.startswith("_") or not hasattr(self._sampler, name):
            raise AttributeError(f"the sub-environments of {type(self).__name__} have no public attribute {name!r}")
        else:
            value = getattr(self._sampler, name)
        return (value,) * self.num_envs

    def set_attr(self, name: str, values: Any) -> None:
        """Set an attribute of every sub-environment (the value must be the same for all; they share it).

        Only plain attributes of the single env that new episodes read (such as ``targets`` of Reach)
        can be set; the parameters, spaces and generators are fixed at construction or by ``reset``.

        Args:
            name: Attribute name.
            values: One value, or a list or tuple of N equal values.

        Raises:
            ValueError: If the values differ between sub-environments, or the attribute is read-only.
        """
        if isinstance(values, (list, tuple)):
            if len(values) != self.num_envs:
                raise ValueError(f"set_attr needs one value or {self.num_envs} values, got {len(values)}")
            if any(v != values[0] for v in values[1:]):
                raise ValueError(f"the sub-environments share {name!r}; got different values {list(values)}")
            values = values[0]
        fixed = ("params", "workspace", "observation_space", "action_space", "render_mode", "metadata", "spec")
        if name.startswith("_") or name in fixed or not hasattr(self._sampler, name):
            raise ValueError(f"{name!r} cannot be set on the sub-environments of {type(self).__name__}")
        modes = type(self._sampler).target_modes if name == "targets" else ()
        if name == "targets" and values not in modes:
            raise ValueError(f"targets must be one of {modes}, got {values!r}")
        setattr(self._sampler, name, values)

    def state_nbytes(self) -> int:
        """Bytes held by the state arrays of the N robots (grows linearly with N).

        Returns:
            The sum of ``nbytes`` over the arrays of ``state`` (0 before the first reset).
        """
        if self._state is None:
            return 0
        return sum(field.nbytes for field in state_arrays(self._state))

    # -- helpers ----------------------------------------------------------------------------------

    def _evaluate(self, state: FamilyState) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Observations and per-robot info arrays (fresh, writable) of robots starting an episode (action 0)."""
        n = state.q.shape[0]
        action, reason = np.zeros((n, self._n_actions)), np.zeros(n, dtype=np.int64)
        parallel = uses_every_core(self.num_envs)  # the kernel of this env's steps (``physics.step``)
        evaluation, observations = evaluate(
            self.params, state, action, reason, self.with_velocity, parallel=parallel, validate=False
        )
        return observations, step_info(self.params, evaluation, reason, state, parallel=parallel)

    def _start_episodes(self, rows: np.ndarray, options: dict[str, Any]) -> FamilyState:
        """Draw a task for each sub-environment of ``rows`` with its own generator; their state at t = 0.

        One compiled call for all of them (the single env's ``start_episodes``), each drawing from its own generator.
        """
        generators = [self._generators[i] for i in rows.tolist()]
        parallel = uses_every_core(self.num_envs)
        return self._sampler.start_episodes(generators, options, self._streams[rows], parallel)

    def _new_generator(self, i: int, seed: int | None) -> None:
        """Give sub-environment i a new generator (seeded with ``seed``, or from entropy) and its stream."""
        self._generators[i], self._seeds[i] = seeding.np_random(seed)
        self._streams[i] = random_streams([self._generators[i]])[0]

    def _restart(self, rows: np.ndarray, observations: np.ndarray, info: dict[str, np.ndarray]) -> None:
        """Autoreset the sub-environments ``rows``: new episodes, their observations and reset infos."""
        for i in rows.tolist():  # Python ints: indexing the list with NumPy integers costs 0.7 µs a row
            if self._generators[i] is None:  # pragma: no cover - every row was reset before stepping
                self._new_generator(i, None)
        fresh = self._start_episodes(rows, {})
        put_rows(self._state, rows, fresh)
        new_obs, new_info = self._evaluate(fresh)
        observations[rows] = new_obs
        for key, value in new_info.items():
            info[key][rows] = value

    def _vector_info(self, info: dict[str, np.ndarray], rows: np.ndarray | None) -> dict[str, Any]:
        """Gymnasium's vector layout: ``key`` → array over N, ``_key`` → mask; ``rows`` None means all."""
        out: dict[str, Any] = {}
        if rows is None:
            for key, value in info.items():
                out[key] = value
                out[f"_{key}"] = np.ones(self.num_envs, dtype=bool)
            return out
        for key, value in info.items():
            if value.dtype == object:
                full = np.full(self.num_envs, None, dtype=object)
            else:
                full = np.zeros((self.num_envs, *value.shape[1:]), dtype=value.dtype)
            full[rows] = value
            mask = np.zeros(self.num_envs, dtype=bool)
            mask[rows] = True
            out[key], out[f"_{key}"] = full, mask
        return out

    def _restart_trails(self, rows: np.ndarray) -> None:
        if self.render_mode is None:
            return
        for i in rows:
            self._trails[i].clear()
            self._trails[i].append(self._trail_point(i))

    def _extend_trails(self, restarted: np.ndarray) -> None:
        if self.render_mode is None:
            return
        for i in range(self.num_envs):
            self._trails[i].append(self._trail_point(i))
        self._restart_trails(restarted)

    def _seed_list(self, seed: Any) -> list[int | None]:
        if seed is None:
            return [None] * self.num_envs
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            return [int(seed) + i for i in range(self.num_envs)]
        if isinstance(seed, Sequence) and not isinstance(seed, str):
            if len(seed) != self.num_envs:
                raise ValueError(
                    f"seed must be an int, None or a sequence of num_envs={self.num_envs}, got {len(seed)}"
                )
            return list(seed)
        raise TypeError(f"seed must be an int, None or a sequence of ints, got {type(seed).__name__} {seed!r}")

    def _mask_rows(self, mask: Any) -> np.ndarray:
        if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_:
            raise TypeError(f"options['reset_mask'] must be a numpy bool array, got {mask!r}")
        if mask.shape != (self.num_envs,):
            raise ValueError(f"options['reset_mask'] must have shape ({self.num_envs},), got {mask.shape}")
        if not mask.any():
            raise ValueError("options['reset_mask'] must select at least one sub-environment")
        return np.flatnonzero(mask)

    def _check_actions(self, actions: Any) -> np.ndarray:
        try:
            a = np.asarray(actions, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(
                f"actions must be an array of shape ({self.num_envs}, {self._n_actions}) of real numbers"
            ) from exc
        if a.shape != (self.num_envs, self._n_actions):
            raise ValueError(f"actions must have shape ({self.num_envs}, {self._n_actions}), got shape {a.shape}")
        return a  # finiteness is checked inside the compiled step


class FamilyReachVectorEnv(FamilyVectorEnv):
    """N robots of ``FamilyReachEnv`` (every Reach id) in one batch; see ``FamilyVectorEnv``."""

    single_env_class = FamilyReachEnv
    default_max_episode_steps = 200


class FamilyTrackVectorEnv(FamilyVectorEnv):
    """N robots of ``FamilyTrackEnv`` (every Track id) in one batch; see ``FamilyVectorEnv``."""

    single_env_class = FamilyTrackEnv
    default_max_episode_steps = 400


if FamilyVectorEnv.__doc__:  # None under python -OO
    FamilyVectorEnv.__doc__ = FamilyVectorEnv.__doc__.replace(
        "    {arguments}",
        table(VECTOR_ARGUMENTS)
        + "\n    | `**kwargs` | | | every argument of the single env, with its defaults and checks |",
    )
