"""Travel distances and paths between lane intersections of a field (metres).

- ``br`` (between rows, early season): every lane is open; distance is Manhattan
  ``|ax - bx| + |ay - by|`` and the path runs along a's row-gap lane to b's cross lane,
  then along it (the paper's BR_nav steps).
- ``aha`` (alley-headland-alley, near canopy closure): travel only along cross lanes
  (alleys and the two headland lanes); to change cross lane go along whichever outer
  row-gap lane (field edge) gives the shorter path, the paper's d_AHA with h on that
  edge. Same cross lane: ``|ay - by|``.
- ``lanes``: shortest paths on the lane graph restricted to the open lanes (by default
  all cross lanes plus the two edge lanes, which equals ``aha``).

Points must lie on lane intersections (candidates and the start corner do).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import shortest_path

from common.arrays import F64
from common.field import Field

NavMode = Literal["br", "aha", "lanes"]
NAV_MODES = ("br", "aha", "lanes")
_TOL = 1e-6


def br_distance(a: F64, b: F64) -> F64:
    """Pairwise Manhattan distances between (n, 2) and (m, 2) points: (n, m)."""
    return np.abs(a[:, None, :] - b[None, :, :]).sum(axis=-1)


def aha_distance(a: F64, b: F64, y_low: float, y_high: float) -> F64:
    """Pairwise AHA distances (n, m) for points on cross lanes; ``y_low``/``y_high``
    are the y of the two field-edge lanes."""
    ay, by = a[:, None, 1], b[None, :, 1]
    dx = np.abs(a[:, None, 0] - b[None, :, 0])
    via_low = np.abs(ay - y_low) + dx + np.abs(by - y_low)
    via_high = np.abs(ay - y_high) + dx + np.abs(by - y_high)
    return np.where(dx <= _TOL, np.abs(ay - by), np.minimum(via_low, via_high))


class Navigator:
    """Distances and lane-following paths for one field and navigation mode.

    ``open_rows``/``open_cross`` (``lanes`` mode only) are indices of passable row-gap
    and cross lanes; None means the two edge lanes / every cross lane. Raises ValueError
    on an unknown mode or lane index.
    """

    def __init__(
        self,
        field: Field,
        nav: str = "aha",
        open_rows: list[int] | None = None,
        open_cross: list[int] | None = None,
    ) -> None:
        if nav not in NAV_MODES:
            raise ValueError(f"nav mode {nav!r}: expected one of {', '.join(NAV_MODES)}")
        self.nav = nav
        self.xs, self.ys = field.cross_lanes_x, field.row_lanes_y
        nr, nc = len(self.ys), len(self.xs)
        rows = [0, nr - 1] if open_rows is None else list(open_rows)
        cross = list(range(nc)) if open_cross is None else list(open_cross)
        for name, idx, n in (("open_rows", rows, nr), ("open_cross", cross, nc)):
            bad = [i for i in idx if not 0 <= i < n]
            if bad:
                raise ValueError(f"{name}: lane index {bad[0]} is outside 0..{n - 1}")
        self.open_rows, self.open_cross = sorted(set(rows)), sorted(set(cross))
        self._dist: F64 | None = None
        self._pred: npt.NDArray[np.int32] | None = None
        if nav == "lanes":
            self._build_graph()

    def _node(self, p: F64) -> int:
        r = int(np.argmin(np.abs(self.ys - p[1])))
        c = int(np.argmin(np.abs(self.xs - p[0])))
        if abs(self.ys[r] - p[1]) > _TOL or abs(self.xs[c] - p[0]) > _TOL:
            raise ValueError(f"point ({p[0]:.3f}, {p[1]:.3f}) is not on a lane intersection")
        return r * len(self.xs) + c

    def _build_graph(self) -> None:
        nr, nc = len(self.ys), len(self.xs)
        i, j, w = [], [], []
        for r in self.open_rows:  # along x on row-gap lane r
            for c in range(nc - 1):
                i.append(r * nc + c)
                j.append(r * nc + c + 1)
                w.append(self.xs[c + 1] - self.xs[c])
        for c in self.open_cross:  # along y on cross lane c
            for r in range(nr - 1):
                i.append(r * nc + c)
                j.append((r + 1) * nc + c)
                w.append(self.ys[r + 1] - self.ys[r])
        g = coo_matrix((w, (i, j)), shape=(nr * nc, nr * nc)).tocsr()
        self._dist, self._pred = shortest_path(g, directed=False, return_predecessors=True)

    def distances(self, pts: F64) -> F64:
        """(n, n) travel distances between points on lane intersections."""
        pts = np.asarray(pts, dtype=np.float64)
        if self.nav == "br":
            return br_distance(pts, pts)
        if self.nav == "aha":
            for p in pts:
                self._node(p)
            return aha_distance(pts, pts, float(self.ys[0]), float(self.ys[-1]))
        assert self._dist is not None
        idx = np.array([self._node(p) for p in pts])
        return np.asarray(self._dist[np.ix_(idx, idx)], dtype=np.float64)

    def path(self, a: F64, b: F64) -> F64:
        """Corner points (k, 2) of the lane path from a to b, both ends included and
        collinear points merged; raises ValueError when b cannot be reached."""
        a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        if self.nav == "br":
            pts = [a, np.array([b[0], a[1]]), b]
        elif self.nav == "aha":
            if abs(a[0] - b[0]) <= _TOL:
                pts = [a, b]
            else:
                lo, hi = float(self.ys[0]), float(self.ys[-1])
                cost = [abs(a[1] - e) + abs(b[1] - e) for e in (lo, hi)]
                e = lo if cost[0] <= cost[1] else hi
                pts = [a, np.array([a[0], e]), np.array([b[0], e]), b]
        else:
            assert self._pred is not None
            na, nb = self._node(a), self._node(b)
            if na != nb and self._pred[na, nb] < 0:
                raise ValueError(f"no open lane path from {a.tolist()} to {b.tolist()}")
            seq = [nb]
            while seq[-1] != na:
                seq.append(int(self._pred[na, seq[-1]]))
            nc = len(self.xs)
            pts = [np.array([self.xs[n % nc], self.ys[n // nc]]) for n in reversed(seq)]
        return _simplify(np.array(pts))


def _simplify(pts: F64) -> F64:
    """Drop repeated points and the middle of straight runs."""
    keep = [pts[0]]
    for p in pts[1:]:
        if np.hypot(*(p - keep[-1])) > _TOL:
            keep.append(p)
    out = [keep[0]]
    for k in range(1, len(keep) - 1):
        d1, d2 = keep[k] - out[-1], keep[k + 1] - keep[k]
        if abs(d1[0] * d2[1] - d1[1] * d2[0]) > _TOL or np.dot(d1, d2) < 0:
            out.append(keep[k])
    if len(keep) > 1:
        out.append(keep[-1])
    return np.array(out)
