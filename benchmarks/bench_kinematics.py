"""Benchmark J_f of the planar 3-RPR: the lesson's SymPy code against Planar3RPR (batched and single).

Run with ``python -m benchmarks.bench_kinematics [--n 10000] [--repeats 7]``. All three methods are
timed on the same random consistent configurations (x drawn in a box, q = IK(x)); each measurement is
repeated and the median is reported, per configuration, in microseconds.
"""

from __future__ import annotations

import os
import platform
import statistics
import sys
import time
from collections.abc import Callable

import numpy as np
import sympy as sp

from benchmarks._cli import kinematics_parser, parse_positive
from kinematics import ParallelMechanism, Planar3RPR

# -- The lesson's section 7 code (Chapter 16, Lesson 2), as printed ----------------------------------

# Symbolic variables
x, y, phi = sp.symbols("x y phi", real=True)
L1, L2, L3 = sp.symbols("L1 L2 L3", positive=True)

# Geometry parameters (example values, change to your mechanism)
B1 = sp.Matrix([0.0, 0.0])
B2 = sp.Matrix([1.0, 0.0])
B3 = sp.Matrix([0.5, sp.sqrt(3) / 2])

P1 = sp.Matrix([0.0, -0.2])
P2 = sp.Matrix([0.2, 0.0])
P3 = sp.Matrix([-0.2, 0.0])

p = sp.Matrix([x, y])
R = sp.Matrix([[sp.cos(phi), -sp.sin(phi)], [sp.sin(phi), sp.cos(phi)]])
S = sp.Matrix([[0, -1], [1, 0]])


def leg_vector(B: sp.Matrix, P: sp.Matrix) -> sp.Matrix:
    """The lesson's d_i = p + R(φ) P_i − B_i, symbolic."""
    return p + R * P - B


d1 = leg_vector(B1, P1)
d2 = leg_vector(B2, P2)
d3 = leg_vector(B3, P3)

Phi1 = d1.dot(d1) - L1**2
Phi2 = d2.dot(d2) - L2**2
Phi3 = d3.dot(d3) - L3**2

Phi = sp.Matrix([Phi1, Phi2, Phi3])
q_vec = sp.Matrix([L1, L2, L3])
x_vec = sp.Matrix([x, y, phi])

Jq_sym = Phi.jacobian(q_vec)
Jx_sym = Phi.jacobian(x_vec)

# Lambdify for numerical evaluation
Jq_fun = sp.lambdify((L1, L2, L3, x, y, phi), Jq_sym, "numpy")
Jx_fun = sp.lambdify((L1, L2, L3, x, y, phi), Jx_sym, "numpy")


def jacobians_3rpr(L_vals, pose):
    """The lesson's function: J_f, J_q, J_x evaluated numerically.

    Args:
        L_vals: array-like [L1, L2, L3].
        pose: array-like [x, y, phi].

    Returns:
        (J_f, J_q, J_x), each a 3×3 array.
    """
    L1v, L2v, L3v = L_vals
    xv, yv, phiv = pose
    Jq = np.array(Jq_fun(L1v, L2v, L3v, xv, yv, phiv), dtype=float)
    Jx = np.array(Jx_fun(L1v, L2v, L3v, xv, yv, phiv), dtype=float)

    # Solve for J_f = - J_x^{-1} J_q
    Jx_inv = np.linalg.inv(Jx)
    Jf = -Jx_inv @ Jq
    return Jf, Jq, Jx


# -- The benchmark -----------------------------------------------------------------------------------


def random_configurations(
    robot: ParallelMechanism,
    n: int,
    seed: int,
    low: tuple[float, ...] = (0.2, 0.1, -1.0),
    high: tuple[float, ...] = (0.8, 0.6, 1.0),
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` consistent configurations: x uniform in [low, high] (default: the 3-RPR's box), q = IK(x).

    Poses within 1e-6 (inverse condition number) of a Type II singularity, where J_f does not exist,
    are redrawn.
    """
    rng = np.random.default_rng(seed)
    kept = np.empty((0, len(low)))
    while len(kept) < n:
        X = rng.uniform(low, high, (n, len(low)))
        icn = robot.inverse_condition_number(robot.inverse_kinematics(X), X)
        kept = np.concatenate([kept, X[icn > 1e-6]])
    X = kept[:n]
    return robot.inverse_kinematics(X), X


def median_seconds(runs: list[Callable[[], object]], repeats: int) -> list[float]:
    """Median wall time [s] of each of ``runs`` over ``repeats`` rounds (time.perf_counter).

    The runs take turns within each round, so a change of machine load affects them alike.
    """
    times: list[list[float]] = [[] for _ in runs]
    for _ in range(repeats):
        for run, samples in zip(runs, times, strict=True):
            start = time.perf_counter()
            run()
            samples.append(time.perf_counter() - start)
    return [statistics.median(samples) for samples in times]


def main(argv: list[str] | None = None) -> None:
    """Time the three ways of computing J_f and print a table, the speed-up ratios and a check."""
    parser = kinematics_parser(__doc__)
    parser.add_argument("--show-symbolic", action="store_true", help="pretty-print J_q and J_x as the lesson")
    args = parse_positive(parser, argv, "n", "repeats")
    lesson_n = args.n if args.lesson_n is None else min(max(args.lesson_n, 1), args.n)

    if args.show_symbolic:
        print("J_q (symbolic):")
        sp.pprint(Jq_sym)
        print("\nJ_x (symbolic):")
        sp.pprint(Jx_sym)
        print()

    robot = Planar3RPR()
    Q, X = random_configurations(robot, args.n, args.seed)
    Q_lesson, X_lesson = Q[:lesson_n], X[:lesson_n]
    pairs = list(zip(Q, X, strict=True))  # the same per-configuration rows the lesson's loop receives

    def lesson_loop() -> list:
        return [jacobians_3rpr(q, pose)[0] for q, pose in zip(Q_lesson, X_lesson, strict=True)]

    def batched() -> np.ndarray:
        return robot.forward_jacobian(Q, X)

    def single_loop() -> list:
        return [robot.forward_jacobian(q, pose) for q, pose in pairs]

    # Warm up (caches, lazily loaded LAPACK), then measure.
    runs = [lesson_loop, batched, single_loop]
    for run in runs:
        run()
    t_lesson, t_batched, t_single = median_seconds(runs, args.repeats)
    t_lesson, t_batched, t_single = t_lesson / lesson_n, t_batched / args.n, t_single / args.n

    J_lesson = np.array(lesson_loop())
    J_batched = batched()
    J_single = np.array(single_loop())
    scale = np.max(np.abs(J_lesson), axis=(1, 2))
    diff_lesson = np.max(np.abs(J_batched[:lesson_n] - J_lesson), axis=(1, 2))
    diff_single = np.max(np.abs(J_batched - J_single), axis=(1, 2))

    print("Planar 3-RPR forward Jacobian J_f = -J_x^-1 J_q (lesson geometry)")
    processor = platform.processor() or platform.machine()
    print(f"machine: {processor}, {os.cpu_count()} CPUs, {platform.system()} {platform.release()}")
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, sympy {sp.__version__}")
    print(
        f"configurations: {args.n} (lesson loop on {lesson_n}), x in [0.2,0.8]x[0.1,0.6]x[-1,1], "
        f"q = IK(x); median of {args.repeats} repeats"
    )
    print()
    print(f"{'method':<46}{'us / config':>14}")
    print(f"{'lesson section 7 (lambdify + np.linalg.inv)':<46}{t_lesson * 1e6:>14.3f}")
    print(f"{'Planar3RPR.forward_jacobian, batched':<46}{t_batched * 1e6:>14.3f}")
    print(f"{'Planar3RPR.forward_jacobian, single calls':<46}{t_single * 1e6:>14.3f}")
    print()
    ratio_batched, ratio_single = t_lesson / t_batched, t_lesson / t_single
    verdict_batched = "ok" if ratio_batched >= 100 else "BELOW TARGET"
    verdict_single = "ok" if ratio_single >= 1.0 else "BELOW TARGET"
    print(f"speed-up lesson / batched: {ratio_batched:10.1f}   (target >= 100: {verdict_batched})")
    print(f"speed-up lesson / single:  {ratio_single:10.2f}   (target >= 1.0: {verdict_single})")
    print()
    print(
        f"agreement batched vs lesson: max abs diff {np.max(diff_lesson):.3e}, "
        f"max relative diff {np.max(diff_lesson / scale):.3e}"
    )
    print(f"agreement batched vs single: max abs diff {np.max(diff_single):.3e}")


if __name__ == "__main__":
    main()
