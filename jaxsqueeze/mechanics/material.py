"""Isotropic linear-elastic material of a plane-stress plate (Section II)."""
from __future__ import annotations

from dataclasses import dataclass

import jax
import numpy as np

from ..tracing import numeric


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
