"""Is a value a concrete array or a tracer inside ``jit``/``vmap``/``jvp``? (the base layer)."""
from __future__ import annotations

import jax


def is_concrete(x) -> bool:
    """True unless ``x`` (or any leaf of it) is a JAX tracer, i.e. eager validation can read it."""
    return not any(isinstance(v, jax.core.Tracer) for v in jax.tree.leaves(x))
