"""Ground-truth attributed waypoints from a recorded trajectory (SPEC §4-5).

Given the TCP path ``x_0 .. x_{T-1}`` and per-step attribute flags ``A`` (T, k) (column 0 = grasp),
choose K step indices and return ``W = [x_i, A_i]`` for them, shape ``(K, 3 + k)``. The path starts
at the robot's current TCP (index 0 is *not* a waypoint). Choice of indices::

    mandatory  for every attribute: its first and last set step (for the grasp: the grasp point
               and the release point), the last step of the trajectory, and - when the first
               attribute onset is at t >= 2 - the step before it that lies farthest from the
               segment x_0 -> x_onset (the approach corner, e.g. "above the object")
    the rest   greedy Ramer-Douglas-Peucker: repeatedly add the step farthest from the polyline
               through x_0 and the chosen points, until K are chosen

The polyline is the one the executor will *drive*: the grasp primitive ends ``grasp_lift_m`` above
the grasp point, so after the grasp onset the polyline continues from that lifted point, and the
path's own lift (the steps before it leaves a 2 cm column around the grasp point) is not a
candidate. Without this, the lone free corner of K = 5 lands on the expert's lift (which the
primitive already does) instead of the corner above the goal, and the carry cuts diagonally
through the goal bin's wall.

If the mandatory points alone exceed K, the latest ones are dropped first except the final step.
The release waypoint (the last grasp-attributed one) takes the TCP position of the step after it,
where the gripper was commanded open (it keeps the grasp flag: carry there, then drop).
Executed with :class:`~awda_bench.primitives.executor.WaypointExecutor`: the approach corner (the
waypoint before the grasp) is raised 15 cm, the grasp point triggers the grasp primitive,
grasp-attributed points after it are carried to, and the first free point after them drops the
object (at the release point, which is grasp-attributed) before moving on.
"""

from __future__ import annotations

import numpy as np

from awda_bench.errors import UsageError


def point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distance [m] of points ``p`` (N, 3) to the segment ``a -> b``."""
    ab = b - a
    denom = float(ab @ ab)
    if denom == 0.0:
        return np.linalg.norm(p - a, axis=1)
    s = np.clip((p - a) @ ab / denom, 0.0, 1.0)
    return np.linalg.norm(p - (a + s[:, None] * ab), axis=1)


def polyline_deviation(
    path: np.ndarray, anchors: list[int], starts: dict[int, np.ndarray] | None = None
) -> np.ndarray:
    """(T,) distance of every path point to the polyline through ``path[anchors]`` (sorted),
    each point measured against the segment between the anchors that bracket it in time.

    ``starts[a]`` replaces ``path[a]`` as the start of the segment leaving anchor ``a``.
    """
    starts = starts or {}
    dev = np.zeros(len(path))
    for a, b in zip(anchors[:-1], anchors[1:], strict=True):
        if b - a > 1:
            start = starts.get(a, path[a])
            dev[a + 1 : b] = point_segment_distance(path[a + 1 : b], start, path[b])
    return dev


LIFT_COLUMN_RADIUS_M = 0.02
"""After the grasp onset, path steps within this horizontal distance [m] of the grasp point (and
before the path first leaves it) belong to the lift and are neither candidates nor deviations."""


def _lift_column(path: np.ndarray, onset: int) -> int:
    """First index after ``onset`` whose xy leaves the column around ``path[onset]``."""
    r = np.linalg.norm(path[onset + 1 :, :2] - path[onset, :2], axis=1)
    out = np.flatnonzero(r > LIFT_COLUMN_RADIUS_M)
    return len(path) if out.size == 0 else onset + 1 + int(out[0])


def _mandatory(path: np.ndarray, attributes: np.ndarray) -> list[int]:
    T = len(path)
    picks: list[int] = []
    onsets = []
    for j in range(attributes.shape[1]):
        on = np.flatnonzero(attributes[:, j])
        if on.size:
            picks += [int(on[0]), int(on[-1])]
            onsets.append(int(on[0]))
    if onsets and min(onsets) >= 2:
        first = min(onsets)
        d = point_segment_distance(path[1:first], path[0], path[first])
        picks.append(1 + int(np.argmax(d)))
    picks.append(T - 1)
    return sorted({i for i in picks if i >= 1})


def extract_waypoint_indices(
    path: np.ndarray, attributes: np.ndarray, K: int = 5, grasp_lift_m: float = 0.15
) -> np.ndarray:
    """The K chosen step indices (sorted, in 1..T-1); fewer only if the path has fewer steps.

    ``grasp_lift_m``: how far the grasp primitive lifts [m] (0 = plain RDP on the path).
    """
    path = np.asarray(path, dtype=np.float64)
    attributes = np.asarray(attributes, dtype=bool)
    if attributes.ndim == 1:
        attributes = attributes[:, None]
    T = len(path)
    if path.shape != (T, 3) or attributes.shape[0] != T or T < 2:
        raise UsageError(
            f"need a path (T >= 2, 3) and attributes (T, k); got {path.shape}, {attributes.shape}"
        )
    if K < 1:
        raise UsageError(f"K (number of waypoints) must be >= 1, got {K}")
    chosen = _mandatory(path, attributes)
    while len(chosen) > K:  # drop the latest non-final mandatory point
        chosen.pop(-2)
    starts: dict[int, np.ndarray] = {}
    excluded = np.zeros(T, dtype=bool)
    grasp_on = np.flatnonzero(attributes[:, 0])
    if grasp_lift_m > 0 and grasp_on.size:
        onset = int(grasp_on[0])
        starts[onset] = path[onset] + np.array([0.0, 0.0, grasp_lift_m])
        excluded[onset + 1 : _lift_column(path, onset)] = True
    while len(chosen) < min(K, T - 1 - int(excluded.sum())):
        dev = polyline_deviation(path, [0, *chosen], starts)
        dev[[0, *chosen]] = -1.0
        dev[excluded] = -1.0
        chosen = sorted([*chosen, int(np.argmax(dev))])
    return np.asarray(chosen, dtype=np.int64)


def extract_waypoints(
    path: np.ndarray, attributes: np.ndarray, K: int = 5, grasp_lift_m: float = 0.15
) -> np.ndarray:
    """Attributed waypoints ``(K, 3 + k)``: positions [m] and 0/1 attribute flags."""
    attributes = np.asarray(attributes, dtype=bool)
    if attributes.ndim == 1:
        attributes = attributes[:, None]
    idx = extract_waypoint_indices(path, attributes, K, grasp_lift_m)
    path = np.asarray(path, np.float64)
    positions = path[idx].copy()
    grasp_on = np.flatnonzero(attributes[:, 0])
    if grasp_on.size and grasp_on[-1] + 1 < len(path):
        # the release point is where the gripper was commanded open, one step after the last
        # grasp-attributed step: at 2 cm per step the TCP still descends up to 2 cm in between
        positions[idx == grasp_on[-1]] = path[grasp_on[-1] + 1]
    return np.hstack([positions, attributes[idx].astype(np.float64)])
