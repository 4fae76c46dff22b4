"""Cross-check of ``kinematics.dynamics`` against MuJoCo on the models of ``kinematics.mjcf.to_mjcf``.

Run with ``python -m benchmarks.bench_mjcf_crosscheck [--integrators RK4 implicitfast] [--solref 0.0005 1]``.
For each preset (planar ones stood up, gravity along −y) it prints the largest drift of the platform points in
0.2 s under our holding forces, at the home pose and at a random pose, and without them; then, from random poses
at rest (``SCENARIOS`` of the tests: 5 for the 3-RPR, hexapod and Delta, 3 for the 3-RRR and 3-PRR) under the
same piecewise-constant efforts for 0.5 s (the holding forces plus random offsets changed every 50 ms; ours
RKMK4 at 1 ms, MuJoCo at 0.25 ms), the largest gap between the final poses, MuJoCo's largest closure violation
along the way and our largest |Φ_i| at the end. The scenarios are those of ``tests/kinematics/test_mjcf.py``,
whose helpers this calls.
"""

from __future__ import annotations

import argparse
import time

from tests.kinematics.test_mjcf import PRESETS, SCENARIOS, compare, drift, robot_and_inertia, start_poses


def main(argv: list[str] | None = None) -> None:
    """Print the statics and the dynamics tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--integrators", nargs="+", default=["RK4", "implicitfast"], help="MuJoCo integrators")
    parser.add_argument("--solref", nargs=2, type=float, default=[0.0005, 1.0], help="closures' solref")
    args = parser.parse_args(argv)
    print("Statics, MuJoCo RK4 at 0.25 ms: largest drift of the platform points in 0.2 s [m]")
    print("| robot | held at home | held at a random pose | no forces |")
    print("|---|---|---|---|")
    for name in PRESETS:
        robot, inertia = robot_and_inertia(name)
        x = start_poses(robot, name, 1)[0]
        cells = [
            drift(robot, inertia, robot.home_pose(), solref=args.solref),
            drift(robot, inertia, x, solref=args.solref),
            drift(robot, inertia, robot.home_pose(), scale=0.0, solref=args.solref),
        ]
        print(f"| {name} | " + " | ".join(f"{v:.2e}" for v in cells) + " |")
    print()
    print(f"Dynamics: starts at rest, 0.5 s; closures' solref {args.solref}")
    print(
        "| robot | starts | MuJoCo integrator | position gap [m] | rotation gap [deg] | closure violation [m] | "
        "our max abs(Φ) [m²] | travel [m] | MuJoCo + ours [s] |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name in PRESETS:
        for integrator in args.integrators:
            clock = time.perf_counter()
            count, fraction, _ = SCENARIOS[name]
            out = compare(name, count, fraction=fraction, integrator=integrator, solref=args.solref)
            seconds = time.perf_counter() - clock
            print(
                f"| {name} | {count} | {integrator} | {out['position'].max():.2e} | {out['angle'].max():.2e} | "
                f"{out['closure'].max():.2e} | {out['phi'].max():.1e} | {out['moved'].min():.3f}–"
                f"{out['moved'].max():.3f} | {seconds:.1f} |"
            )


if __name__ == "__main__":
    main()
