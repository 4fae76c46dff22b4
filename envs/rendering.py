"""Headless rendering of a planar 3-RPR robot to an RGB array (Pillow), and a window for "human" mode."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from envs.core import EnvParams

__all__ = ["HumanWindow", "condition_color", "leg_color", "render_frame"]

_BACKGROUND = (250, 250, 247)
_BASE = (90, 90, 90)
_PLATFORM = (40, 90, 180)
_TARGET = (200, 40, 160)
_TRAIL = (120, 160, 220)
_TEXT = (20, 20, 20)


def leg_color(k: float, safe_threshold: float, hard_threshold: float) -> tuple[int, int, int]:
    """Leg colour for an inverse condition number: green when safe, through orange, to red at the hard stop.

    The colour is interpolated linearly between red (k ≤ hard_threshold) and green (k ≥ safe_threshold).
    A non-finite k (a singular pose) is drawn red.

    Args:
        k: Homogeneous inverse condition number in [0, 1].
        safe_threshold: k at and above which the legs are green.
        hard_threshold: k at and below which the legs are red; less than ``safe_threshold``.

    Returns:
        An RGB triple.
    """
    k = float(k)
    if not math.isfinite(k):
        k = hard_threshold
    s = min(max((k - hard_threshold) / (safe_threshold - hard_threshold), 0.0), 1.0)
    red, green = (215, 40, 40), (40, 160, 70)
    return tuple(int(round(r + s * (g - r))) for r, g in zip(red, green))


def condition_color(k: float, params: EnvParams) -> tuple[int, int, int]:
    """Leg colour for an inverse condition number with the thresholds of ``params`` (see ``leg_color``).

    Args:
        k: Homogeneous inverse condition number in [0, 1].
        params: Environment constants (safe and hard thresholds).

    Returns:
        An RGB triple.
    """
    return leg_color(k, params.safe_threshold, params.hard_threshold)


class _View:
    """World [m] to pixel mapping of a square frame covering the pose bounds."""

    def __init__(self, params: EnvParams, size: int) -> None:
        lo, hi = np.array(params.pose_low[:2]), np.array(params.pose_high[:2])
        center, half = (lo + hi) / 2.0, float(np.max(hi - lo)) / 2.0 * 1.05
        self.origin = center - half
        self.scale = size / (2.0 * half)
        self.size = size

    def __call__(self, p: np.ndarray) -> list[tuple[float, float]]:
        pix = (np.atleast_2d(p) - self.origin) * self.scale
        return [(float(u), float(self.size - v)) for u, v in pix]


def render_frame(
    params: EnvParams,
    q: np.ndarray,
    x: np.ndarray,
    target: np.ndarray,
    inverse_condition: float,
    trail: Sequence[np.ndarray] = (),
    step: int | None = None,
    size: int = 480,
) -> np.ndarray:
    """Draw the base, the legs coloured by conditioning, the platform, the target and a trail.

    Args:
        params: Environment constants (robot geometry, bounds, thresholds).
        q: Strokes [m], shape (3,) (shown as text).
        x: Platform pose (x [m], y [m], φ [rad]), shape (3,).
        target: Target pose, shape (3,).
        inverse_condition: Current homogeneous inverse condition number.
        trail: Past platform positions (x, y) [m], oldest first.
        step: Step index to print, if given.
        size: Side of the square image [px].

    Returns:
        The frame, uint8 of shape (size, size, 3).
    """
    robot = params.robot
    view = _View(params, size)
    image = Image.new("RGB", (size, size), _BACKGROUND)
    draw = ImageDraw.Draw(image)
    base = view(robot.base)
    draw.polygon(base, outline=_BASE, width=2)
    target_points = view(robot.platform_points_in_base(target, validate=False))
    draw.polygon(target_points, outline=_TARGET, width=2)
    cx, cy = view(target[:2])[0]
    draw.line([(cx - 6, cy), (cx + 6, cy)], fill=_TARGET, width=2)
    draw.line([(cx, cy - 6), (cx, cy + 6)], fill=_TARGET, width=2)
    if len(trail) > 1:
        draw.line(view(np.asarray(trail)), fill=_TRAIL, width=2)
    platform = view(robot.platform_points_in_base(x, validate=False))
    leg_color = condition_color(inverse_condition, params)
    for b, p in zip(base, platform):
        draw.line([b, p], fill=leg_color, width=4)
    draw.polygon(platform, fill=_PLATFORM, outline=_PLATFORM)
    for b in base:
        draw.ellipse([b[0] - 5, b[1] - 5, b[0] + 5, b[1] + 5], fill=_BASE)
    font = ImageFont.load_default()
    lines = [f"k = {inverse_condition:.3f}", "L = " + ", ".join(f"{v:.3f}" for v in np.asarray(q))]
    if step is not None:
        lines.insert(0, f"step {step}")
    draw.multiline_text((8, 8), "\n".join(lines), fill=_TEXT, font=font)
    return np.asarray(image, dtype=np.uint8)


class HumanWindow:
    """A matplotlib window that shows frames as they come (needs a display)."""

    def __init__(self, fps: float) -> None:
        """Open the window lazily at the first frame.

        Args:
            fps: Frames per second to pace the display.
        """
        self._fps = fps
        self._figure = None
        self._image = None

    def show(self, frame: np.ndarray) -> None:
        """Display one frame.

        Args:
            frame: RGB image, uint8 of shape (H, W, 3).
        """
        import matplotlib.pyplot as plt

        if self._figure is None:
            plt.ion()
            self._figure, ax = plt.subplots(figsize=(5, 5))
            ax.set_axis_off()
            self._image = ax.imshow(frame)
        else:
            self._image.set_data(frame)
        self._figure.canvas.draw_idle()
        plt.pause(1.0 / self._fps)

    def close(self) -> None:
        """Close the window if it is open."""
        if self._figure is not None:
            import matplotlib.pyplot as plt

            plt.close(self._figure)
            self._figure = None
