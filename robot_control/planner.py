"""The planner baseline: a certified safe path from the start to the target, then followed.

The planner knows the geometry and may be slow; it is the ceiling the learned policies are measured against
on hard targets, and it answers how many hard tasks can be done at all. Two planners give the same ``Plan``:

- ``SafePlanner``, for any robot of the family (2-D to 6-D pose spaces): OMPL's RRT-Connect in the scaled pose
  coordinates z = (p, ℓ_c θ) within the pose bounds, whose state validity checker and motion validator are the
  family's compiled certificate (``envs.tasks.certificate.safety_batch`` and ``segment_min_safety_batch``: both
  singularity types, stroke and joint limits less the margin, safety ≥ k_safe along each segment at
  ``segment_spacing``), then OMPL's path simplification (shortcutting, vertex reduction, B-spline smoothing, each
  step kept only where the certificate still holds). The default planner.
- ``SafeGraph``, for planar robots with a certified grid (``task_region="grid"``): the cheapest path through the
  grid's safe nodes, with a cost that prefers clearance from the singular zone (below).

**The grid graph.** Its nodes are the safe nodes of the certified grid (``envs.tasks.grid``: strokes inside the limits
with the stroke margin and safety ≥ k_safe, in a component the tasks are drawn from). Two nodes of the same
component that are neighbours in the 26-neighbourhood are joined when the straight segment between them is
*certified*: at points at most ``spacing`` apart in z = (x, y, ℓ_c φ) (ends included), every stroke lies inside
the limits less the margin and the safety (k; with cranks and sliders also k_I, ``envs.tasks.grid``) is at
least k_safe; the family's one certificate, ``envs.tasks.certificate.segment_min_safety_batch``, decides it, as it
does for the task samplers. An edge costs its length in z times 1 + w (1 − k_e / k_c)₊, where k_e is the
smallest safety on it and k_c = ``clearance`` · k_safe: among paths of similar length, the one that keeps away
from the singular zone wins.

**A plan.** If the straight segment start → target is certified, it is the plan (both planners). Otherwise
the grid graph joins the start and the target to the safe nodes of their 5 × 5 × 5 neighbourhoods by certified
segments, Dijkstra's algorithm (``scipy.sparse.csgraph``) finds the cheapest node path from the start's nodes to
one of the target's (the start's connecting segment is not costed), and the path is shortened greedily: from
each kept waypoint, the furthest later one whose straight segment is certified and keeps k at least as high as
the waypoints it skips (capped at k_c) is the next. ``SafePlanner`` runs RRT-Connect (``time_limit`` at most),
simplifies the path and checks every segment of the result once more. A task for which no path is found is
reported as having none, and the controller then falls back to the straight line; a replan from a pose off the
path (``PathFollower``'s ``replan_distance``) that finds none keeps the certified plan instead. A start or
target that is not safe itself (a state a policy visited, relabelled by the planner; an ill-conditioned target)
is allowed: a segment out of it needs only to keep ``start_floor`` times its safety, and the rest of the path is
certified as usual.

**Following.** ``PathFollower`` keeps one plan per row of a batch and gives a *carrot*: the point
``lookahead`` ahead of the platform's closest point along the planned polyline (in z; progress never goes
back), or the target once the carrot reaches it; between waypoints it is interpolated linearly in the pose
coordinates (the rotation vector, for spatial robots). It plans when a row shows a new target (a new episode).
``robot_control.controllers.PlannerController`` steers toward the carrot with resolved-rate control;
``robot_control.wrappers.PlannerWaypointWrapper`` shows the carrot to a policy as part of its observation, and
``PlannerResidualWrapper`` adds a policy's correction to the planner controller's action.
"""

from __future__ import annotations

import atexit
import collections
import functools
import gc
import time
import weakref
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from envs._extras import require
from envs.kernels import generic as fk
from envs.params import FamilyParams
from envs.physics import wrap_angle
from envs.tasks.grid import WorkspaceMap, WorkspaceSpec, certify_workspace

__all__ = ["PLANNERS", "PathFollower", "Plan", "SafeGraph", "SafePlanner", "make_planner", "safe_graph"]

#: Plans a ``PathFollower`` keeps in its log.
LOG_LENGTH = 10_000
#: Half of the 26-neighbourhood (the other half are the reversed edges).
_OFFSETS = tuple((i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) > (0, 0, 0))


def _end_floor(k_safe: float, k_end: float, fraction: float) -> float:
    """The safety a segment out of a path's start or target must keep: k_safe, or ``fraction`` of an unsafe end's."""
    return k_safe if k_end >= k_safe else fraction * k_end


def _segment_lengths(waypoints: np.ndarray, metric: np.ndarray) -> np.ndarray:
    """Lengths in z = (p, ℓ_c θ) [m] of the segments of a polyline of poses (P, m), shape (P − 1,)."""
    return np.linalg.norm(np.diff(waypoints, axis=0) * metric, axis=-1)


def _closest_on_segments(waypoints: np.ndarray, metric: np.ndarray, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest points of a polyline's segments to a pose: (distance in z [m], fraction along), each (P − 1,).

    Args:
        waypoints: Poses of the polyline, shape (P, m).
        metric: Pose metric (1 for positions, ℓ_c for angles), shape (m,).
        pose: The pose, shape (m,).
    """
    a, b, z = waypoints[:-1] * metric, waypoints[1:] * metric, pose * metric
    d = b - a
    t = np.clip(np.sum((z - a) * d, axis=-1) / np.maximum(np.sum(d * d, axis=-1), 1e-18), 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * d - z, axis=-1), t


@dataclass(frozen=True)
class Plan:
    """One planned path.

    Attributes:
        waypoints: Poses from the start to the target in the env's pose coordinates (planar (x [m], y [m], φ [rad]),
            spatial (p [m], r [rad]) with r the rotation vector, translational p [m]), shape (P, m).
        found: Whether a certified path exists (else ``waypoints`` is the straight segment, not certified).
        length: Length of the polyline in z = (p, ℓ_c θ) [m].
        straight: Length of the straight segment start → target in z [m].
        min_k: Smallest safety at the checked points of the path (−1 where a stroke leaves its limits less the
            margin).
        seconds: Wall time spent planning [s].
    """

    waypoints: np.ndarray
    found: bool
    length: float
    straight: float
    min_k: float
    seconds: float


class SafeGraph:
    """The certified graph of a workspace and the queries on it (see the module docstring).

    Args:
        workspace: The certified grid (its spec gives the robot, the stroke limits and k_safe).
        spacing: Largest gap between checked points of a segment, in z [m].
        clearance: k_c / k_safe, the conditioning the edge costs prefer.
        weight: w, the extra cost of an edge with k_e = 0 relative to its length.
        start_floor: Fraction of an unsafe start's own safety the first segment out of it must keep.
    """

    def __init__(
        self,
        workspace: WorkspaceMap,
        spacing: float = 0.01,
        clearance: float = 2.0,
        weight: float = 4.0,
        start_floor: float = 0.8,
    ) -> None:
        spec = workspace.spec
        self.start_floor = float(start_floor)
        self.workspace = workspace
        self.robot = spec.robot
        self.spacing, self.weight = float(spacing), float(weight)
        self.k_safe = float(spec.safe_threshold)
        self.k_clear = float(clearance) * self.k_safe
        self.metric = np.array([1.0, 1.0, spec.robot.characteristic_length])
        self.shape = workspace.labels.shape
        labels = workspace.labels
        self.safe = np.isin(labels, workspace.component_ids)
        self.nodes = workspace.nodes.reshape(-1, 3)
        heads, tails, costs = [], [], []
        flat = np.arange(labels.size).reshape(self.shape)
        for offset in _OFFSETS:
            src = tuple(slice(max(0, -o), n - max(0, o)) for o, n in zip(offset, self.shape))
            dst = tuple(slice(s.start + o, s.stop + o) for s, o in zip(src, offset))
            ok = self.safe[src] & self.safe[dst] & (labels[src] == labels[dst])
            a, b = flat[src][ok], flat[dst][ok]
            k_min = self.segment_min_k(self.nodes[a], self.nodes[b])
            good = k_min >= self.k_safe
            a, b, k_min = a[good], b[good], k_min[good]
            length = np.linalg.norm((self.nodes[b] - self.nodes[a]) * self.metric, axis=-1)
            cost = length * (1.0 + self.weight * np.clip(1.0 - k_min / self.k_clear, 0.0, None))
            heads += [a, b]
            tails += [b, a]
            costs += [cost, cost]
        head, tail, cost = np.concatenate(heads), np.concatenate(tails), np.concatenate(costs)
        self.graph = sparse.csr_matrix((cost, (head, tail)), shape=(labels.size, labels.size))
        self.edges = head.size // 2

    # -- certification -------------------------------------------------------------------------------

    def segment_min_k(self, start: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Smallest safety at the checked points of each segment; −1 where a stroke leaves its limits, shape (M,).

        Args:
            start: Poses (x [m], y [m], φ [rad]), shape (M, 3).
            target: Poses, shape (M, 3).
        """
        start, target = np.atleast_2d(start), np.atleast_2d(target)
        return fk.segment_min_safety_batch(self.workspace.spec.constants, start, target, self.spacing)

    # -- queries -------------------------------------------------------------------------------------

    def _anchors(self, pose: np.ndarray, floor: float, reach: int = 2) -> tuple[np.ndarray, np.ndarray]:
        """Safe nodes within ``reach`` cells of the pose joined to it by a segment keeping safety ≥ ``floor``."""
        centre = np.array(self.workspace.node_index(pose[None]))[:, 0]
        ranges = [np.arange(max(0, c - reach), min(n, c + reach + 1)) for c, n in zip(centre, self.shape)]
        grid = np.stack(np.meshgrid(*ranges, indexing="ij"), axis=-1).reshape(-1, 3)
        flat = np.ravel_multi_index(grid.T, self.shape)
        flat = flat[self.safe.ravel()[flat]]
        k = self.segment_min_k(np.repeat(pose[None], len(flat), axis=0), self.nodes[flat])
        ok = k >= floor
        return flat[ok], k[ok]

    def plan(self, start: np.ndarray, target: np.ndarray) -> Plan:
        """The planned path from ``start`` to ``target`` (poses (x [m], y [m], φ [rad]), shape (3,))."""
        clock = time.perf_counter()
        start = np.asarray(start, dtype=float).reshape(3)
        target = np.asarray(target, dtype=float).reshape(3)
        straight = float(np.linalg.norm((target - start) * self.metric))
        floor = _end_floor(self.k_safe, float(self.segment_min_k(start[None], start[None])[0]), self.start_floor)
        k_line = float(self.segment_min_k(start[None], target[None])[0])
        if k_line >= floor:
            path = np.stack([start, target])
            return Plan(path, True, straight, straight, k_line, time.perf_counter() - clock)
        sources, _ = self._anchors(start, floor)
        sinks, _ = self._anchors(target, self.k_safe)
        if sources.size and sinks.size:
            dist, pred, _ = csgraph.dijkstra(self.graph, indices=sources, min_only=True, return_predecessors=True)
            tail = np.linalg.norm((target - self.nodes[sinks]) * self.metric, axis=-1)
            total = dist[sinks] + tail
            best = int(np.argmin(total))
            if np.isfinite(total[best]):
                node = int(sinks[best])
                chain = [node]
                while pred[node] >= 0:
                    node = int(pred[node])
                    chain.append(node)
                path = np.concatenate([start[None], self.nodes[chain[::-1]], target[None]])
                path = self._shortcut(path, floor)
                min_k = float(np.min(self.segment_min_k(path[:-1], path[1:])))
                length = float(_segment_lengths(path, self.metric).sum())
                return Plan(path, True, length, straight, min_k, time.perf_counter() - clock)
        path = np.stack([start, target])
        return Plan(path, False, straight, straight, k_line, time.perf_counter() - clock)

    def _shortcut(self, path: np.ndarray, floor: float) -> np.ndarray:
        """Greedy shortening: from each kept waypoint jump to the furthest certified one (see the docstring).

        Jumps from the start need only keep ``floor`` (the start's floor, k_safe for a safe start).
        """
        node_k = self.segment_min_k(path, path)  # k at each waypoint
        kept = [0]
        i = 0
        last = len(path) - 1
        while i < last:
            later = np.arange(i + 1, last + 1)
            k = self.segment_min_k(np.repeat(path[i][None], len(later), axis=0), path[later])
            # the waypoints a jump i → j skips must not have had better conditioning than the jump keeps
            need = floor if i == 0 else self.k_safe
            skipped = np.minimum(np.minimum.accumulate(node_k[i + 1 :]), self.k_clear)
            ok = (k >= need) & (k >= np.concatenate([[need], skipped[:-1]]))
            ok[0] = True  # the next waypoint is joined by a certified edge
            i = int(later[np.flatnonzero(ok)[-1]])
            kept.append(i)
        return path[kept]


@functools.lru_cache(maxsize=4)
def _cached_graph(spec: WorkspaceSpec) -> SafeGraph:
    return SafeGraph(certify_workspace(spec))


def safe_graph(params: FamilyParams) -> SafeGraph:
    """The certified graph of an environment's grid with the default settings (built once per geometry).

    Raises:
        ValueError: If the environment has no certified grid (a planar robot with ``task_region="grid"``).
    """
    if params.workspace is None or params.robot.pose_space.name != "planar":
        raise ValueError(
            "the planner needs a planar robot with task_region='grid', got "
            f"{params.robot.pose_space.name} with task_region={params.task_region!r}"
        )
    return _cached_graph(params.workspace.spec)


class SafePlanner:
    """Certified paths for any robot of the family, planned by OMPL (see the module docstring).

    Args:
        params: Environment constants (the robot, its limits, k_safe, the pose bounds, ``segment_spacing``).
        time_limit: Longest time RRT-Connect may search for one path [s]; a task it does not solve in that time
            is reported as having no path.
        start_floor: Fraction of an unsafe start's (or target's) own safety a segment out of it must keep.
        bound_margin: Fraction of each pose coordinate's range kept free inside the pose bounds.
        seed: Seed of OMPL's random number generator (set once per process, by the first planner built).
    """

    def __init__(
        self,
        params: FamilyParams,
        time_limit: float = 2.0,
        start_floor: float = 0.8,
        bound_margin: float = 0.02,
        seed: int = 0,
    ) -> None:
        ob = require("ompl.base", "planner", "the planner")
        og = require("ompl.geometric", "planner", "the planner")

        _seed_ompl(seed)
        if not (np.isfinite(time_limit) and time_limit > 0.0):
            raise ValueError(f"time_limit must be a positive time [s], got {time_limit!r}")
        if not (0.0 < start_floor <= 1.0):
            raise ValueError(f"start_floor must be in (0, 1], got {start_floor!r}")
        self.params = params
        self.constants = params.packed
        self.metric = params.pose_metric
        self.m = params.robot.n_pose
        self.spacing = float(params.segment_spacing)
        self.k_safe = float(params.safe_threshold)
        self.time_limit, self.start_floor = float(time_limit), float(start_floor)
        low, high = np.asarray(params.pose_low, dtype=float), np.asarray(params.pose_high, dtype=float)
        pad = bound_margin * (high - low)
        self.low, self.high = low + pad, high - pad
        space = ob.RealVectorStateSpace(self.m)
        bounds = ob.RealVectorBounds(self.m)
        for j in range(self.m):
            bounds.setLow(j, float(self.low[j] * self.metric[j]))
            bounds.setHigh(j, float(self.high[j] * self.metric[j]))
        space.setBounds(bounds)
        info = ob.SpaceInformation(space)
        # OMPL's objects hold the callbacks; weak references let the planner be freed (no cycle through C++)
        me = weakref.proxy(self)
        info.setStateValidityChecker(lambda state: me._state_valid(state))
        self._validator = _MotionValidator(info, lambda a, b: me._motion_valid(a, b))
        info.setMotionValidator(self._validator)
        info.setup()
        self._space, self._info = space, info
        self._setup = og.SimpleSetup(info)
        self._setup.setPlanner(og.RRTConnect(info))
        # the current query's ends (exempt from the state check) and the safety edges out of each must keep
        self._ends = np.full((2, self.m), np.nan)
        self._end_floors = np.full(2, self.k_safe)
        _LIVE.add(self)

    def close(self) -> None:
        """Free OMPL's objects (done for every live planner at exit, before the bindings shut down)."""
        for name in ("_setup", "_validator", "_info", "_space"):
            self.__dict__.pop(name, None)

    # -- certification (the callbacks OMPL calls) ----------------------------------------------------

    def _pose(self, state) -> np.ndarray:
        return np.array([state[j] for j in range(self.m)]) / self.metric

    def safety(self, poses: np.ndarray) -> np.ndarray:
        """Safety (``envs.tasks.certificate.safety_batch``) at poses of shape (M, m), shape (M,)."""
        return fk.safety_batch(self.constants, np.atleast_2d(poses))[0]

    def segment_min_k(self, start: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Smallest safety along each geodesic start → target (poses (M, m)) at ``segment_spacing``, shape (M,)."""
        return fk.segment_min_safety_batch(self.constants, np.atleast_2d(start), np.atleast_2d(target), self.spacing)

    def _floor(self, pose: np.ndarray) -> float:
        """The safety an edge at ``pose`` must keep: an end's floor at the query's start or target, else k_safe."""
        at_end = np.all(np.abs(pose - self._ends) <= 1e-12, axis=-1)
        return float(self._end_floors[at_end].min()) if at_end.any() else self.k_safe

    def _state_valid(self, state) -> bool:
        pose = self._pose(state)
        return bool(self.safety(pose[None])[0] >= self._floor(pose))

    def _motion_valid(self, a, b) -> bool:
        pa, pb = self._pose(a), self._pose(b)
        return bool(self.segment_min_k(pa[None], pb[None])[0] >= min(self._floor(pa), self._floor(pb)))

    # -- queries -------------------------------------------------------------------------------------

    def _state(self, pose: np.ndarray):
        state = self._space.allocState()
        for j, value in enumerate(pose * self.metric):
            state[j] = float(value)
        return state

    def plan(self, start: np.ndarray, target: np.ndarray) -> Plan:
        """The planned path from ``start`` to ``target`` (poses in the env's coordinates, each shape (m,))."""
        clock = time.perf_counter()
        start = np.asarray(start, dtype=float).reshape(self.m)
        target = np.asarray(target, dtype=float).reshape(self.m)
        straight = float(np.linalg.norm((target - start) * self.metric))
        k_ends = self.safety(np.stack([start, target]))
        self._ends = np.stack([start, target])
        self._end_floors = np.array([_end_floor(self.k_safe, k, self.start_floor) for k in k_ends])
        k_line = float(self.segment_min_k(start[None], target[None])[0])
        if k_line >= self._end_floors.min():
            path = np.stack([start, target])
            return Plan(path, True, straight, straight, k_line, time.perf_counter() - clock)
        inside = np.all(start >= self.low) and np.all(start <= self.high)
        inside &= np.all(target >= self.low) and np.all(target <= self.high)
        if inside and k_ends.min() > 0.0:
            ss = self._setup
            ss.clear()
            ss.setStartAndGoalStates(self._state(start), self._state(target))
            solved = ss.solve(self.time_limit)
            if ss.haveExactSolutionPath() and bool(solved):
                ss.simplifySolution()
                states = ss.getSolutionPath().getStates()
                path = np.stack([self._pose(s) for s in states])
                path[0], path[-1] = start, target
                k_edges = self.segment_min_k(path[:-1], path[1:])
                floors = np.full(len(k_edges), self.k_safe)
                floors[0], floors[-1] = self._end_floors[0], self._end_floors[1]
                if len(k_edges) == 1:
                    floors[0] = self._end_floors.min()
                if np.all(k_edges >= floors):
                    min_k, length = float(k_edges.min()), float(_segment_lengths(path, self.metric).sum())
                    return Plan(path, True, length, straight, min_k, time.perf_counter() - clock)
        path = np.stack([start, target])
        return Plan(path, False, straight, straight, k_line, time.perf_counter() - clock)


class _MotionValidator:
    """OMPL's motion validator calling a Python predicate of two states (built lazily: OMPL imports on first use)."""

    def __new__(cls, info, predicate):
        ob = require("ompl.base", "planner", "the planner")

        class Validator(ob.MotionValidator):
            def __init__(self, info, predicate) -> None:
                super().__init__(info)
                self.predicate = predicate

            def checkMotion(self, a, b, *rest) -> bool:
                return self.predicate(a, b)

        return Validator(info, predicate)


_OMPL_SEEDED: list[int] = []
_LIVE: weakref.WeakSet[SafePlanner] = weakref.WeakSet()


@atexit.register
def _close_planners() -> None:
    for planner in list(_LIVE):
        planner.close()
    gc.collect()


def _seed_ompl(seed: int) -> None:
    """Seed OMPL's generator once per process (its later seeds are drawn from it) and quieten its log."""
    ou = require("ompl.util", "planner", "the planner")

    if not _OMPL_SEEDED:
        ou.setLogLevel(ou.LOG_ERROR)
        ou.RNG.setSeed(int(seed))
        _OMPL_SEEDED.append(int(seed))


#: Planner kinds by name: "ompl" (any robot) and "grid" (planar robots with a certified grid).
PLANNERS = ("ompl", "grid")


def make_planner(params: FamilyParams, kind: str = "auto") -> SafeGraph | SafePlanner:
    """A planner for an environment: ``kind`` "ompl", "grid", or "auto" (the grid where there is one, else OMPL).

    Raises:
        ValueError: For an unknown kind, or "grid" on an environment without a certified grid.
    """
    if kind not in ("auto", *PLANNERS):
        raise ValueError(f"planner must be one of {('auto', *PLANNERS)}, got {kind!r}")
    if kind == "grid" or (kind == "auto" and params.workspace is not None):
        return safe_graph(params)
    return SafePlanner(params)


class PathFollower:
    """Plans per row of a batch and the carrot each row steers toward (see the module docstring).

    Args:
        params: Environment constants.
        lookahead: Distance of the carrot ahead of the closest point of the path, in z [m].
        planner: "auto" (the grid graph where the env has a certified grid, else OMPL), "ompl" or "grid".
        replan_distance: If given, a row whose pose is farther than this from its path (in z [m]) is planned
            afresh from the pose: the carrot is then a function of the pose and the target alone, as an expert
            that relabels the states a learner visits must be (``training.distill``). Where no certified path
            exists from the pose (beside the band, or within the strokes' margins) but the row's current plan is
            certified, that plan stays and the carrot steers back toward it. None: plan once per episode.
        cross_track: Steer along a straight (one-segment) plan too, toward the carrot on it, instead of straight at
            the target from wherever the robot is: a robot that drifts off a certified line is brought back to it.
    """

    def __init__(
        self,
        params: FamilyParams,
        lookahead: float = 0.1,
        planner: str = "auto",
        replan_distance: float | None = None,
        cross_track: bool = False,
    ) -> None:
        if not (np.isfinite(lookahead) and lookahead > 0.0):
            raise ValueError(f"lookahead must be a positive distance [m], got {lookahead!r}")
        if replan_distance is not None and not (np.isfinite(replan_distance) and replan_distance > 0.0):
            raise ValueError(f"replan_distance must be None or a positive distance [m], got {replan_distance!r}")
        self.replan_distance = None if replan_distance is None else float(replan_distance)
        self.params = params
        self.lookahead = float(lookahead)
        self.cross_track = bool(cross_track)
        self.metric = params.pose_metric
        self.planar = params.robot.pose_space.name == "planar"
        self.graph = make_planner(params, planner)
        self._rows: dict[int, tuple] = {}  # row → (target, plan, arc lengths, progress, last pose)
        # a pose step longer than the fastest platform motion of one period (every leg at max rate)
        self._jump = 4.0 * params.max_rate * params.dt
        #: The plans made, in order (the last ``LOG_LENGTH``, so a long training run does not keep them all).
        self.log: collections.deque[Plan] = collections.deque(maxlen=LOG_LENGTH)

    def reset_row(self, row: int, pose: np.ndarray, target: np.ndarray) -> Plan:
        """Plan row ``row`` afresh from ``pose`` to ``target`` (each (m,)) and return the plan."""
        plan = self.graph.plan(pose, target)
        self.log.append(plan)
        self._install(row, plan, target, pose)
        return plan

    def _install(self, row: int, plan: Plan, target: np.ndarray, pose: np.ndarray) -> None:
        arc = np.concatenate([[0.0], np.cumsum(_segment_lengths(plan.waypoints, self.metric))])
        self._rows[row] = (np.array(target, dtype=float), plan, arc, 0.0, np.array(pose, dtype=float))

    def carrot(self, row: int, pose: np.ndarray, target: np.ndarray) -> np.ndarray:
        """The pose row ``row`` steers toward, shape (m,); plans first if the row shows a new episode.

        A new episode is another target (the observation's float32 rounding moves it by ≪ 1e-4) or a jump
        of the pose no control period can make (a reset to the same target).
        """
        pose = np.asarray(pose, dtype=float)
        entry = self._rows.get(row)
        if (
            entry is None
            or not np.allclose(entry[0], target, rtol=0.0, atol=1e-4)
            or np.linalg.norm((pose - entry[4]) * self.metric) > self._jump
        ):
            self.reset_row(row, pose, target)
            entry = self._rows[row]
        elif (
            self.replan_distance is not None
            and _closest_on_segments(entry[1].waypoints, self.metric, pose)[0].min() > self.replan_distance
        ):
            plan = self.graph.plan(pose, target)
            self.log.append(plan)
            if plan.found or not entry[1].found:
                self._install(row, plan, target, pose)
                entry = self._rows[row]
            # else: no certified path from here (a start beside the band or the strokes' margins); the certified
            # plan stays, and the carrot steers back toward it rather than straight at the target
        goal_pose, plan, arc, progress, _ = entry
        w = plan.waypoints
        follow = len(w) > 2 or self.cross_track  # a one-segment plan ends at the target: steer there directly
        if follow and progress < arc[-1]:
            # closest point of the polyline to the pose, at or after the progress made so far
            gap, t = _closest_on_segments(w, self.metric, pose)
            along = arc[:-1] + t * (arc[1:] - arc[:-1])
            gap[along < progress - 1e-12] = np.inf
            if np.isfinite(gap).any():
                progress = max(progress, float(along[int(np.argmin(gap))]))
        self._rows[row] = (goal_pose, plan, arc, progress, pose.copy())
        goal = progress + self.lookahead
        if not follow or goal >= arc[-1]:
            out = np.array(target, dtype=float)
        else:
            j = int(np.searchsorted(arc, goal, side="right")) - 1
            f = (goal - arc[j]) / (arc[j + 1] - arc[j])
            out = w[j] + f * (w[j + 1] - w[j])
        if self.planar:
            out[2] = pose[2] + wrap_angle(out[2] - pose[2])
        return out

    def last_plan_metrics(self, row: int | None = None) -> dict[str, float] | None:
        """The last plan's figures (for the evaluation's per-episode record), or None before any.

        Args:
            row: The batch row whose current plan to describe; None: the last plan made for any row.
        """
        if row is not None:
            entry = self._rows.get(row)
            plan = None if entry is None else entry[1]
        else:
            plan = self.log[-1] if self.log else None
        if plan is None:
            return None
        return {
            "path_found": float(plan.found),
            "planned_length_ratio": plan.length / plan.straight if plan.straight > 0 else 1.0,
            "planned_min_k": plan.min_k,
            "planning_s": plan.seconds,
        }
