"""Task sampling is fair and the certified workspace is sound: safe starts, targets and references."""

from __future__ import annotations

import numpy as np
import pytest

from envs.kernels import generic as fk
from envs.kernels import setup as numba_setup
from envs.tasks import grid_kernels as workspace_kernels
from envs.tasks.grid import WorkspaceMap
from tests.envs.helpers import pose_metric

#: (env id, reset options) of every way to get a Reach task; the flag says whether it is a hard one.
REACH_CASES = [
    pytest.param("Planar3RPRReach-v0", None, False, id="standard"),
    pytest.param("Planar3RPRReach-v0", {"targets": "hard"}, True, id="hard-option"),
    pytest.param("Planar3RPRReachHard-v0", None, True, id="hard-id"),
]

SEEDS = range(25)


def is_safe(params, workspace: WorkspaceMap, x: np.ndarray) -> np.ndarray:
    """Whether poses (M, 3) are safe (sampling box, strokes with margin, k ≥ k_safe) and in a sampled region."""
    x = np.ascontiguousarray(np.reshape(x, (-1, 3)), dtype=np.float64)
    in_region = np.isin(workspace.component_of(x), workspace.component_ids)
    return fk.safe_batch(params.packed, x) & in_region


def segment_min_condition(params, start: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Smallest k (library, LAPACK) at the sampler's points of each straight line start → target, shape (M,).

    NaN where a point is out of the actuators' reach; a leg of zero length is kept at 1e-9 (as the grid's is).
    """
    s = np.linspace(0.0, 1.0, workspace_kernels.SEGMENT_POINTS)[None, :, None]
    points = start[:, None, :] + s * (target - start)[:, None, :]
    q = params.robot.inverse_kinematics(points, validate=False)
    if "leg" in params.robot.actuator_kinds:
        q = np.maximum(q, 1e-9)
    k = np.full(q.shape[:2], np.nan)
    reached = np.all(np.isfinite(q), axis=-1)
    k[reached] = params.robot.inverse_condition_number(q[reached], points[reached], validate=False)
    return k.min(axis=1)


def component_node(workspace: WorkspaceMap, params, component: int, rank: int = 0) -> np.ndarray:
    """Pose of the ``rank``-th best-conditioned safe node of a sampled component, shape (3,)."""
    flat = workspace.component_nodes[int(component)]
    poses = workspace.nodes.reshape(-1, 3)[flat]
    inside = fk.safe_batch(params.packed, np.ascontiguousarray(poses))
    flat, poses = flat[inside], poses[inside]
    order = np.argsort(-workspace.safety.ravel()[flat], kind="stable")
    return poses[order[rank]].copy()


def _reach_tasks(env, options) -> tuple[np.ndarray, np.ndarray]:
    """(starts, targets), each (len(SEEDS), 3), of resets with the given options."""
    starts, targets = [], []
    for seed in SEEDS:
        _, info = env.reset(seed=seed, options=options)
        np.testing.assert_array_equal(info["pose"], env.unwrapped.state.x[0])
        starts.append(info["pose"])
        targets.append(info["target"])
    return np.array(starts), np.array(targets)


@pytest.mark.parametrize(("env_id", "options", "hard"), REACH_CASES)
def test_start_and_target_are_safe_and_connected(env_id, options, hard, make_env):
    """Start and target are both safe and lie in the same component of the certified workspace."""
    env = make_env(env_id)
    params, workspace = env.unwrapped.params, env.unwrapped.workspace
    starts, targets = _reach_tasks(env, options)
    assert is_safe(params, workspace, starts).all()
    assert is_safe(params, workspace, targets).all()
    start_components = workspace.component_of(starts)
    np.testing.assert_array_equal(start_components, workspace.component_of(targets))
    assert np.isin(start_components, workspace.component_ids).all()


@pytest.mark.parametrize(("env_id", "options", "hard"), REACH_CASES)
def test_targets_are_far_and_hard_ones_cross_the_ill_conditioned_zone(env_id, options, hard, make_env):
    """Every pair is ≥ 0.1 m apart in (x, y, ℓ_c φ); hard pairs' straight line dips below hard_threshold."""
    env = make_env(env_id)
    params = env.unwrapped.params
    starts, targets = _reach_tasks(env, options)
    distance = np.linalg.norm((targets - starts) * pose_metric(params), axis=-1)
    assert distance.min() >= 0.1, distance.min()
    line_min = segment_min_condition(params, starts, targets)
    if hard:
        assert np.all(line_min < params.hard_threshold), line_min
    else:
        assert np.any(line_min >= params.hard_threshold), "standard targets are all hard ones"


@pytest.mark.parametrize("env_id", ["Planar3RPRReach-v0", "Planar3RRRReach-v0"])
def test_the_straight_line_check_of_hard_pairs_matches_the_library(env_id, make_env):
    """``_straight_dips_below`` says whether the library's k dips below the threshold at the sampler's points.

    Random lines of the pose bounds (the 3-RRR's cranks cannot reach some of their points: k is NaN there, which
    rejects the line), at the hard threshold and at thresholds where the proof of k ≥ t succeeds at most points.
    """
    params = make_env(env_id).unwrapped.params
    lo, hi = np.array(params.pose_low), np.array(params.pose_high)
    rng = np.random.default_rng(17)
    start, target = lo + (hi - lo) * rng.random((2, 400, 3))
    line_min = segment_min_condition(params, start, target)
    outcomes = set()
    for threshold in (params.hard_threshold, 0.1, 0.3):
        got = np.array(
            [
                workspace_kernels._straight_dips_below(params.packed, a, b, workspace_kernels.SEGMENT_POINTS, threshold)
                for a, b in zip(start, target)
            ]
        )
        clear = ~np.isclose(line_min, threshold, rtol=1e-9)
        np.testing.assert_array_equal(got[clear], (line_min < threshold)[clear])
        outcomes |= set(got.tolist())
    assert outcomes == {True, False}
    if "leg" not in params.robot.actuator_kinds:
        assert np.isnan(line_min).any(), "no line leaves the cranks' reach"


def test_every_component_has_one_det_sign(make_env):
    """Within each connected safe region sign(det J_x) is constant (one working mode per region)."""
    workspace = make_env("Planar3RPRReach-v0").unwrapped.workspace
    labels = np.unique(workspace.labels)
    labels = labels[labels != 0]
    assert labels.size >= 1
    for component in labels:
        signs = np.unique(workspace.det_sign[workspace.labels == component])
        assert signs.size == 1 and signs[0] != 0, f"component {component} has det signs {signs}"
    assert set(workspace.component_ids) <= set(labels)


def test_grid_certification_is_sound(make_env):
    """Along the segment between face-adjacent safe nodes of a kept component, k stays above hard_threshold."""
    env = make_env("Planar3RPRReach-v0")
    params, workspace = env.unwrapped.params, env.unwrapped.workspace
    rng = np.random.default_rng(5)
    labels = workspace.labels
    shape = np.array(labels.shape)
    kept = np.argwhere(np.isin(labels, workspace.component_ids))
    first = kept[rng.integers(0, len(kept), size=20_000)]
    second = first.copy()
    axis = rng.integers(0, 3, size=len(first))
    second[np.arange(len(first)), axis] += rng.choice([-1, 1], size=len(first))
    inside = np.all((second >= 0) & (second < shape), axis=-1)
    first, second = first[inside], second[inside]
    same = labels[tuple(first.T)] == labels[tuple(second.T)]
    first, second = first[same], second[same]
    assert len(first) > 10_000
    nodes = workspace.nodes
    a, b = nodes[tuple(first.T)], nodes[tuple(second.T)]
    s = np.linspace(0.0, 1.0, 20)[None, :, None]
    points = a[:, None, :] + s * (b - a)[:, None, :]
    q = params.robot.inverse_kinematics(points)
    k = params.robot.inverse_condition_number(q, points)
    worst = np.unravel_index(np.argmin(k), k.shape)
    assert k.min() > params.hard_threshold, f"k = {k.min()} at {points[worst]}"


def test_track_references_are_safe_everywhere(make_env):
    """Every step pose along a period of each sampled reference is safe and in one component."""
    env = make_env("Planar3RPRTrack-v0")
    unwrapped = env.unwrapped
    params, workspace = unwrapped.params, unwrapped.workspace
    period_steps = int(round(params.track_period / params.dt))
    t = np.arange(period_steps)
    failures = []
    for seed in range(200):
        env.reset(seed=seed)
        reference = unwrapped.state.reference
        one = [np.repeat(a, len(t), axis=0) for a in (reference.center, reference.amplitude, reference.phase)]
        poses, _ = fk.reference_batch(params.packed, t, *one)
        safe = is_safe(params, workspace, poses)
        components = np.unique(workspace.component_of(poses))
        if not safe.all() or components.size != 1:
            failures.append((seed, t[~safe].tolist(), components.tolist()))
    assert not failures, f"unsafe reference points (seed, steps, components): {failures}"


def test_explicit_start_and_target(make_env):
    """reset(options={"start", "target"}) with safe poses of one component starts exactly there."""
    env = make_env("Planar3RPRReach-v0")
    workspace = env.unwrapped.workspace
    component = workspace.component_ids[np.argmax(workspace.component_weights)]
    start, target = (
        component_node(workspace, env.unwrapped.params, component, 0),
        component_node(workspace, env.unwrapped.params, component, 50),
    )
    for options in ({"start": start, "target": target}, {"start": start, "target": target, "targets": "hard"}):
        obs, info = env.reset(seed=0, options=options)
        np.testing.assert_array_equal(env.unwrapped.state.x[0], start)
        np.testing.assert_array_equal(info["pose"], start)
        np.testing.assert_array_equal(info["target"], target)
        np.testing.assert_allclose(obs[:2], start[:2], rtol=0, atol=1e-6)
        np.testing.assert_allclose(obs[4:6], target[:2], rtol=0, atol=1e-6)
    _, _, terminated, _, _ = env.step(np.zeros(3, dtype=np.float32))
    assert not terminated


@pytest.mark.parametrize("given", ["start", "target"])
def test_explicit_start_or_target_alone(given, make_env):
    """Giving only a safe start (or target) draws the other end in the same component."""
    env = make_env("Planar3RPRReach-v0")
    workspace = env.unwrapped.workspace
    smallest = workspace.component_ids[np.argmin(workspace.component_weights)]
    pose = component_node(workspace, env.unwrapped.params, smallest)
    for seed in range(10):
        _, info = env.reset(seed=seed, options={given: pose})
        other = info["target"] if given == "start" else info["pose"]
        np.testing.assert_array_equal(info["pose"] if given == "start" else info["target"], pose)
        assert workspace.component_of(other) == smallest


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"start": [0.5, 0.3]}, r"options\['start'\] must be 3 finite numbers, got \[0.5, 0.3\]"),
        ({"target": [[0.5, 0.3, 0.0]]}, r"options\['target'\] must be 3 finite numbers, got \[\[0.5, 0.3, 0.0\]\]"),
        ({"start": [0.5, np.nan, 0.0]}, r"options\['start'\] must be 3 finite numbers, got \[0.5, nan, 0.0\]"),
        ({"start": [5.0, 5.0, 0.0]}, r"options\['start'\] = \[5.0, 5.0, 0.0\] is not in the certified safe"),
        ({"target": [0.5, 0.0, 0.0]}, r"options\['target'\] = \[0.5, 0.0, 0.0\] is not in the certified safe set"),
        ({"targets": "impossible"}, r"options\['targets'\] must be one of \('standard', 'hard', 'mixed'\)"),
        ({"goal": [0.5, 0.3, 0.0]}, r"unknown reset option\(s\) \['goal'\]"),
    ],
)
def test_bad_reach_options_raise(options, match, make_env):
    """Wrong-shaped, non-finite or unsafe poses and unknown keys are refused with a precise message."""
    env = make_env("Planar3RPRReach-v0")
    with pytest.raises(ValueError, match=match):
        env.reset(seed=0, options=options)


def test_explicit_poses_in_different_components_raise(make_env):
    """A start and a target in different safe regions (different working modes) are refused."""
    env = make_env("Planar3RPRReach-v0")
    workspace = env.unwrapped.workspace
    first, second = workspace.component_ids[:2]
    options = {
        "start": component_node(workspace, env.unwrapped.params, first),
        "target": component_node(workspace, env.unwrapped.params, second),
    }
    with pytest.raises(ValueError, match="different safe regions"):
        env.reset(seed=0, options=options)


@pytest.mark.parametrize("key", ["start", "targets", "speed"])
def test_track_refuses_unknown_options(key, make_env):
    """Track takes no reset options; any key is refused, naming it."""
    env = make_env("Planar3RPRTrack-v0")
    with pytest.raises(ValueError, match=rf"unknown reset option\(s\) \['{key}'\]"):
        env.reset(seed=0, options={key: [0.5, 0.3, 0.0]})


# -- the kernels draw from the env's own generators ------------------------------------------------------

BIT_GENERATORS = [np.random.PCG64, np.random.PCG64DXSM, np.random.MT19937, np.random.Philox, np.random.SFC64]


@pytest.mark.parametrize("bit_generator", BIT_GENERATORS, ids=lambda b: b.__name__)
def test_kernel_streams_draw_what_generator_random_draws(bit_generator):
    """``numba_setup.uniform_batch`` gives ``Generator.random``'s numbers and leaves the same generator state."""
    mine = [np.random.Generator(bit_generator(seed)) for seed in (1, 2, 3)]
    numpy = [np.random.Generator(bit_generator(seed)) for seed in (1, 2, 3)]
    drawn = numba_setup.uniform_batch(numba_setup.random_streams(mine), 257)
    for row, generator in zip(drawn, numpy):
        np.testing.assert_array_equal(row, generator.random(257))
    for a, b in zip(mine, numpy):
        np.testing.assert_equal(a.bit_generator.state, b.bit_generator.state)


def test_random_streams_refuse_non_generators():
    """A legacy RandomState has no bit generator to hand to the kernels: a TypeError names it."""
    with pytest.raises(TypeError, match=r"expected a numpy\.random\.Generator, got RandomState"):
        numba_setup.random_streams([np.random.RandomState(0)])


@pytest.mark.parametrize(
    ("env_id", "options"),
    [
        ("Planar3RPRReach-v0", {}),
        ("Planar3RPRReach-v0", {"targets": "hard"}),
        ("Planar3RPRTrack-v0", {}),
    ],
)
def test_sample_tasks_in_one_call_equal_one_at_a_time(env_id, options, make_env):
    """The vector env's batched draw (one generator per task) equals drawing each task alone."""
    env = make_env(env_id).unwrapped
    seeds = range(40, 52)
    starts, reference = env.sample_tasks([np.random.default_rng(s) for s in seeds], options)
    assert starts.shape == (len(seeds), 3)
    for i, seed in enumerate(seeds):
        start, alone = env.sample_tasks([np.random.default_rng(seed)], options)
        np.testing.assert_array_equal(starts[i], start[0])
        for batched, single in zip(reference[:3], alone[:3]):
            np.testing.assert_array_equal(batched[i], single[0])
