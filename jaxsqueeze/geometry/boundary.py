"""The boundary of an object: loop neighbours, the one outward normal, and the node ↔ slot map.

Boundary *positions* (slots) index the contact-capable nodes in boundary order (``mesh.boundary``
for a mesh, ``arange(m)`` for a band): loop by loop, outer loop first, each loop with the material
on its left. Every module that needs a normal or a position reads it from here.
"""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..tracing import is_concrete


def neighbours(loops, m: int):
    """(prev, next) position arrays (m,) of each boundary position along its own loop."""
    loops = tuple(loops) or (m,)
    prev, nxt, start = [], [], 0
    for size in loops:
        k = np.arange(size)
        prev.append(start + (k - 1) % size)
        nxt.append(start + (k + 1) % size)
        start += size
    return np.concatenate(prev), np.concatenate(nxt)


def normals(x, loops, xp=jnp):
    """(m, 2) outward unit normals at boundary points ``x`` (m, 2) ordered as the loops.

    The normalized sum of the unit outward normals of the two edges at a node (at a corner,
    the bisector); where the two edges fold back onto each other, the next edge's normal.
    Works on undeformed or deformed positions; ``xp`` is ``jnp`` (traceable) or ``np``.
    """
    prev, nxt = neighbours(loops, x.shape[0])
    e = x[nxt] - x
    n = xp.stack([e[:, 1], -e[:, 0]], axis=1) / xp.linalg.norm(e, axis=1, keepdims=True)
    s = n + n[prev]
    norm = xp.linalg.norm(s, axis=1, keepdims=True)
    return xp.where(norm > 1e-12, s / xp.maximum(norm, 1e-300), n)


def inside(x, loops, q, xp=jnp):
    """(k,) bool: which points ``q`` (k, 2) lie inside the object bounded by the loops of ``x``
    (m, 2): inside the outer loop and outside every hole (the even-odd rule: a ray from the
    point crosses the boundary an odd number of times). For a band, inside its curve."""
    _, nxt = neighbours(loops, x.shape[0])
    a, b = x[None, :, :], x[nxt][None, :, :]
    q = q[:, None, :]
    straddles = (a[..., 1] > q[..., 1]) != (b[..., 1] > q[..., 1])
    dy = xp.where(straddles, b[..., 1] - a[..., 1], 1.0)
    x_cross = a[..., 0] + (q[..., 1] - a[..., 1]) * (b[..., 0] - a[..., 0]) / dy
    return xp.sum(straddles & (q[..., 0] < x_cross), axis=1) % 2 == 1


def crossing(x, loops, chunk: int = 256):
    """The first pair of boundary edges that cross each other, as positions (a, b) of their
    first nodes (edge k runs from position k to the next one along its loop), or ``None``.

    ``x`` (m, 2) boundary points ordered as the loops (numpy). Only proper crossings count
    (each edge's ends strictly on both sides of the other); edges that share a node never do.
    O(m²) in chunks of ``chunk`` edges: a fraction of a second for a few thousand nodes.
    """
    x = np.asarray(x, float)
    _, nxt = neighbours(loops, x.shape[0])
    a, b = x, x[nxt]
    k = np.arange(len(x))
    scale = np.ptp(x, axis=0).max() if len(x) else 1.0          # the extent, not the distance from 0

    def side(p, q, r):         # twice the signed area of (p, q, r), broadcast
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

    tol = 1e-12 * scale * scale
    for lo in range(0, len(x), chunk):
        i = k[lo:lo + chunk, None]
        ai, bi = a[i], b[i]
        s1, s2 = side(ai, bi, a[None]), side(ai, bi, b[None])
        s3, s4 = side(a[None], b[None], ai), side(a[None], b[None], bi)
        hit = (s1 * s2 < -tol * tol) & (s3 * s4 < -tol * tol)
        hit &= (i != k) & (nxt[i] != k) & (i != nxt[None])      # edges sharing a node
        if hit.any():
            r, c = np.argwhere(hit)[0]
            return int(lo + r), int(c)
    return None


def position_table(boundary_nodes, n: int) -> np.ndarray:
    """(n,) int64: the boundary position of each of the object's n nodes, −1 for interior nodes."""
    table = np.full(int(n), -1, dtype=np.int64)
    table[np.asarray(boundary_nodes)] = np.arange(len(boundary_nodes))
    return table


def lookup(table, nodes):
    """Positions of node indices ``nodes`` through a :func:`position_table`, −1 for an interior
    or out-of-range node. Traceable: a bad node gives −1, never another node (eager numbers
    give a numpy array, without device round trips)."""
    xp = np if is_concrete((table, nodes)) else jnp
    with jax.numpy_dtype_promotion("standard"):      # (i, j) may be two integer types
        nodes = xp.asarray(nodes)
    n = table.shape[0]
    ok = (nodes >= 0) & (nodes < n)
    return xp.where(ok, xp.asarray(table)[xp.clip(nodes, 0, n - 1)], -1)


def positions(boundary_nodes, nodes) -> np.ndarray:
    """Eager positions of node indices ``nodes`` among ``boundary_nodes``; raises ``ValueError``
    naming every node that is not on the boundary, or any index that is not an integer."""
    given = np.asarray(nodes)
    if given.size and given.dtype.kind not in "iu":
        raise ValueError(f"node indices must be integers, got {given.tolist()} ({given.dtype}); use boundary node "
                         "numbers (mesh.boundary, or Scene.nearest_boundary_node)")
    nodes = given.astype(np.int64)
    b = np.asarray(boundary_nodes)
    n = int(max(b.max(initial=0), nodes.max(initial=0))) + 1
    pos = np.asarray(lookup(position_table(b, n), nodes))
    if np.any(pos < 0):
        bad = sorted({int(v) for v in nodes[pos < 0]})
        raise ValueError(f"node(s) {bad[:8]}{' ...' if len(bad) > 8 else ''} are not on the boundary; "
                         "use boundary nodes (mesh.boundary, or Scene.nearest_boundary_node).")
    return pos


# ----------------------------------------------------------------------------- smooth parametrization
class Curve(NamedTuple):
    """A periodic C² cubic spline through the nodes of one boundary loop, by chord length s.

    knots: (k + 1,) arc-length parameter of each node, 0 … ``perimeter`` (the first node again
    at the end); coef: (k, 4, 2) cubic coefficients of x and y on each span, in powers of the
    local parameter (s − knots[i]), highest first. Arrays only, so a curve is a pytree leaf set
    that traced code evaluates (:func:`point`), and s can be traced and differentiated.
    Units are those of the points it was built from.
    """

    knots: jax.Array
    coef: jax.Array

    @property
    def perimeter(self):
        return self.knots[-1]


def curve(x, loops=None, loop: int = 0) -> Curve:
    """The :class:`Curve` through loop ``loop`` (default the outer one) of boundary points
    ``x`` (m, 2), which run loop by loop with the material on the left."""
    from scipy.interpolate import CubicSpline

    x = np.asarray(x, float)
    loops = tuple(loops) if loops else (x.shape[0],)
    start = int(np.sum(loops[:loop]))
    p = x[start:start + loops[loop]]
    closed = np.vstack([p, p[:1]])
    knots = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    spline = CubicSpline(knots, closed, bc_type="periodic")
    return Curve(knots, np.transpose(spline.c, (1, 0, 2)).copy())


def point(c: Curve, s):
    """Position p(s) (..., 2) and outward unit normal n(s) (..., 2) at arc length ``s`` (...,),
    periodic in the perimeter. C¹ in s (C² for the position), so a fingertip centre
    p(s) + r n(s) moves smoothly with s between nodes."""
    knots, coef = jnp.asarray(c.knots), jnp.asarray(c.coef)
    s = jnp.mod(jnp.asarray(s, knots.dtype), knots[-1])
    i = jnp.clip(jnp.searchsorted(knots, s, side="right") - 1, 0, coef.shape[0] - 1)
    t = (s - knots[i])[..., None]
    a = coef[i]                                          # (..., 4, 2)
    p = ((a[..., 0, :] * t + a[..., 1, :]) * t + a[..., 2, :]) * t + a[..., 3, :]
    dp = (3 * a[..., 0, :] * t + 2 * a[..., 1, :]) * t + a[..., 2, :]
    tan = dp / jnp.linalg.norm(dp, axis=-1, keepdims=True)
    return p, jnp.stack([tan[..., 1], -tan[..., 0]], axis=-1)


def arc_length(c: Curve, k) -> np.ndarray:
    """Arc-length coordinate of node(s) ``k`` (positions within the loop) on the curve."""
    return np.asarray(c.knots)[np.asarray(k)]
