"""Is a value a concrete array or a tracer inside ``jit``/``vmap``/``jvp``? Which frame is the
user's (for a warning's ``stacklevel``)? And the library's own host ↔ device transfers, allowed
under a caller's ``jax.transfer_guard``. (the base layer)"""
from __future__ import annotations

import functools
import sys

import jax
import numpy as np


def is_concrete(x) -> bool:
    """True unless ``x`` (or any leaf of it) is a JAX tracer, i.e. eager validation can read it."""
    return not any(isinstance(v, jax.core.Tracer) for v in jax.tree.leaves(x))


def staged() -> bool:
    """True inside a staging trace (``jax.jit``, ``lax.cond`` branches, ...), where even a
    computation on concrete values gives a tracer: an eager path that reads the values it
    computes cannot run there, although every input is concrete."""
    return isinstance(jax.numpy.zeros(()), jax.core.Tracer)


def own_transfers(fun):
    """``fun`` with the host ↔ device transfers it makes allowed under a caller's
    ``jax.transfer_guard``: an eager call takes host numbers (a scene's floats, a mesh's
    numpy arrays) into compiled programs and returns host arrays, by design. The guard keeps
    watching the caller's own code."""
    @functools.wraps(fun)
    def allowed(*args, **kwargs):
        with jax.transfer_guard("allow"):
            return fun(*args, **kwargs)
    return allowed


def caller_level() -> int:
    """The ``stacklevel`` for ``warnings.warn`` called here that names the first frame outside
    the jaxsqueeze package: the user's line that asked for what the warning is about."""
    f, level = sys._getframe(1), 1
    while f is not None and f.f_globals.get("__name__", "").partition(".")[0] == __name__.partition(".")[0]:
        f, level = f.f_back, level + 1
    return level


def as_array(x, dtype=None) -> jax.Array:
    """``x`` as a JAX array of ``dtype`` (default: its own, canonicalized: 64-bit types become
    32-bit ones unless x64 is on). A host value (Python number, numpy array) is transferred as
    it is: ``jnp.asarray`` of one compiles a small program per shape and dtype, which a first
    squeeze paid about a dozen times. A tracer is converted in its trace."""
    if is_concrete(x) and not isinstance(x, jax.Array):
        a = np.asarray(x, dtype)
        return jax.device_put(a.astype(jax.dtypes.canonicalize_dtype(a.dtype), copy=False))
    return jax.numpy.asarray(x, dtype)


def _any_tracer(x, test) -> bool:
    """True if ``test(tracer)`` holds for a tracer of any leaf of ``x`` or one it wraps (a
    ``vmap``/``jit`` tracer's ``val``, a JVP tracer's ``primal``), up to 8 levels deep."""
    def walk(t, depth=0) -> bool:
        if not isinstance(t, jax.core.Tracer) or depth > 8:
            return False
        return test(t) or any(walk(getattr(t, a, None), depth + 1) for a in ("val", "primal"))
    return any(walk(v) for v in jax.tree.leaves(x))


def reverse_mode(x) -> bool:
    """True if any leaf of ``x`` is being differentiated in reverse mode (``jax.grad``,
    ``jax.vjp``, ``jax.jacrev``, ``jax.linearize``), also through ``vmap``/``jit`` tracers
    around it. Read from the tracers' class names (``LinearizeTracer``; a ``JVPTracer`` whose
    tangent is being staged out in older JAX), so a JAX that renames them only loses the
    clearer error, never a result."""
    def rev(t) -> bool:
        name = type(t).__name__
        return name == "LinearizeTracer" or (
            name == "JVPTracer" and type(getattr(t, "tangent", None)).__name__ == "JaxprTracer")
    return _any_tracer(x, rev)


def differentiated(x) -> bool:
    """True if any leaf of ``x`` carries a forward-mode tangent (``jax.jvp``, ``jax.jacfwd``),
    also through ``vmap``/``jit`` tracers around it (read from the tracers' class names, as
    :func:`reverse_mode`)."""
    return _any_tracer(x, lambda t: type(t).__name__ == "JVPTracer")


def forward_levels(x) -> int:
    """How many forward-mode differentiations (``jax.jvp``/``jax.jacfwd`` traces) the leaves of
    ``x`` carry tangents of, through ``vmap``/``jit`` tracers around them: 2 or more is a
    second derivative (read from the tracers' class names, as :func:`reverse_mode`; a JAX
    whose tracers do not name their trace counts 0, and the squeeze's own derivative rule
    still refuses a second derivative)."""
    traces = set()

    def count(t) -> bool:
        trace = getattr(t, "_trace", None)
        level = getattr(trace, "tag", None) or getattr(trace, "main", None)     # (JAX >= 0.4.36; older)
        if type(t).__name__ == "JVPTracer" and level is not None:
            traces.add(id(level))
        return False                  # walk every leaf and everything it wraps
    _any_tracer(x, count)
    return len(traces)


def numeric(x) -> bool:
    """True for a concrete number or array of numbers (what eager validation can check).

    False for tracers and for the placeholders JAX puts in pytree fields while it rebuilds
    a dataclass (``None``, ``object()``), so ``__post_init__`` checks skip those.
    """
    if x is None or not is_concrete(x):
        return False
    try:
        return np.asarray(x).dtype.kind in "biuf"
    except Exception:      # noqa: BLE001  (anything that is not array-like is not a number)
        return False
