"""Lines of code that state each robot's geometry against those of the generic family core.

Run as ``python -m benchmarks.count_lines``. A line counts when it holds code (not blank, not a comment, not
part of a docstring); the count is taken with ``tokenize``, so it is the same on every machine.
"""

from __future__ import annotations

import io
import tokenize
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: What states a robot: its preset (geometry and defaults) and the env presets of its registered ids.
ROBOTS = {
    "Stewart–Gough hexapod (kinematics/stewart_gough.py)": ["kinematics/stewart_gough.py"],
    "planar 3-RPR (kinematics/planar_3rpr.py: geometry, plus its fused J_f and all assembly modes)": [
        "kinematics/planar_3rpr.py"
    ],
    "Delta (kinematics/delta.py: geometry, plus its closed-form forward kinematics)": ["kinematics/delta.py"],
    "planar 3-RRR and 3-PRR (kinematics/planar_rrr_prr.py)": ["kinematics/planar_rrr_prr.py"],
}
#: The generic family core, written once for every member.
CORE = [
    "kinematics/mechanism.py",
    "kinematics/family.py",
    "kinematics/pose_space.py",
    "kinematics/actuation.py",
    "kinematics/family_singularities.py",
    "kinematics/linalg.py",
    "envs/kernels/layout.py",
    "envs/kernels/packing.py",
    "envs/kernels/pose.py",
    "envs/kernels/constraints.py",
    "envs/kernels/step.py",
    "envs/kernels/evaluation.py",
    "envs/kernels/paths.py",
    "envs/kernels/three.py",
    "envs/kernels/linalg.py",
    "envs/arguments.py",
    "envs/params.py",
    "envs/presets.py",
    "envs/physics.py",
    "envs/env.py",
    "envs/vector.py",
    "envs/tasks/certificate.py",
    "envs/tasks/samplers.py",
    "envs/tasks/grid.py",
    "envs/tasks/grid_kernels.py",
    "envs/rendering.py",
]


def code_lines(path: Path) -> int:
    """Lines of ``path`` that hold code: not blank, not comments, not docstrings."""
    source = path.read_text()
    lines: set[int] = set()
    previous = tokenize.NEWLINE
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        kind = token.type
        if kind in (tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT):
            if kind in (tokenize.NEWLINE, tokenize.NL):
                previous = kind
            continue
        if kind == tokenize.STRING and previous in (tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT):
            previous = tokenize.STRING  # a docstring (a string statement)
            continue
        lines.update(range(token.start[0], token.end[0] + 1))
        previous = kind
    return len(lines)


def main() -> int:
    """Print the table."""
    print("| part | files | code lines |")
    print("|---|---|---|")
    for name, files in ROBOTS.items():
        print(f"| {name} | {len(files)} | {sum(code_lines(ROOT / f) for f in files)} |")
    total = sum(code_lines(ROOT / f) for f in CORE)
    print(f"| generic family core ({', '.join(CORE)}) | {len(CORE)} | {total} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
