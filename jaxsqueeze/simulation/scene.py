"""A squeeze scene: object, material, fingers, grip, friction, depth and effects (DESIGN 2.5, 2.7)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import jax
import numpy as np

from ..mechanics.material import Material
from ..tracing import is_concrete
from .laws import CONTACT_MODELS, FRICTION_MODELS
from ..geometry.mesh import Mesh
from ..mechanics.operator import Compliance



@dataclass(frozen=True)
class Fingers:
    """Two identical round fingertips of radius ``radius`` [m] (Section IV).

    Finger 1 touches grip node ``grip[0]`` and stays still; finger 2 touches ``grip[1]`` and
    translates by the squeeze depth d toward finger 1 along p_i − p_j. Each centre lies on
    the outward normal at its node, one radius away.

    rotation: optional fingertip rotation schedules α1(d), α2(d) [rad] (Section IV-D), as
        polynomial coefficients in d [m], highest power first (``numpy.polyval`` order),
        shape (2, k). Fingertips rotate about their own centres. ``None`` compiles no
        rotation code at all.
    """

    radius: Any
    rotation: Any = None

    def __post_init__(self):
        if is_concrete(self.radius):
            r = np.asarray(self.radius, float)
            if not (np.all(np.isfinite(r)) and np.all(r > 0)):
                raise ValueError(f"Fingers.radius={self.radius!r} must be a finite length > 0 m.")
        if self.rotation is not None and is_concrete(self.rotation):
            rot = np.asarray(self.rotation, float)
            if rot.ndim != 2 or rot.shape[0] != 2 or not np.all(np.isfinite(rot)):
                raise ValueError("Fingers.rotation must be finite polynomial coefficients of shape (2, k): "
                                 f"one row per finger, highest power first; got shape {rot.shape}.")


@dataclass(frozen=True)
class Settings:
    """Accuracy and capacity settings of a squeeze. Each is an explicit knob (DESIGN 2.8).

    step: squeeze step [m]; default ``depth / 50``.
    event_tol: width [m] to which an event's depth is bracketed before the final
        implicit-function refinement; default ``step * 1e-4``.
    newton_tol: slip-angle Newton tolerance on the update [rad]; default 1e-11 in float64,
        1e-5 in float32.
    gap_tol: penetration [m] a free node may reach before event A fires; default
        ``1e-9 * L`` (float64) or ``1e-5 * L`` (float32), with L the object length.
    capacity: number of contact slots (static). Contact nodes beyond it give ``Status.OVERFLOW``.
    max_steps: bound on loop iterations (steps plus event resolutions), static.
    max_events: capacity of the event log, static.
    newton_iters: Newton iteration bound, static.
    bisect_iters: iteration bound for locating an event (regula falsi + bisection), static.
    """

    step: float | None = None
    event_tol: float | None = None
    newton_tol: float | None = None
    gap_tol: float | None = None
    capacity: int = 64
    max_steps: int = 400
    max_events: int = 256
    newton_iters: int = 30
    bisect_iters: int = 40


@dataclass(frozen=True, eq=False)
class Scene:
    """Everything that defines one squeeze.

    Args:
        mesh: the object: a :class:`~jaxsqueeze.mesh.Mesh` (solid) or a
            :class:`~jaxsqueeze.band.Band` (ring-like object).
        material: :class:`~jaxsqueeze.material.Material`.
        fingers: :class:`Fingers`.
        grip: (i, j) mesh node indices on the boundary touched by finger 1 and finger 2.
        friction: Coulomb coefficient μ ≥ 0.
        depth: target squeeze depth d [m] > 0.
        friction_model: "coulomb" (stick/slip, events A–D), "frictionless" (every contact
            slides, no C/D events) or "stick" (full stick: no Newton solve, no slip events).
        contact: "segment" (contact regions grow: event A) or "point" (one contact per
            finger, no event A; for ring-like objects, Section V-A).
        method: compliance build ("sparse", "dense", "spectral"); ignored for bands.
        settings: :class:`Settings`.
    """

    mesh: Any
    material: Material
    fingers: Fingers
    grip: Any
    friction: Any = 0.5
    depth: Any = 0.01
    friction_model: str = "coulomb"
    contact: str = "segment"
    method: str = "sparse"
    settings: Settings = field(default_factory=Settings)

    def replace(self, **changes) -> "Scene":
        """A copy with some fields changed (the compliance cache is shared)."""
        return dataclasses.replace(self, **changes)

    def __post_init__(self):
        if self.friction_model not in FRICTION_MODELS:
            raise ValueError(f"friction_model={self.friction_model!r}; choose one of {FRICTION_MODELS}.")
        if self.contact not in CONTACT_MODELS:
            raise ValueError(f"contact={self.contact!r}; choose one of {CONTACT_MODELS}.")
        if is_concrete(self.friction):
            mu = np.asarray(self.friction, float)
            if not np.all(np.isfinite(mu)) or np.any(mu < 0):
                raise ValueError(f"friction={self.friction!r} must be a finite coefficient mu >= 0.")
        if is_concrete(self.depth):
            d = np.asarray(self.depth, float)
            if not np.all(np.isfinite(d)) or np.any(d <= 0):
                raise ValueError(f"depth={self.depth!r} must be a finite squeeze depth > 0 m.")
        if is_concrete(self.grip):
            g = np.asarray(self.grip)
            if g.shape[-1:] != (2,) or not np.issubdtype(g.dtype, np.integer):
                raise ValueError(f"grip={self.grip!r} must be two integer boundary node indices (i, j).")
            if g.ndim == 1:
                if g[0] == g[1]:
                    raise ValueError(f"grip={self.grip!r} names node {g[0]} twice; the fingers need two different nodes.")
                on = set(np.asarray(self.boundary_nodes()).tolist())
                bad = [int(v) for v in g if int(v) not in on]
                if bad:
                    raise ValueError(f"grip node(s) {bad} are not on the boundary; pick nodes from "
                                     "mesh.boundary (or use Scene.nearest_boundary_node).")
        s = self.settings
        for name in ("capacity", "max_steps", "max_events", "newton_iters", "bisect_iters"):
            v = getattr(s, name)
            if not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"Settings.{name}={v!r} must be a positive integer.")
        if s.capacity < 2:
            raise ValueError("Settings.capacity must be at least 2 (one contact per finger).")
        for name in ("step", "event_tol", "newton_tol", "gap_tol"):
            v = getattr(s, name)
            if v is not None and is_concrete(v) and not (np.isfinite(v) and v > 0):
                raise ValueError(f"Settings.{name}={v!r} must be a finite value > 0 (or None for the default).")

    # ------------------------------------------------------------------ object helpers
    def boundary_nodes(self) -> np.ndarray:
        """(m,) node indices that can touch a finger (``arange(m)`` for a band)."""
        if isinstance(self.mesh, Mesh):
            return np.asarray(self.mesh.boundary)
        return np.arange(self.mesh.m)

    def nearest_boundary_node(self, xy) -> int:
        """Boundary node nearest to the point ``xy`` (2,) given in the user's frame [m]."""
        return nearest_boundary_node(self.mesh, xy)

    def operator(self) -> Compliance:
        """The compliance operator of the object, built once and cached per (object, nu, method)."""
        return compliance_of(self.mesh, self.material, self.method)


_CACHE: dict = {}


def compliance_of(obj, material: Material, method: str = "sparse") -> Compliance:
    """Cached compliance operator of a mesh or band (E and thickness only rescale it).

    A band (:class:`~jaxsqueeze.band.Band`) is built once per band object: its scaled
    compliance ``E h T K^+ T^T`` does not depend on E (nor on nu, which a band does not
    have), so ``method`` and ``material.nu`` are ignored and the stiffness scale is
    ``material.E * band.height``. The band's out-of-plane extent is ``band.height``;
    ``material.thickness`` must equal it (raises ``ValueError`` otherwise, rather than
    silently using one of two different values).
    """
    from ..mechanics.fem import compliance

    solid = isinstance(obj, Mesh)
    if not solid:
        from ..mechanics.band import Band

        if not isinstance(obj, Band):
            raise TypeError(f"Scene.mesh must be a jaxsqueeze Mesh or Band, got {type(obj).__name__}")
        if is_concrete(material.thickness) and not np.allclose(np.asarray(material.thickness, float), obj.height,
                                                             rtol=1e-9, atol=0.0):
            raise ValueError(f"Material.thickness={material.thickness!r} differs from the band height "
                             f"{obj.height!r} m; for a band both are its out-of-plane extent h "
                             "(use Material(E, nu, thickness=band.height)).")
    key = (id(obj), float(material.nu) if solid else None, method if solid else "band")
    hit = _CACHE.get(key)
    if hit is None or hit[0] is not obj:
        if solid:
            op = compliance(obj, material, method)
        else:
            from ..mechanics.band import band_compliance
            op = band_compliance(obj, 1.0)      # scaled G is independent of E
        _CACHE[key] = hit = (obj, op)
    op = hit[1]
    h = material.thickness if solid else obj.height
    return dataclasses.replace(op, stiffness=jax.numpy.asarray(material.E * h, op.G.dtype))


def nearest_boundary_node(obj, xy) -> int:
    """Boundary node of a mesh or band nearest to ``xy`` (2,) in the caller's frame [m]
    (``points + offset``; both :class:`Mesh` and :class:`~jaxsqueeze.band.Band` keep the node
    centroid at the origin and the caller's frame in ``offset``)."""
    xy = np.asarray(xy, float)
    if isinstance(obj, Mesh):
        pts, nodes = obj.points[obj.boundary] + obj.offset, np.asarray(obj.boundary)
    else:
        pts, nodes = obj.points + obj.offset, np.arange(obj.m)
    return int(nodes[np.argmin(np.linalg.norm(pts - xy, axis=1))])
