"""Isotropic linear-elastic material of a plane-stress plate (Section II)."""
from __future__ import annotations

from dataclasses import dataclass

import jax
import numpy as np

from ..numbers import kind
from ..tracing import is_concrete, numeric


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Material:
    """Young's modulus ``E`` [Pa], Poisson's ratio ``nu`` [-] and plate ``thickness`` [m].

    Plane stress requires ``E > 0``, ``-1 < nu <= 0.5`` and ``thickness > 0``.
    Every field is an array leaf, so a ``Material`` can be traced, differentiated and vmapped.
    Validation runs whenever the values are concrete (not inside ``jit``).
    """

    E: float
    nu: float
    thickness: float

    def __post_init__(self):
        checks = (
            ("E", self.E, lambda v: v > 0, "Young's modulus E must be > 0 Pa"),
            ("nu", self.nu, lambda v: (v > -1.0) & (v <= 0.5), "Poisson's ratio nu must satisfy -1 < nu <= 0.5"),
            ("thickness", self.thickness, lambda v: v > 0, "thickness must be > 0 m"),
        )
        for name, value, ok, what in checks:
            if not numeric(value):
                continue
            v = np.asarray(value, dtype=float)
            if not np.all(np.isfinite(v)):
                raise ValueError(f"Material.{name}={value!r} is not finite; {what}.")
            if not np.all(ok(v)):
                raise ValueError(f"Material.{name}={value!r} is out of range; {what}.")


_UNITS = {"E": "Pa", "nu": "-", "thickness": "m"}


def checked(material: Material) -> Material:
    """``material`` when each of E, ν and the thickness is one real number (or a tracer);
    else ``ValueError`` naming the field. A ``Material`` holds anything (JAX rebuilds it with
    placeholders, masks and axis specs), so the functions that compute with one check it:
    a cast would read "1e5" as 1e5 Pa and True as 1 Pa, and drop an imaginary part."""
    if not isinstance(material, Material):
        raise TypeError(f"expected a jsq.Material(E, nu, thickness), got {type(material).__name__}")
    for name, unit in _UNITS.items():
        v = getattr(material, name)
        if not is_concrete(v):
            continue
        if v is None or isinstance(v, (str, bytes, bool, np.bool_)) or kind(v) not in "iuf":
            raise ValueError(f"Material.{name} = {v!r:.80}: expected one real number [{unit}]")
        if np.ndim(v):
            raise ValueError(f"Material.{name} has shape {np.shape(v)}: one material takes one number; for many "
                             "values use jax.vmap")
    return material

