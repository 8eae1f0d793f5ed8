"""Functions that a ``vmap`` on the CPU runs one member at a time, at every order of forward
differentiation (the base layer).

Why: jaxlib's CPU LAPACK kernels and a batched ``lax.while_loop`` both go badly under
``vmap``. A batched LAPACK call (Cholesky, triangular solve, LU) parallelises over its batch
on XLA's intra-op thread pool, and two of them running at once can each hold a pool thread
while waiting for another: on a 2-core machine a ``jax.vmap`` of a ``jax.jacfwd`` of the
dense compliance build in ``nu`` (its primal and tangent solves) waited forever. A batched
squeeze loop runs every member's event location at every step (10–20× slower per grasp).
:func:`one_at_a_time` gives the same function with a batching rule that runs the members
with ``lax.map`` on the CPU (the plain ``vmap`` on an accelerator), and a derivative rule
whose ``jvp`` is batched the same way, so that ``vmap(jacfwd(f))``, ``jacfwd(vmap(f))`` and
``vmap(f)`` all run the members one after another and equal a loop over them.
"""
from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jax.custom_batching import custom_vmap
from jax.custom_derivatives import SymbolicZero

from .compiler import platform
from .tracing import floating


def one_at_a_time(fn: Callable) -> Callable:
    """``fn`` (flat arrays → pytree of arrays) with the batching rule above. Its derivative is
    its own rule (:func:`_jvp_of`): the ``jvp`` of ``fn`` in the inputs that carry a tangent
    (``custom_vmap``'s own rule would give every input a tangent of zeros, and derive ``fn``
    once more before the batching rule replaces it), batched by the same rule. The arguments
    are a flat list of arrays: ``custom_vmap`` cannot take a pytree with an empty (None) node."""
    run = jax.custom_jvp(_members(fn))
    run.defjvp(_jvp_of(fn), symbolic_zeros=True)
    return run


def _members(fn, primals: int | None = None):
    """``fn`` with the batching rule. ``primals``: for ``fn(*primals, *tangents)``, how many
    arguments are primals; a batch of tangents alone (``jax.jacfwd``) is then vmapped: one
    member, its tangents batched."""
    @custom_vmap
    def run(*xs):
        return fn(*xs)

    @run.def_vmap
    def rule(axis_size, flags, *xs):
        every = lambda out, b: jax.tree.map(lambda _: b, out)  # noqa: E731
        if not any(flags):
            out = fn(*xs)
            return out, every(out, False)
        if primals is not None and not any(flags[:primals]):
            # one member with its tangents batched; a batch of members around it (a vmap of
            # jacfwd) comes back through this rule
            tangents = jax.vmap(fn, in_axes=[0 if f else None for f in flags], out_axes=(None, 0))
            out = _members(tangents)(*xs)
            return out, (every(out[0], False), every(out[1], True))
        if platform() != "cpu":
            full = [x if f else jnp.broadcast_to(x, (axis_size,) + jnp.shape(x)) for x, f in zip(xs, flags)]
            out = jax.vmap(fn)(*full)
            return out, every(out, True)

        def one(batched):
            it = iter(batched)
            return fn(*[next(it) if f else x for x, f in zip(xs, flags)])

        out = lax.map(one, [x for x, f in zip(xs, flags) if f])
        return out, every(out, True)

    return run


def _jvp_of(fn):
    """The ``custom_jvp`` rule (with symbolic zeros) of ``fn``: the ``jvp`` in the arguments
    whose tangent is not a symbolic zero, batched by :func:`_members`; integer outputs get
    ``float0`` tangents (outside the batching rule: ``lax.map`` cannot carry ``float0``, so a
    placeholder passes through it)."""
    def rule(primals, tangents):
        moving = [not isinstance(t, SymbolicZero) for t in tangents]

        def jvp(*xs):
            ps, ts = xs[:len(primals)], xs[len(primals):]

            def of_moving(*ys):
                it = iter(ys)
                return fn(*[next(it) if m else p for p, m in zip(ps, moving)])

            out, dout = jax.jvp(of_moving, tuple(p for p, m in zip(ps, moving) if m), ts)
            return out, jax.tree.map(lambda o, t: t if floating(o) else jnp.zeros((), jnp.int8), out, dout)

        out, dout = _members(jvp, len(primals))(*primals, *(t for t, m in zip(tangents, moving) if m))
        return out, jax.tree.map(lambda o, t: t if floating(o) else np.zeros(jnp.shape(o), jax.dtypes.float0), out, dout)

    return rule
