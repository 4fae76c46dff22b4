"""The kinematics layer imports nothing from the layers above it (Gymnasium, SB3, torch)."""

import json
import subprocess
import sys

import pytest

HEAVY = ("gymnasium", "stable_baselines3", "torch")


@pytest.mark.parametrize(
    "statement",
    [
        "import kinematics",
        "from kinematics import Planar3RPR; Planar3RPR().forward_jacobian([0.6, 0.5, 0.6], [0.5, 0.3, 0.1])",
        "import kinematics.linalg, kinematics.mechanism, kinematics.planar_3rpr, kinematics._validation",
    ],
)
def test_kinematics_does_not_import_upper_layers(statement):
    """A fresh interpreter that uses kinematics has no gymnasium, stable_baselines3 or torch loaded."""
    code = f"import json, sys\n{statement}\nprint(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    modules = json.loads(done.stdout.splitlines()[-1])
    assert "kinematics" in modules
    for name in HEAVY:
        assert not any(m == name or m.startswith(name + ".") for m in modules), f"kinematics imported {name}"


def test_kinematics_needs_only_numpy():
    """Besides the standard library, numpy is the only third-party package kinematics loads."""
    code = (
        "import sys\nbefore = set(sys.modules)\nimport kinematics\n"
        "print(' '.join(sorted({m.split('.')[0] for m in set(sys.modules) - before})))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded = set(done.stdout.split())
    third_party = {m for m in loaded - set(sys.stdlib_module_names) if not m.startswith("_")}
    assert third_party <= {"kinematics", "numpy"}, third_party
