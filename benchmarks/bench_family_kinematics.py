"""Benchmark J_f of the Stewart–Gough hexapod: the lesson's SymPy method applied to the 6-UPS against StewartGough.

Run with ``python -m benchmarks.bench_family_kinematics [--n 10000] [--repeats 7] [--lesson-n N]``.
Anchor, timed in the same run: the lesson's section 7 code (``bench_kinematics``) applied to the hexapod. Φ_i =
‖p + R(r) P_i − B_i‖² − q_i² is built in SymPy with R(r) by Rodrigues' formula and the default geometry's
numbers; J_q = ∂Φ/∂q, and J_x is ∂Φ/∂(p, θ) at θ = 0 for R → (I + [θ]×) R(r), the Jacobian with respect to the
platform twist (v, ω) in {B}, whose row i is 2 (d_iᵀ, ((R P_i) × d_i)ᵀ). Both are lambdified with NumPy and
J_f = −inv(J_x) @ J_q is computed per configuration in a Python loop.
Subject: ``StewartGough().forward_jacobian(q, x, validate=False)`` on the whole batch (also shown: the batch
with validation, and one call per configuration).
Protocol: random consistent configurations (x drawn in the task box of StewartGoughReach-v0, q = IK(x));
the two J_f are checked to agree to 1e-9 before any timing; after a warm-up the methods take turns within
each of the repeats (``bench_kinematics.median_seconds``) and the median is reported per configuration.
Target: batched ≥ 100× faster than the lesson's loop.
"""

from __future__ import annotations

import os
import platform
import sys
import time

import numpy as np
import sympy as sp

from benchmarks._cli import kinematics_parser, parse_positive
from benchmarks.bench_kinematics import median_seconds, random_configurations
from kinematics import StewartGough
from kinematics.stewart_gough import DEFAULT_HEXAPOD_BASE, DEFAULT_HEXAPOD_PLATFORM

TARGET_SPEED_UP = 100.0
#: Largest |J_f(StewartGough) − J_f(lesson)| accepted before timing.
AGREEMENT_TOLERANCE = 1e-9
#: Box of the poses (p [m], r [rad]): the task box (``sample_low``, ``sample_high``) of StewartGoughReach-v0.
POSE_LOW = (-0.1, -0.1, 0.4, -0.2, -0.2, -0.5)
POSE_HIGH = (0.1, 0.1, 0.6, 0.2, 0.2, 0.5)

# -- The lesson's section 7 method, applied to the 6-UPS ----------------------------------------------

# Symbolic variables: leg lengths q_i, pose x = (p, r), and the small rotation θ of the twist
q1, q2, q3, q4, q5, q6 = sp.symbols("q1:7", positive=True)
px, py, pz = sp.symbols("p_x p_y p_z", real=True)
rx, ry, rz = sp.symbols("r_x r_y r_z", real=True)
tx, ty, tz = sp.symbols("theta_x theta_y theta_z", real=True)

# Geometry parameters: the default hexapod's anchors B_i and platform points P_i
B = [sp.Matrix(row) for row in DEFAULT_HEXAPOD_BASE.tolist()]
P = [sp.Matrix(row) for row in DEFAULT_HEXAPOD_PLATFORM.tolist()]


def skew(v: sp.Matrix) -> sp.Matrix:
    """[v]×, the matrix of the cross product v × ·, symbolic."""
    return sp.Matrix([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


p = sp.Matrix([px, py, pz])
r = sp.Matrix([rx, ry, rz])
angle = sp.sqrt(rx**2 + ry**2 + rz**2)
R = sp.eye(3) + sp.sin(angle) / angle * skew(r) + (1 - sp.cos(angle)) / angle**2 * skew(r) * skew(r)
theta = sp.Matrix([tx, ty, tz])
R_turned = (sp.eye(3) + skew(theta)) * R  # exp([θ]×) R to first order in θ: enough for ∂/∂θ at θ = 0


def leg_vector(B_i: sp.Matrix, P_i: sp.Matrix) -> sp.Matrix:
    """The lesson's d_i = p + R P_i − B_i, symbolic, with R turned by θ."""
    return p + R_turned * P_i - B_i


q_vec = sp.Matrix([q1, q2, q3, q4, q5, q6])
Phi = sp.Matrix([leg_vector(B_i, P_i).dot(leg_vector(B_i, P_i)) - q_i**2 for B_i, P_i, q_i in zip(B, P, q_vec)])
twist = sp.Matrix([px, py, pz, tx, ty, tz])
at_theta_zero = {tx: 0, ty: 0, tz: 0}

Jq_sym = Phi.jacobian(q_vec).subs(at_theta_zero)
Jx_sym = Phi.jacobian(twist).subs(at_theta_zero)

# Lambdify for numerical evaluation
Jq_fun = sp.lambdify((q1, q2, q3, q4, q5, q6, px, py, pz, rx, ry, rz), Jq_sym, "numpy")
Jx_fun = sp.lambdify((q1, q2, q3, q4, q5, q6, px, py, pz, rx, ry, rz), Jx_sym, "numpy")


def jacobians_6ups(L_vals, pose):
    """The lesson's function for the hexapod: J_f, J_q, J_x evaluated numerically.

    Args:
        L_vals: array-like [q1, …, q6] [m].
        pose: array-like [p_x, p_y, p_z, r_x, r_y, r_z] [m, rad], r ≠ 0 (Rodrigues' formula divides by |r|).

    Returns:
        (J_f, J_q, J_x), each a 6×6 array; J_x and J_f refer to the twist (v, ω).
    """
    Jq = np.array(Jq_fun(*L_vals, *pose), dtype=float)
    Jx = np.array(Jx_fun(*L_vals, *pose), dtype=float)

    # Solve for J_f = - J_x^{-1} J_q
    Jx_inv = np.linalg.inv(Jx)
    Jf = -Jx_inv @ Jq
    return Jf, Jq, Jx


# -- The benchmark -----------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> None:
    """Check agreement, time the ways of computing J_f and print a table, the speed-up and the target."""
    parser = kinematics_parser(__doc__)
    args = parse_positive(parser, argv, "n", "repeats")
    lesson_n = args.n if args.lesson_n is None else min(max(args.lesson_n, 1), args.n)

    robot = StewartGough()
    Q, X = random_configurations(robot, args.n, args.seed, POSE_LOW, POSE_HIGH)
    Q_lesson, X_lesson = Q[:lesson_n], X[:lesson_n]
    pairs = list(zip(Q, X, strict=True))  # the same per-configuration rows the lesson's loop receives

    def lesson_loop() -> list:
        return [jacobians_6ups(q, pose)[0] for q, pose in zip(Q_lesson, X_lesson, strict=True)]

    def batched() -> np.ndarray:
        return robot.forward_jacobian(Q, X, validate=False)

    def batched_validated() -> np.ndarray:
        return robot.forward_jacobian(Q, X)

    def single_loop() -> list:
        return [robot.forward_jacobian(q, pose, validate=False) for q, pose in pairs]

    # Agreement first: nothing is timed unless the two methods give the same J_f.
    J_lesson = np.array(lesson_loop())
    J_batched = batched()
    J_single = np.array(single_loop())
    diff_lesson = np.max(np.abs(J_batched[:lesson_n] - J_lesson), axis=(1, 2))
    scale = np.max(np.abs(J_lesson), axis=(1, 2))
    diff_single = np.max(np.abs(J_batched - J_single))
    diff_validated = np.max(np.abs(J_batched - batched_validated()))
    if not np.max(diff_lesson) <= AGREEMENT_TOLERANCE:
        worst = int(np.argmax(diff_lesson))
        raise SystemExit(
            f"J_f of StewartGough and of the lesson's method differ by {np.max(diff_lesson):.3e} > "
            f"{AGREEMENT_TOLERANCE:g} at configuration {worst} (q = {Q[worst].tolist()}, x = {X[worst].tolist()}); "
            "not timing"
        )

    # Warm up (caches, lazily loaded LAPACK), then measure.
    runs = [lesson_loop, batched, batched_validated, single_loop]
    for run in runs:
        run()
    start = time.perf_counter()
    t_lesson, t_batched, t_validated, t_single = median_seconds(runs, args.repeats)
    wall = time.perf_counter() - start
    t_lesson, t_batched = t_lesson / lesson_n, t_batched / args.n
    t_validated, t_single = t_validated / args.n, t_single / args.n

    print("Stewart-Gough (6-UPS) forward Jacobian J_f = -J_x^-1 J_q, twist coordinates (default geometry)")
    processor = platform.processor() or platform.machine()
    print(f"machine: {processor}, {os.cpu_count()} CPUs, {platform.system()} {platform.release()}")
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, sympy {sp.__version__}")
    box = ", ".join(f"[{lo:g},{hi:g}]" for lo, hi in zip(POSE_LOW, POSE_HIGH))
    print(f"configurations: {args.n} (lesson loop on {lesson_n}), x = (p, r) in {box}, q = IK(x)")
    print(f"median of {args.repeats} repeats (methods in turn; {wall:.0f} s of timing)")
    print()
    print(f"{'method':<58}{'us / config':>14}")
    print(f"{'lesson section 7 method (lambdify + np.linalg.inv)':<58}{t_lesson * 1e6:>14.3f}")
    print(f"{'StewartGough.forward_jacobian, batched, validate=False':<58}{t_batched * 1e6:>14.3f}")
    print(f"{'StewartGough.forward_jacobian, batched, validate=True':<58}{t_validated * 1e6:>14.3f}")
    print(f"{'StewartGough.forward_jacobian, single calls, validate=False':<58}{t_single * 1e6:>14.3f}")
    print()
    ratio = t_lesson / t_batched
    verdict = "PASS" if ratio >= TARGET_SPEED_UP else "MISS"
    print(f"speed-up lesson / batched:            {ratio:10.1f}   (target >= {TARGET_SPEED_UP:g}: {verdict})")
    print(f"speed-up lesson / batched, validated: {t_lesson / t_validated:10.1f}")
    print(f"speed-up lesson / single calls:       {t_lesson / t_single:10.2f}")
    print()
    print(
        f"agreement batched vs lesson (checked <= {AGREEMENT_TOLERANCE:g} before timing): max abs diff "
        f"{np.max(diff_lesson):.3e}, max relative diff {np.max(diff_lesson / scale):.3e}"
    )
    print(f"agreement batched vs single: max abs diff {diff_single:.3e}; vs validated: {diff_validated:.3e}")


if __name__ == "__main__":
    main()
