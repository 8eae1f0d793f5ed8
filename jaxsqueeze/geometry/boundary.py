"""The boundary of an object: loop neighbours, the one outward normal, and the node ↔ slot map.

Boundary *positions* (slots) index the contact-capable nodes in boundary order (``mesh.boundary``
for a mesh, ``arange(m)`` for a band): loop by loop, outer loop first, each loop with the material
on its left. Every module that needs a normal or a position reads it from here.
"""
from __future__ import annotations

import jax.numpy as jnp
import numpy as np


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


def position_table(boundary_nodes, n: int) -> np.ndarray:
    """(n,) int64: the boundary position of each of the object's n nodes, −1 for interior nodes."""
    table = np.full(int(n), -1, dtype=np.int64)
    table[np.asarray(boundary_nodes)] = np.arange(len(boundary_nodes))
    return table


def lookup(table, nodes):
    """Positions of node indices ``nodes`` through a :func:`position_table`, −1 for an interior
    or out-of-range node. Traceable: a bad node gives −1, never another node."""
    nodes = jnp.asarray(nodes)
    n = table.shape[0]
    ok = (nodes >= 0) & (nodes < n)
    return jnp.where(ok, jnp.asarray(table)[jnp.clip(nodes, 0, n - 1)], -1)


def positions(boundary_nodes, nodes) -> np.ndarray:
    """Eager positions of node indices ``nodes`` among ``boundary_nodes``; raises ``ValueError``
    naming every node that is not on the boundary."""
    nodes = np.asarray(nodes, dtype=np.int64)
    b = np.asarray(boundary_nodes)
    n = int(max(b.max(initial=0), nodes.max(initial=0))) + 1
    pos = np.asarray(lookup(position_table(b, n), nodes))
    if np.any(pos < 0):
        bad = sorted({int(v) for v in nodes[pos < 0]})
        raise ValueError(f"node(s) {bad[:8]}{' ...' if len(bad) > 8 else ''} are not on the boundary; "
                         "use boundary nodes (mesh.boundary, or Scene.nearest_boundary_node).")
    return pos
