"""The bordered system of eq. (4) and deformation from prescribed displacements (Section III)."""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..compiler import precise
from ..geometry import boundary
from ..numbers import kind, real_array
from ..tracing import is_concrete, own_transfers
from .operator import Compliance, field_displacement


def bordered_matrix(A: jax.Array, B: jax.Array, active: jax.Array) -> jax.Array:
    """M = [[A, B], [Bᵀ, 0]] of eq. (4) over s slots, with inactive slots made inert.

    Args:
        A: (2s, 2s) compliance block at the slot nodes (scaled).
        B: (2s, 3) rigid-mode rows at the slot nodes (scaled).
        active: (s,) bool; an inactive slot gets an identity row, so its force is 0.
    Returns:
        (2s + 3, 2s + 3) symmetric matrix, nonsingular when at least two slots are active
        (Theorem 3).
    """
    a2 = jnp.repeat(active, 2)
    Am = jnp.where(a2[:, None] & a2[None, :], A, 0.0) + jnp.diag(jnp.where(a2, 0.0, 1.0))
    Bm = jnp.where(a2[:, None], B, 0.0)
    top = jnp.concatenate([Am, Bm], axis=1)
    bottom = jnp.concatenate([Bm.T, jnp.zeros((3, 3), A.dtype)], axis=1)
    return jnp.concatenate([top, bottom], axis=0)


@jax.jit
@precise
def bordered_solve(A: jax.Array, B: jax.Array, d: jax.Array, active: jax.Array | None = None):
    """Solve eq. (4): A f + B g = d, Bᵀ f = 0.

    Args:
        A: (2s, 2s), B: (2s, 3), d: (2s,) prescribed displacements (scaled), active: (s,) bool.
    Returns:
        f: (2s,) forces (scaled; zero at inactive slots), g: (3,) rigid amplitudes
        (t_x, t_y, rotation) in scaled units.
    """
    s = A.shape[0] // 2
    active = jnp.ones(s, bool) if active is None else active
    M = bordered_matrix(A, B, active)
    rhs = jnp.concatenate([jnp.where(jnp.repeat(active, 2), d, 0.0), jnp.zeros(3, d.dtype)])
    x = jnp.linalg.solve(M, rhs)
    return x[: 2 * s], x[2 * s:]


class Deformation(NamedTuple):
    """Result of :func:`deform` (SI units).

    forces: (s, 2) forces the prescribers exert on the object at the given nodes [N].
    g: (3,) rigid part of the displacement: x, y translation [m] and rotation [rad] about
        the node centroid (the paper's g in an unnormalized basis).
    displacement: (n, 2) displacement of every node [m], or None if the operator has no field map.
    """

    forces: jax.Array
    g: jax.Array
    displacement: jax.Array | None


def boundary_slots(op: Compliance, nodes) -> np.ndarray:
    """Positions of mesh node indices ``nodes`` among the operator's contact-capable nodes."""
    return boundary.positions(np.asarray(op.nodes), np.asarray(nodes).reshape(-1))


def slot_dofs(slots: jax.Array) -> jax.Array:
    """(2s,) interleaved DOF indices of boundary slots."""
    return jnp.stack([2 * slots, 2 * slots + 1], axis=-1).reshape(-1)


@own_transfers
def deform(op: Compliance, nodes, displacements) -> Deformation:
    """Deformation from prescribed displacements of s ≥ 2 boundary nodes (Section III, eq. 4).

    Args:
        op: compliance operator (:func:`jaxsqueeze.fem.compliance`).
        nodes: (s,) mesh node indices, each on the boundary, all distinct.
        displacements: (s, 2) prescribed displacements [m].
    Returns:
        :class:`Deformation` with forces [N], g, and the displacement of every node [m].
    """
    if kind(nodes) == "O" or np.ndim(nodes) != 1:
        got = f"{nodes!r:.80}" if kind(nodes) == "O" else f"shape {np.shape(nodes)}"
        raise ValueError(f"nodes must be a flat list of s boundary node indices, got {got}")
    if is_concrete(displacements):
        real_array(displacements, "displacements", "m")
    slots = boundary_slots(op, nodes)
    s = slots.size
    if s < 2:
        raise ValueError(f"deform needs displacements at s >= 2 nodes (got s={s}); with one node "
                         "the object is free to rotate about it (Section III).")
    if len(set(slots.tolist())) != s:
        raise ValueError(f"nodes {np.asarray(nodes).tolist()} contain duplicates; give each node once.")
    d = jnp.asarray(displacements, op.G.dtype)
    if d.shape != (s, 2):
        raise ValueError(f"displacements must have shape ({s}, 2), got {tuple(d.shape)}.")
    bad = np.flatnonzero(~np.all(np.isfinite(np.asarray(d)), axis=1)) if is_concrete(d) else []
    if len(bad):
        raise ValueError(f"displacements of node(s) {np.asarray(nodes).reshape(-1)[bad].tolist()} are not finite; "
                         "give finite displacements [m].")
    return _deform(op, jnp.asarray(slots), d)


@jax.jit
@precise
def _deform(op: Compliance, slots, d):
    dofs = slot_dofs(slots)
    f_hat, g = bordered_solve(op.G[dofs][:, dofs], op.N[dofs], d.reshape(-1) / op.length)
    forces = (f_hat * op.force_scale).reshape(-1, 2)
    g_si = g * jnp.array([op.length, op.length, 1.0])
    if op.field is None:
        return Deformation(forces, g_si, None)
    F = jnp.zeros(op.G.shape[0], f_hat.dtype).at[dofs].set(f_hat)
    return Deformation(forces, g_si, field_displacement(op, F, g) * op.length)


# ----------------------------------------------------------------------------- the factored contact set
# The squeeze keeps the inverse of the bordered matrix M of eq. (4) over a fixed number S of
# contact slots (DESIGN 2.4): an inactive slot has an identity block and no coupling, so its force
# is 0. M changes only when a contact is made (event A) or broken (event B), and then in one
# slot, so its inverse is updated in O(S^2) by bordering instead of being rebuilt in O(S^3):
#
#   activate slot k   M' = [[M, b], [b^T, c]] (k moved last):  with w = M^-1 b, Z = (c - b^T w)^-1,
#                     M'^-1 = [[M^-1 + w Z w^T, -w Z], [-Z w^T, Z]]
#   deactivate slot k M'^-1 (others) = P - q t^-1 q^T  for  M^-1 = [[P, q], [q^T, t]]
#
# (Schur complements of a 2x2 block). Both are exact, but their round-off compounds over many
# updates on fine meshes; contacts.update checks the result and recomputes it then
# (docs/numerics.md §3 measures it).
def inv2(a: jax.Array) -> jax.Array:
    """Inverse of a (..., 2, 2) matrix (closed form; no LAPACK call, safe under ``vmap``)."""
    det = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
    adj = jnp.stack([jnp.stack([a[..., 1, 1], -a[..., 0, 1]], -1), jnp.stack([-a[..., 1, 0], a[..., 0, 0]], -1)], -2)
    return adj / det[..., None, None]


def _block_rows(Minv, k, rows):
    """Minv with rows 2k, 2k+1 replaced by ``rows`` (2, n) and columns 2k, 2k+1 by rows.T."""
    Minv = jax.lax.dynamic_update_slice(Minv, rows, (2 * k, 0))
    return jax.lax.dynamic_update_slice(Minv, rows.T, (0, 2 * k))


def inverse_activate(Minv: jax.Array, k, b: jax.Array, c: jax.Array) -> jax.Array:
    """Inverse of the bordered matrix after slot k becomes active.

    Args:
        Minv: (n, n) current inverse, slot k inactive (identity block, no coupling).
        k: () slot index.
        b: (n, 2) the new coupling of slot k's two DOFs to every row of M: compliance entries
            at the other active slots, rigid-mode rows in the last three; zero at inactive
            slots and at slot k itself.
        c: (2, 2) compliance block of the node itself.
    """
    w = Minv @ b
    Z = inv2(c - b.T @ w)
    Minv = Minv + w @ Z @ w.T
    rows = jax.lax.dynamic_update_slice(-(Z @ w.T), Z, (0, 2 * k))
    return _block_rows(Minv, k, rows)


def inverse_deactivate(Minv: jax.Array, k) -> jax.Array:
    """Inverse of the bordered matrix after active slot k becomes inactive (identity block)."""
    n = Minv.shape[0]
    q = jax.lax.dynamic_slice(Minv, (0, 2 * k), (n, 2))
    t = jax.lax.dynamic_slice(q, (2 * k, 0), (2, 2))
    q = jax.lax.dynamic_update_slice(q, jnp.zeros((2, 2), q.dtype), (2 * k, 0))
    Minv = Minv - q @ inv2(t) @ q.T
    rows = jax.lax.dynamic_update_slice(jnp.zeros((2, n), Minv.dtype), jnp.eye(2, dtype=Minv.dtype), (0, 2 * k))
    return _block_rows(Minv, k, rows)
