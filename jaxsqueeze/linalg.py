"""Small dense solves for the squeeze loop that stay safe under ``vmap``.

Why: jaxlib's CPU LAPACK kernels parallelise over a ``vmap`` batch on XLA's intra-op thread
pool. Called from inside a ``lax.while_loop`` that already runs on that pool, the batched
LU waits on itself: on a 2-core machine ``jax.vmap`` of a squeeze over three grasps
deadlocked (``jax::ParallelBatchMap`` in ``LuDecomposition`` blocked forever). So
:func:`solve` uses LAPACK for a single system and, through ``custom_vmap``, Gauss–Jordan
elimination in ordinary array operations for a batch. The systems are small (2s + 3
unknowns), the two paths agree to round-off, and both are forward-mode differentiable.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax
from jax.custom_batching import custom_vmap


@custom_vmap
def solve(A: jax.Array, B: jax.Array) -> jax.Array:
    """Solve A X = B for a small nonsingular (n, n) A; B is (n,) or (n, k)."""
    return jnp.linalg.solve(A, B)


@solve.def_vmap
def _solve_batched(axis_size, in_batched, A, B):
    A = A if in_batched[0] else jnp.broadcast_to(A, (axis_size,) + A.shape)
    B = B if in_batched[1] else jnp.broadcast_to(B, (axis_size,) + B.shape)
    return jax.vmap(gauss_jordan)(A, B), True


def gauss_jordan(A: jax.Array, B: jax.Array, rtol: float | None = None) -> jax.Array:
    """Solve A X = B by Gauss–Jordan elimination.

    Args:
        A: (n, n) matrix.
        B: (n,) or (n, k) right-hand sides.
        rtol: None for partial (row) pivoting. A number selects complete pivoting and
            truncation: once the largest remaining pivot is below ``rtol * max|A|``, the
            remaining unknowns are set to zero (a rank-revealing, least-change solve for
            (nearly) singular A).
    Returns:
        X with the shape of B.
    """
    vec = B.ndim == 1
    B = B[:, None] if vec else B
    n = A.shape[0]
    M = jnp.concatenate([A, B.astype(A.dtype)], axis=1)
    idx = jnp.arange(n)
    floor = (0.0 if rtol is None else rtol) * jnp.max(jnp.abs(A))

    def body(k, carry):
        M, perm = carry
        left = jnp.abs(M[:, :n])
        live = idx >= k
        if rtol is None:
            i, j = jnp.argmax(jnp.where(live, left[:, k], -1.0)), k
        else:
            flat = jnp.argmax(jnp.where(live[:, None] & live[None, :], left, -1.0))
            i, j = flat // n, flat % n
        # bring the pivot to (k, k)
        rows = idx.at[k].set(i).at[i].set(k)
        M = M[rows]
        cols = jnp.concatenate([idx.at[k].set(j).at[j].set(k), jnp.arange(n, M.shape[1])])
        M = M[:, cols]
        perm = perm[idx.at[k].set(j).at[j].set(k)]
        piv = M[k, k]
        ok = jnp.abs(piv) > floor
        row = M[k] / jnp.where(ok, piv, 1.0)
        elim = M - jnp.outer(M[:, k], row)
        elim = elim.at[k].set(row)
        # a dropped pivot: this unknown is zero and takes no part in the other rows
        dropped = M.at[k].set(jnp.zeros_like(M[k]).at[k].set(1.0)).at[:, k].set(jnp.where(idx == k, 1.0, 0.0))
        return jnp.where(ok, elim, dropped), perm

    M, perm = lax.fori_loop(0, n, body, (M, idx))
    X = jnp.zeros_like(M[:, n:]).at[perm].set(M[:, n:])
    return X[:, 0] if vec else X


def inv(A: jax.Array) -> jax.Array:
    """Inverse of a small nonsingular (n, n) matrix."""
    return solve(A, jnp.eye(A.shape[0], dtype=A.dtype))
