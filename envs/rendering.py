"""Colours of the headless frames (``envs.rendering_family``) and the window of "human" rendering."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["HumanWindow", "leg_color"]

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
