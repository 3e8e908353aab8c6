"""Faces of a planar arrangement of polylines (the regions the traced curves bound).

The curves of :mod:`optkin.analysis.continuation` are polylines in a plane. The regions
they bound (aspects, workspaces) are the faces of their arrangement: every pair of segments
is intersected, open ends are snapped onto the curve they stop on (within a tolerance of
the continuation step), dangling pieces are pruned, and the faces are walked on the
half-edge structure (the next half-edge turns clockwise-most). Faces are counter-clockwise
outer rings with the outer rings of the components nested in them as holes, so that the
connectivity of a region follows the traced curves, not a grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["Face", "faces", "ring_area", "point_in_face", "points_in_ring", "close_pairs"]


@dataclass(init=False)
class Face:
    """A bounded face: ``outer`` (k, 2) counter-clockwise, ``holes`` clockwise rings.

    ``point``, a point well inside the face (None when none was found), is computed when
    first read: most faces of an arrangement are slivers that the callers drop by their
    area without ever asking (in the 3-D aspects of a 3-RPR, 2821 faces in 88 sections,
    whose interior points took 40 % of the time of :func:`faces`).
    """

    outer: np.ndarray
    holes: list[np.ndarray]
    area: float

    def __init__(self, outer: np.ndarray, holes: list[np.ndarray] | None = None,
                 area: float = 0.0, point: Any = ...) -> None:
        self.outer = outer
        self.holes = [] if holes is None else holes
        self.area = area
        self._point = point  # ... (Ellipsis): not computed yet

    @property
    def point(self) -> np.ndarray | None:
        if self._point is ...:
            self._point = _interior_point(self)
        return self._point

    @point.setter
    def point(self, value: np.ndarray | None) -> None:
        self._point = value

    def contains(self, P: np.ndarray) -> np.ndarray:
        return point_in_face(self, P)


#: Elements per temporary array in the chunked all-pairs loops (points x edges, segment x
#: segment). Small enough (about 1 MB of float64) for glibc to recycle the blocks from its
#: heap: with the 2-4 million of before, every temporary was a fresh ``mmap`` whose pages
#: fault in at first touch, and a worker's first five-bar ``aspects`` paid about 0.1 s
#: more than its next ones (points_in_ring 80 ms against 21 ms on a 400-edge ring and
#: 5000 points; 19 ms against 17 ms with this size).
_CHUNK = 131_072


def ring_area(R: np.ndarray) -> float:
    x, y = R[:, 0], R[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def arc_area(R: np.ndarray, max_turn: float = 0.3) -> float:
    """The signed area of a closed ring whose vertices lie on smooth curves sampled with a
    bounded turning (traced curves), corrected for the arcs between them: an edge whose
    ends turn by theta (the mean of its smooth ends' exterior angles; a corner, turning
    more than ``max_turn``, is where two curves meet and adds nothing) bounds, with its
    arc, a segment of area chord^2 theta / 12 (a circular arc's, to third order). On a
    regular N-gon inscribed in a circle the deficit pi r^2 - area falls from O(1/N^2) to
    O(1/N^4)."""
    R = np.asarray(R, dtype=float)
    if len(R) > 1 and np.allclose(R[0], R[-1]):
        R = R[:-1]
    a = ring_area(R)
    if len(R) < 4:
        return a
    e = np.roll(R, -1, axis=0) - R  # edge k: from vertex k to k + 1
    ang = np.arctan2(e[:, 1], e[:, 0])
    turn = (ang - np.roll(ang, 1) + np.pi) % (2 * np.pi) - np.pi  # at vertex k
    smooth = np.abs(turn) < max_turn
    t0, t1 = np.where(smooth, turn, 0.0), np.roll(np.where(smooth, turn, 0.0), -1)
    n = smooth.astype(int) + np.roll(smooth, -1).astype(int)
    theta = np.where(n > 0, (t0 + t1) / np.maximum(n, 1), 0.0)
    return a + float(np.sum(np.einsum("ij,ij->i", e, e) * theta) / 12.0)


def face_arc_area(f: Face, max_turn: float = 0.3) -> float:
    """:func:`arc_area` of a face: its outer ring's less its holes'."""
    return arc_area(f.outer, max_turn) + sum(arc_area(h, max_turn) for h in f.holes)


def points_in_ring(R: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Which of the points ``P`` (n x 2) lie inside the closed ring ``R`` (m x 2, first
    vertex not repeated or repeated): the even-odd crossing rule, a ray to +x.

    Points on the ring itself may go either way. An edge can only cross the ray of a point
    whose y lies in the edge's half-open y-range, so the points are sorted by y and each
    edge visits only the run of points in its range (two binary searches): the work is
    the number of (edge, point) crossings, about n times the few edges a horizontal line
    meets, instead of n x m (20-40x less on a five-bar's traced aspects). The crossing's
    x is computed from the same expression as a brute-force sweep, so the answer is the
    same bit for bit. Written here rather than borrowed from ``matplotlib.path`` (the same
    rule in C): importing matplotlib costs a worker process about 0.3 s, more than most
    of the problems it runs.
    """
    P = np.atleast_2d(np.asarray(P, dtype=float))
    R = np.asarray(R, dtype=float)
    n = len(P)
    A, B = R, np.roll(R, -1, axis=0)
    if n == 0 or len(A) == 0:
        return np.zeros(n, dtype=bool)
    # (ay > py) != (by > py)  <=>  min(ay, by) <= py < max(ay, by)
    lo_y, hi_y = np.minimum(A[:, 1], B[:, 1]), np.maximum(A[:, 1], B[:, 1])
    order = np.argsort(P[:, 1], kind="stable")
    ys = P[order, 1]
    first = np.searchsorted(ys, lo_y, side="left")
    stop = np.searchsorted(ys, hi_y, side="left")
    count = np.maximum(stop - first, 0)
    odd = np.zeros(n, dtype=np.int64)
    ends = np.cumsum(count)
    e0 = 0
    while e0 < len(A):  # edges in runs of about _CHUNK (edge, point) pairs
        e1 = int(np.searchsorted(ends, (ends[e0 - 1] if e0 else 0) + _CHUNK, side="right"))
        e1 = max(e1, e0 + 1)
        c = count[e0:e1]
        tot = int(c.sum())
        if tot:
            edge = np.repeat(np.arange(e0, e1), c)
            offs = np.cumsum(c) - c
            k = order[np.arange(tot) - np.repeat(offs - first[e0:e1], c)]
            a, b = A[edge], B[edge]
            py = P[k, 1]
            x = a[:, 0] + (py - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
            odd += np.bincount(k[P[k, 0] < x], minlength=n)
        e0 = e1
    return (odd % 2).astype(bool)


def point_in_face(f: Face, P: np.ndarray) -> np.ndarray:
    P = np.atleast_2d(P)
    inside = points_in_ring(f.outer, P)
    for h in f.holes:
        inside &= ~points_in_ring(h, P)
    return inside


def close_pairs(X: np.ndarray, cell: np.ndarray, tol: float) -> np.ndarray:
    """Pairs (i, j), i < j, of the points ``X`` (n x 2) at most ``tol`` apart, given each
    point's distinct cell ``cell`` = round(X / tol) (integer-valued, n x 2): such points'
    cells differ by at most 2 in each coordinate (1 but for rounding halves to even), so
    each cell is looked up among those neighbours by a sorted key. (What ``scipy.spatial.cKDTree.query_pairs`` gives; importing
    ``scipy.spatial`` costs a worker process about 0.4 s.)
    """
    n = len(X)
    if n < 2:
        return np.zeros((0, 2), dtype=int)
    ux, rx = np.unique(cell[:, 0], return_inverse=True)
    uy, ry = np.unique(cell[:, 1], return_inverse=True)
    rx, ry = np.asarray(rx).ravel(), np.asarray(ry).ravel()
    key = rx.astype(np.int64) * len(uy) + ry
    order = np.argsort(key)
    skey = key[order]
    found = []
    offsets = [(dx, dy) for dx in range(3) for dy in range(-2, 3) if dx > 0 or dy > 0]
    for dx, dy in offsets:  # each unordered pair of cells once
        tx, ty = cell[:, 0] + dx, cell[:, 1] + dy
        jx = np.searchsorted(ux, tx).clip(0, len(ux) - 1)
        jy = np.searchsorted(uy, ty).clip(0, len(uy) - 1)
        ok = (ux[jx] == tx) & (uy[jy] == ty)
        k = jx.astype(np.int64) * len(uy) + jy
        pos = np.searchsorted(skey, k).clip(0, n - 1)
        ok &= skey[pos] == k
        i = np.flatnonzero(ok)
        j = order[pos[ok]]
        found.append(np.c_[i, j])
    pairs = np.vstack(found)
    d = np.linalg.norm(X[pairs[:, 0]] - X[pairs[:, 1]], axis=1)
    pairs = np.sort(pairs[d <= tol], axis=1)
    return pairs


def _segments(lines: list[tuple[np.ndarray, bool]]):
    A, B, pid = [], [], []
    for k, (P, closed) in enumerate(lines):
        P = np.asarray(P, dtype=float)
        if closed and np.linalg.norm(P[0] - P[-1]) > 0:
            P = np.vstack([P, P[:1]])
        if len(P) < 2:
            continue
        A.append(P[:-1])
        B.append(P[1:])
        pid.append(np.full(len(P) - 1, k))
    if not A:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, int)
    A, B, pid = np.vstack(A), np.vstack(B), np.concatenate(pid)
    keep = np.linalg.norm(B - A, axis=1) > 0
    return A[keep], B[keep], pid[keep]


def _project(p: np.ndarray, A: np.ndarray, B: np.ndarray):
    d = B - A
    L2 = np.einsum("ij,ij->i", d, d)
    t = np.clip(np.einsum("ij,ij->i", p - A, d) / np.where(L2 > 0, L2, 1), 0, 1)
    Q = A + t[:, None] * d
    dist = np.linalg.norm(Q - p, axis=1)
    return t, Q, dist


def _seg_dist(P: np.ndarray, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Distance of every point P (k, 2) to the nearest segment [A, B] (n, 2)."""
    out = np.empty(len(P))
    d = B - A
    L2 = np.einsum("ij,ij->i", d, d)
    L2 = np.where(L2 > 0, L2, 1)
    step = max(1, _CHUNK // 2 // max(len(A), 1))
    for s0 in range(0, len(P), step):
        Q = P[s0:s0 + step, None, :] - A[None]
        t = np.clip(np.einsum("kij,ij->ki", Q, d) / L2, 0, 1)
        E = Q - t[..., None] * d[None]
        out[s0:s0 + step] = np.sqrt(np.min(np.einsum("kij,kij->ki", E, E), axis=1))
    return out


def faces(lines: list[tuple[np.ndarray, bool]], snap: float, dedupe: float = 0.0) -> list[Face]:
    """The bounded faces of the arrangement of ``lines`` = [(points (k, 2), closed), ...].

    ``snap``: open ends farther than this from every other curve dangle (and are pruned);
    nearer ones are moved onto the nearest curve. ``dedupe`` > 0 drops segments whose
    midpoint lies within ``dedupe`` of an earlier curve's segment (overlapping copies).
    """
    lines = [(np.asarray(P, dtype=float), bool(c)) for P, c in lines if len(P) >= 2]
    A, B, pid = _segments(lines)
    if len(A) == 0:
        return []
    if dedupe > 0:
        keep = np.ones(len(A), dtype=bool)
        M = 0.5 * (A + B)
        for k in np.unique(pid):
            mine = np.flatnonzero(pid == k)
            other = np.flatnonzero((pid < k) & keep)
            if len(other) == 0:
                continue
            keep[mine] = _seg_dist(M[mine], A[other], B[other]) >= dedupe
        if not keep.all():
            # the kept pieces become new open polylines, whose ends are snapped as usual
            new_lines = []
            for k in np.unique(pid):
                idx = np.flatnonzero(pid == k)
                kk = keep[idx]
                closed = lines[k][1] and kk.all()
                if closed:
                    new_lines.append(lines[k])
                    continue
                cuts = np.flatnonzero(np.diff(kk.astype(int)) != 0) + 1
                for part_idx, part_keep in zip(np.split(idx, cuts), np.split(kk, cuts)):
                    if part_keep[0]:
                        new_lines.append((np.vstack([A[part_idx], B[part_idx[-1:]]]), False))
            return faces(new_lines, snap, 0.0)
    n = len(A)
    splits: list[list[float]] = [[0.0, 1.0] for _ in range(n)]
    # snap open ends onto the nearest other segment
    ends = []
    for k, (_, closed) in enumerate(lines):
        if closed:
            continue
        idx = np.flatnonzero(pid == k)
        if len(idx) == 0:
            continue
        ends.append((idx[0], 0))
        ends.append((idx[-1], 1))
    for si, which in ends:
        p = A[si] if which == 0 else B[si]
        mask = np.ones(n, dtype=bool)
        mask[max(si - 1, 0):si + 2] = False
        mask &= ~((pid == pid[si]) & (np.abs(np.arange(n) - si) < 3))
        if not mask.any():
            continue
        idx = np.flatnonzero(mask)
        t, Q, dist = _project(p, A[idx], B[idx])
        j = int(np.argmin(dist))
        if dist[j] < snap:
            q = Q[j]
            if which == 0:
                A[si] = q
            else:
                B[si] = q
            splits[idx[j]].append(float(t[j]))
    # pairwise intersections: bounding-box candidates first (chunked), then the exact test
    d = B - A
    lo, hi = np.minimum(A, B), np.maximum(A, B)
    chunk = max(1, 2 * _CHUNK // max(n, 1))
    eps = 1e-12
    n_hits = 0
    for s0 in range(0, n, chunk):
        s1 = min(n, s0 + chunk)
        ov = ((lo[s0:s1, None, 0] <= hi[None, :, 0]) & (hi[s0:s1, None, 0] >= lo[None, :, 0])
              & (lo[s0:s1, None, 1] <= hi[None, :, 1]) & (hi[s0:s1, None, 1] >= lo[None, :, 1]))
        ii, jj = np.nonzero(ov)
        ii = ii + s0
        sel = jj > ii
        ii, jj = ii[sel], jj[sel]
        if len(ii) == 0:
            continue
        da, db = d[ii], d[jj]
        den = da[:, 0] * db[:, 1] - da[:, 1] * db[:, 0]
        w = A[jj] - A[ii]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[:, 0] * db[:, 1] - w[:, 1] * db[:, 0]) / den
            u = (w[:, 0] * da[:, 1] - w[:, 1] * da[:, 0]) / den
        hit = (np.abs(den) > 1e-300) & (t >= -eps) & (t <= 1 + eps) & (u >= -eps) & (u <= 1 + eps)
        n_hits += int(hit.sum())
        if dedupe == 0.0 and n_hits > 20 * n:
            # overlapping copies of curves (every segment crossing dozens of others): an
            # arrangement of them takes hours; drop the copies first (a segment within 5 %
            # of the longest chord, snap / 3, of an earlier curve: beyond the sagitta of a
            # chord turning 0.25 rad, 3 %)
            return faces(lines, snap, dedupe=0.05 * snap / 3.0)
        for i, j, tt, uu in zip(ii[hit].tolist(), jj[hit].tolist(),
                                np.clip(t[hit], 0, 1).tolist(), np.clip(u[hit], 0, 1).tolist()):
            splits[i].append(tt)
            splits[j].append(uu)
    # vertices and edges: plain segments in bulk, split ones one by one
    plain = np.array([len(sp) == 2 for sp in splits])
    ip = np.flatnonzero(plain)
    pts = list(np.vstack([A[ip], B[ip]])) if len(ip) else []
    k = len(ip)
    edges_raw = [(a, a + k) for a in range(k)]
    # (nearly every segment is split: a polyline's neighbours meet it at its ends, t = 0 or
    # 1; a Python set sorts these few values 30x faster than np.unique, one call each)
    split = np.flatnonzero(~plain)
    ts_all = [sorted(set(splits[i])) for i in split.tolist()]
    counts = np.array([len(ts) for ts in ts_all], dtype=int)
    if len(split):
        seg = np.repeat(split, counts)
        tt = np.fromiter((t for ts in ts_all for t in ts), dtype=float, count=int(counts.sum()))
        base = len(pts)  # the split segments come after the plain ones
        P = A[seg] + tt[:, None] * d[seg]
        starts = base + np.concatenate([[0], np.cumsum(counts)[:-1]])
        first_pt = np.repeat(starts, counts - 1)
        within = np.arange(int((counts - 1).sum())) - np.repeat(
            np.concatenate([[0], np.cumsum(counts - 1)[:-1]]), counts - 1)
        q0 = first_pt + within
        edges_raw += list(zip(q0.tolist(), (q0 + 1).tolist()))
        pts.extend(P)
    pts = np.array(pts)
    scale = float(np.max(np.ptp(pts, axis=0))) or 1.0
    if not math.isfinite(scale):
        scale = 1.0
    tol = 1e-9 * scale
    # vertices within tol merge: first those in one cell of a tol grid (any number of
    # coincident points at once), then pairs of cells' representatives closer than tol
    with np.errstate(invalid="ignore", over="ignore"):
        cell = np.round(pts / tol)
    cell[~np.isfinite(cell)] = 0.0
    _, first, inv = np.unique(cell, axis=0, return_index=True, return_inverse=True)
    inv = np.asarray(inv).ravel()
    reps = pts[first]
    pairs = close_pairs(np.nan_to_num(reps), cell[first], tol)
    parent = np.arange(len(reps))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for a, b in pairs:
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    root_rep = np.array([find(i) for i in range(len(reps))], dtype=int)
    root = first[root_rep][inv] if len(pts) else np.zeros(0, dtype=int)
    E = {(min(root[a], root[b]), max(root[a], root[b])) for a, b in edges_raw if root[a] != root[b]}
    # prune dangling edges
    adj: dict[int, set[int]] = {}
    for a, b in E:
        adj.setdefault(a, set()).add(b)
        adj.setdefault(b, set()).add(a)
    stack = [v for v, s in adj.items() if len(s) <= 1]
    while stack:
        v = stack.pop()
        for w in list(adj.get(v, ())):
            adj[w].discard(v)
            if len(adj[w]) == 1:
                stack.append(w)
        adj.pop(v, None)
    if not adj:
        return []
    # half-edge walk
    # each vertex's neighbours by angle, all vertices in one sort (by vertex, then angle;
    # stable: ties keep the neighbours' order, as a sort per vertex did)
    V = np.fromiter((v for v, nb in adj.items() for _ in nb), dtype=np.intp)
    W = np.fromiter((w for nb in adj.values() for w in nb), dtype=np.intp)
    srt = np.lexsort((np.arctan2(pts[W, 1] - pts[V, 1], pts[W, 0] - pts[V, 0]), V))
    V, W = V[srt].tolist(), W[srt].tolist()
    order: dict[int, list[int]] = {}
    pos: dict[tuple[int, int], int] = {}
    for v, w in zip(V, W):
        lst = order.setdefault(v, [])
        pos[(v, w)] = len(lst)
        lst.append(w)
    seen: set[tuple[int, int]] = set()
    cycles = []
    for v in adj:
        for w in adj[v]:
            if (v, w) in seen:
                continue
            cyc = []
            a, b = v, w
            while (a, b) not in seen:
                seen.add((a, b))
                cyc.append(a)
                lst = order[b]
                k = pos[(b, a)]
                c = lst[(k - 1) % len(lst)]
                a, b = b, c
            cycles.append(np.array(cyc))
    # components (for hole assignment)
    comp = {}
    cid = 0
    for v in adj:
        if v in comp:
            continue
        st = [v]
        comp[v] = cid
        while st:
            x = st.pop()
            for y in adj[x]:
                if y not in comp:
                    comp[y] = cid
                    st.append(y)
        cid += 1
    pos_f, neg_f = [], []
    for cyc in cycles:
        R = pts[cyc]
        ar = ring_area(R)
        if ar > 0:
            pos_f.append((R, ar, comp[cyc[0]]))
        elif ar < 0:
            neg_f.append((R, ar, comp[cyc[0]]))
    out = [Face(outer=R, holes=[], area=ar) for R, ar, _ in pos_f]
    tiny = 1e-10 * scale * scale
    for R, ar, c in neg_f:
        best, barea = None, np.inf
        probe = R[0]
        for k, (_, arp, cp) in enumerate(pos_f):
            if cp == c:
                continue
            if arp < barea and points_in_ring(pos_f[k][0], probe)[0]:
                best, barea = k, arp
        if best is not None:
            out[best].holes.append(R)
            out[best].area += ar
    return [f for f in out if f.area > tiny]


def _interior_point(f: Face) -> np.ndarray | None:
    """A point well inside the face (the best of offsets from the edge midpoints)."""
    R = f.outer
    allr = [R] + list(f.holes)
    segA = np.vstack([r for r in allr])
    segB = np.vstack([np.roll(r, -1, axis=0) for r in allr])
    size = np.sqrt(max(f.area, 1e-300))
    Rn = np.roll(R, -1, axis=0)
    mids = 0.5 * (R + Rn)
    tang = Rn - R
    nrm = np.stack([-tang[:, 1], tang[:, 0]], 1)
    ln = np.linalg.norm(nrm, axis=1)
    ok = ln > 0
    nrm[ok] /= ln[ok, None]
    step = max(1, len(R) // 40)
    # offsets from the edges' midpoints, the deepest first; a point offset by frac * size
    # from its edge's midpoint is at most that far from the boundary, so once the best so
    # far is at least the next offset, no later candidate can beat it (the same point as
    # trying them all: ties go to the earlier candidate either way)
    best, best_d = None, -np.inf
    fracs = (0.2, 0.05, 0.01, 1e-3)
    for frac in fracs:
        if best is not None and best_d >= frac * size:
            break
        C = mids[::step] + frac * size * nrm[::step]
        C = C[point_in_face(f, C)]
        if len(C):
            dist = _seg_dist(C, segA, segB)
            j = int(np.argmax(dist))
            if dist[j] > best_d:
                best, best_d = C[j], float(dist[j])
    return best
