"""Figures of evaluations: trajectories over the conditioning map, k over time, and GIFs (matplotlib Agg)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from PIL import Image

from envs.kernels import generic as fk
from envs.params import FamilyParams
from envs.tasks.grid import WorkspaceMap
from training.records import EpisodeRecord

__all__ = ["condition_figure", "paths_slice_figure", "safety_slice", "save_gif", "trajectories_figure"]


def _condition_slice(params: FamilyParams, workspace: WorkspaceMap, phi: float) -> tuple[np.ndarray, np.ndarray]:
    """Inverse condition number over (x, y) at orientation φ, NaN where a stroke limit is violated."""
    xs, ys, _ = workspace.axes
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    poses = np.stack([X, Y, np.full_like(X, phi)], axis=-1)
    robot = params.robot
    q = robot.inverse_kinematics(poses, validate=False)
    lo, hi = params.stroke_limits
    k = robot.inverse_condition_number(np.maximum(q, 1e-9), poses, validate=False)
    reachable = (q.min(axis=-1) >= lo) & (q.max(axis=-1) <= hi)
    return np.where(reachable, k, np.nan), np.array([xs[0], xs[-1], ys[0], ys[-1]])


def trajectories_figure(
    runs: dict[str, list[EpisodeRecord]],
    params: FamilyParams,
    workspace: WorkspaceMap,
    path: Path,
    episodes: int = 4,
) -> Path:
    """Paths of the first episodes of each agent over the map of k where each came closest to a singularity.

    Rows are agents, columns episodes (the same seeds, so the same start and target across a column).
    The background is the homogeneous inverse condition number on the (x, y) plane at the orientation
    φ the platform had when k was smallest along the episode; grey is out of the stroke limits; the
    hatched zone is k < k_safe (orange line), the red line k = hard threshold.

    Args:
        runs: Agent label → its episode records.
        params: Environment constants.
        workspace: Certified grid (its axes set the map's resolution).
        path: Output PNG.
        episodes: Columns to draw.

    Returns:
        ``path``.
    """
    labels = list(runs)
    cols = min(episodes, min(len(r) for r in runs.values()))
    fig, axes = plt.subplots(len(labels), cols, figsize=(3.4 * cols, 3.3 * len(labels)), squeeze=False)
    cmap = plt.get_cmap("viridis").with_extremes(bad="0.85")
    image = None
    for row, label in enumerate(labels):
        for col in range(cols):
            rec = runs[label][col]
            ax = axes[row, col]
            phi = float(rec.poses[int(np.argmin(rec.inverse_condition)), 2])
            k_map, extent = _condition_slice(params, workspace, phi)
            image = ax.imshow(k_map.T, origin="lower", extent=extent, cmap=cmap, vmin=0.0, vmax=1.0)
            ax.contourf(
                np.linspace(extent[0], extent[1], k_map.shape[0]),
                np.linspace(extent[2], extent[3], k_map.shape[1]),
                np.nan_to_num(k_map.T, nan=1.0),
                levels=[0.0, params.safe_threshold],
                colors="none",
                hatches=["////"],
            )
            ax.contour(
                np.linspace(extent[0], extent[1], k_map.shape[0]),
                np.linspace(extent[2], extent[3], k_map.shape[1]),
                np.nan_to_num(k_map.T, nan=1.0),
                levels=[params.hard_threshold, params.safe_threshold],
                colors=["red", "orange"],
                linewidths=0.8,
            )
            ax.plot(rec.poses[:, 0], rec.poses[:, 1], color="white", lw=2.2)
            ax.plot(rec.poses[:, 0], rec.poses[:, 1], color="C3", lw=1.2)
            ax.plot(*rec.poses[0, :2], "o", color="white", mec="k", ms=6)
            ax.plot(*rec.targets[-1, :2], "*", color="magenta", mec="k", ms=12)
            ax.plot(*rec.poses[-1, :2], "x", color="k", ms=7)
            outcome = "success" if rec.success else (rec.termination_reason or "not reached")
            ax.set_title(f"{label}\nep {rec.episode}: {outcome}, min k {rec.min_inverse_condition:.3f}", fontsize=8)
            ax.set_xticks([])
            ax.set_yticks([])
    if image is not None:
        fig.colorbar(image, ax=axes, shrink=0.8, label="inverse condition number k at φ of the episode's min k")
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return path


def condition_figure(
    runs: dict[str, list[EpisodeRecord]], params: FamilyParams, path: Path, episodes: int = 20
) -> Path:
    """Inverse condition number over time for each agent, with the safe and hard thresholds.

    Args:
        runs: Agent label → its episode records.
        params: Environment constants.
        path: Output PNG.
        episodes: Episodes drawn per agent.

    Returns:
        ``path``.
    """
    fig, axes = plt.subplots(1, len(runs), figsize=(5.0 * len(runs), 3.4), squeeze=False, sharey=True)
    for ax, (label, records) in zip(axes[0], runs.items()):
        for rec in records[:episodes]:
            t = np.arange(len(rec.inverse_condition)) * params.dt
            color = "C3" if rec.singularity_termination else ("C2" if rec.success else "C0")
            ax.plot(t, rec.inverse_condition, color=color, lw=0.9, alpha=0.8)
        ax.axhline(params.safe_threshold, color="orange", ls="--", lw=1, label="safe threshold")
        ax.axhline(params.hard_threshold, color="red", ls="--", lw=1, label="hard threshold (terminates)")
        ax.set(title=label, xlabel="time [s]", ylim=(0, 1))
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("inverse condition number k")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def save_gif(frames: list[np.ndarray], path: Path, fps: float, max_frames: int = 600) -> Path:
    """Write RGB frames as an animated GIF (Pillow), subsampled to at most ``max_frames``.

    Args:
        frames: uint8 images of shape (H, W, 3).
        path: Output file.
        fps: Playback rate of the unsampled frames.
        max_frames: Largest number of frames kept.

    Returns:
        ``path``.
    """
    stride = max(1, int(np.ceil(len(frames) / max_frames)))
    kept = frames[::stride]
    # One 64-colour palette from a sample of the frames, shared by all (quantising each frame on its own costs
    # about 20× more and makes the colours flicker from frame to frame).
    sample = np.concatenate(kept[:: max(1, len(kept) // 8)], axis=0)
    palette = Image.fromarray(sample).quantize(colors=64)
    images = [Image.fromarray(f).quantize(palette=palette, dither=Image.Dither.NONE) for f in kept]
    duration = int(round(1000.0 * stride / fps))
    images[0].save(path, save_all=True, append_images=images[1:], duration=duration, loop=0)
    return path


def safety_slice(
    params: FamilyParams, through: np.ndarray, resolution: int = 121
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The certificate's safety over the (x, y) plane through a pose: the map behind ``paths_slice_figure``.

    Args:
        params: Environment constants (the robot, its limits, k_safe, the pose bounds).
        through: The pose the plane goes through, shape (m,) [m, rad]: every coordinate but x and y is kept.
        resolution: Grid points per axis, over the pose bounds.

    Returns:
        (x (R,) [m], y (R,) [m], safety (R, R) indexed [x, y]: ``envs.tasks.certificate.safety_batch``, k (with
        cranks and sliders min(k, k_I · k_safe / k_I,safe)), NaN where an actuator leaves its limits).
    """
    low, high = np.asarray(params.pose_low, dtype=float), np.asarray(params.pose_high, dtype=float)
    xs, ys = np.linspace(low[0], high[0], resolution), np.linspace(low[1], high[1], resolution)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    poses = np.repeat(np.asarray(through, dtype=float)[None], X.size, axis=0)
    poses[:, 0], poses[:, 1] = X.ravel(), Y.ravel()
    safety = fk.safety_batch(params.packed, poses)[0].reshape(X.shape)
    return xs, ys, np.where(safety < 0.0, np.nan, safety)


def paths_slice_figure(runs: dict[str, EpisodeRecord], params: FamilyParams, path: Path, title: str) -> Path:
    """Several agents' paths on one episode over the safety map of the (x, y) plane through the reference's worst pose.

    The plane goes through the pose where the first agent's path has its smallest k (every other coordinate, the
    height and orientation of a spatial robot or φ of a planar one, is that pose's); the paths are drawn projected
    onto it. Grey is out of the actuator limits; the hatched zone is safety < k_safe (orange line), the red line
    safety = k_hard.

    Args:
        runs: Agent label → its record of the episode (the same reset seed for all).
        params: Environment constants.
        path: Output PNG.
        title: The figure's title (the robot and the episode).

    Returns:
        ``path``.
    """
    first = next(iter(runs.values()))
    through = first.poses[int(np.argmin(first.inverse_condition))]
    xs, ys, safety = safety_slice(params, through)
    fig, ax = plt.subplots(figsize=(6.4, 5.4))
    cmap = plt.get_cmap("viridis").with_extremes(bad="0.85")
    image = ax.imshow(
        safety.T, origin="lower", extent=(xs[0], xs[-1], ys[0], ys[-1]), cmap=cmap, vmin=0.0, vmax=0.6, aspect="auto"
    )
    filled = np.nan_to_num(safety.T, nan=1.0)
    ax.contourf(xs, ys, filled, levels=[0.0, params.safe_threshold], colors="none", hatches=["////"])
    ax.contour(
        xs, ys, filled, levels=[params.hard_threshold, params.safe_threshold], colors=["red", "orange"], linewidths=0.9
    )
    colours = ("#1f77b4", "#2ca02c", "#e377c2", "#8c564b", "#17becf", "#bcbd22")  # none of the contours' red/orange
    for i, (label, rec) in enumerate(runs.items()):
        outcome = "reached" if rec.success else (rec.termination_reason or "not reached")
        colour = colours[i % len(colours)]
        width = max(3.2 - 0.5 * i, 1.0)  # earlier agents drawn wider, so that a path on another stays visible
        ax.plot(rec.poses[:, 0], rec.poses[:, 1], color="white", lw=width + 1.4)
        ax.plot(
            rec.poses[:, 0], rec.poses[:, 1], color=colour, lw=width,
            label=f"{label}: {outcome}, min k {rec.min_inverse_condition:.3f}",
        )  # fmt: skip
        ax.plot(*rec.poses[-1, :2], "x", color=colour, mec="k", ms=8)
    # the view: the slice's reachable part and every path, with a margin
    finite = np.isfinite(safety)
    points = np.concatenate([rec.poses[:, :2] for rec in runs.values()])
    if finite.any():
        reach = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1)[finite]
        points = np.concatenate([points, reach])
    low, high = points.min(axis=0), points.max(axis=0)
    pad = 0.08 * np.maximum(high - low, 1e-3)
    ax.set_xlim(max(xs[0], low[0] - pad[0]), min(xs[-1], high[0] + pad[0]))
    ax.set_ylim(max(ys[0], low[1] - pad[1]), min(ys[-1], high[1] + pad[1]))
    ax.plot(*first.poses[0, :2], "o", color="white", mec="k", ms=7, label="start")
    ax.plot(*first.targets[-1, :2], "*", color="magenta", mec="k", ms=13, label="target")
    ax.plot(*through[:2], "D", color="orange", mec="k", ms=5, label=f"{next(iter(runs))}'s min k (the plane's pose)")
    others = ", ".join(f"{v:.3g}" for v in through[2:])
    ax.set_title(f"{title}\nslice at the other pose coordinates ({others})", fontsize=9)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(fontsize=7, loc="lower left", framealpha=0.85)
    fig.colorbar(image, ax=ax, shrink=0.85, label="safety (k) on the slice")
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return path
