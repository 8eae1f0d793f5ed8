"""Curved elastic bands (Section V-A): ring-like objects such as trimmed cookie cutters.

A band is swept by a rectangular cross-section along a closed counterclockwise curve
gamma(s) (arc length s, perimeter P). Its displacement is delta(s) = alpha(s) t + beta(s) n.

Conventions (stated because the paper's formulas depend on them):
    t = dgamma/ds, n = (t_y, -t_x) the OUTWARD normal (the right normal of a CCW curve),
    kappa > 0 where the curve turns left (convex parts of a CCW outline; 1/R on a circle),
    so that dt/ds = -kappa n and dn/ds = kappa t. Then
        extension        eps  = t . delta' = dalpha/ds + kappa beta,
        rotation         phi  = (z x t) . delta' = kappa alpha - dbeta/ds   (counterclockwise),
        curvature change zeta = dphi/ds = -d2beta/ds2 + dkappa/ds alpha + kappa dalpha/ds.
    The paper writes eps = alpha' - kappa beta and zeta = -beta'' - kappa' alpha - kappa alpha'
    with the Frenet (inward) normal; with beta_paper = -beta these are our eps and -zeta, so
    the energy is the same. Rigid motions give eps = zeta = 0 exactly: a translation has
    delta' = 0; a rotation omega has delta' = omega z x t, so eps = 0 and phi = omega.

Strain energy U = 1/2 E int (A eps^2 + I zeta^2) ds with A = w h and I = h w^3 / 12, where
    w = ``width``: the wall thickness IN the plane of the curve (the bending dimension), and
    h = ``height``: the band's extent OUT of the plane (the paper's "thickness" h = 5 mm,
    and the thickness in the operator's force scale E h L).
    The paper prints U = 1/2 E w int (h eps^2 + h^3/12 zeta^2) ds, i.e. it cubes the
    dimension it calls h. For bending in the plane of the curve the cubed dimension must be
    the one lying in that plane: the wall thickness. A cookie cutter is a thin sheet
    (about 0.4-0.5 mm) standing several mm tall, so we cube ``width`` (default 0.5 mm) and
    keep ``height`` (default 5 mm, the paper's value) linear; this is the paper's formula
    with its w and h exchanged. The literal reading (a 5 mm wall in the plane, 5^3 times
    stiffer in bending per unit height) is ``width=5e-3`` with ``height`` the other size
    (it warns on the heart: a 5 mm wall is thicker than the 2.2 mm radius at its cusps).
    A wall at least half as thick as the band is wide is refused (a length in mm, most
    likely); one thicker than the tightest radius of curvature warns.

Discretization (isoparametric, Cartesian): the geometry is a periodic cubic spline through
the m nodes (scipy ``CubicSpline``, ``bc_type='periodic'``), parametrized by arc length
(chord length, then twice by the spline's own arc length, so J = |dgamma/du| ~ 1); one
element per spline piece. The displacement is cubic Hermite (C1) in the same parameter u,
in Cartesian components: DOFs per node (delta_x, delta_y, ddelta_x/ds, ddelta_y/ds)
(ndof = 4 m, node k at 4k..4k+3). Strains use the exact spline geometry at 5 Gauss points
per element: eps = gamma_u . delta_u / J^2, phi = (gamma_u x delta_u) / J^2,
zeta = phi_u / J. Membrane locking: the membrane strain enters the energy through its L2
projection onto linear functions of u on each element (:data:`LINEAR`; an assumed strain,
equivalent to integrating the membrane term at 2 Gauss points where J is constant). With the
full quadratic-and-up strain a curved element cannot bend without stretching, and EA / EI
= 12 / w^2 makes that stretching dominate when the wall is much thinner than an element is
long: a 1 m ring of 32 nodes with a 10 um wall was 62 % too stiff, and the 8 cm heart of 128
nodes 1.1 % at 10 um and 17 % at 0.1 um. Projected, the ring is within 1e-5 of the closed
form at every wall from 0.1 m to 10 um and the heart within 1e-4. On a straight element the
axial block is then EA/l (u2 - u1)^2 + EA l / 12 (theta1 - theta2)^2 (a constant force is
exact), and the rigid motions still have zero strain.

Why Cartesian rather than (alpha, beta) Hermite: a rigid rotation z x (gamma - c) is itself a
cubic in u on each element, so all three rigid motions lie in the element space EXACTLY and
have zero energy to round-off (no projection needed, no dkappa/ds from spline third
derivatives), and the inextensible bending modes are approximated far better: an
(alpha, beta)-Hermite version of this element was 3x too stiff for the heart at m = 128
(membrane locking where the curvature varies fast); this one, with the projected membrane
strain, has the heart's pinch compliance within 2e-4 of m = 512 at m = 64 (2e-3 without the
projection). beta needs C1 (zeta holds beta''); Cartesian C1 with the C2 spline gives C1
alpha and beta. The node xy displacement is read off directly (``Band.to_xy``);
alpha = t . delta and beta = n . delta at the nodes.

Geometry error enters through the spline through the nodes (O(l^4) in position, O(l^2) in
curvature, element length l), so :meth:`Band.from_function` only chooses the nodes: m points
equally spaced in arc length on the exact curve. :func:`band_stiffness` removes the
round-off-level rigid-mode residue (orthogonal projection), so its null space is exactly
:meth:`Band.rigid_dofs`.

The operator (:func:`band_compliance`, method "band") uses all m nodes as contact-capable
nodes: G = E h T K^+ T^T in the scaled units of DESIGN 2.3 (lengths / L, forces / (E h L)),
L = the larger bounding-box side of the nodes. A thin band is compliant, so G is large
(entries of a few 1e5 for an 8 cm cookie cutter with a 0.5 mm wall); it scales as (L/w)^3.
"""
from __future__ import annotations

import dataclasses
import os
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.interpolate import CubicSpline

from ..geometry.boundary import crossing
from ..geometry.curves import arclength_params
from ..geometry.mesh import ByContent
from ..numbers import gib, positive, real_array
from ..tracing import as_array, caller_level, own_transfers
from .operator import Compliance, FieldMap, rigid_modes

NQ = 5                                                  # Gauss points per element
_XI, _WQ = np.polynomial.legendre.leggauss(NQ)
_XI, _WQ = 0.5 * (_XI + 1.0), 0.5 * _WQ                 # on [0, 1]
_V = np.stack([np.ones(NQ), 2 * _XI - 1], axis=1)      # (NQ, 2) linear functions of xi at the Gauss points
#: (NQ, NQ) L2 projection (on [0, 1]) of a field at the Gauss points onto linear functions:
#: the assumed membrane strain (see the module docstring, "membrane locking")
LINEAR = _V @ np.linalg.solve(_V.T @ (_WQ[:, None] * _V), _V.T * _WQ)


def _hermite(xi):
    """Cubic Hermite basis on [0, 1] and its first two xi-derivatives, each (k, 4)."""
    x = np.asarray(xi, dtype=np.float64)[:, None]
    H = np.hstack([1 - 3 * x**2 + 2 * x**3, x - 2 * x**2 + x**3, 3 * x**2 - 2 * x**3, -x**2 + x**3])
    H1 = np.hstack([-6 * x + 6 * x**2, 1 - 4 * x + 3 * x**2, 6 * x - 6 * x**2, -2 * x + 3 * x**2])
    H2 = np.hstack([-6 + 12 * x, -4 + 6 * x, 6 - 12 * x, -2 + 6 * x])
    return H, H1, H2


def _spline(xy: np.ndarray, iters: int = 2):
    """Periodic cubic spline through closed polyline ``xy`` (n, 2), parametrized by arc length.

    Returns (spline, knots (n,), period). Knot spacing starts as chord length and is replaced
    ``iters`` times by the arc length of the current spline's pieces.
    """
    closed = np.vstack([xy, xy[:1]])
    seg = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    if np.any(seg <= 0):
        raise ValueError("curve points must be distinct (consecutive points coincide)")
    xg, wg = np.polynomial.legendre.leggauss(8)
    for it in range(iters + 1):
        u = np.concatenate([[0.0], np.cumsum(seg)])
        cs = CubicSpline(u, closed, bc_type="periodic", axis=0)
        if it == iters:
            break
        uq = u[:-1, None] + 0.5 * (xg + 1.0) * seg[:, None]
        seg = 0.5 * seg * (np.linalg.norm(cs(uq, 1), axis=-1) @ wg)
    return cs, u[:-1], u[-1]


#: fewest band nodes: the spline through fewer does not resolve even a circle
MIN_NODES = 8
#: most band nodes a band is built with (a setting: assign it or set the environment variable
#: ``JAXSQUEEZE_MAX_BAND_NODES``): its operator is dense, (4m)² numbers, 0.5 GB at m = 2048
MAX_NODES = int(float(os.environ.get("JAXSQUEEZE_MAX_BAND_NODES", 2048)))
_FEW = ("a ring of 4 nodes is about 800 times too stiff and one of 8 about 35 % (a circle); use at least 64 nodes "
        "for a curved outline (the examples use 128)")


#: consecutive band points closer than this share of the mean spacing coincide
COINCIDENT = 1e-6


#: the band sizes [m] the library takes: within them the stiffness (E w^3 / L^3 and the like)
#: and the arc lengths stay far from float64's overflow and underflow
EXTENT = (1e-9, 1e9)


def _check_extent(xy: np.ndarray) -> None:
    size = float(np.max(np.ptp(xy, axis=0)))
    if not EXTENT[0] <= size <= EXTENT[1]:
        raise ValueError(f"the band's size, {size:.3g} m across, is outside the {EXTENT[0]:g} .. {EXTENT[1]:g} m "
                         "that the band model resolves: lengths are in metres (a length in millimetres is 1000 "
                         "times too large)")


def _touching(xy: np.ndarray, tol: float, chunk: int = 256):
    """The first point of a closed polyline xy (m, 2) within ``tol`` [m] of a segment that does
    not end at it, as (point, segment's first point), or None: a curve that touches itself
    without crossing (a spike back to an earlier point). O(m^2) in chunks of ``chunk`` points."""
    a, b = xy, np.roll(xy, -1, axis=0)
    e = b - a
    m, seg = len(xy), np.arange(len(xy))
    for lo in range(0, m, chunk):
        i = np.arange(lo, min(lo + chunk, m))[:, None]
        p = xy[i]                                                      # (c, 1, 2)
        t = np.clip(np.sum((p - a) * e, axis=-1) / np.sum(e * e, axis=-1), 0.0, 1.0)
        dist = np.linalg.norm(p - (a + t[..., None] * e), axis=-1)     # (c, m)
        hit = (dist <= tol) & (seg != i) & ((seg + 1) % m != i)
        if hit.any():
            r, c = np.argwhere(hit)[0]
            return int(lo + r), int(c)
    return None


def _check_size(m: int) -> None:
    """Refuse a band of more than :data:`MAX_NODES` nodes before any O(m²) work."""
    if m > MAX_NODES:
        raise ValueError(f"a band of {m:,} nodes needs dense matrices of (4m)² = {gib((4 * m) ** 2 * 8)} "
                         f"each, beyond the limit of {MAX_NODES:,} nodes (jaxsqueeze.mechanics.band.MAX_NODES, env "
                         "JAXSQUEEZE_MAX_BAND_NODES); 128-256 nodes resolve the examples' outlines")


def _check_wall(width: float, xy: np.ndarray, kappa: np.ndarray) -> None:
    """Refuse a wall that fills the ring; warn where it is thicker than the curve's radius of
    curvature (the thin curved-beam model does not hold there)."""
    short = float(np.min(np.ptp(xy, axis=0)))
    if width >= 0.5 * short:
        raise ValueError(f"band width = {width:g} m is the wall thickness in the plane, but the band is only "
                         f"{short:g} m across: the wall would fill the ring. Give it in metres (a cookie cutter's "
                         "wall is about 0.5e-3 m)")
    k = int(np.argmax(np.abs(kappa)))
    if width * abs(kappa[k]) > 1.0:
        warnings.warn(f"band width = {width:g} m is thicker than the band's tightest radius of curvature "
                      f"({1 / abs(kappa[k]):.3g} m, at node {k}): the thin-wall beam model does not hold "
                      "there", stacklevel=caller_level())


def _length(name: str, v) -> float:
    """A band dimension as a float, or ValueError naming it (finite and > 0 m)."""
    return positive(v, f"band {name}", "m")


@dataclass(frozen=True, eq=False, init=False)
class Band(ByContent):
    """Discretized band on a closed counterclockwise curve: ``Band(xy, width=..., height=...)``
    (the same as :meth:`from_curve`) or :meth:`from_function`.

    Frame (the same convention as :class:`~jaxsqueeze.mesh.Mesh`): ``points`` are translated
    so that the node centroid is at the origin, and ``offset`` (2,) is that centroid in the
    caller's frame, so ``points + offset`` are the coordinates the band was built from. The
    squeeze results (``res.centres``, ``res.boundary_displacement``) and the operator
    (``op.points * op.length == points``) are in this centroid frame; plots, scene files
    (``grip.points``) and :func:`jaxsqueeze.scene.nearest_boundary_node` use the caller's.

    Mesh-like read-only views so that code written for meshes reads a band as its boundary:
    ``n == m`` (every node is a boundary node), ``boundary == arange(m)``, ``loops == (m,)``,
    ``triangles`` (0, 3) (a band has no area elements; see :meth:`segments` for its polyline).

    Attributes:
        points: (m, 2) node positions [m], node centroid at the origin.
        offset: (2,) node centroid in the caller's frame [m].
        tangents: (m, 2) unit tangents t (counterclockwise).
        normals: (m, 2) outward unit normals n = (t_y, -t_x).
        curvature: (m,) kappa [1/m] of the spline, > 0 where the curve turns left.
        s: (m,) arc length of each node from node 0 [m].
        perimeter: () P [m].
        width: () w [m], wall thickness in the plane (the bending dimension).
        height: () h [m], extent out of the plane.
        du: (m,) parameter length of element k (nodes k, k+1); jac: (m,) J = ds/du at node k.
        qd1, qd2: (m, NQ, 2) dgamma/du and d2gamma/du2 at the Gauss points of each element.
    """

    points: np.ndarray
    tangents: np.ndarray
    normals: np.ndarray
    curvature: np.ndarray
    s: np.ndarray
    perimeter: float
    width: float
    height: float
    du: np.ndarray
    jac: np.ndarray
    qd1: np.ndarray
    qd2: np.ndarray
    offset: np.ndarray

    def __init__(self, points, tangents=None, normals=None, curvature=None, s=None, perimeter=None,
                 width=0.5e-3, height=5e-3, du=None, jac=None, qd1=None, qd2=None, offset=None):
        """``Band(xy, width=..., height=...)``: the band through the closed counterclockwise
        polyline ``xy`` (:meth:`from_curve`, whose errors it raises). Every field given (the
        library's own construction, and ``dataclasses.replace``) takes them as they are."""
        derived = (tangents, normals, curvature, s, perimeter, du, jac, qd1, qd2)
        if all(v is None for v in derived + (offset,)):
            built = type(self).from_curve(points, width, height)
            values = [getattr(built, f.name) for f in dataclasses.fields(built)]
        elif any(v is None for v in derived):
            raise TypeError("build a band as Band(xy, width=..., height=...) or Band.from_function(gamma, m): "
                            "its tangents, normals, curvature, arc lengths and spline data are derived from them")
        else:
            values = [points, tangents, normals, curvature, s, perimeter, width, height, du, jac, qd1, qd2,
                      np.zeros(2) if offset is None else offset]
        self._fill(values)

    def __repr__(self) -> str:
        w, h = np.ptp(np.asarray(self.points, float), axis=0)
        return (f"Band({self.m} nodes, perimeter {float(self.perimeter):.4g} m, wall {float(self.width):.4g} m wide "
                f"and {float(self.height):.4g} m high, {w:.4g} × {h:.4g} m)")

    @property
    def m(self) -> int:
        return int(self.points.shape[0])

    @property
    def n(self) -> int:
        """Number of nodes (all on the boundary), as ``Mesh.n``."""
        return self.m

    @property
    def boundary(self) -> np.ndarray:
        """(m,) ``arange(m)``: every node can touch a finger (as ``Mesh.boundary``)."""
        return np.arange(self.m)

    @property
    def loops(self) -> tuple:
        """``(m,)``: one closed counterclockwise loop (as ``Mesh.loops``)."""
        return (self.m,)

    @property
    def triangles(self) -> np.ndarray:
        """(0, 3): a band has no triangles (its polyline is :meth:`segments`)."""
        return np.zeros((0, 3), np.int64)

    def segments(self) -> np.ndarray:
        """(m, 2) node pairs (k, k + 1 mod m) of the closed polyline through the nodes."""
        k = np.arange(self.m)
        return np.stack([k, (k + 1) % self.m], axis=1)

    @property
    def ndof(self) -> int:
        return 4 * self.m

    @classmethod
    def from_curve(cls, xy, width: float = 0.5e-3, height: float = 5e-3) -> "Band":
        """Band through the closed counterclockwise polyline ``xy`` (m, 2) [m] (a last point
        that repeats the first, to round-off, is dropped).

        The points are the nodes and the knots of the periodic arc-length spline that is the
        band's geometry; use enough of them to resolve the curvature. Two consecutive points
        closer than :data:`COINCIDENT` of the mean spacing are an error (the spline's knots
        would coincide).
        """
        xy = real_array(xy, "xy", "m")
        if xy.ndim == 2 and xy.shape[1:] == (2,) and len(xy) > MIN_NODES and np.all(np.isfinite(xy)):
            with np.errstate(over="ignore", invalid="ignore"):      # (a curve of 1e300 m: _check_extent says so)
                gaps = np.linalg.norm(np.diff(xy, axis=0), axis=1)
                if np.linalg.norm(xy[-1] - xy[0]) <= COINCIDENT * gaps.mean():
                    xy = xy[:-1]                     # the closing point of a sampled closed curve
        _check_size(len(xy))
        if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] < MIN_NODES or not np.all(np.isfinite(xy)):
            if xy.ndim == 2 and xy.shape[1] == 2 and xy.shape[0] >= MIN_NODES:
                k = int(np.flatnonzero(~np.isfinite(xy).all(axis=1))[0])
                raise ValueError(f"xy (m, 2) must be finite: point {k} is {xy[k].tolist()}")
            raise ValueError(f"xy must be a finite (m, 2) array with m >= {MIN_NODES}, got shape {xy.shape}: "
                             f"{_FEW}")
        _check_extent(xy)
        gaps = np.linalg.norm(np.roll(xy, -1, axis=0) - xy, axis=1)
        close = np.flatnonzero(gaps <= COINCIDENT * gaps.mean())
        if close.size:
            k = int(close[0])
            raise ValueError(f"band points {k} and {(k + 1) % len(xy)} coincide ({gaps[k]:.3g} m apart, mean spacing "
                             f"{gaps.mean():.3g} m; {close.size} such pair(s)): remove the repeated points")
        width, height = _length("width", width), _length("height", height)
        offset = xy.mean(axis=0)
        xy = xy - offset                 # (far from the origin, the area's digits would cancel)
        x, y = xy[:, 0], xy[:, 1]
        hit = crossing(xy, (len(xy),))
        if hit is not None:
            a, b = ([k, (k + 1) % len(xy)] for k in hit)
            raise ValueError(f"the band curve crosses itself: segment {a} crosses segment {b} (point indices); "
                             "order the points along the curve")
        area = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
        if area <= 1e-12 * np.sum(gaps) ** 2:
            raise ValueError("the band curve encloses no area (its points lie on a line)" if area > -1e-12 * np.sum(
                gaps) ** 2 else "the band curve must run counterclockwise (positive signed area): reverse the points")
        touch = _touching(xy, COINCIDENT * gaps.mean())
        if touch is not None:
            k, j = touch
            raise ValueError(f"the band curve touches itself: point {k} lies on segment {[j, (j + 1) % len(xy)]} "
                             "(point indices); a band is one simple closed curve: remove the spike or loop there")
        cs, u, period = _spline(xy)
        m = u.shape[0]
        du = np.diff(np.append(u, period))
        d1, d2 = cs(u, 1), cs(u, 2)
        J = np.linalg.norm(d1, axis=1)
        t = d1 / J[:, None]
        kappa = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / J**3
        _check_wall(width, xy, kappa)
        uq = np.minimum(u[:, None] + _XI[None, :] * du[:, None], period)
        xg, wg = np.polynomial.legendre.leggauss(8)
        ue = u[:, None] + 0.5 * (xg + 1.0) * du[:, None]
        s = np.concatenate([[0.0], np.cumsum(0.5 * du * (np.linalg.norm(cs(ue, 1), axis=-1) @ wg))])
        return cls(points=xy, offset=offset, tangents=t, normals=np.stack([t[:, 1], -t[:, 0]], axis=1),
                   curvature=kappa, s=s[:m], perimeter=float(s[m]), width=float(width),
                   height=float(height), du=du, jac=J, qd1=cs(uq, 1), qd2=cs(uq, 2))

    @classmethod
    def from_function(cls, gamma: Callable, m: int, width: float = 0.5e-3, height: float = 5e-3) -> "Band":
        """Band with m nodes equally spaced in arc length on the closed CCW curve ``gamma``.

        ``gamma(p)``: p in [0, 1) (k,) -> points (k, 2) [m], vectorized (see
        :mod:`jaxsqueeze.curves`). Node 0 is gamma(0).
        """
        if not callable(gamma):
            raise TypeError(f"gamma must be a function p -> (k, 2) points [m] of the curve, got {gamma!r}")
        if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < MIN_NODES:
            raise ValueError(f"a band needs an integer number of nodes m >= {MIN_NODES}, got {m!r}: {_FEW}")
        _check_size(m)
        coarse = real_array(gamma(np.arange(64) / 64), "the curve's points", "m")
        if coarse.shape == (64, 2) and np.all(np.isfinite(coarse)):
            _check_extent(coarse)                 # (before arc lengths that would overflow)
        return cls.from_curve(np.asarray(gamma(arclength_params(gamma, m))), width, height)

    def to_xy(self) -> np.ndarray:
        """T (2m, ndof): nodal xy displacements (interleaved x0, y0, x1, ...) from band DOFs."""
        m = self.m
        T = np.zeros((2 * m, 4 * m))
        T[np.arange(2 * m), 4 * (np.arange(2 * m) // 2) + np.arange(2 * m) % 2] = 1.0
        return T

    def rigid_dofs(self, center=None) -> np.ndarray:
        """R (ndof, 3): DOFs of unit x and y translation [m] and unit rotation [rad] about
        ``center`` (centroid frame; default: the node centroid, the origin). Exact: the interpolated fields are rigid."""
        c = self.points.mean(axis=0) if center is None else real_array(center, "center", "m")
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise ValueError(f"center must be one finite (x, y) point [m] in the band's centroid frame; got {c.tolist()}")
        r, t = self.points - c, self.tangents
        R = np.zeros((4 * self.m, 3))
        R[0::4, 0] = R[1::4, 1] = 1.0
        R[0::4, 2], R[1::4, 2], R[2::4, 2], R[3::4, 2] = -r[:, 1], r[:, 0], -t[:, 1], t[:, 0]
        return R

    def rotation(self, dofs) -> np.ndarray:
        """(m,) small rotation phi [rad] (counterclockwise) of the band's cross-section at
        each node: phi = t x d(delta)/ds, from the slope DOFs of ``dofs`` (4m,)."""
        d = self._nodal(dofs)[:, 2:]
        return self.tangents[:, 0] * d[:, 1] - self.tangents[:, 1] * d[:, 0]

    def alpha_beta(self, dofs) -> np.ndarray:
        """Tangential and outward normal nodal displacement (m, 2) [m]: (alpha_k, beta_k), from
        ``dofs`` (4m,): (dx [m], dy [m], dx/ds, dy/ds) per node."""
        d = self._nodal(dofs)[:, :2]
        return np.stack([np.sum(d * self.tangents, 1), np.sum(d * self.normals, 1)], axis=1)

    def _nodal(self, dofs) -> np.ndarray:
        """(m, 4) per-node DOFs from the band's (4m,) DOF vector, or ValueError."""
        d = real_array(dofs, "band DOFs")
        if d.shape != (4 * self.m,):
            raise ValueError(f"band DOFs must have shape (4m,) = ({4 * self.m},) for this band of m = {self.m} "
                             f"nodes (dx, dy, dx/ds, dy/ds per node); got {d.shape}")
        return d.reshape(self.m, 4)

    def _dof_scale(self) -> np.ndarray:
        """D (ndof,): 1 on displacements, the mean element length on the slope DOFs."""
        ell = self.perimeter / self.m
        return np.tile([1.0, 1.0, ell, ell], self.m)


def element_stiffness(du, Ja, Jb, d1, d2, EA, EI) -> np.ndarray:
    """Element stiffness matrices (e, 8, 8) for DOFs (dx, dy, dx/ds, dy/ds) at both nodes.

    Args:
        du: (e,) parameter length of each element; Ja, Jb: (e,) ds/du at its two nodes.
        d1, d2: (e, NQ, 2) dgamma/du and d2gamma/du2 at the Gauss points.
        EA [N], EI [N m^2]: membrane and bending rigidity.
    On a straight element (gamma = (u, 0)) the y block is the Euler-Bernoulli beam element
    EI/l^3 [[12, 6l, -12, 6l], [6l, 4l^2, -6l, 2l^2], ...] and the x block a cubic bar.
    """
    du = np.asarray(du, dtype=np.float64)
    e = du.shape[0]
    _, H1, H2 = _hermite(_XI)
    c = np.stack([np.ones(e), du * Ja, np.ones(e), du * Jb], axis=1)[:, None, :]     # (e, 1, 4)
    N1, N2 = H1[None] * c / du[:, None, None], H2[None] * c / du[:, None, None] ** 2
    ix, iy = [0, 2, 4, 6], [1, 3, 5, 7]
    dxu, dyu, dxuu, dyuu = (np.zeros((e, NQ, 8)) for _ in range(4))
    dxu[..., ix], dyu[..., iy], dxuu[..., ix], dyuu[..., iy] = N1, N1, N2, N2
    gx, gy, gxx, gyy = d1[..., 0, None], d1[..., 1, None], d2[..., 0, None], d2[..., 1, None]
    J = np.linalg.norm(d1, axis=-1)[..., None]
    Ju = (gx * gxx + gy * gyy) / J
    Be = LINEAR @ ((gx * dxu + gy * dyu) / J**2)                        # eps, assumed linear per element
    cross = gx * dyu - gy * dxu                                         # gamma_u x delta_u
    cross_u = gxx * dyu - gyy * dxu + gx * dyuu - gy * dxuu
    Bz = (cross_u / J**2 - 2.0 * cross * Ju / J**3) / J                 # zeta = dphi/ds
    wt = (_WQ[None, :] * du[:, None] * J[..., 0])[..., None, None]
    return np.sum(wt * (EA * Be[..., :, None] * Be[..., None, :] + EI * Bz[..., :, None] * Bz[..., None, :]), axis=1)


def band_stiffness(band: Band, E: float, project: bool = True) -> np.ndarray:
    """Stiffness K (ndof, ndof) of ``band`` [N/m on displacement DOFs, N on slope DOFs].

    Symmetric PSD, rank ndof - 3. The rigid DOF vectors have zero energy to round-off;
    ``project=True`` (default) also removes that round-off (orthogonal projection, slope DOFs
    scaled by the mean element length), so the null space is exactly :meth:`Band.rigid_dofs`.
    """
    E = positive(E, "Young's modulus E", "Pa")
    w, h = band.width, band.height
    m = band.m
    ke = element_stiffness(band.du, band.jac, np.roll(band.jac, -1), band.qd1, band.qd2,
                           E * w * h, E * h * w**3 / 12.0)
    k = np.arange(m)
    dofs = np.concatenate([4 * k[:, None] + np.arange(4), 4 * ((k[:, None] + 1) % m) + np.arange(4)], axis=1)
    K = np.zeros((4 * m, 4 * m))
    np.add.at(K, (dofs[:, :, None], dofs[:, None, :]), ke)
    if project:
        D = band._dof_scale()
        Q, _ = np.linalg.qr(D[:, None] * band.rigid_dofs())
        Ks = K / np.outer(D, D)
        Ks = Ks - Q @ (Q.T @ Ks)
        Ks = Ks - (Ks @ Q) @ Q.T
        K = Ks * np.outer(D, D)
    return 0.5 * (K + K.T)


def band_pinv(band: Band, K: np.ndarray, check: bool = True) -> np.ndarray:
    """Generalized inverse X (ndof, ndof) of the projected ``K``: K X b = b for every b
    orthogonal to the rigid DOF vectors (e.g. b = T^T F for a self-equilibrated xy load F).
    ``check``: warn or refuse where round-off can reach the result (:func:`_check_roundoff`);
    off where the band's operator was built, and so checked, before."""
    D = band._dof_scale()
    Q, _ = np.linalg.qr(D[:, None] * band.rigid_dofs())
    Ks = K / np.outer(D, D)
    c = np.trace(Ks) / Ks.shape[0]
    A = Ks + c * (Q @ Q.T)
    Xs = np.linalg.inv(A)
    if check:
        _check_roundoff(band, np.finfo(np.float64).eps * np.linalg.norm(A, 1) * np.linalg.norm(Xs, 1))
    Xs = Xs - (Q @ Q.T) / c
    return 0.5 * (Xs + Xs.T) / np.outer(D, D)


#: relative round-off (eps times the 1-norm condition number) of a band's inverse stiffness
#: above which a band warns, and at or above which it is refused
ROUNDOFF_WARN, ROUNDOFF_LIMIT = 1e-2, 1.0


def _check_roundoff(band: Band, roundoff: float) -> None:
    """Warn where the round-off bound ``roundoff`` (eps times the condition number) reaches
    ``ROUNDOFF_WARN`` of the compliance, refuse where it reaches ``ROUNDOFF_LIMIT``. The
    stiffness is conditioned as membrane over bending, 12 (l / w)^2 per element, times the m^2
    of a chain of elements. The bound is pessimistic for one pinch (a 4 cm ring of 32 nodes:
    bound 0.016 at a 0.1 um wall, error 3e-6 against the closed form; bound 1.6 at 10 nm,
    error 1.3e-3), less so for a squeeze: the 8 cm heart of 128 nodes has bound 2e-3 at a
    1 um wall (grip force within 5e-5 of the 0.5 mm wall's, scaled by w^3), and at 10 nm
    (bound 40) it squeezed to a wrong SLIP_FAILURE, as at 0.1 um with 512 nodes (bound 3.3);
    0.1 um with 256 nodes (bound 0.85) was 1.4 % off."""
    if roundoff < ROUNDOFF_WARN:
        return
    what = (f"band width = {band.width:g} m with m = {band.m} nodes ({band.perimeter:.3g} m around): its "
            f"stiffness (membrane over bending ~ 12 (l/w)^2, l = {band.perimeter / band.m:.3g} m per element) "
            f"is so ill-conditioned that round-off can reach {roundoff:.2g} of the compliance "
            "(a bound: eps times its condition number)")
    fix = ("check that the width is the wall thickness in metres (a cookie cutter's is about 0.5e-3 m); "
           "fewer nodes help as m^2")
    if roundoff >= ROUNDOFF_LIMIT:
        raise ValueError(f"{what}: no digit of the result is assured; {fix}")
    warnings.warn(f"{what}; {fix}", stacklevel=caller_level())


@own_transfers
def band_compliance(band: Band, E: float, dtype=None) -> Compliance:
    """Compliance operator (method "band") of ``band`` with Young's modulus ``E`` [Pa].

    All m nodes are contact-capable (``nodes = arange(m)``, ``loops = (m,)``). Scaled units:
    L = larger bounding-box side of the nodes [m], stiffness = E h [N/m]; ``G`` (2m, 2m) =
    E h T K^+ T^T, exact on self-equilibrated loads up to a rigid motion;
    ``N = rigid_modes(points)``; the field map is G itself (a band has no other nodes).
    """
    E = positive(E, "Young's modulus E", "Pa")
    T = band.to_xy()
    G = (E * band.height) * (T @ band_pinv(band, band_stiffness(band, E)) @ T.T)
    G = 0.5 * (G + G.T)
    L = float(np.max(np.ptp(band.points, axis=0)))
    pts = (band.points - band.points.mean(axis=0)) / L
    arr = lambda a: as_array(a, dtype)   # noqa: E731
    return Compliance(
        points=arr(pts), normals=arr(band.normals), G=arr(G), N=arr(rigid_modes(pts, xp=np)),
        length=arr(L), stiffness=arr(E * band.height), nodes=as_array(np.arange(band.m)),
        method="band", loops=(band.m,), field=FieldMap(lambda f, G=G: G @ f, pts))
