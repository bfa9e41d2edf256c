"""Volume of the convex hull of a cluster's points (Quickhull, Barber et al. 1996), compiled.

Each object's volume is one 3-D hull. Qhull (through scipy) costs ~0.5 ms a hull of 3,000
points, most of it setting up and tearing down its state, and a 640 x 480 tabletop view has
four or five objects: ~2.6 ms of its ~40 ms detection. Here: the initial simplex of four
extreme points, each face's outside set, its farthest point added by turns (the faces it
sees replaced by a cone over their horizon), until no point is outside a face by more than
round-off: the same volumes to ~1e-13, in half the time.

Points (Q, 3) float64 metres; the volume in m^3. A set flat within round-off has no volume
(0.0, as Qhull raises on it). Where round-off breaks the face structure (a horizon that is not
one simple loop: a sliver face on near-coplanar points) the kernel gives up and says so
(-1.0), and the caller asks Qhull.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer

__all__ = ["FAILED", "hull_volume"]

FAILED = -1.0
# Distances within this fraction of the points' extent are round-off: a point that close to
# a face's plane is on it, not outside (Qhull's own tolerance is of this order).
_ROUNDOFF = 1e-12


@njit(cache=True, nogil=True)
def _plane(q: np.ndarray, a: int, b: int, c: int, out: np.ndarray) -> None:
    # Unit normal of the face a -> b -> c (counter-clockwise seen from outside) and its
    # offset: out = (nx, ny, nz, n . q[a]); a sliver's normal is 0 (it sees no point).
    ux, uy, uz = q[b, 0] - q[a, 0], q[b, 1] - q[a, 1], q[b, 2] - q[a, 2]
    vx, vy, vz = q[c, 0] - q[a, 0], q[c, 1] - q[a, 1], q[c, 2] - q[a, 2]
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    length = np.sqrt(nx * nx + ny * ny + nz * nz)
    if length > 0.0:
        nx, ny, nz = nx / length, ny / length, nz / length
    out[0], out[1], out[2] = nx, ny, nz
    out[3] = nx * q[a, 0] + ny * q[a, 1] + nz * q[a, 2]


@njit(cache=True, nogil=True)
def _distance(plane: np.ndarray, q: np.ndarray, i: int) -> float:
    return plane[0] * q[i, 0] + plane[1] * q[i, 1] + plane[2] * q[i, 2] - plane[3]


@njit(cache=True, nogil=True)
def _simplex(q: np.ndarray, tol: float) -> np.ndarray:
    """Four points spanning a tetrahedron of q (Q, 3), or fewer when q is flat within tol."""
    n = len(q)
    i0 = i1 = 0
    for i in range(n):  # the extremes along x, then whichever point is farthest from i0
        if q[i, 0] < q[i0, 0]:
            i0 = i
    best = -1.0
    for i in range(n):
        d = (q[i, 0] - q[i0, 0]) ** 2 + (q[i, 1] - q[i0, 1]) ** 2 + (q[i, 2] - q[i0, 2]) ** 2
        if d > best:
            best, i1 = d, i
    if np.sqrt(best) <= tol:
        return np.array([i0], dtype=np.int64)
    dx, dy, dz = q[i1, 0] - q[i0, 0], q[i1, 1] - q[i0, 1], q[i1, 2] - q[i0, 2]
    norm = np.sqrt(dx * dx + dy * dy + dz * dz)
    best, i2 = -1.0, 0
    for i in range(n):  # farthest from the line i0 - i1
        ux, uy, uz = q[i, 0] - q[i0, 0], q[i, 1] - q[i0, 1], q[i, 2] - q[i0, 2]
        cx, cy, cz = uy * dz - uz * dy, uz * dx - ux * dz, ux * dy - uy * dx
        d = np.sqrt(cx * cx + cy * cy + cz * cz) / norm
        if d > best:
            best, i2 = d, i
    if best <= tol:
        return np.array([i0, i1], dtype=np.int64)
    plane = np.empty(4)
    _plane(q, i0, i1, i2, plane)
    best, i3 = -1.0, 0
    for i in range(n):  # farthest from the plane i0, i1, i2
        d = abs(_distance(plane, q, i))
        if d > best:
            best, i3 = d, i
    if best <= tol:
        return np.array([i0, i1, i2], dtype=np.int64)
    if _distance(plane, q, i3) > 0.0:  # i3 above: the base is seen from below
        i1, i2 = i2, i1
    return np.array([i0, i1, i2, i3], dtype=np.int64)


@njit(cache=True, nogil=True)
def _faces(cap):  # type: ignore[no-untyped-def]
    # Room for cap faces: vertices, planes, neighbours, outside sets (head, farthest point and
    # its distance), live flags and visit marks.
    return (
        np.empty((cap, 3), np.int64),
        np.empty((cap, 4)),
        np.empty((cap, 3), np.int64),
        np.full(cap, -1, np.int64),
        np.full(cap, -1, np.int64),
        np.zeros(cap),
        np.zeros(cap, np.bool_),
        np.zeros(cap, np.int64),
    )


@njit(cache=True, nogil=True)
def _grow(fv, planes, nb, head, far, fard, alive, seen):  # type: ignore[no-untyped-def]
    # Twice the room, the faces so far copied over.
    out = _faces(2 * len(fv))
    m = len(fv)
    for f in range(m):  # loops, not slice copies: those cost a fresh install compile time
        for k in range(3):
            out[0][f, k], out[2][f, k] = fv[f, k], nb[f, k]
        for k in range(4):
            out[1][f, k] = planes[f, k]
        out[3][f], out[4][f], out[5][f] = head[f], far[f], fard[f]
        out[6][f], out[7][f] = alive[f], seen[f]
    return out


@njit(cache=True, nogil=True)
def _assign(q, i, first, last, planes, alive, head, far, fard, nxt, tol) -> None:  # type: ignore[no-untyped-def]
    # Put point i in the outside set of the first live face in [first, last) it is above.
    for f in range(first, last):
        if not alive[f]:
            continue
        d = _distance(planes[f], q, i)
        if d > tol:
            nxt[i] = head[f]
            head[f] = i
            if d > fard[f]:
                far[f], fard[f] = i, d
            return


@njit(cache=True, nogil=True)
def _expand(q, fv, planes, nb, head, far, fard, alive, seen, nxt, nf, tol):  # type: ignore[no-untyped-def]
    """Quickhull's loop from the simplex's faces (nf of them); the hull's volume, or -1.0."""
    n = len(q)
    # Room for every face (a face is pushed and seen once a step) and three edges each.
    stack = np.empty(len(fv), np.int64)
    visible = np.empty(len(fv), np.int64)
    edges = np.empty((3 * len(fv), 2), np.int64)  # horizon: (visible face, its edge 0..2)
    start_of = np.full(n, -1, np.int64)  # new face whose edge 0 starts at a vertex
    start_stamp = np.zeros(n, np.int64)
    stamp = 0
    f = 0
    while f < nf:
        if not alive[f] or head[f] < 0:
            f += 1
            continue
        eye = far[f]
        stamp += 1
        if len(visible) < len(fv):  # the faces grew last step: room for them all
            stack = np.empty(len(fv), np.int64)
            visible = np.empty(len(fv), np.int64)
            edges = np.empty((3 * len(fv), 2), np.int64)
        # The faces the eye sees, connected to f; the edges where they meet the others.
        nv = ne = 0
        top = 1
        stack[0] = f
        seen[f] = stamp
        while top > 0:
            top -= 1
            g = stack[top]
            visible[nv] = g
            nv += 1
            for k in range(3):
                h = nb[g, k]
                if seen[h] == stamp:
                    continue
                if _distance(planes[h], q, eye) > tol:
                    seen[h] = stamp
                    stack[top] = h
                    top += 1
                else:
                    edges[ne, 0], edges[ne, 1] = g, k
                    ne += 1
        while nf + ne > len(fv):
            fv, planes, nb, head, far, fard, alive, seen = _grow(
                fv, planes, nb, head, far, fard, alive, seen
            )
        # A cone of new faces (v0 -> v1 -> eye) over the horizon, linked across it.
        first = nf
        for e in range(ne):
            g, k = edges[e, 0], edges[e, 1]
            v0, v1, h = fv[g, k], fv[g, (k + 1) % 3], nb[g, k]
            if start_stamp[v0] == stamp:  # the horizon passes a vertex twice
                return -1.0
            start_stamp[v0], start_of[v0] = stamp, nf
            fv[nf, 0], fv[nf, 1], fv[nf, 2] = v0, v1, eye
            _plane(q, v0, v1, eye, planes[nf])
            nb[nf, 0] = h
            for kk in range(3):  # the face beyond the horizon now borders the new one
                if nb[h, kk] == g and fv[h, kk] == v1:
                    nb[h, kk] = nf
            alive[nf], head[nf], far[nf], fard[nf] = True, -1, -1, 0.0
            nf += 1
        for e in range(first, nf):
            v1 = fv[e, 1]
            if start_stamp[v1] != stamp:
                return -1.0
            nb[e, 1] = start_of[v1]
            nb[start_of[v1], 2] = e
        steps, e = 0, first  # one simple loop, or the cone is no disc
        while True:
            e = nb[e, 1]
            steps += 1
            if e == first or steps > ne:
                break
        if steps != ne:
            return -1.0
        for v in range(nv):
            alive[visible[v]] = False
        for v in range(nv):  # the points the removed faces saw, to the cone's faces
            i = head[visible[v]]
            while i >= 0:
                following = nxt[i]
                if i != eye:
                    _assign(q, i, first, nf, planes, alive, head, far, fard, nxt, tol)
                i = following
        f += 1
    volume = 0.0
    for g in range(nf):
        if alive[g]:
            a, b, c = fv[g, 0], fv[g, 1], fv[g, 2]
            volume += (
                q[a, 0] * (q[b, 1] * q[c, 2] - q[b, 2] * q[c, 1])
                - q[a, 1] * (q[b, 0] * q[c, 2] - q[b, 2] * q[c, 0])
                + q[a, 2] * (q[b, 0] * q[c, 1] - q[b, 1] * q[c, 0])
            )
    return volume / 6.0


@njit(cache=True, nogil=True)
def hull_volume(points: np.ndarray) -> float:
    """Volume (m^3) of the convex hull of points (Q, 3) float64 metres; 0.0 when they are
    flat within round-off; FAILED (-1.0) when round-off defeats the construction."""
    n = len(points)
    if n < 4:
        return 0.0
    # Centred: the volume's sum and the planes' offsets lose no bits. (Loops: array
    # expressions cost a fresh install compile time.)
    cx = cy = cz = 0.0
    for i in range(n):
        cx, cy, cz = cx + points[i, 0], cy + points[i, 1], cz + points[i, 2]
    cx, cy, cz = cx / n, cy / n, cz / n
    q = np.empty((n, 3))
    extent = 1e-300
    for i in range(n):
        q[i, 0], q[i, 1], q[i, 2] = points[i, 0] - cx, points[i, 1] - cy, points[i, 2] - cz
        extent = max(extent, abs(q[i, 0]), abs(q[i, 1]), abs(q[i, 2]))
    tol = _ROUNDOFF * extent * 8.0
    simplex = _simplex(q, tol)
    if len(simplex) < 4:
        return 0.0
    cap = 64
    while cap < 8 * n:
        cap *= 2
    fv, planes, nb, head, far, fard, alive, seen = _faces(cap)
    a, b, c, d = simplex[0], simplex[1], simplex[2], simplex[3]
    # The tetrahedron's faces, counter-clockwise from outside (d is below a, b, c), and
    # their neighbours across edges 0 (v0 -> v1), 1 (v1 -> v2), 2 (v2 -> v0).
    fv[0, 0], fv[0, 1], fv[0, 2] = a, b, c
    fv[1, 0], fv[1, 1], fv[1, 2] = a, d, b
    fv[2, 0], fv[2, 1], fv[2, 2] = b, d, c
    fv[3, 0], fv[3, 1], fv[3, 2] = c, d, a
    nb[0, 0], nb[0, 1], nb[0, 2] = 1, 2, 3
    nb[1, 0], nb[1, 1], nb[1, 2] = 3, 2, 0
    nb[2, 0], nb[2, 1], nb[2, 2] = 1, 3, 0
    nb[3, 0], nb[3, 1], nb[3, 2] = 2, 1, 0
    for f in range(4):
        _plane(q, fv[f, 0], fv[f, 1], fv[f, 2], planes[f])
        alive[f] = True
    nf = 4
    nxt = np.full(n, -1, np.int64)
    for i in range(n):
        if i != a and i != b and i != c and i != d:
            _assign(q, i, 0, 4, planes, alive, head, far, fard, nxt, tol)
    status = _expand(q, fv, planes, nb, head, far, fard, alive, seen, nxt, nf, tol)
    if status < 0:
        return FAILED
    return status


@warmer
def _warm() -> None:
    hull_volume(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.1, 0.1, 0.1]]))
