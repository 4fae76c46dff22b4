"""Family rendering: frame format for planar and spatial robots, motion, leg colour by conditioning, headless."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from envs.rendering import leg_color, render_family_frame
from kinematics import Planar3RPR, StewartGough

REPO_ROOT = Path(__file__).resolve().parents[2]
SAFE, HARD = 0.2, 0.05
#: Half-widths of the hexapod's view bounds around its home pose (p [m], r [rad]).
HEXAPOD_SPAN = np.array([0.15, 0.15, 0.12, 0.4, 0.4, 0.6])
#: A shifted and tilted hexapod pose, relative to home (p [m], r [rad]).
HEXAPOD_OFFSET = np.array([0.05, -0.03, 0.04, 0.15, -0.1, 0.2])


def _hexapod_case() -> tuple[StewartGough, dict]:
    robot = StewartGough()
    home = robot.home_pose()
    return robot, {"view_low": home - HEXAPOD_SPAN, "view_high": home + HEXAPOD_SPAN}


def _planar_case() -> tuple[Planar3RPR, dict]:
    return Planar3RPR(), {"view_low": [0.0, 0.0, -np.pi], "view_high": [1.0, 0.9, np.pi]}


def _render(robot, bounds, x, k=0.5, **kwargs) -> np.ndarray:
    target = robot.home_pose()
    return render_family_frame(robot, x, target, k, safe_threshold=SAFE, hard_threshold=HARD, **bounds, **kwargs)


CASES = {
    "hexapod-home": (_hexapod_case, np.zeros(6)),
    "hexapod-tilted": (_hexapod_case, HEXAPOD_OFFSET),
    "planar-3rpr": (_planar_case, np.array([0.05, -0.03, 0.3])),
}


@pytest.mark.parametrize("case", CASES)
def test_frame_is_uint8_rgb(case):
    """Frames are (480, 480, 3) uint8 with a drawing on them (not a blank canvas)."""
    make, offset = CASES[case]
    robot, bounds = make()
    home = robot.home_pose()
    trail = [home[: robot.pose_space.point_dim] + shift for shift in (0.0, 0.02, 0.05)]
    frame = _render(robot, bounds, home + offset, step=3, trail=trail)
    assert frame.shape == (480, 480, 3)
    assert frame.dtype == np.uint8
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 10, "the frame is (almost) blank"


@pytest.mark.parametrize("make", [_hexapod_case, _planar_case], ids=["hexapod", "planar"])
def test_frames_are_deterministic_and_follow_the_pose(make):
    """The same pose gives the same frame; another pose gives another one."""
    robot, bounds = make()
    home = robot.home_pose()
    moved = home + (HEXAPOD_OFFSET if robot.pose_space.name == "spatial" else np.array([0.05, -0.03, 0.3]))
    frame = _render(robot, bounds, home)
    np.testing.assert_array_equal(_render(robot, bounds, home), frame)
    assert np.any(_render(robot, bounds, moved) != frame)


@pytest.mark.parametrize("make", [_hexapod_case, _planar_case], ids=["hexapod", "planar"])
def test_legs_turn_red_near_a_singularity(make):
    """Below the hard threshold the legs are drawn red, above the safe one green."""
    robot, bounds = make()
    x = robot.home_pose()
    red, green = leg_color(0.0, SAFE, HARD), leg_color(1.0, SAFE, HARD)

    def count(frame: np.ndarray, color: tuple[int, int, int]) -> int:
        return int(np.sum(np.all(frame.reshape(-1, 3) == color, axis=1)))

    near = _render(robot, bounds, x, k=0.5 * HARD)
    safe = _render(robot, bounds, x, k=2.0 * SAFE)
    assert count(near, red) - count(safe, red) > 500
    assert count(safe, green) - count(near, green) > 500


def test_leg_color_runs_from_red_to_green():
    """Red at and below the hard threshold, green at and above the safe one, red at a singular (NaN) k."""
    red, green = (215, 40, 40), (40, 160, 70)
    assert leg_color(0.0, SAFE, HARD) == leg_color(HARD, SAFE, HARD) == red
    assert leg_color(1.0, SAFE, HARD) == leg_color(SAFE, SAFE, HARD) == green
    assert leg_color(float("nan"), SAFE, HARD) == red
    greens = [leg_color(k, SAFE, HARD)[1] for k in np.linspace(HARD, SAFE, 7)]
    assert greens == sorted(greens)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"x": np.zeros(3)}, r"x must have shape \(6,\), got \(3,\)"),
        ({"target": np.full(6, np.nan)}, "target must be finite"),
        ({"safe_threshold": 0.01}, "safe_threshold must exceed hard_threshold"),
        ({"view_high": np.zeros(6)}, "view_high must exceed view_low"),
        ({"size": 8}, "size must be an integer of at least 32"),
        ({"trail": [np.zeros(2), np.zeros(2)]}, r"trail .* shape \(3,\), got shape \(2, 2\)"),
    ],
    ids=["x-shape", "target-nan", "thresholds", "view", "size", "trail"],
)
def test_bad_arguments_are_named(change, match):
    """Wrong shapes or values raise a ValueError that names the argument."""
    robot, bounds = _hexapod_case()
    arguments = {
        "x": robot.home_pose(),
        "target": robot.home_pose(),
        "inverse_condition": 0.5,
        "safe_threshold": SAFE,
        "hard_threshold": HARD,
        **bounds,
        **change,
    }
    with pytest.raises(ValueError, match=match):
        render_family_frame(robot, **arguments)


def test_headless_and_windowless():
    """Without DISPLAY, rendering works and loads no plotting or windowing library."""
    code = (
        "import json, sys\n"
        "import numpy as np\n"
        "from kinematics import Planar3RPR, StewartGough\n"
        "from envs.rendering import render_family_frame\n"
        "shapes = []\n"
        "for robot in (StewartGough(), Planar3RPR()):\n"
        "    h = robot.home_pose()\n"
        "    f = render_family_frame(robot, h, h, 0.5, safe_threshold=0.2, hard_threshold=0.05,\n"
        "                            view_low=h - 0.2, view_high=h + 0.2, step=1)\n"
        "    shapes.append([list(f.shape), str(f.dtype)])\n"
        "print(json.dumps({'shapes': shapes, 'modules': sorted(sys.modules)}))\n"
    )
    environment = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO_ROOT, env=environment, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout.splitlines()[-1])
    assert result["shapes"] == [[[480, 480, 3], "uint8"]] * 2
    loaded = {name.split(".")[0] for name in result["modules"]}
    windowing = {"matplotlib", "pygame", "pyglet", "tkinter", "_tkinter", "PyQt5", "PyQt6", "PySide2", "PySide6"}
    windowing |= {"wx", "gi", "cv2", "OpenGL", "glfw"}
    assert not loaded & windowing
