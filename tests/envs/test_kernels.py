"""The compiled family kernels on the 3-RPR preset against NumPy oracles built on the kinematics library.

``envs.physics`` runs the dynamics, reward and observation of every robot through Numba kernels (a planar robot
with legs in registers, ``envs.kernels.paths``). Here, with ``ROBOT_PRESETS["planar_3rpr"]``, they are checked
against straightforward NumPy versions of the same algorithm that call ``kinematics.Planar3RPR`` (itself checked
against the lesson, SymPy and finite differences) and LAPACK.
"""

from __future__ import annotations

import numpy as np
import pytest

from envs import physics
from envs import state as family_state
from envs.kernels import generic as fk
from envs.kernels import layout as family_layout
from envs.kernels import linalg as linalg_kernels
from envs.kernels import setup as numba_setup
from envs.kernels import step as step_kernels
from envs.params import FamilyParams
from envs.physics import FamilyReference, FamilyState, initial_state
from envs.presets import build_family_params
from kinematics import Planar3RPR

# -- NumPy oracles (the pre-kernel implementation of the transition, on the kinematics library) ---------------


def _oracle_predict(params, q, x, q_rate, h, rate):
    robot = params.robot

    def pose_rate(q_, x_):
        return np.einsum("nij,nj->ni", robot.forward_jacobian(q_, x_, validate=False), q_rate)

    k1 = rate
    if params.integrator == "euler":
        return x + h * k1
    k2 = pose_rate(q + 0.5 * h * q_rate, x + 0.5 * h * k1)
    k3 = pose_rate(q + 0.5 * h * q_rate, x + 0.5 * h * k2)
    k4 = pose_rate(q + h * q_rate, x + h * k3)
    return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def oracle_transition(params: FamilyParams, state: FamilyState, action: np.ndarray):
    """physics.transition as NumPy array code on Planar3RPR's forward_jacobian / forward_kinematics / SVD."""
    robot = params.robot
    metric = params.pose_metric
    a = np.clip(action, -1.0, 1.0)
    lo, hi = params.stroke_limits
    q_new = np.clip(state.q + a * (params.max_rate * params.dt), lo, hi)
    q_rate = (q_new - state.q) / params.dt
    n_robots = len(state.q)
    q_next, x_next = state.q.copy(), state.x.copy()
    residual = state.residual.copy()
    reason = np.zeros(n_robots, dtype=np.int64)
    jumps = np.zeros(n_robots)
    for i in range(n_robots):
        q0, x0 = state.q[i : i + 1], state.x[i : i + 1]
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            rate = np.einsum("nij,nj->ni", robot.forward_jacobian(q0, x0, validate=False), q_rate[i : i + 1])
            motion = np.linalg.norm(rate * params.dt * metric)
            count = np.ceil(motion / params.max_substep)
        n = int(np.clip(count, 1, params.max_substeps)) if np.isfinite(count) else params.max_substeps
        q_k, x_k, res, failed, jump = q0, x0, residual[i], False, 0.0
        for k in range(n):
            q_to = q0 + (k + 1) / n * (q_new[i : i + 1] - q0)
            with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
                if k > 0:
                    rate = np.einsum("nij,nj->ni", robot.forward_jacobian(q_k, x_k, validate=False), q_rate[i : i + 1])
                x_pred = _oracle_predict(params, q_k, x_k, q_rate[i : i + 1], params.dt / n, rate)
                if not np.isfinite(x_pred).all():
                    failed = True
                    break
                fk = robot.forward_kinematics(
                    q_to,
                    x_pred,
                    tolerance=params.newton_tolerance,
                    max_iterations=params.newton_max_iterations,
                    validate=False,
                )
            if not bool(np.all(fk.converged)):
                failed = True
                break
            jump = max(jump, float(np.linalg.norm((fk.x - x_pred) * metric)))
            q_k, x_k, res = q_to, fk.x, float(np.asarray(fk.residual).ravel()[0])
        if failed:
            q_k, x_k, res = q0, x0, residual[i]
        k_new, det = robot.singularity_measures(q_k[0], x_k[0], validate=False)
        out = bool(np.any((x_k[0] < params.pose_low) | (x_k[0] > params.pose_high)))
        if failed:
            reason[i] = family_state.NEWTON_FAILED
        elif jump > params.jump_tolerance:
            reason[i] = family_state.ASSEMBLY_MODE_CHANGE
        elif np.sign(det) != state.det_sign[i]:
            reason[i] = family_state.SINGULARITY_CROSSED
        elif k_new < params.hard_threshold:
            reason[i] = family_state.SINGULAR
        elif out:
            reason[i] = family_state.OUT_OF_BOUNDS
        q_next[i], x_next[i], residual[i], jumps[i] = q_k[0], x_k[0], res, jump
    return q_next, x_next, residual, a, q_rate, reason, jumps


def _params(**overrides) -> FamilyParams:
    """The 3-RPR preset (the constants of the Planar3RPR ids), with overrides."""
    return build_family_params("planar_3rpr", **overrides)


def _reference(target: np.ndarray) -> FamilyReference:
    """Fixed targets (Reach): amplitudes and phases zero."""
    n = len(target)
    return FamilyReference(np.array(target, dtype=np.float64), np.zeros((n, 3)), np.zeros((n, 3)))


def _random_states(params: FamilyParams, rng: np.random.Generator, n: int) -> FamilyState:
    """Draw n reachable configurations spread over the pose bounds (many near singularities), t = 0."""
    low, high = np.array(params.pose_low), np.array(params.pose_high)
    x = rng.uniform(low, high, size=(20 * n, 3))
    q = params.robot.inverse_kinematics(x, validate=False)
    lo, hi = params.stroke_limits
    keep = np.flatnonzero((q.min(axis=-1) > lo) & (q.max(axis=-1) < hi))[:n]
    assert keep.size == n
    return initial_state(params, x[keep], _reference(x[keep]))


@pytest.fixture(scope="module")
def params() -> FamilyParams:
    """The 3-RPR preset's environment constants."""
    return _params()


@pytest.mark.parametrize("integrator", ["euler", "rk4"])
def test_transition_matches_numpy_oracle(integrator, rng):
    """2000 random states and saturated-ish actions: the same reasons exactly, poses to 1e-12, same stroke rates.

    Only states whose deciding quantity (the oracle's k, its jump, a pose coordinate) lies within a relative
    1e-9 of its threshold are left out of the reason comparison, where two correct roundings may differ;
    they are counted and must stay rare.
    """
    p = _params(integrator=integrator)
    state = _random_states(p, rng, 2000)
    action = rng.uniform(-1.5, 1.5, size=(2000, 3))
    new, outcome = physics.transition(p, state, action)
    q, x, _, a, q_rate, reason, jump = oracle_transition(p, state, action)
    np.testing.assert_array_equal(outcome.action, a)
    np.testing.assert_allclose(outcome.q_rate, q_rate, rtol=0, atol=1e-15)
    k_oracle, _ = p.robot.singularity_measures(q, x, validate=False)
    bounds = np.array([p.pose_low, p.pose_high])
    near = (
        (np.abs(k_oracle - p.hard_threshold) <= 1e-9 * p.hard_threshold)
        | (np.abs(jump - p.jump_tolerance) <= 1e-9 * p.jump_tolerance)
        | np.any(np.abs(x[:, None, :] - bounds) <= 1e-9 * np.maximum(np.abs(bounds), 1.0), axis=(1, 2))
    )
    assert near.sum() <= 10, f"{near.sum()} of 2000 states lie within 1e-9 of a threshold"
    differ = np.flatnonzero((outcome.reason != reason) & ~near)
    assert differ.size == 0, (
        f"reasons differ for states {differ[:10]}: env {outcome.reason[differ[:10]]}, oracle {reason[differ[:10]]}"
    )
    agree = outcome.reason == reason
    both_ok = agree & (reason == 0)
    assert both_ok.sum() > 500  # many ordinary steps are compared, not just terminations
    np.testing.assert_allclose(new.x[both_ok], x[both_ok], rtol=0, atol=1e-11)
    np.testing.assert_allclose(new.q[both_ok], q[both_ok], rtol=0, atol=1e-15)
    np.testing.assert_allclose(outcome.jump[both_ok], jump[both_ok], rtol=1e-6, atol=1e-12)
    assert np.all(new.residual[both_ok] <= p.newton_tolerance)
    k_ref, det_ref = p.robot.singularity_measures(new.q, new.x, validate=False)
    np.testing.assert_allclose(new.inverse_condition, k_ref, rtol=1e-9)
    np.testing.assert_array_equal(np.sign(det_ref)[both_ok], new.det_sign[both_ok])
    np.testing.assert_array_equal(new.actuator_condition, 1.0)  # legs: no Type I measure
    assert set(np.unique(reason)) > {0}  # the sample reaches terminations too


def test_conditioning_matches_lapack_svd(params, rng):
    """Inverse condition number of the homogeneous J_i and sign(det J_x) against the library (LAPACK)."""
    state = _random_states(params, rng, 5000)
    k_ref, det = params.robot.singularity_measures(state.q, state.x, validate=False)
    assert k_ref.min() < 1e-3 and k_ref.max() > 0.7  # near-singular and well-conditioned poses alike
    k, sign = fk.singularity_batch(params.packed, state.q, state.x)
    np.testing.assert_allclose(k, k_ref, rtol=1e-10)
    np.testing.assert_array_equal(sign, np.sign(det))
    # initial_state measures the same (strokes from the closed-form inverse kinematics)
    np.testing.assert_allclose(state.q, params.robot.inverse_kinematics(state.x, validate=False), rtol=0, atol=1e-15)
    np.testing.assert_allclose(state.inverse_condition, k_ref, rtol=1e-10)
    np.testing.assert_array_equal(state.det_sign, np.sign(det))


@pytest.mark.parametrize("case", ["random", "near_singular", "top_two_equal", "bottom_two_equal", "isotropic"])
def test_singular_value_ratio_against_lapack(case, rng):
    """The closed form (with its Jacobi fallback) against LAPACK, including (nearly) repeated singular values."""
    closed, jacobi = linalg_kernels.singular_value_ratio3, linalg_kernels._singular_value_ratio
    for _ in range(3000):
        u, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        v, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        s = np.sort(rng.uniform(0.1, 10.0, size=3))[::-1]
        if case == "near_singular":
            s[2] = s[0] * 10 ** rng.uniform(-6, -1)
        elif case == "top_two_equal":
            s[1] = s[0] * (1 - 10 ** rng.uniform(-16, -3))
        elif case == "bottom_two_equal":
            s[2] = s[1] * (1 - 10 ** rng.uniform(-16, -3))
        elif case == "isotropic":
            s[:] = s[0] * (1 - 10 ** rng.uniform(-16, -3, size=3))
        m = (u * s) @ v.T
        sv = np.linalg.svd(m, compute_uv=False)
        expected = sv[-1] / sv[0]
        tol = 1e-12 + 64 * np.finfo(float).eps / expected  # LAPACK's σ_min is accurate to eps·σ_max
        assert closed(*m.ravel()) == pytest.approx(expected, rel=tol)
        assert jacobi(*m.ravel()) == pytest.approx(expected, rel=tol)
    assert closed(*np.zeros(9)) == 0.0
    assert closed(*np.eye(3).ravel()) == 1.0
    assert np.isnan(closed(*np.full(9, np.nan)))


def test_observation_and_rewards_match_numpy_formulas(params, rng):
    """Observation layout, reward terms, errors and success against direct NumPy formulas (Reach and Track)."""
    n = 500
    state = _random_states(params, rng, n)
    lo, hi = params.stroke_limits
    omega = 2.0 * np.pi / params.track_period
    action = rng.uniform(-1, 1, size=(n, 3))
    reason = rng.integers(0, 3, size=n)
    center = state.x[rng.permutation(n)]
    moving = FamilyReference(center, rng.uniform(0.0, 0.1, size=(n, 3)), rng.uniform(-np.pi, np.pi, size=(n, 3)))
    t = rng.integers(0, 200, size=n)
    for with_velocity, reference, size in ((False, _reference(center), 18), (True, moving, 21)):
        tau = omega * t * params.dt
        target = reference.center + reference.amplitude * np.sin(tau[:, None] + reference.phase)
        velocity = reference.amplitude * omega * np.cos(tau[:, None] + reference.phase)
        current = state._replace(t=t, reference=reference)
        delta = target - current.x
        wrapped = (delta[:, 2] + np.pi) % (2 * np.pi) - np.pi
        expected = np.concatenate(
            [
                current.x[:, :2],
                np.cos(current.x[:, 2:3]),
                np.sin(current.x[:, 2:3]),
                target[:, :2],
                np.cos(target[:, 2:3]),
                np.sin(target[:, 2:3]),
                delta[:, :2],
                wrapped[:, None],
                2.0 * (current.q - lo) / (hi - lo) - 1.0,
                (params.robot.inverse_kinematics(target, validate=False) - current.q) / (hi - lo),
                current.inverse_condition[:, None],
                velocity,
            ],
            axis=-1,
        )
        low, high = physics.observation_bounds(params, with_velocity)
        evaluation, got = physics.evaluate(params, current, action, reason, with_velocity)
        assert got.dtype == np.float32 and got.shape == (n, size)
        np.testing.assert_allclose(got, np.clip(expected[:, :size], low, high).astype(np.float32), rtol=2e-7, atol=1e-7)
        rows = params.evaluation_rows
        np.testing.assert_allclose(evaluation[rows["target"]].T, target, rtol=0, atol=1e-15)
        np.testing.assert_allclose(evaluation[rows["target_velocity"]].T, velocity, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(evaluation[rows["pose"]].T, current.x)
        position = np.hypot(delta[:, 0], delta[:, 1])
        np.testing.assert_allclose(evaluation[rows["position_error"]], position, rtol=1e-14, atol=1e-16)
        np.testing.assert_allclose(evaluation[rows["orientation_error"]], np.abs(wrapped), rtol=1e-14, atol=1e-15)
        success = (reason == 0) & (position <= 0.02) & (np.abs(wrapped) <= 0.1)
        np.testing.assert_array_equal(evaluation[rows["is_success"]] != 0, success)
        np.testing.assert_array_equal(evaluation[rows["cost"]], current.inverse_condition < params.safe_threshold)
    target = center
    terms = physics.reward_terms(params, state.x, target, state.inverse_condition, action, reason)
    delta = target - state.x
    wrapped = (delta[:, 2] + np.pi) % (2 * np.pi) - np.pi
    position = np.hypot(delta[:, 0], delta[:, 1])
    l_c = params.robot.characteristic_length
    gap = np.maximum(params.safe_threshold - state.inverse_condition, 0.0) / params.safe_threshold
    np.testing.assert_allclose(terms["reward_tracking"], -(position + l_c * np.abs(wrapped)), rtol=1e-14)
    np.testing.assert_allclose(terms["reward_singularity"], -(gap**2), rtol=1e-14)
    np.testing.assert_allclose(terms["reward_action"], -0.01 * np.sum(action**2, axis=-1), rtol=1e-14)
    np.testing.assert_array_equal(terms["reward_termination"], -50.0 * (reason != 0))
    np.testing.assert_array_equal(terms["reward_actuator_singularity"], 0.0)


@numba_setup.jit
def _claim_all(hits, counter):
    """Mark each index of ``hits`` this thread claims; the number it claimed (the test of ``claim``)."""
    claimed = 0
    i = numba_setup.claim(counter)
    while i < hits.shape[0]:
        hits[i] += 1
        claimed += 1
        i = numba_setup.claim(counter)
    return claimed


def test_threads_claim_every_chunk_exactly_once():
    """``on_every_core``'s threads share the chunks out through ``claim``: each taken once, none left over.

    Two million one-instruction chunks make the threads contend for the counter: a claim that is not atomic hands
    some chunks out twice.
    """
    hits = np.zeros(2_000_000, dtype=np.int64)
    claimed = numba_setup.on_every_core(_claim_all, hits)
    assert len(claimed) == numba_setup.THREADS
    assert sum(claimed) == hits.shape[0]
    np.testing.assert_array_equal(hits, 1)


def test_wrap_is_pythons_modulo_bit_for_bit():
    """``pose._wrap`` (its fast range and its fallback) equals (a + π) % 2π − π in Python, to the last bit."""
    import math

    from envs.kernels import pose

    rng = np.random.default_rng(3)
    two_pi = 2.0 * math.pi
    edges = [0.0, -0.0, math.pi, -math.pi, two_pi, -two_pi, 3 * math.pi, -3 * math.pi, 4 * math.pi, 1e-300, 1e300]
    edges += [np.nextafter(e, s) for e in (math.pi, -math.pi, 3 * math.pi, -3 * math.pi) for s in (-np.inf, np.inf)]
    values = [*edges, *rng.uniform(-4 * math.pi, 4 * math.pi, 20000), *rng.uniform(-1e3, 1e3, 2000), math.inf, math.nan]
    for value in values:
        want, got = (value + math.pi) % two_pi - math.pi, pose._wrap(value)
        assert (math.isnan(want) and math.isnan(got)) or (
            want == got and math.copysign(1, want) == math.copysign(1, got)
        ), value


#: The kernels' allocations (what ``_unkept_borrows`` counts as made here).
_ALLOCATORS = {
    "empty",
    "zeros",
    "_work",
    "allocate_lanes",
    "_allocate_moved",
    "from_extra",
    "lane_work",
    "_dynamics_work",
    "_unpack",  # a StepCall's records, with the dynamics' work array
}


def _unkept_borrows(source: str) -> list[str]:
    """Locals of ``source``'s functions that are borrowed but neither kept alive nor returned (``setup.borrow``).

    A local made by a call (an allocation, a record) and passed to ``borrow`` must be used by ``keep_alive`` or a
    ``return`` after its last borrowed use: Numba frees it after its last use, and the borrowed views would then
    read freed memory. Arguments (held by the caller) and plain names of them need nothing.
    """
    import ast

    def allocates(node) -> bool:  # the value holds arrays allocated here (records of arguments do not)
        if isinstance(node, ast.Call):
            name = getattr(node.func, "id", getattr(node.func, "attr", ""))
            if name == "borrow":
                return False
            if name in _ALLOCATORS:
                return True
        return any(allocates(child) for child in ast.iter_child_nodes(node))

    def own_nodes(function):  # the function's own statements, not those of the functions it defines
        stack = [node for node in function.body if not isinstance(node, ast.FunctionDef)]
        while stack:
            node = stack.pop()
            yield node
            stack += [c for c in ast.iter_child_nodes(node) if not isinstance(c, (ast.FunctionDef, ast.Lambda))]

    problems = []
    for function in (node for node in ast.walk(ast.parse(source)) if isinstance(node, ast.FunctionDef)):
        owned = set()
        for node in own_nodes(function):
            if isinstance(node, ast.Assign) and allocates(node.value):
                owned |= {n.id for t in node.targets for n in ast.walk(t) if isinstance(n, ast.Name)}
        borrowed, kept = set(), set()
        for node in own_nodes(function):
            if isinstance(node, ast.Call) and getattr(node.func, "id", "") in ("borrow", "keep_alive"):
                names = {n.id for a in node.args for n in ast.walk(a) if isinstance(n, ast.Name)}
                (borrowed if node.func.id == "borrow" else kept).update(names)
            if isinstance(node, ast.Return) and node.value is not None:
                kept |= {n.id for n in ast.walk(node.value) if isinstance(n, ast.Name)}
        problems += [f"{function.name}: {name}" for name in sorted((borrowed & owned) - kept)]
    return problems


def test_borrowed_locals_are_kept_alive():
    """Every kernel keeps what it borrows alive to the end (the rule of ``_unkept_borrows``), and the rule bites."""
    from pathlib import Path

    root = Path(numba_setup.__file__).parents[1]
    sources = [path for path in sorted(root.rglob("*.py")) if "borrow(" in path.read_text()]
    assert len(sources) >= 4
    for path in sources:
        assert _unkept_borrows(path.read_text()) == [], path
    planted = "def k(x):\n    work = _work()\n    w, x = borrow((work, x))\n    return w[0] + x[0]\n"
    assert _unkept_borrows(planted) == ["k: work"]


def _claims_in_a_child(queue):
    hits = np.zeros(100_000, dtype=np.int64)
    numba_setup.on_every_core(_claim_all, hits)
    queue.put(int(hits.sum()))


def test_a_forked_child_gets_threads_of_its_own():
    """A child forked after the pool ran (``SubprocVecEnv``, ``AsyncVectorEnv``) runs its batches on new threads.

    The parent's worker threads do not exist in the child: handing them work would wait forever.
    """
    import multiprocessing

    numba_setup.on_every_core(_claim_all, np.zeros(1000, dtype=np.int64))  # the parent's pool exists
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_claims_in_a_child, args=(queue,))
    child.start()
    child.join(timeout=60)
    if child.is_alive():
        child.kill()
        pytest.fail("the forked child's batch did not finish in 60 s")
    assert child.exitcode == 0
    assert queue.get(timeout=5) == 100_000


def _step_arrays(result) -> list[np.ndarray]:
    """Every array of a ``physics.step`` result: the state's (reference included), the outcome's, evaluation, obs."""
    new, outcome, evaluation, obs = result
    return [*family_state.state_arrays(new), *(a for a in outcome if a is not None), evaluation, obs]


def test_parallel_kernel_equals_serial(params, rng, monkeypatch):
    """Large batches run on every core (``on_every_core``); the result is bit-identical to the one-thread loop."""
    n = fk.PARALLEL_MIN_BATCH + 7
    state = _random_states(params, rng, n)
    action = rng.uniform(-1, 1, size=(n, 3))
    parallel = [a.copy() for a in _step_arrays(physics.step(params, state, action, False))]
    monkeypatch.setattr(step_kernels, "PARALLEL_MIN_BATCH", 10**9)
    serial = _step_arrays(physics.step(params, state, action, False))
    for a, b in zip(parallel, serial):
        np.testing.assert_array_equal(a, b)


def test_batches_from_two_threads_at_once_and_on_one_thread_equal_the_serial_step(params, rng, monkeypatch):
    """Batches of two Python threads at once, and batches on one thread, equal the one-thread loop's results.

    The two threads share the pool (neither waits forever nor mixes rows); ``NUMBA_NUM_THREADS=1`` (``THREADS`` 1)
    runs a batch on the calling thread alone. Overlap depends on timing: a counter shared by the batches (planted)
    failed this test in about half the runs.
    """
    import threading

    n = 8 * fk.PARALLEL_MIN_BATCH + 3
    cases = []
    for _ in range(2):
        state = _random_states(params, rng, n)
        cases.append((state, rng.uniform(-1, 1, size=(n, 3))))
    got: list = [None, None]
    start = threading.Barrier(2)

    def run(index):
        state, action = cases[index]
        start.wait()
        for _ in range(60):  # many batches each, so that they overlap
            result = [a.copy() for a in _step_arrays(physics.step(params, state, action, False))]
        got[index] = result

    threads = [threading.Thread(target=run, args=(index,)) for index in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=120)
    assert not any(thread.is_alive() for thread in threads)
    monkeypatch.setattr(numba_setup, "THREADS", 1)
    one_thread = [[a.copy() for a in _step_arrays(physics.step(params, s, a, False))] for s, a in cases]
    monkeypatch.setattr(step_kernels, "PARALLEL_MIN_BATCH", 10**9)
    for (state, action), parallel, alone in zip(cases, got, one_thread):
        serial = _step_arrays(physics.step(params, state, action, False))
        for a, b, c in zip(parallel, alone, serial, strict=True):
            np.testing.assert_array_equal(a, c)
            np.testing.assert_array_equal(b, c)


def test_step_equals_transition_then_evaluate(params, rng):
    """The fused step is transition followed by evaluate, to the last bit."""
    state = _random_states(params, rng, 300)
    action = rng.uniform(-1, 1, size=(300, 3))
    new, outcome, evaluation, obs = physics.step(params, state, action, True)
    new2, outcome2 = physics.transition(params, state, action)
    evaluation2, obs2 = physics.evaluate(params, new2, outcome2.action, outcome2.reason, True)
    for a, b in zip([*new[:-1], *outcome, evaluation, obs], [*new2[:-1], *outcome2, evaluation2, obs2]):
        np.testing.assert_array_equal(a, b)
    rows = params.evaluation_rows
    terms = physics.reward_terms(
        params, new.x, evaluation[rows["target"]].T, new.inverse_condition, outcome.action, outcome.reason
    )
    total = sum(terms.values())
    np.testing.assert_array_equal(evaluation[rows["reward"]], total)


def test_mismatched_batches_are_refused(params, rng):
    """Actions of the wrong width or batch size are refused with a clear error before the kernels run."""
    state = _random_states(params, rng, 4)
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        physics.transition(params, state, np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"action must have shape \(4, 3\), got \(3, 3\)"):
        physics.step(params, state, np.zeros((3, 3)), False)
    with pytest.raises(ValueError, match=r"target must have shape \(N, 3\)"):
        physics.reward_terms(params, state.x, state.x[:, :2], state.inverse_condition, np.zeros((4, 3)), np.zeros(4))


def test_packed_constants_follow_params():
    """Every constant the kernels read comes from the params (a changed weight changes the reward)."""
    robot = Planar3RPR()
    p = _params(position_weight=2.0, termination_penalty=7.0, success_reward=3.0, stroke_limits=(0.25, 1.1))
    c = p.packed
    assert c[family_layout.C_WP] == 2.0 and c[family_layout.C_PENALTY] == 7.0 and c[family_layout.C_BONUS] == 3.0
    assert (c[family_layout.C_LMIN], c[family_layout.C_LMAX]) == (0.25, 1.1)
    base = c[family_layout.C_B : family_layout.C_B + 9].reshape(3, 3)
    np.testing.assert_array_equal(base[:, :2], robot.base)
    np.testing.assert_array_equal(base[:, 2], 0.0)
    np.testing.assert_array_equal(c[family_layout.C_SCALE : family_layout.C_SCALE + 3], robot.pose_scale)
    assert c[family_layout.C_LC] == robot.characteristic_length
    assert not c.flags.writeable


def test_step_buffers_give_the_fresh_result(params, rng):
    """Stepping into reused buffers (as the single env does) equals stepping into fresh arrays."""
    state = _random_states(params, rng, 5)
    action = rng.uniform(-1, 1, size=(5, 3))
    buffers = (physics.StepBuffers(params, 5, False), physics.StepBuffers(params, 5, False))
    reused = state
    fresh = state
    for k in range(4):
        reused, *_ = physics.step(params, reused, action, False, buffers[k % 2])
        fresh, *_ = physics.step(params, fresh, action, False)
    for a, b in zip([*reused[:-1], *reused.reference], [*fresh[:-1], *fresh.reference]):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(physics.NonFiniteActionError, match="action must be finite") as caught:
        physics.step(params, state, np.where(np.arange(5)[:, None] == 3, np.inf, action), False)
    np.testing.assert_array_equal(caught.value.rows, [3])


@pytest.mark.parametrize("field", ["q", "x", "t", "det_sign", "residual", "reference", "twist"])
def test_reused_buffers_read_a_state_changed_in_one_array(rng, field):
    """Reused buffers step a state that differs from the last in one array as fresh buffers do.

    The ``StepCall`` they keep must read that array (the twist under force control).
    """
    params = _params(control="force") if field == "twist" else _params()
    state, other = _random_states(params, rng, 2), _random_states(params, rng, 2)
    other = other._replace(t=other.t + 3, det_sign=-state.det_sign, residual=other.residual + 1e-3)
    if field == "twist":
        other = other._replace(twist=rng.uniform(-0.1, 0.1, size=other.twist.shape))
    if field == "residual":  # read only where the correction fails (the robot keeps it): strokes that cannot assemble
        state = state._replace(q=3.0 * state.q)
    action = rng.uniform(-1, 1, size=(2, 3))
    buffers = physics.StepBuffers(params, 2, False)
    physics.step(params, state, action, False, buffers)
    changed = state._replace(**{field: getattr(other, field)})
    reused = physics.step(params, changed, action, False, buffers)
    fresh = physics.step(params, changed, action, False)
    for a, b in zip([*reused[0][:7], reused[2], reused[3]], [*fresh[0][:7], fresh[2], fresh[3]], strict=True):
        np.testing.assert_array_equal(a, b)


def test_env_state_is_a_copy(rng):
    """env.unwrapped.state is a snapshot: kept across steps it does not change, and editing it changes nothing."""
    import gymnasium as gym

    env = gym.make("Planar3RPRReach-v0")
    assert isinstance(env.unwrapped.params, FamilyParams)
    env.reset(seed=3)
    first = env.unwrapped.state
    kept = first.x.copy()
    for _ in range(3):
        env.step(rng.uniform(-1, 1, size=3).astype(np.float32))
    np.testing.assert_array_equal(first.x, kept)
    now = env.unwrapped.state
    now.x[:] = 123.0
    assert not np.any(env.unwrapped.state.x == 123.0)
    env.close()


@pytest.mark.parametrize(
    ("env_id", "kwargs"),
    [
        ("Planar3RPRReach-v0", {}),
        ("StewartGoughForceReach-v0", {}),
        ("DeltaForceReach-v0", {"observation_source": "encoders", "geometry_variation": 0.01}),
    ],
)
def test_every_role_of_the_step_runs_the_steps_compiled_kernel(monkeypatch, env_id, kwargs):
    """Episode starts and the look-ahead build a ``StepCall`` of the very type the env's step builds.

    The robots at rest at their start poses and their targets' strokes (``ASSEMBLE``, ``STROKES``), the evaluation
    at rest (``EVALUATE``), the holding forces (``HOLD``) and ``physics.transition`` (``TRANSITION``, the shield's
    look-ahead) all run the step's
    kernel without compiling a second specialisation of it (seconds at the first reset). A call whose constants,
    say, were writable would be another type.
    """
    import gymnasium as gym
    import numba

    from envs.kernels import records

    built = []
    original = step_kernels._new_step_call

    def recording(*args):
        call = original(*args)
        built.append((args[-2], numba.typeof(call)))  # (its mode, its type)
        return call

    monkeypatch.setattr(step_kernels, "_new_step_call", recording)
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    inner = env.unwrapped
    physics.transition(inner.params, inner.state, np.zeros(inner.state.q.shape))
    physics.with_strokes(inner.params, inner.state.reference._replace(strokes=None))  # a target's strokes alone
    stepped = numba.typeof(inner._buffers[0]._call)
    modes = {records.STEP, records.EVALUATE, records.TRANSITION, records.ASSEMBLE, records.STROKES}
    if inner.params.control == "force":
        modes.add(records.HOLD)  # the holding forces of the reset's info
    assert {mode for mode, _ in built} == modes
    assert all(typ == stepped for _, typ in built), [mode for mode, typ in built if typ != stepped]
    env.close()


def test_the_register_paths_compile_one_entry_kernel_and_the_work_array_path_two():
    """On the register paths the one-thread step is the multi-core step's kernel; the work-array path has its own.

    Each entry kernel compiles the whole step. The work-array path's multi-core kernel puts spatial robots' SVDs in
    SIMD lanes under rate control, which a single robot should not have to compile; under force control it moves
    them one at a time, and is the one-thread step too.
    """
    from envs.kernels.packing import ROW_PATHS, WORK_ARRAYS

    for (path, space), kernels in step_kernels._PATH_KERNELS.items():
        assert path in ROW_PATHS
        assert (kernels.step_serial is kernels.step_chunks) == (path != WORK_ARRAYS), (path, space)
        # under force control no path uses the lanes: one kernel for both
        assert kernels.one_thread(force=True) is kernels.step_chunks
        assert kernels.one_thread(force=False) is kernels.step_serial


def test_a_call_built_for_one_thread_is_refused_on_every_core(params, rng):
    """``step_on_every_core`` needs a call with a counter of its own (``step_call(threads=True)``).

    Threads sharing the empty counter of a one-thread call would each step every robot, at the same time.
    """
    n = fk.PARALLEL_MIN_BATCH
    state = _random_states(params, rng, n)
    observation = (*physics.observation_bounds(params, False), False)
    out = fk.allocate_step(n, 3, observation[0].shape[0])
    motion = (state.q, state.x, state.t, state.det_sign, state.residual)
    reference = tuple(physics.with_strokes(params, state.reference, True))
    kernels = fk.path_kernels(params.packed_rows)
    action = np.zeros((n, 3))
    call = fk.step_call(params.packed_rows, params.packed_rows, observation, motion, reference, out)
    with pytest.raises(ValueError, match=r"counter of shape \(1,\).*got \(0,\)"):
        fk.step_on_every_core(kernels, call, action)
    threaded = fk.step_call(params.packed_rows, params.packed_rows, observation, motion, reference, out, threads=True)
    assert not fk.step_on_every_core(kernels, threaded, action)


@pytest.mark.parametrize("num_envs", [1, fk.PARALLEL_MIN_BATCH + 1])
@pytest.mark.parametrize("env_id", ["StewartGoughReach-v0", "Planar3RPRReach-v0"])
def test_an_env_runs_one_entry_kernel_of_the_step(monkeypatch, env_id, num_envs):
    """A vector env that steps on every core starts, restarts and looks ahead on that kernel too; a small one never.

    On the work-array path (the hexapod) each entry kernel (one thread, every core) compiles the whole step: an env
    that used both would compile it twice. Every role (``envs.kernels.modes``) follows the env's choice, the
    shield's look-ahead included. The 3-RPR is checked by role: its two are one kernel.
    """
    import gymnasium as gym

    from envs.wrappers.shield import VectorSingularityShield

    used = []

    def recording(name, kernel):
        def run(*args):
            used.append(name)
            return kernel(*args)

        return run

    patched = {
        key: step_kernels.PathKernels(recording("one thread", k.step_serial), recording("every core", k.step_chunks))
        for key, k in step_kernels._PATH_KERNELS.items()
    }
    monkeypatch.setattr(step_kernels, "_PATH_KERNELS", patched)
    env = VectorSingularityShield(
        gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", max_episode_steps=3)
    )
    env.reset(seed=0)
    for _ in range(4):  # the episodes end after 3 steps and restart
        env.step(np.full(env.action_space.shape, 0.5, dtype=np.float32))
    env.reset(options={"reset_mask": np.arange(num_envs) % 2 == 0})
    assert set(used) == {"every core" if num_envs >= fk.PARALLEL_MIN_BATCH else "one thread"}
    env.close()


@pytest.mark.parametrize("parallel", [False, True])
def test_the_evaluation_at_rest_leaves_the_state_as_it_was(params, rng, parallel):
    """``physics.evaluate`` writes nothing into the state's arrays, which the step's kernel runs on, told not to move.

    Not q, x, t, k, k_I, the residual, the reference nor the actions; on one thread and on every core.
    """
    n = 2 * fk.PARALLEL_MIN_BATCH + 5
    state = _random_states(params, rng, n)
    state = state._replace(t=rng.integers(0, 50, size=n))
    action, reason = rng.uniform(-1, 1, size=(n, 3)), rng.integers(0, 3, size=n)
    before = [np.copy(a) for a in (*state[:7], *state.reference[:3], action, reason)]
    physics.evaluate(params, state, action, reason, True, parallel=parallel)
    after = (*state[:7], *state.reference[:3], action, reason)
    for old, new in zip(before, after, strict=True):
        np.testing.assert_array_equal(new, old)
