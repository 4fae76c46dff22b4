"""How many random safe task pairs of each robot's task boxes are detour tasks, and whether their ids reset.

Usage::

    python -m experiments.detour_survey --pairs 5000 --out docs/results/detour_survey

A *detour* hard Reach task (``hard_kind="detour"``, see ``envs.env.FamilyReachEnv``, Starting State) has a safe
start and a safe target (strokes inside the limits less the stroke margin, safety = min(k, k_I k_safe / k_I,safe)
≥ k_safe, in the task box ``sample_low``–``sample_high``), at least ``min_distance`` apart, whose straight
geodesic dips below k_safe while staying inside the task box and the stroke limits, and a waypoint whose two
geodesics start → waypoint → target are safe. For each robot and each box of ``SURVEY_BOXES`` (its preset's
box and larger candidates), the survey draws ``pairs`` such pairs (uniform in the box, each pose safe, the
pair at least ``min_distance`` apart, seeded) and sorts them into:

* ``straight_safe``: the straight geodesic is safe at the preset's ``segment_spacing`` (a standard task);
* ``leaves``: the straight geodesic leaves the stroke limits less the margin (``leaves_strokes``) or only
  the task box (``leaves_box``) before it is known to stay safe; such pairs are not hard tasks;
* ``dips``: it dips below k_safe inside both (``dips_below_hard``: below k_hard), split by a search of up to
  ``waypoints`` random safe waypoints of the box, each certified like the env's (``certified_segment_batch``,
  inside the box) into ``detour`` (one found) and ``no_detour``; ``detour_env`` counts the
  detours found within the env's ``WAYPOINT_TRIES`` waypoints, the ones its sampler would keep.

Every safety is the env's compiled certificate (``envs.tasks.certificate.safety_batch``, ``segment_batch`` and
``certified_segment_batch`` on the box's packed constants ``FamilyParams.packed``). For every box whose
``detour_env`` share of the pairs reaches ``--min-share``, ``resets`` resets of ``ParallelRobotReachHard-v0``
with the box's settings and ``hard_kind="detour"`` are timed, and each task is checked to be a detour task. The
JSON holds the counts and timings; the Markdown table is generated from it.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
from envs.kernels import generic as fk
from envs.params import FamilyParams
from envs.presets import build_family_params

__all__ = [
    "SURVEY_BOXES",
    "SurveyBox",
    "classify_pairs",
    "draw_pairs",
    "draw_safe_poses",
    "main",
    "render_markdown",
    "reset_check",
    "run_survey",
    "survey_box",
]

#: The registered id every box's reset check makes (``robot=`` a preset name, the box's settings).
RESET_ENV_ID = "ParallelRobotReachHard-v0"
#: Waypoints certified per compiled call while searching a pair's detour.
_WAYPOINT_CHUNK = 16
#: The survey re-checks every certified path at its spacing divided by this.
FINER = 10
#: The 3-RPR's preset draws its tasks on a grid; in a box (the survey, and a box detour id) it needs these.
_BOX_TASKS = {"task_region": "box", "track_shape": "sinusoid"}


@dataclass(frozen=True)
class SurveyBox:
    """A robot's task box to survey: a preset and the ``FamilyParams`` settings that change it.

    Attributes:
        robot: A preset name of ``envs.presets.ROBOT_PRESETS``.
        name: Short label of the box, unique per robot.
        description: What the box is, for the table.
        settings: Keyword arguments of the env over the preset's (``sample_low``, ``sample_high``, strokes, …).
    """

    robot: str
    name: str
    description: str
    settings: dict[str, Any] = field(default_factory=dict)

    def params(self) -> FamilyParams:
        """The box's validated parameters (the preset, the settings, ``hard_kind="detour"``)."""
        return build_family_params(self.robot, **self.env_kwargs())

    def env_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of ``gym.make(RESET_ENV_ID, ...)`` for detour tasks in this box."""
        return {**self.settings, "hard_kind": "detour"}


#: The boxes surveyed: each robot's preset box, then larger candidates around its Type II singularities.
_HEXAPOD_LONG = {"stroke_limits": (0.3, 1.1)}
_PRR_BAND = {"stroke_limits": (0.0, 0.52), "pose_low": (-0.2, -0.2, 0.0), "pose_high": (0.2, 0.2, 3.0)}
SURVEY_BOXES: tuple[SurveyBox, ...] = (
    SurveyBox("planar_3rpr", "preset", "the preset's box (x −0.15–1.15, y −0.25–1.15, φ ±1.47)", _BOX_TASKS),
    SurveyBox("planar_3rrr", "preset", "the preset's box (±0.1 m, φ ±0.7)"),
    SurveyBox(
        "planar_3rrr",
        "bounds",
        "the pose bounds (±0.125 m, φ ±0.9)",
        {"sample_low": (-0.125, -0.125, -0.9), "sample_high": (0.125, 0.125, 0.9)},
    ),
    SurveyBox("planar_3prr", "preset", "the derived box (±0.09 m, φ ±0.36)"),
    SurveyBox(
        "planar_3prr",
        "band",
        "±0.15 m, φ 1.4–2.6 across its Type II band (φ ≈ 2), rails 0–0.52 m",
        {**_PRR_BAND, "sample_low": (-0.15, -0.15, 1.4), "sample_high": (0.15, 0.15, 2.6)},
    ),
    SurveyBox(
        "planar_3prr",
        "below band",
        "±0.15 m, φ 0.5–2.1, up to the band",
        {**_PRR_BAND, "sample_low": (-0.15, -0.15, 0.5), "sample_high": (0.15, 0.15, 2.1)},
    ),
    SurveyBox("stewart_gough", "preset", "the standard box (±0.1 m, z 0.4–0.6 m, tilts ±0.2, yaw ±0.5)"),
    SurveyBox("stewart_gough_hard", "hard preset", "tilts ±0.3, yaw ±1.45, strokes 0.40–0.85 m"),
    SurveyBox(
        "stewart_gough_hard",
        "yaw 1.5, tilts 0.5",
        "±0.12 m, z 0.38–0.62 m, tilts ±0.5, yaw ±1.5, strokes 0.40–0.85 m",
        {"sample_low": (-0.12, -0.12, 0.38, -0.5, -0.5, -1.5), "sample_high": (0.12, 0.12, 0.62, 0.5, 0.5, 1.5)},
    ),
    SurveyBox(
        "stewart_gough_hard",
        "yaw 1.5, long strokes",
        "±0.12 m, z 0.38–0.62 m, tilts ±0.5, yaw ±1.5, strokes 0.3–1.1 m",
        {
            **_HEXAPOD_LONG,
            "sample_low": (-0.12, -0.12, 0.38, -0.5, -0.5, -1.5),
            "sample_high": (0.12, 0.12, 0.62, 0.5, 0.5, 1.5),
        },
    ),
    SurveyBox(
        "stewart_gough_hard",
        "bounds, long strokes",
        "the pose bounds (±0.2 m, z 0.3–0.75 m, tilts ±0.6, yaw ±1.9: both sides of Fichter's), strokes 0.3–1.1 m",
        {
            **_HEXAPOD_LONG,
            "sample_low": (-0.2, -0.2, 0.3, -0.6, -0.6, -1.9),
            "sample_high": (0.2, 0.2, 0.75, 0.6, 0.6, 1.9),
        },
    ),
    SurveyBox("delta", "preset", "the preset's box (±0.6 m, z −1.7 to −1.0 m)"),
    SurveyBox(
        "delta",
        "bounds",
        "the pose bounds (±0.75 m, z −1.8 to −0.85 m), its outer lower edge",
        {"sample_low": (-0.75, -0.75, -1.8), "sample_high": (0.75, 0.75, -0.85)},
    ),
    SurveyBox(
        "delta",
        "wide",
        "±1.0 m, z −1.9 to −0.7 m, motors −1.2 to 1.7 rad",
        {
            "stroke_limits": (-1.2, 1.7),
            "pose_low": (-1.0, -1.0, -1.9),
            "pose_high": (1.0, 1.0, -0.7),
            "sample_low": (-1.0, -1.0, -1.9),
            "sample_high": (1.0, 1.0, -0.7),
        },
    ),
)


def draw_safe_poses(params: FamilyParams, count: int, rng: np.random.Generator) -> tuple[np.ndarray, int]:
    """``count`` poses drawn uniformly in the task box, kept when safe (the env's ``_draw_safe``).

    Args:
        params: The box's parameters.
        count: Poses to return.
        rng: The random source.

    Returns:
        (poses (count, m), the number of poses drawn to find them).
    """
    c = params.packed
    low, high = np.array(params.sample_low), np.array(params.sample_high)
    kept: list[np.ndarray] = []
    found = drawn = 0
    batch = max(64, count)
    while found < count:
        x = low + (high - low) * rng.random((batch, len(low)))
        safety, _ = fk.safety_batch(c, x)
        x = x[safety >= params.safe_threshold]
        kept.append(x)
        found += len(x)
        drawn += batch
        if drawn > 10_000 * count + 1_000_000:
            raise RuntimeError(f"fewer than {count} safe poses among {drawn} of the task box")
    return np.concatenate(kept)[:count], drawn


def _distance(params: FamilyParams, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """‖(δp, ℓ_c δθ)‖ of the geodesic from a to b [m], shape (N,)."""
    return np.linalg.norm(params.robot.pose_difference(b, a) * params.pose_metric, axis=-1)


def draw_pairs(params: FamilyParams, count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, int]:
    """``count`` (start, target) pairs of safe poses at least ``min_distance`` apart.

    Args:
        params: The box's parameters.
        count: Pairs to return.
        rng: The random source.

    Returns:
        (starts (count, m), targets (count, m), the number of box poses drawn to find them).
    """
    starts, targets = [], []
    found = drawn = 0
    while found < count:
        a, da = draw_safe_poses(params, count, rng)
        b, db = draw_safe_poses(params, count, rng)
        keep = _distance(params, a, b) >= params.min_distance
        starts.append(a[keep])
        targets.append(b[keep])
        found += int(keep.sum())
        drawn += da + db
    return np.concatenate(starts)[:count], np.concatenate(targets)[:count], drawn


def _first_detour(
    params: FamilyParams, start: np.ndarray, target: np.ndarray, waypoints: int, rng: np.random.Generator
) -> tuple[int, np.ndarray | None]:
    """The first of up to ``waypoints`` random safe waypoints certifying a detour: (its index, it), or (−1, None)."""
    c, safe = params.packed, params.safe_threshold
    for begin in range(0, waypoints, _WAYPOINT_CHUNK):
        size = min(_WAYPOINT_CHUNK, waypoints - begin)
        w, _ = draw_safe_poses(params, size, rng)
        first = fk.certified_segment_batch(c, np.repeat(start[None], size, axis=0), w, safe) >= safe
        if not first.any():
            continue
        rows = np.flatnonzero(first)
        second = fk.certified_segment_batch(c, w[rows], np.repeat(target[None], rows.size, axis=0), safe) >= safe
        if second.any():
            row = int(rows[np.argmax(second)])
            return begin + row, w[row]
    return -1, None


def classify_pairs(
    params: FamilyParams, starts: np.ndarray, targets: np.ndarray, waypoints: int, rng: np.random.Generator
) -> dict[str, np.ndarray]:
    """The straight-path certificate of each pair and, for those that dip, the first certified waypoint.

    Args:
        params: The box's parameters.
        starts: Safe poses, shape (N, m).
        targets: Safe poses, shape (N, m).
        waypoints: Most random safe waypoints tried per dipping pair.
        rng: The random source of the waypoints.

    Returns:
        ``straight``: the env's ``segment_batch`` (smallest safety, −1 where the path leaves the box or the
        strokes), ``free``: ``segment_min_safety_batch`` (−1 only where it leaves the strokes), ``detour``: the
        index of the first waypoint that certifies a detour (−1: none; −2: the pair does not dip), each (N,);
        ``waypoint``: that waypoint, (N, m), NaN where there is none.
    """
    c = params.packed
    straight = fk.segment_batch(c, starts, targets)
    free = fk.segment_min_safety_batch(c, starts, targets, params.segment_spacing)
    detour = np.full(len(starts), -2, dtype=np.int64)
    waypoint = np.full(starts.shape, np.nan)
    for i in np.flatnonzero((straight >= 0.0) & (straight < params.safe_threshold)):
        detour[i], found = _first_detour(params, starts[i], targets[i], waypoints, rng)
        if found is not None:
            waypoint[i] = found
    return {"straight": straight, "free": free, "detour": detour, "waypoint": waypoint}


def _safe_share(params: FamilyParams, rng: np.random.Generator, count: int = 20_000) -> float:
    """The share of ``count`` uniform poses of the task box that are safe."""
    low, high = np.array(params.sample_low), np.array(params.sample_high)
    safety, _ = fk.safety_batch(params.packed, low + (high - low) * rng.random((count, len(low))))
    return float(np.mean(safety >= params.safe_threshold))


def survey_box(box: SurveyBox, pairs: int, waypoints: int, seed: int) -> dict[str, Any]:
    """Count the kinds of ``pairs`` random safe pairs of one box (see the module docstring).

    Args:
        box: The box.
        pairs: Pairs to draw.
        waypoints: Most waypoints tried per dipping pair.
        seed: Seed of the box's random source.

    Returns:
        The box's settings and counts, JSON-ready.
    """
    params = box.params()
    rng = np.random.default_rng(seed)
    began = time.perf_counter()
    starts, targets, _ = draw_pairs(params, pairs, rng)
    result = classify_pairs(params, starts, targets, waypoints, rng)
    straight, free, detour = result["straight"], result["free"], result["detour"]
    _, sign_start = fk.safety_batch(params.packed, starts)
    _, sign_target = fk.safety_batch(params.packed, targets)
    opposite = sign_start != sign_target
    # The same certificates at a spacing FINER times smaller: does a certified path stay safe between its points?
    fine = params.segment_spacing / FINER
    straight_fine = fk.segment_min_safety_batch(params.packed, starts, targets, fine)
    env_detour = (detour >= 0) & (detour < fk.WAYPOINT_TRIES)
    rows = np.flatnonzero(env_detour)
    waypoint = result["waypoint"][rows]
    detour_fine = np.minimum(
        fk.segment_min_safety_batch(params.packed, starts[rows], waypoint, fine),
        fk.segment_min_safety_batch(params.packed, waypoint, targets[rows], fine),
    )
    safe, hard = params.safe_threshold, params.hard_threshold
    dips = (straight >= 0.0) & (straight < safe)
    counts = {
        "pairs": int(pairs),
        "straight_safe": int(np.sum(straight >= safe)),
        "leaves": int(np.sum(straight < 0.0)),
        "leaves_strokes": int(np.sum(free < 0.0)),
        "leaves_box": int(np.sum((straight < 0.0) & (free >= 0.0))),
        "dips": int(dips.sum()),
        "dips_below_hard": int(np.sum(dips & (straight < hard))),
        "dips_opposite_sign": int(np.sum(dips & opposite)),
        "detour": int(np.sum(detour >= 0)),
        "detour_env": int(np.sum((detour >= 0) & (detour < fk.WAYPOINT_TRIES))),
        "no_detour": int(np.sum(detour == -1)),
        "straight_safe_opposite_sign": int(np.sum((straight >= safe) & opposite)),
        "straight_safe_fine": int(np.sum((straight >= safe) & (straight_fine >= safe))),
        "detour_env_opposite_sign": int(np.sum(env_detour & opposite)),
        "detour_env_fine": int(np.sum(detour_fine >= safe)),
    }
    return {
        "robot": box.robot,
        "box": box.name,
        "description": box.description,
        "settings": {k: list(v) if isinstance(v, tuple) else v for k, v in box.settings.items()},
        "sample_low": list(params.sample_low),
        "sample_high": list(params.sample_high),
        "stroke_limits": list(params.stroke_limits),
        "safe_threshold": safe,
        "segment_spacing": params.segment_spacing,
        "min_distance": params.min_distance,
        "seed": seed,
        "waypoints": waypoints,
        "finer": FINER,
        "env_waypoints": fk.WAYPOINT_TRIES,
        "safe_share_of_box": _safe_share(params, rng),
        "counts": counts,
        "seconds": time.perf_counter() - began,
    }


def reset_check(box: SurveyBox, resets: int, seed: int) -> dict[str, Any]:
    """Time ``resets`` hard resets of ``RESET_ENV_ID`` in the box and check that each task is a detour task.

    Args:
        box: The box.
        resets: Resets after the first (which may compile).
        seed: Seed of the first reset.

    Returns:
        {"first_seconds", "mean_ms", "max_ms", "failures" (resets that raised), "not_detour" (tasks whose straight
        path does not dip inside the box and strokes, or whose waypoint's legs are not safe), "opposite_sign"
        (tasks whose start and target have opposite sign(det J_x): no singularity-free path joins them)}.
    """
    env = gym.make(RESET_ENV_ID, robot=box.robot, **box.env_kwargs())
    params = env.unwrapped.params
    c, safe = params.packed, params.safe_threshold
    began = time.perf_counter()
    env.reset(seed=seed)
    first = time.perf_counter() - began
    times, failures, not_detour, opposite = [], 0, 0, 0
    for _ in range(resets):
        began = time.perf_counter()
        try:
            _, info = env.reset()
        except RuntimeError:
            failures += 1
            continue
        times.append(time.perf_counter() - began)
        start, target = info["pose"][None], info["target"][None]
        waypoint = env.unwrapped.last_waypoints[:1]
        straight = fk.segment_batch(c, start, target)[0]
        legs = min(fk.segment_batch(c, start, waypoint)[0], fk.segment_batch(c, waypoint, target)[0])
        not_detour += int(not (0.0 <= straight < safe <= legs))
        signs = fk.safety_batch(c, np.concatenate([start, target]))[1]
        opposite += int(signs[0] != signs[1])
    env.close()
    return {
        "resets": resets,
        "first_seconds": first,
        "mean_ms": 1e3 * float(np.mean(times)) if times else None,
        "max_ms": 1e3 * float(np.max(times)) if times else None,
        "failures": failures,
        "not_detour": not_detour,
        "opposite_sign": opposite,
    }


def run_survey(
    boxes: tuple[SurveyBox, ...], pairs: int, waypoints: int, seed: int, resets: int, min_share: float
) -> dict[str, Any]:
    """Survey every box, and check the resets of those whose ``detour_env`` share reaches ``min_share``.

    Args:
        boxes: The boxes.
        pairs: Pairs per box.
        waypoints: Most waypoints tried per dipping pair.
        seed: Seed of the first box (box i uses seed + i).
        resets: Resets per checked box (0: none).
        min_share: Smallest ``detour_env`` share of the pairs for a reset check.

    Returns:
        {"command", "pairs", "waypoints", "seed", "resets", "min_share", "boxes": [survey_box results, each with
        "reset" (reset_check) or None]}.
    """
    out = []
    for i, box in enumerate(boxes):
        result = survey_box(box, pairs, waypoints, seed + i)
        share = result["counts"]["detour_env"] / pairs
        result["reset"] = reset_check(box, resets, seed) if resets and share >= min_share else None
        out.append(result)
    return {
        "command": "python -m experiments.detour_survey " + " ".join(sys.argv[1:]),
        "pairs": pairs,
        "waypoints": waypoints,
        "seed": seed,
        "resets": resets,
        "min_share": min_share,
        "boxes": out,
    }


def _percent(count: int, total: int) -> str:
    return f"{100.0 * count / total:.1f}" if total else "–"


def render_markdown(survey: dict[str, Any]) -> str:
    """The survey's tables (counts as percentages of the pairs, and the reset checks), from its JSON.

    Args:
        survey: ``run_survey``'s result (as read back from its JSON).

    Returns:
        Markdown text with a ``# `` title.
    """
    lines = [
        "# Detour tasks per robot and task box",
        "",
        f"Generated by `{survey['command']}` ({survey['pairs']} random safe pairs per box, up to "
        f"{survey['waypoints']} random safe waypoints per pair whose straight path dips; the env keeps a pair "
        f"when one of its first {survey['boxes'][0]['env_waypoints'] if survey['boxes'] else '–'} waypoints "
        "certifies a detour). Percentages of the pairs. *Straight*: the straight geodesic is safe; *leaves*: it "
        "leaves the stroke limits (less the margin) or the task box; *dips*: it dips below k_safe inside both, "
        "with a detour through one waypoint found (*detour*; *env*: among the env's first waypoints) or not "
        "(*none*). *± sign*: dipping pairs whose start and target have opposite sign(det J_x), which no "
        f"singularity-free path joins. *Fine*: certified env detours still safe with paths checked "
        f"{survey['boxes'][0]['finer'] if survey['boxes'] else '–'}× more finely; *straight fine*: likewise for "
        "the straight safe paths.",
        "",
        "| robot | box | safe share of box | straight | leaves | dips | ± sign | detour | env | none "
        "| env, fine | straight fine | spacing [m] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in survey["boxes"]:
        c, n = r["counts"], r["counts"]["pairs"]
        lines.append(
            f"| {r['robot']} | {r['box']}: {r['description']} | {100 * r['safe_share_of_box']:.1f} "
            f"| {_percent(c['straight_safe'], n)} | {_percent(c['leaves'], n)} | {_percent(c['dips'], n)} "
            f"| {_percent(c['dips_opposite_sign'], n)} | {_percent(c['detour'], n)} | {_percent(c['detour_env'], n)} "
            f"| {_percent(c['no_detour'], n)} | {_percent(c['detour_env_fine'], n)} "
            f"| {_percent(c['straight_safe_fine'], n)} | {r['segment_spacing']:g} |"
        )
    checked = [r for r in survey["boxes"] if r["reset"] is not None]
    lines += [
        "",
        f'Reset checks: `gym.make("{RESET_ENV_ID}", robot=..., hard_kind="detour", ...)` with each box\'s '
        f"settings, for the boxes whose env detours are at least {100 * survey['min_share']:g} % of the pairs; "
        "the first reset (which may compile) apart, then the others; *not detour*: tasks whose straight path "
        "does not dip or whose legs through the waypoint are not safe; *± sign*: tasks whose start and target have "
        "opposite sign(det J_x), so that every path between them, the certified detour too, crosses a singularity.",
        "",
        "| robot | box | resets | first [s] | mean [ms] | max [ms] | failures | not detour | ± sign |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in checked:
        t = r["reset"]
        mean = "–" if t["mean_ms"] is None else f"{t['mean_ms']:.2f}"
        peak = "–" if t["max_ms"] is None else f"{t['max_ms']:.2f}"
        lines.append(
            f"| {r['robot']} | {r['box']} | {t['resets']} | {t['first_seconds']:.2f} | {mean} | {peak} "
            f"| {t['failures']} | {t['not_detour']} | {t['opposite_sign']} |"
        )
    if not checked:
        lines.append("| – | no box reaches the share | | | | | | | |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Run the survey and write ``detour_survey.json`` and ``detour_survey.md`` into ``--out``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=5000, help="random safe pairs per box")
    parser.add_argument("--waypoints", type=int, default=200, help="most waypoints tried per dipping pair")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--resets", type=int, default=200, help="timed resets per box that reaches --min-share")
    parser.add_argument("--min-share", type=float, default=0.01, help="env detour share that earns a reset check")
    parser.add_argument("--robots", nargs="*", default=None, help="only these presets (default: every box)")
    parser.add_argument("--out", type=Path, default=Path("docs/results/detour_survey"))
    args = parser.parse_args(argv)
    if args.pairs < 1 or args.waypoints < 1 or args.resets < 0:
        parser.error(
            f"--pairs and --waypoints must be ≥ 1 and --resets ≥ 0, got {args.pairs}, {args.waypoints}, {args.resets}"
        )
    boxes = tuple(b for b in SURVEY_BOXES if args.robots is None or b.robot in args.robots)
    if not boxes:
        parser.error(
            f"--robots {args.robots} matches no box; presets surveyed: {sorted({b.robot for b in SURVEY_BOXES})}"
        )
    survey = run_survey(boxes, args.pairs, args.waypoints, args.seed, args.resets, args.min_share)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "detour_survey.json").write_text(json.dumps(survey, indent=2) + "\n")
    (args.out / "detour_survey.md").write_text(
        render_markdown(json.loads((args.out / "detour_survey.json").read_text()))
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
