"""How the library's own top-level programs are compiled (issue 11, "Compilation").

On the CPU the squeeze is dozens of small operations per loop iteration; XLA:CPU's fusion
emitters spend compile time on them that buys no run time. Without them the XLA compile of
the foam-square squeeze takes 1.9 s instead of 3.4 s, and the program runs as fast and gives
the same numbers; LLVM's optimisation level 1 instead of 2 takes another ~0.2 s off, again
at the same run time and numbers (level 0 would save 1 s but runs 2.3x slower)
(``benchmarks/compile_options.py``; ``benchmarks/README.md``, "Compilation and host work").
JAX accepts compiler options only on a
top-level ``jax.jit`` (not inside a user's ``jit``), and an option this jaxlib does not know is
an error, so :func:`jit` gives a function that

* called eagerly (no tracer among its arguments, not inside a trace), compiles with
  :func:`options` — the options of :data:`CPU_OPTIONS` this jaxlib accepts, probed once;
* called inside ``jit``, ``vmap`` or ``jvp``, is the plain ``jax.jit`` of the same function.

Nothing global is changed (DESIGN 4): no ``XLA_FLAGS``, no JAX config.
"""
from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from .tracing import is_concrete

#: options for the library's top-level programs on the CPU (applied only where accepted)
CPU_OPTIONS = {"xla_cpu_use_fusion_emitters": False, "xla_backend_optimization_level": 1}


@functools.lru_cache(maxsize=None)
def options() -> tuple:
    """The (name, value) pairs of :data:`CPU_OPTIONS` that this jaxlib accepts on the default
    backend, each probed by compiling a one-op program with it; ``()`` off the CPU."""
    if jax.default_backend() != "cpu":
        return ()
    return tuple(item for item in sorted(CPU_OPTIONS.items()) if _accepted(*item))


def _accepted(name, value) -> bool:
    try:
        jax.jit(lambda x: x + 1, compiler_options={name: value}).lower(jnp.zeros(())).compile()
    except Exception:   # noqa: BLE001  (a jaxlib without this option: compile without it)
        return False
    return True


def _top_level(args, kwargs) -> bool:
    """No tracer in the arguments and no trace around the call (inside ``jit`` even a new
    constant is a tracer)."""
    return is_concrete((args, kwargs)) and is_concrete(jnp.zeros(()))


class TopLevelJit:
    """``jax.jit(fun, **jit_kwargs)``, compiled with :func:`options` when called at the top level."""

    def __init__(self, fun, **jit_kwargs):
        self.plain = jax.jit(fun, **jit_kwargs)
        self._fun, self._kwargs, self._tuned = fun, jit_kwargs, None
        functools.update_wrapper(self, fun)

    def _top(self):
        if self._tuned is None:
            opts = options()
            self._tuned = jax.jit(self._fun, compiler_options=dict(opts), **self._kwargs) if opts else self.plain
        return self._tuned

    def __call__(self, *args, **kwargs):
        return (self._top() if _top_level(args, kwargs) else self.plain)(*args, **kwargs)

    def lower(self, *args, **kwargs):
        """Lower for a top-level compile (what an eager call compiles)."""
        return self._top().lower(*args, **kwargs)

    def _cache_size(self) -> int:
        """Compiled programs held, both variants (tests check that a call did not recompile)."""
        n = self.plain._cache_size()
        return n + (self._tuned._cache_size() if self._tuned not in (None, self.plain) else 0)


def jit(fun=None, **jit_kwargs):
    """:class:`TopLevelJit` of ``fun``; usable as ``@jit`` or ``@jit(static_argnames=...)``."""
    if fun is None:
        return functools.partial(jit, **jit_kwargs)
    return TopLevelJit(fun, **jit_kwargs)


__all__ = ["CPU_OPTIONS", "TopLevelJit", "jit", "options"]
