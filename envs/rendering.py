"""Headless rendering of any robot of the family to an RGB array (Pillow), and the window of "human" mode.

One drawing per pose space: a top view for planar robots, a perspective view for spatial and translational ones.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache
from typing import Any

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from envs._extras import require

__all__ = ["HumanWindow", "leg_color", "render_family_frame"]

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
        plt = require("matplotlib.pyplot", "train", 'render_mode="human"')
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


# Fills and grid of the drawings.
_GRID = (226, 226, 220)
_BASE_FILL = (232, 232, 226)
_PLATFORM_FILL = (168, 194, 234)
#: Axis colours of a frame triad: x red, y green, z blue; the target's are paler.
_AXES = ((215, 40, 40), (40, 160, 70), (40, 80, 215))
_GHOST_AXES = ((235, 150, 150), (140, 205, 155), (150, 170, 235))

#: Fixed camera of the spatial view: azimuth from the x axis of {B} and elevation above its xy plane [deg].
_AZIMUTH_DEG = 35.0
_ELEVATION_DEG = 25.0
#: Distance from the camera to the centre of the framed box, in units of the box's half-diagonal.
_CAMERA_DISTANCE = 3.0
#: Fraction of the image side left empty on each edge.
_MARGIN = 0.05


@lru_cache(maxsize=8)
def _font(size: int) -> Any:
    """Pillow's default font at ``size`` px (loaded once per size)."""
    return ImageFont.load_default(size=size)


def _pose(name: str, value: Any, m: int) -> np.ndarray:
    """A finite float pose of shape (m,), or a ``ValueError`` naming it."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (m,):
        raise ValueError(f"{name} must have shape ({m},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    return arr


def _framed_box(robot: Any, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Corners (lo, hi) [m], shape (d,), of the box holding the base anchors and the platforms in the bounds.

    The position bounds are widened by the platform's radius horizontally and by half of it vertically (a
    platform tilted by up to 30°), the base by the longest crank.
    """
    d = robot.pose_space.point_dim
    reach = np.full(d, float(np.max(np.linalg.norm(robot.platform, axis=1))))
    if d == 3:
        reach[2] *= 0.5
    base = np.asarray(robot.base)
    arm = float(np.max(robot.crank_radii))  # the cranks' elbows swing this far around their motors
    lo = np.minimum(low[:d] - reach, base.min(axis=0) - arm)
    hi = np.maximum(high[:d] + reach, base.max(axis=0) + arm)
    return lo, hi


def _dashed(draw: ImageDraw.ImageDraw, pixels: np.ndarray, fill: tuple[int, int, int], width: int, dash: float) -> None:
    """Draw the closed polygon through ``pixels`` (shape (n, 2)) with dashes of ``dash`` px."""
    for a, b in zip(pixels, np.roll(pixels, -1, axis=0)):
        n = max(1, int(np.linalg.norm(b - a) / dash))
        t = np.linspace(0.0, 1.0, n + 1)
        points = a + t[:, None] * (b - a)
        for i in range(0, n, 2):
            draw.line([tuple(points[i]), tuple(points[i + 1])], fill=fill, width=width)


class _PlanView:
    """Top-down map from {B} points [m] to pixels: a square frame around a 2-D box, y up."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, size: int) -> None:
        center, half = (lo + hi) / 2.0, float(np.max(hi - lo)) / 2.0 / (1.0 - 2.0 * _MARGIN)
        self.origin = center - half
        self.scale = size / (2.0 * half)
        self.size = size

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Pixels (column, row), shape (n, 2), of points of shape (n, 2) or (2,)."""
        pix = (np.atleast_2d(points) - self.origin) * self.scale
        pix[:, 1] = self.size - pix[:, 1]
        return pix


class _Camera:
    """Perspective map from {B} points [m] to pixels, from a fixed azimuth and elevation, framing a 3-D box."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, size: int) -> None:
        centre = (lo + hi) / 2.0
        radius = float(np.linalg.norm(hi - lo)) / 2.0
        az, el = math.radians(_AZIMUTH_DEG), math.radians(_ELEVATION_DEG)
        towards_eye = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        self.eye = centre + _CAMERA_DISTANCE * radius * towards_eye
        forward = -towards_eye
        right = np.cross(forward, (0.0, 0.0, 1.0))
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        self.axes = np.stack([right, up, forward])  # rows: camera axes in {B}
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        uv, _ = self._image_plane(corners)
        uv_lo, uv_hi = uv.min(axis=0), uv.max(axis=0)
        self.scale = size * (1.0 - 2.0 * _MARGIN) / float(np.max(uv_hi - uv_lo))
        self.uv_centre = (uv_lo + uv_hi) / 2.0
        self.size = size

    def _image_plane(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normalised image coordinates (right, up), shape (n, 2), and depths [m] along the view, shape (n,)."""
        camera = (np.atleast_2d(points) - self.eye) @ self.axes.T
        depth = camera[:, 2]
        return camera[:, :2] / depth[:, None], depth

    def __call__(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (column, row), shape (n, 2), and depths [m], shape (n,), of points of shape (n, 3) or (3,)."""
        uv, depth = self._image_plane(points)
        pix = (uv - self.uv_centre) * self.scale
        pix[:, 0] += self.size / 2.0
        pix[:, 1] = self.size / 2.0 - pix[:, 1]
        return pix, depth


def _nice_spacing(extent: float) -> float:
    """A round grid spacing (1, 2 or 5 × 10ⁿ m) giving about eight cells over ``extent`` [m]."""
    raw = extent / 8.0
    power = 10.0 ** math.floor(math.log10(raw))
    return next(f * power for f in (1.0, 2.0, 5.0, 10.0) if f * power >= raw)


def _points(pixels: np.ndarray) -> list[tuple[float, float]]:
    """Pixel rows as the list of tuples Pillow draws."""
    return [(float(u), float(v)) for u, v in pixels]


def _draw_planar(
    draw: ImageDraw.ImageDraw,
    robot: Any,
    x: np.ndarray,
    target: np.ndarray,
    color: tuple[int, int, int],
    box: tuple[np.ndarray, np.ndarray],
    trail: np.ndarray,
    size: int,
    anchors: np.ndarray | None = None,
) -> None:
    """Top-down drawing: base triangle, target ghost, trail, legs, platform and its (x, y) triad.

    With ``anchors`` (cranks' elbows or sliders' carriages, shape (n, 2) [m]) each leg is drawn as its actuator's
    part B_i → A_i in grey and its link A_i → P_i in the conditioning colour.
    """
    view = _PlanView(*box, size)
    line, dot, axis = max(2, size // 120), max(3, size // 96), 0.5 * robot.characteristic_length
    base = view(robot.base)
    draw.polygon(_points(base), fill=_BASE_FILL, outline=_BASE, width=max(1, line // 2))
    ghost = view(robot.platform_points_in_base(target, validate=False))
    _dashed(draw, ghost, _TARGET, max(1, line // 2), dash=size / 80)
    cx, cy = view(target[:2])[0]
    arm = size / 80
    draw.line([(cx - arm, cy), (cx + arm, cy)], fill=_TARGET, width=max(1, line // 2))
    draw.line([(cx, cy - arm), (cx, cy + arm)], fill=_TARGET, width=max(1, line // 2))
    if len(trail) > 1:
        draw.line(_points(view(trail)), fill=_TRAIL, width=max(1, line // 2))
    platform = view(robot.platform_points_in_base(x, validate=False))
    starts = base if anchors is None else view(anchors)
    if anchors is not None:
        for b, a in zip(base, starts):
            draw.line([tuple(b), tuple(a)], fill=_BASE, width=2 * line)
    for b, p in zip(starts, platform):
        draw.line([tuple(b), tuple(p)], fill=color, width=2 * line)
    draw.polygon(_points(platform), fill=_PLATFORM_FILL, outline=_PLATFORM, width=line)
    R = robot.rotation_matrix(x, validate=False)
    origin = view(x[:2])[0]
    for j in range(2):
        tip = view(x[:2] + axis * R[:, j])[0]
        draw.line([tuple(origin), tuple(tip)], fill=_AXES[j], width=line)
    for u, v in np.concatenate([base, platform]):
        draw.ellipse([u - dot, v - dot, u + dot, v + dot], fill=_BASE)


def _draw_spatial(
    draw: ImageDraw.ImageDraw,
    robot: Any,
    x: np.ndarray,
    target: np.ndarray,
    color: tuple[int, int, int],
    box: tuple[np.ndarray, np.ndarray],
    trail: np.ndarray,
    size: int,
    anchors: np.ndarray | None = None,
) -> None:
    """Perspective drawing, far things first: ground grid, base, legs and platform by depth, then trail and triads.

    With ``anchors`` (cranks' elbows or sliders' carriages, shape (n, 3) [m]) each leg is drawn as its actuator's
    part B_i → A_i in grey and its link A_i → P_i in the conditioning colour.
    """
    lo, hi = box
    camera = _Camera(lo, hi, size)
    line, dot = max(2, size // 120), max(3, size // 120)
    axis = robot.characteristic_length / 3.0
    ground = float(np.min(robot.base[:, 2]))

    spacing = _nice_spacing(float(np.max(hi[:2] - lo[:2])))
    xs = np.arange(math.ceil(lo[0] / spacing), math.floor(hi[0] / spacing) + 1) * spacing
    ys = np.arange(math.ceil(lo[1] / spacing), math.floor(hi[1] / spacing) + 1) * spacing
    ends = [((gx, lo[1], ground), (gx, hi[1], ground)) for gx in (lo[0], *xs, hi[0])]
    ends += [((lo[0], gy, ground), (hi[0], gy, ground)) for gy in (lo[1], *ys, hi[1])]
    grid, _ = camera(np.reshape(ends, (-1, 3)))
    for a, b in zip(grid[0::2], grid[1::2]):
        draw.line([tuple(a), tuple(b)], fill=_GRID, width=1)

    base, base_depth = camera(robot.base)
    draw.polygon(_points(base), fill=_BASE_FILL, outline=_BASE, width=max(1, line // 2))
    for u, v in base:
        draw.ellipse([u - dot, v - dot, u + dot, v + dot], fill=_BASE)

    platform, platform_depth = camera(robot.platform_points_in_base(x, validate=False))
    starts, start_depth = (base, base_depth) if anchors is None else camera(anchors)
    leg_depth = (start_depth + platform_depth) / 2.0
    centre_depth = float(np.mean(platform_depth))
    order = np.argsort(-leg_depth)

    def draw_leg(i: int) -> None:
        if anchors is not None:
            draw.line([tuple(base[i]), tuple(starts[i])], fill=_BASE, width=2 * line + 1)
        draw.line([tuple(starts[i]), tuple(platform[i])], fill=color, width=2 * line + 1)
        u, v = platform[i]
        draw.ellipse([u - dot, v - dot, u + dot, v + dot], fill=_BASE)

    for i in order[leg_depth[order] > centre_depth]:
        draw_leg(i)
    draw.polygon(_points(platform), fill=_PLATFORM_FILL, outline=_PLATFORM, width=line)
    for i in order[leg_depth[order] <= centre_depth]:
        draw_leg(i)

    if len(trail) > 1:
        draw.line(_points(camera(trail)[0]), fill=_TRAIL, width=line)
    ghost, _ = camera(robot.platform_points_in_base(target, validate=False))
    _dashed(draw, ghost, _TARGET, max(1, line // 2), dash=size / 80)
    for pose, colours, width in ((target, _GHOST_AXES, max(1, line // 2)), (x, _AXES, line)):
        R = robot.rotation_matrix(pose, validate=False)
        p = pose[:3]
        pixels, depth = camera(np.vstack([p, p + axis * R.T]))
        for j in np.argsort(-depth[1:]):
            draw.line([tuple(pixels[0]), tuple(pixels[j + 1])], fill=colours[j], width=width)


def render_family_frame(
    robot: Any,
    x: Any,
    target: Any,
    inverse_condition: float,
    *,
    safe_threshold: float,
    hard_threshold: float,
    view_low: Sequence[float],
    view_high: Sequence[float],
    trail: Sequence[Any] = (),
    step: int | None = None,
    size: int = 480,
    q: Any = None,
) -> np.ndarray:
    """Draw a robot of the distance-constraint family, its legs coloured by conditioning, its target and a trail.

    Planar robots are drawn top-down (y up): the base triangle, the legs, the platform polygon with its x (red)
    and y (green) axes, the target platform as a dashed magenta outline with a cross at its origin, and the trail.
    Spatial robots are drawn in perspective from a fixed camera (azimuth 35°, elevation 25°, looking at the
    centre of the framed box): a ground grid in the plane of the lowest anchor, the base polygon (anchors joined
    in order), the legs and the platform polygon in depth order, the triad of {P} (x red, y green, z blue, of
    length ℓ_c/3, 0.1 m for the default hexapod), the target platform as a dashed magenta outline with a pale
    triad, and the trail. Both print "t = step  k = …" in the top-left corner. The framing depends on the robot
    and the view bounds only, so that frames of one episode share a camera.

    Args:
        robot: A ``kinematics.DistanceConstraintMechanism`` (pose space planar, spatial or translational).
        x: Platform pose of {P} in {B}, shape (m,): planar (x [m], y [m], φ [rad]); spatial (p [m],
            rotation vector r [rad]); translational (p [m], drawn as the spatial ones with R = I).
        target: Target pose, shape (m,), same convention.
        inverse_condition: Homogeneous inverse condition number k in [0, 1] (printed and used for the legs'
            colour, see ``leg_color``).
        safe_threshold: k at and above which the legs are green.
        hard_threshold: k at and below which the legs are red; less than ``safe_threshold``.
        view_low: Lower pose bounds, m values; the position part (first d) sets the framed region, which is
            widened to hold the base anchors and a platform anywhere inside the bounds.
        view_high: Upper pose bounds, m values, above ``view_low`` in the position part.
        trail: Past platform positions [m] in {B}, each of shape (d,), oldest first; drawn as a polyline.
        step: Step index to print, if given.
        size: Side of the square image [px], at least 32.
        q: Actuator coordinates, shape (n,); with cranks or sliders they place the elbows or carriages (default:
            the robot's inverse kinematics of x, on its chosen branches).

    Returns:
        The frame, uint8 of shape (size, size, 3).

    Raises:
        ValueError: An unknown pose space, arguments of the wrong shape, non-finite poses, thresholds out of
            order, empty view bounds or a size below 32.
    """
    space = robot.pose_space
    if space.name not in ("planar", "spatial", "translational"):
        raise ValueError(f"robot.pose_space.name must be 'planar', 'spatial' or 'translational', got {space.name!r}")
    m, d = space.n_pose, space.point_dim
    x, target = _pose("x", x, m), _pose("target", target, m)
    low, high = _pose("view_low", view_low, m), _pose("view_high", view_high, m)
    if not np.all(high[:d] > low[:d]):
        raise ValueError(f"view_high must exceed view_low in its first {d} entries, got {low[:d]} and {high[:d]}")
    if not float(safe_threshold) > float(hard_threshold):
        raise ValueError(f"safe_threshold must exceed hard_threshold, got {safe_threshold!r} and {hard_threshold!r}")
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < 32:
        raise ValueError(f"size must be an integer of at least 32 [px], got {size!r}")
    size = int(size)
    trail_points = np.asarray(trail, dtype=np.float64) if len(trail) else np.empty((0, d))
    if trail_points.ndim != 2 or trail_points.shape[1] != d:
        raise ValueError(f"trail must be a sequence of positions of shape ({d},), got shape {trail_points.shape}")

    image = Image.new("RGB", (size, size), _BACKGROUND)
    draw = ImageDraw.Draw(image)
    color = leg_color(inverse_condition, safe_threshold, hard_threshold)
    box = _framed_box(robot, low, high)
    anchors = None
    if any(kind != "leg" for kind in robot.actuator_kinds):
        strokes = robot.inverse_kinematics(x, validate=False) if q is None else np.asarray(q, dtype=np.float64)
        anchors = robot.anchors(strokes, validate=False)
    if space.name == "planar":
        _draw_planar(draw, robot, x, target, color, box, trail_points, size, anchors)
    else:
        _draw_spatial(draw, robot, x, target, color, box, trail_points, size, anchors)

    text = f"k = {float(inverse_condition):.3f}"
    if step is not None:
        text = f"t = {step}  {text}"
    draw.text((8, 8), text, fill=_TEXT, font=_font(max(10, size // 36)))
    return np.asarray(image, dtype=np.uint8)
