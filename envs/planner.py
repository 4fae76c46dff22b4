"""The planner baseline of planar robots: a shortest safe path through the certified grid, then followed.

The planner knows the geometry and may be slow; it is the ceiling the learned policies are measured against
on hard targets, and it answers how many hard tasks can be done at all.

**The graph.** Its nodes are the safe nodes of the certified grid (``envs.tasks.grid``: strokes inside the limits
with the stroke margin and safety ≥ k_safe, in a component the tasks are drawn from). Two nodes of the same
component that are neighbours in the 26-neighbourhood are joined when the straight segment between them is
*certified*: at points at most ``spacing`` apart in z = (x, y, ℓ_c φ) (ends included), every stroke lies inside
the limits less the margin and the safety (k; with cranks and sliders also k_I, ``envs.tasks.grid``) is at
least k_safe; the family's one certificate, ``envs.kernels.generic.segment_min_safety_batch``, decides it, as it
does for the task samplers. An edge costs its length in z times 1 + w (1 − k_e / k_c)₊, where k_e is the
smallest safety on it and k_c = ``clearance`` · k_safe: among paths of similar length, the one that keeps away
from the singular zone wins.

**A plan.** If the straight segment start → target is certified, it is the plan. Otherwise the start and the
target are joined to the safe nodes of their 5 × 5 × 5 neighbourhoods by certified segments, Dijkstra's
algorithm (``scipy.sparse.csgraph``) finds the cheapest node path from the start's nodes to one of the
target's (the start's connecting segment is not costed), and the path is shortened greedily: from each kept
waypoint, the furthest later one whose straight segment is certified and keeps k at least as high as the
waypoints it skips (capped at k_c) is the next. A task for which no such path exists is reported as having
none, and the controller then falls back to the straight line.

**Following.** ``PathFollower`` keeps one plan per row of a batch and gives a *carrot*: the point
``lookahead`` ahead of the platform's closest point along the planned polyline (progress never goes back),
or the target once the carrot reaches it. It plans when a row shows a new target (a new episode).
``envs.controllers.PlannerController`` steers toward the carrot with resolved-rate control;
``envs.wrappers.planner.PlannerWaypointWrapper`` shows the carrot to a policy as part of its observation, and
``PlannerResidualWrapper`` adds a policy's correction to the planner controller's action.
"""

from __future__ import annotations

import collections
import functools
import time
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from envs.kernels import generic as fk
from envs.params import FamilyParams
from envs.physics import wrap_angle
from envs.tasks.grid import WorkspaceMap, WorkspaceSpec, certify_workspace

__all__ = ["PathFollower", "Plan", "SafeGraph", "safe_graph"]

#: Plans a ``PathFollower`` keeps in its log.
LOG_LENGTH = 10_000
#: Half of the 26-neighbourhood (the other half are the reversed edges).
_OFFSETS = tuple((i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) > (0, 0, 0))


@dataclass(frozen=True)
class Plan:
    """One planned path.

    Attributes:
        waypoints: Poses (x [m], y [m], φ [rad]) from the start to the target, shape (P, 3).
        found: Whether a certified path exists (else ``waypoints`` is the straight segment, not certified).
        length: Length of the polyline in z = (x, y, ℓ_c φ) [m].
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
    """

    def __init__(
        self,
        workspace: WorkspaceMap,
        spacing: float = 0.01,
        clearance: float = 2.0,
        weight: float = 4.0,
    ) -> None:
        spec = workspace.spec
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

    def _length(self, waypoints: np.ndarray) -> float:
        return float(np.linalg.norm(np.diff(waypoints, axis=0) * self.metric, axis=-1).sum())

    def _anchors(self, pose: np.ndarray, reach: int = 2) -> tuple[np.ndarray, np.ndarray]:
        """Safe nodes within ``reach`` cells of the pose joined to it by a certified segment: (nodes, k_min)."""
        centre = np.array(self.workspace.node_index(pose[None]))[:, 0]
        ranges = [np.arange(max(0, c - reach), min(n, c + reach + 1)) for c, n in zip(centre, self.shape)]
        grid = np.stack(np.meshgrid(*ranges, indexing="ij"), axis=-1).reshape(-1, 3)
        flat = np.ravel_multi_index(grid.T, self.shape)
        flat = flat[self.safe.ravel()[flat]]
        k = self.segment_min_k(np.repeat(pose[None], len(flat), axis=0), self.nodes[flat])
        ok = k >= self.k_safe
        return flat[ok], k[ok]

    def plan(self, start: np.ndarray, target: np.ndarray) -> Plan:
        """The planned path from ``start`` to ``target`` (poses (x [m], y [m], φ [rad]), shape (3,))."""
        clock = time.perf_counter()
        start = np.asarray(start, dtype=float).reshape(3)
        target = np.asarray(target, dtype=float).reshape(3)
        straight = float(np.linalg.norm((target - start) * self.metric))
        k_line = float(self.segment_min_k(start[None], target[None])[0])
        if k_line >= self.k_safe:
            path = np.stack([start, target])
            return Plan(path, True, straight, straight, k_line, time.perf_counter() - clock)
        sources, _ = self._anchors(start)
        sinks, _ = self._anchors(target)
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
                path = self._shortcut(path)
                min_k = float(np.min(self.segment_min_k(path[:-1], path[1:])))
                return Plan(path, True, self._length(path), straight, min_k, time.perf_counter() - clock)
        path = np.stack([start, target])
        return Plan(path, False, straight, straight, k_line, time.perf_counter() - clock)

    def _shortcut(self, path: np.ndarray) -> np.ndarray:
        """Greedy shortening: from each kept waypoint jump to the furthest certified one (see the docstring)."""
        node_k = self.segment_min_k(path, path)  # k at each waypoint
        kept = [0]
        i = 0
        last = len(path) - 1
        while i < last:
            later = np.arange(i + 1, last + 1)
            k = self.segment_min_k(np.repeat(path[i][None], len(later), axis=0), path[later])
            # the waypoints a jump i → j skips must not have had better conditioning than the jump keeps
            floor = np.minimum(np.minimum.accumulate(node_k[i + 1 :]), self.k_clear)
            ok = (k >= self.k_safe) & (k >= np.concatenate([[self.k_safe], floor[:-1]]))
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


class PathFollower:
    """Plans per row of a batch and the carrot each row steers toward (see the module docstring).

    Args:
        params: Environment constants of a planar robot with ``task_region="grid"``.
        lookahead: Distance of the carrot ahead of the closest point of the path, in z [m].
    """

    def __init__(self, params: FamilyParams, lookahead: float = 0.1) -> None:
        if not (np.isfinite(lookahead) and lookahead > 0.0):
            raise ValueError(f"lookahead must be a positive distance [m], got {lookahead!r}")
        self.params = params
        self.lookahead = float(lookahead)
        self.metric = params.pose_metric
        self.graph = safe_graph(params)
        self._rows: dict[int, tuple] = {}  # row → (target, plan, arc lengths, progress, last pose)
        # a pose step longer than the fastest platform motion of one period (every leg at max rate)
        self._jump = 4.0 * params.max_rate * params.dt
        #: The plans made, in order (the last ``LOG_LENGTH``, so a long training run does not keep them all).
        self.log: collections.deque[Plan] = collections.deque(maxlen=LOG_LENGTH)

    def reset_row(self, row: int, pose: np.ndarray, target: np.ndarray) -> Plan:
        """Plan row ``row`` afresh from ``pose`` to ``target`` (each (3,)) and return the plan."""
        plan = self.graph.plan(pose, target)
        self.log.append(plan)
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(plan.waypoints, axis=0) * self.metric, axis=-1))])
        self._rows[row] = (np.array(target, dtype=float), plan, arc, 0.0, np.array(pose, dtype=float))
        return plan

    def carrot(self, row: int, pose: np.ndarray, target: np.ndarray) -> np.ndarray:
        """The pose row ``row`` steers toward, shape (3,); plans first if the row shows a new episode.

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
        goal_pose, plan, arc, progress, _ = entry
        w = plan.waypoints
        if len(w) > 2 and progress < arc[-1]:
            # closest point of the polyline to the pose, at or after the progress made so far
            a, b, z = w[:-1] * self.metric, w[1:] * self.metric, pose * self.metric
            d = b - a
            t = np.clip(np.sum((z - a) * d, axis=-1) / np.maximum(np.sum(d * d, axis=-1), 1e-18), 0.0, 1.0)
            gap = np.linalg.norm(a + t[:, None] * d - z, axis=-1)
            along = arc[:-1] + t * (arc[1:] - arc[:-1])
            gap[along < progress - 1e-12] = np.inf
            if np.isfinite(gap).any():
                progress = max(progress, float(along[int(np.argmin(gap))]))
        self._rows[row] = (goal_pose, plan, arc, progress, pose.copy())
        goal = progress + self.lookahead
        if len(w) == 2 or goal >= arc[-1]:
            out = np.array(target, dtype=float)
        else:
            j = int(np.searchsorted(arc, goal, side="right")) - 1
            f = (goal - arc[j]) / (arc[j + 1] - arc[j])
            out = w[j] + f * (w[j + 1] - w[j])
        out[2] = pose[2] + wrap_angle(out[2] - pose[2])
        return out

    def last_plan_metrics(self) -> dict[str, float] | None:
        """The last plan's figures (for the evaluation's per-episode record), or None before any."""
        if not self.log:
            return None
        plan = self.log[-1]
        return {
            "path_found": float(plan.found),
            "planned_length_ratio": plan.length / plan.straight if plan.straight > 0 else 1.0,
            "planned_min_k": plan.min_k,
            "planning_s": plan.seconds,
        }
