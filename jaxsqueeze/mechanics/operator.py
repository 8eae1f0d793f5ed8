"""The compliance operator: what the squeeze engine sees of an object (DESIGN 2.2).

A solid triangle mesh (:func:`jaxsqueeze.fem.compliance`) and a curved band
(:mod:`jaxsqueeze.band`) both provide one. The engine only reads the compliance block at
contact-capable nodes, the rigid-mode rows there, and the geometry of those nodes.

Internal units (DESIGN 2.3): lengths are divided by ``length`` (L) and forces by
``stiffness * length`` (E h L), so ``G`` is dimensionless and O(1).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from ..compiler import precise
from ..tracing import as_array, is_concrete


class FieldMap:
    """Displacement of every node of the object under forces at the contact-capable nodes.

    ``solve(f_hat)`` maps scaled forces ``(2m,)`` (interleaved x, y) to the scaled compliance
    part of the displacement of all ``n`` nodes ``(2n,)``; ``points`` ``(n, 2)`` are the scaled
    positions of all nodes, from which the rigid modes follow (see :func:`rigid_modes`).
    It runs outside JAX (numpy/scipy) and is reached from traced code through a callback.
    Hashes by identity, so it can sit in a pytree's static part.
    """

    def __init__(self, solve: Callable[[np.ndarray], np.ndarray], points: np.ndarray):
        self.solve = solve
        self.points = np.asarray(points, dtype=np.float64)
        self.n = self.points.shape[0]


def rigid_modes(points, xp=jnp):
    """Rigid-mode rows (2k, 3) at positions ``points`` (k, 2), DOFs interleaved (``xp``: numpy
    for concrete points outside JAX).

    Columns: unit x translation, unit y translation, and small rotation about the origin
    (the node centroid), so ``g`` reads (t_x, t_y, angle) in the units of ``points``.
    Unnormalized on purpose: entries stay O(1) in scaled units however many nodes there are,
    which keeps the bordered matrix of eq. (4) well conditioned (DESIGN 2.3).
    """
    points = xp.asarray(points)
    k = points.shape[0]
    one, zero = xp.ones(k, points.dtype), xp.zeros(k, points.dtype)
    rows_x = xp.stack([one, zero, -points[:, 1]], axis=1)
    rows_y = xp.stack([zero, one, points[:, 0]], axis=1)
    return xp.stack([rows_x, rows_y], axis=1).reshape(2 * k, 3)


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Compliance:
    """Boundary compliance operator in scaled units.

    Attributes:
        points: (m, 2) contact-capable node positions divided by ``length`` (centroid frame).
        normals: (m, 2) outward unit normals at those nodes.
        G: (2m, 2m) scaled compliance, DOFs interleaved x0, y0, x1, y1, ... Exact on
            self-equilibrated forces: u_hat = G f_hat + N g for some rigid g.
        N: (2m, 3) rigid-mode rows at those nodes, ``rigid_modes(points)``: x translation,
            y translation, rotation about the node centroid (scaled, unnormalized).
        length: () object length L [m].
        stiffness: () E * thickness [N/m]; forces scale as ``stiffness * length`` [N].
        nodes: (m,) int, index of each contact-capable node among the object's nodes.
        nu: () Poisson's ratio the solid's G was built for (None for a band, which has none).
        method: static, name of the build ("spectral", "dense", "sparse", "band").
        loops: static, lengths of the boundary loops (outer first), summing to m.
        field: static, a :class:`FieldMap` for displacements of all nodes, or None.
    """

    points: jax.Array
    normals: jax.Array
    G: jax.Array
    N: jax.Array
    length: jax.Array
    stiffness: jax.Array
    nodes: jax.Array
    nu: jax.Array | None = None
    method: str = field(metadata=dict(static=True), default="dense")
    loops: tuple = field(metadata=dict(static=True), default=())
    field: FieldMap | None = field(metadata=dict(static=True), default=None, compare=False)

    def __repr__(self) -> str:
        try:
            L = self.length
            size = f"L = {float(L):.4g} m" if is_concrete(L) and np.ndim(L) == 0 else f"L of shape {np.shape(L)}"
            return (f"Compliance({self.method} build, {self.m} boundary nodes, {size}, {jnp.result_type(self.G)}"
                    f"{', field map' if self.field is not None else ''})")
        except Exception:  # noqa: BLE001  (a repr must not raise, whatever JAX's tree code put in the fields)
            return f"Compliance({self.method} build)"

    @property
    def m(self) -> int:
        return self.points.shape[0]

    @property
    def force_scale(self):
        """Force unit [N] of the scaled system: E h L."""
        return self.stiffness * self.length


def _field_solve_host(fmap: FieldMap, f_hat):
    f = np.asarray(f_hat, dtype=np.float64)
    if f.ndim == 1:
        return fmap.solve(f)
    return np.stack([fmap.solve(fi) for fi in f.reshape(-1, f.shape[-1])]).reshape(f.shape[:-1] + (2 * fmap.n,))


def field_displacement(op: Compliance, f_hat: jax.Array, g: jax.Array) -> jax.Array:
    """Scaled displacement (n, 2) of every node under scaled contact forces.

    Args:
        op: the operator; ``op.field`` must not be None.
        f_hat: (2m,) scaled forces at the contact-capable nodes (interleaved).
        g: (3,) rigid-mode amplitudes from the bordered solve.
    Linear in ``f_hat`` and ``g``; forward-mode differentiable; works under jit and vmap.
    """
    if op.field is None:
        raise ValueError("this compliance operator carries no field map; rebuild it with the default options")
    if is_concrete((f_hat, g)) and np.ndim(f_hat) == 1:   # eager: the host solve (a callback compiles per call)
        return as_array(field_on_host(op, f_hat, g), jnp.result_type(f_hat))
    return _field(op.field, f_hat, g)


def field_on_host(op: Compliance, f_hat, g) -> np.ndarray:
    """:func:`field_displacement` of one concrete solve as a numpy array (n, 2) of the forces'
    precision, for callers that want it on the host (an eager squeeze's trimmed result)."""
    fmap = op.field
    u = fmap.solve(np.asarray(f_hat, np.float64)) + rigid_modes(fmap.points, xp=np) @ np.asarray(g, np.float64)
    return u.reshape(-1, 2).astype(np.dtype(jnp.result_type(f_hat)), copy=False)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _field_linear(fmap, f_hat):
    dt = f_hat.dtype        # (the callback, kept in the program, must not hold the tracer f_hat)
    shape = jax.ShapeDtypeStruct(f_hat.shape[:-1] + (2 * fmap.n,), dt)
    return jax.pure_callback(lambda f: _field_solve_host(fmap, f).astype(dt), shape, f_hat, vmap_method="expand_dims")


@_field_linear.defjvp
def _field_linear_jvp(fmap, primals, tangents):
    (f_hat,), (df,) = primals, tangents
    return _field_linear(fmap, f_hat), _field_linear(fmap, df)


@functools.partial(jax.jit, static_argnums=0)     # one program, not ~15 small ones, under eager jacfwd/vmap
@precise
def _field(fmap: FieldMap, f_hat, g):
    u = _field_linear(fmap, f_hat) + rigid_modes(jnp.asarray(fmap.points, f_hat.dtype)) @ g
    return u.reshape(-1, 2)
