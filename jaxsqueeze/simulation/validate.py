"""Placeholder of the validation layer (replaced by the full one)."""
from __future__ import annotations

import jax.numpy as jnp

FIELDS = ("grip",)


def invalid_index(values: dict):
    g = values.get("grip_slots")
    if g is None:
        return jnp.array(-1, jnp.int32)
    bad = jnp.any(g < 0) | (g[0] == g[1])
    return jnp.where(bad, 0, -1).astype(jnp.int32)


def problems(values: dict) -> list[str]:
    return []


def raise_if_invalid(values: dict) -> None:
    return None
