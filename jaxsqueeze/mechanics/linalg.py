"""Small dense solves for the squeeze loop that stay safe under ``vmap``.

Why: jaxlib's CPU LAPACK kernels parallelise over a ``vmap`` batch on XLA's intra-op thread
pool. Called from inside a ``lax.while_loop`` that already runs on that pool, the batched
LU waits on itself: on a 2-core machine ``jax.vmap`` of a squeeze over three grasps
deadlocked (``jax::ParallelBatchMap`` in ``LuDecomposition`` blocked forever). The functions
here are ``custom_vmap``: a batch is solved one system at a time with ``lax.map``, so LAPACK
never sees a batch dimension, and a batched result equals the loop of single solves.
They stay forward-mode differentiable.

Inside a one-kernel region (:func:`jaxsqueeze.compiler.one_kernel`), which cannot call
LAPACK, they eliminate in plain JAX operations instead (:func:`gauss_jordan`).
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax
from jax.custom_batching import custom_vmap

from ..compiler import in_kernel, platform


def gauss_jordan(A: jax.Array, B: jax.Array) -> jax.Array:
    """Solve A X = B, (n, n) and (n,) or (n, k), by Gauss–Jordan elimination with partial
    pivoting: n steps of a ``fori_loop`` of plain JAX operations (no LAPACK call). A singular
    A gives non-finite values, as LAPACK's solve does."""
    n = A.shape[0]
    M = jnp.concatenate([A, B[:, None] if B.ndim == 1 else B], axis=1)
    rows = jnp.arange(n)

    def eliminate(k, M):
        p = jnp.argmax(jnp.where(rows >= k, jnp.abs(M[:, k]), -1.0))
        Mk, Mp = M[k], M[p]
        M = lax.dynamic_update_index_in_dim(M, Mk, p, 0)
        pivot = Mp / Mp[k]
        M = M - jnp.where(rows == k, 0.0, M[:, k])[:, None] * pivot[None, :]
        return lax.dynamic_update_index_in_dim(M, pivot, k, 0)

    X = lax.fori_loop(0, n, eliminate, M)[:, n:]
    return X[:, 0] if B.ndim == 1 else X


def _dense_solve(A, B):
    return gauss_jordan(A, B) if in_kernel() else jnp.linalg.solve(A, B)


def _one_at_a_time(plain):
    """Batch rule: one system at a time on the CPU, the batched kernel elsewhere (GPU solvers
    have no such deadlock). The loop body is the plain function, not the custom_vmap one: a
    forward-mode tangent batched by ``jax.jacfwd`` then batches only right-hand sides (no
    batched LU) instead of re-entering this rule forever."""
    def rule(axis_size, in_batched, A, B):
        if not any(in_batched):       # only tangents are batched (jax.jacfwd): one system
            return plain(A, B), False
        A = A if in_batched[0] else jnp.broadcast_to(A, (axis_size,) + A.shape)
        B = B if in_batched[1] else jnp.broadcast_to(B, (axis_size,) + B.shape)
        if platform() == "cpu":
            return lax.map(lambda ab: plain(*ab), (A, B)), True
        return jax.vmap(plain)(A, B), True
    return rule


@custom_vmap
def solve(A: jax.Array, B: jax.Array) -> jax.Array:
    """Solve A X = B for a small nonsingular (n, n) A; B is (n,) or (n, k)."""
    return _dense_solve(A, B)


solve.def_vmap(_one_at_a_time(_dense_solve))


def inv(A: jax.Array) -> jax.Array:
    """Inverse of a small nonsingular (n, n) matrix."""
    return solve(A, jnp.eye(A.shape[0], dtype=A.dtype))
