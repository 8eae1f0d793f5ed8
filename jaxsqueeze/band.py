"""Curved elastic bands (Section V-A): ring-like objects such as trimmed cookie cutters.

A band is swept by a rectangular cross-section along a closed counterclockwise curve
gamma(s) (arc length s, perimeter P). Its displacement is delta(s) = alpha(s) t + beta(s) n.

Conventions (stated because the paper's formulas depend on them):
    t = dgamma/ds, n = (t_y, -t_x) the OUTWARD normal (the right normal of a CCW curve),
    kappa > 0 where the curve turns left (convex parts of a CCW outline; 1/R on a circle),
    so that dt/ds = -kappa n and dn/ds = kappa t. Then
        extension        eps  = dalpha/ds + kappa beta,
        rotation         phi  = kappa alpha - dbeta/ds   (counterclockwise),
        curvature change zeta = dphi/ds = -d2beta/ds2 + dkappa/ds alpha + kappa dalpha/ds.
    The paper writes eps = alpha' - kappa beta and zeta = -beta'' - kappa' alpha - kappa alpha'
    with the Frenet (inward) normal; with beta_paper = -beta these are our eps and -zeta, the
    same energy. Rigid motions give eps = phi' = 0 exactly: translation v has delta' = 0;
    rotation omega has delta' = omega z x t, so eps = 0 and phi = omega is constant.

Strain energy U = 1/2 E int (A eps^2 + I zeta^2) ds with A = w h and I = h w^3 / 12, where
    w = ``width``: the wall thickness IN the plane of the curve (the bending dimension), and
    h = ``height``: the band's extent OUT of the plane (the cutter's height; the paper's
    "thickness" h = 5 mm, and the thickness of the operator's scaling E h).
    The paper prints U = 1/2 E w int (h eps^2 + h^3/12 zeta^2) ds, i.e. it cubes the
    dimension it calls h. For in-plane bending of a wall the cubed dimension must be the one
    lying in the plane, the wall thickness. A cookie cutter is a thin sheet (about 0.4-0.5 mm)
    standing 5 mm or more tall, so we cube the wall thickness ``width`` (default 0.5 mm) and
    keep ``height`` (default 5 mm, the paper's value) linear. Reading the paper literally
    (a 5 mm wall in the plane) is ``width=5e-3`` with ``height`` the out-of-plane size.

Discretization: m nodes on the curve, one element between consecutive nodes, DOFs per node
(alpha, dalpha/ds, beta, dbeta/ds) (ndof = 4 m, node k at 4k..4k+3). Both alpha and beta are
cubic Hermite (C1) in the curve parameter u: beta needs C1 for its second derivative, and a
cubic alpha (rather than linear) lets alpha' follow kappa beta, which keeps membrane locking
small on curved elements. Energy by 5-point Gauss quadrature per element.

Geometry: a periodic cubic spline (scipy ``CubicSpline``, ``bc_type='periodic'``) through the
curve points, parametrized by arc length (chord length, then two re-parametrizations by the
spline's own arc length, so |dgamma/du| = 1 to about the spline error). t, n, kappa and
dkappa/ds at nodes and quadrature points come from its derivatives; the exact Jacobian
J = |dgamma/du| is kept in the chain rule. :meth:`Band.from_function` fits the spline through
a dense sampling of the function (geometry then is near exact whatever m), with the m nodes
equally spaced in arc length; :meth:`Band.from_curve` fits it through the given polyline,
whose points become the nodes.

Rigid modes: cubic Hermite fields reproduce the interpolated rigid motions only up to the
interpolation error, so the raw stiffness gives them a small energy (relative O(1e-6) at
m = 64). :func:`band_stiffness` therefore projects them out: K <- P K P with P the orthogonal
projector (slope DOFs scaled by the mean element length, so all DOFs are lengths) onto the
complement of the three rigid DOF vectors (which are exact at the nodes). The null space is
then exactly the rigid motions and the change to K is of the order of the discretization
error. The nodal xy displacement delta_k = alpha_k t_k + beta_k n_k (matrix ``T``) maps the
rigid DOF vectors to exact rigid motions, so a self-equilibrated xy load F gives a DOF load
T^T F orthogonal to them.

The operator (:func:`band_compliance`, method "band") uses all m nodes as contact-capable
nodes: G = E h T K^+ T^T in the scaled units of DESIGN 2.3 (lengths / L, forces / (E h L)),
L = the larger bounding-box side of the nodes. A thin band is compliant, so G is large
(about 1e6 for an 8 cm cookie cutter with a 0.5 mm wall); its scale is (L/w)^3.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import jax.numpy as jnp
import numpy as np
from scipy.interpolate import CubicSpline

from .operator import Compliance, FieldMap, rigid_modes

NQ = 5                                                  # Gauss points per element
_XI, _WQ = np.polynomial.legendre.leggauss(NQ)
_XI, _WQ = 0.5 * (_XI + 1.0), 0.5 * _WQ                 # on [0, 1]


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
    ``iters`` times by the arc length of the current spline's segments.
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


def _geometry(cs, u):
    """Spline geometry at parameters u (any shape): J, dJ/du, tangent, kappa, dkappa/du."""
    d1, d2, d3 = cs(u, 1), cs(u, 2), cs(u, 3)
    J = np.linalg.norm(d1, axis=-1)
    Ju = np.einsum("...i,...i->...", d1, d2) / J
    c = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]
    cu = d1[..., 0] * d3[..., 1] - d1[..., 1] * d3[..., 0]
    kappa = c / J**3
    kappa_u = cu / J**3 - 3.0 * c * Ju / J**4
    return J, Ju, d1 / J[..., None], kappa, kappa_u


@dataclass(frozen=True, eq=False)
class Band:
    """Discretized band on a closed counterclockwise curve (build with the class methods).

    Attributes:
        points: (m, 2) node positions [m] in the caller's frame.
        tangents: (m, 2) unit tangents t (counterclockwise).
        normals: (m, 2) outward unit normals n = (t_y, -t_x).
        curvature: (m,) kappa [1/m], > 0 where the curve turns left (convex parts).
        s: (m,) arc length of each node from node 0 [m].
        perimeter: () P [m].
        width: () w [m], wall thickness in the plane (the bending dimension).
        height: () h [m], extent out of the plane.
        du, jac: (m,) parameter length of element k (nodes k, k+1) and J = ds/du at node k.
        qJ, qJu, qkappa, qkappa_u: (m, NQ) J, dJ/du, kappa, dkappa/du at Gauss points.
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
    qJ: np.ndarray
    qJu: np.ndarray
    qkappa: np.ndarray
    qkappa_u: np.ndarray

    @property
    def m(self) -> int:
        return int(self.points.shape[0])

    @property
    def ndof(self) -> int:
        return 4 * self.m

    @classmethod
    def _build(cls, cs, period, u_nodes, width, height) -> "Band":
        if not (width > 0 and height > 0):
            raise ValueError(f"band width and height must be > 0 m, got {width!r}, {height!r}")
        m = u_nodes.shape[0]
        du = np.diff(np.append(u_nodes, period))
        J, _, t, kappa, _ = _geometry(cs, u_nodes)
        uq = (u_nodes[:, None] + _XI[None, :] * du[:, None]) % period
        qJ, qJu, _, qk, qku = _geometry(cs, uq)
        xg, wg = np.polynomial.legendre.leggauss(8)
        ue = u_nodes[:, None] + 0.5 * (xg + 1.0) * du[:, None]
        ds = 0.5 * du * (np.linalg.norm(cs(ue % period, 1), axis=-1) @ wg)
        s = np.concatenate([[0.0], np.cumsum(ds)])
        return cls(points=cs(u_nodes), tangents=t, normals=np.stack([t[:, 1], -t[:, 0]], axis=1),
                   curvature=kappa, s=s[:m], perimeter=float(s[m]), width=float(width),
                   height=float(height), du=du, jac=J, qJ=qJ, qJu=qJu, qkappa=qk, qkappa_u=qku)

    @classmethod
    def from_curve(cls, xy, width: float = 0.5e-3, height: float = 5e-3) -> "Band":
        """Band through the closed counterclockwise polyline ``xy`` (m, 2) [m] (no repeated end).

        The points are the nodes; geometry from the periodic arc-length spline through them,
        so a smooth outline needs enough points for its curvature (and dkappa/ds) to converge.
        """
        xy = np.asarray(xy, dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] < 4 or not np.all(np.isfinite(xy)):
            raise ValueError(f"xy must be a finite (m, 2) array with m >= 4, got shape {xy.shape}")
        x, y = xy[:, 0], xy[:, 1]
        area = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
        if area <= 0:
            raise ValueError("the band curve must run counterclockwise (positive signed area)")
        cs, u, period = _spline(xy)
        return cls._build(cs, period, u, width, height)

    @classmethod
    def from_function(cls, gamma: Callable, m: int, width: float = 0.5e-3, height: float = 5e-3,
                      dense: int | None = None) -> "Band":
        """Band on the closed CCW curve ``gamma(p)`` (p in [0, 1) -> (k, 2) [m]), m nodes.

        Geometry from a spline through ``dense`` samples (default ``max(32 m, 4096)``) at
        equal steps of p; the m nodes are equally spaced in arc length, node 0 at gamma(0).
        See :mod:`jaxsqueeze.curves` for outlines.
        """
        n = max(32 * m, 4096) if dense is None else int(dense)
        xy = np.asarray(gamma(np.arange(n) / n), dtype=np.float64)
        x, y = xy[:, 0], xy[:, 1]
        if 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) <= 0:
            raise ValueError("gamma must run counterclockwise")
        if m < 4:
            raise ValueError(f"a band needs m >= 4 nodes, got {m}")
        cs, _, period = _spline(xy)
        return cls._build(cs, period, np.arange(m) * (period / m), width, height)

    def to_xy(self) -> np.ndarray:
        """T (2m, ndof): nodal xy displacements (interleaved) delta_k = alpha_k t_k + beta_k n_k."""
        m = self.m
        T = np.zeros((2 * m, 4 * m))
        k = np.arange(m)
        for d in range(2):
            T[2 * k + d, 4 * k] = self.tangents[:, d]
            T[2 * k + d, 4 * k + 2] = self.normals[:, d]
        return T

    def rigid_dofs(self, center=None) -> np.ndarray:
        """R (ndof, 3): DOFs of x translation, y translation, rotation about ``center``.

        Default center: the node centroid. Columns are exact (at the nodes) for unit
        translation [m] and unit angle [rad]: alpha = t.v, beta = n.v, alpha' = -kappa n.v,
        beta' = kappa t.v, with v = z x (x - center) - plus beta' -= 1 for the rotation.
        """
        c = self.points.mean(axis=0) if center is None else np.asarray(center, dtype=np.float64)
        t, n, k = self.tangents, self.normals, self.curvature
        r = self.points - c
        vs = [np.tile([1.0, 0.0], (self.m, 1)), np.tile([0.0, 1.0], (self.m, 1)),
              np.stack([-r[:, 1], r[:, 0]], axis=1)]
        R = np.zeros((4 * self.m, 3))
        for j, v in enumerate(vs):
            tv, nv = np.sum(t * v, axis=1), np.sum(n * v, axis=1)
            R[0::4, j], R[1::4, j], R[2::4, j], R[3::4, j] = tv, -k * nv, nv, k * tv
        R[3::4, 2] -= 1.0
        return R

    def _dof_scale(self) -> np.ndarray:
        """D (ndof,): 1 on alpha, beta and the mean element length on the slope DOFs."""
        return np.tile([1.0, self.perimeter / self.m, 1.0, self.perimeter / self.m], self.m)


def element_stiffness(du, Ja, Jb, qJ, qJu, qkappa, qkappa_u, EA, EI, membrane_points=NQ) -> np.ndarray:
    """Element stiffness matrices (e, 8, 8) for element DOFs (alpha, alpha', beta, beta') x 2.

    Args:
        du: (e,) parameter length of each element; Ja, Jb: (e,) ds/du at its two nodes.
        qJ, qJu, qkappa, qkappa_u: (e, NQ) J, dJ/du, kappa, dkappa/du at the Gauss points.
        EA [N], EI [N m^2]: membrane and bending rigidity.
        membrane_points: Gauss points for the membrane term (NQ: full; fewer: reduced).
    Slope DOFs are derivatives in arc length. On a straight element (kappa = 0, J = 1) the
    beta block is the Euler-Bernoulli beam element, EI/l^3 [[12, 6l, -12, 6l], ...].
    """
    def B(xi, J, Ju, k, ku):
        H, H1, H2 = _hermite(xi)
        c = np.stack([np.ones_like(du), du * Ja, np.ones_like(du), du * Jb], axis=1)[:, None, :]   # (e,1,4)
        N0 = H[None] * c
        N1 = H1[None] * c / du[:, None, None]
        N2 = H2[None] * c / du[:, None, None] ** 2
        J, Ju, k, ku = (a[..., None] for a in (J, Ju, k, ku))
        ia, ib = [0, 1, 4, 5], [2, 3, 6, 7]
        Be, Bz = np.zeros(N0.shape[:2] + (8,)), np.zeros(N0.shape[:2] + (8,))
        Be[..., ia] = N1 / J
        Be[..., ib] = k * N0
        Bz[..., ia] = (ku * N0 + k * N1) / J
        Bz[..., ib] = (-N2 / J + N1 * Ju / J**2) / J
        return Be, Bz

    outer = lambda w, A: np.sum(w[..., None, None] * A[..., :, None] * A[..., None, :], axis=1)  # noqa: E731
    Be, Bz = B(_XI, qJ, qJu, qkappa, qkappa_u)
    K = EI * outer(_WQ[None, :] * du[:, None] * qJ, Bz)
    if membrane_points == NQ:
        return K + EA * outer(_WQ[None, :] * du[:, None] * qJ, Be)
    xr, wr = np.polynomial.legendre.leggauss(membrane_points)
    xr, wr = 0.5 * (xr + 1.0), 0.5 * wr
    # geometry at the reduced points: J and kappa interpolated from the NQ-point values
    V = np.polynomial.legendre.legvander(2 * _XI - 1, NQ - 1)
    Vr = np.polynomial.legendre.legvander(2 * xr - 1, NQ - 1)
    Pm = Vr @ np.linalg.inv(V)
    Jr, kr = qJ @ Pm.T, qkappa @ Pm.T
    Be, _ = B(xr, Jr, Jr, kr, kr)
    return K + EA * outer(wr[None, :] * du[:, None] * Jr, Be)


def band_stiffness(band: Band, E: float, project: bool = True, membrane_points: int = NQ) -> np.ndarray:
    """Stiffness K (ndof, ndof) [SI: N/m on alpha, beta; slope DOFs dimensionless] of ``band``.

    Symmetric PSD. With ``project=True`` (default) the rigid DOF vectors are projected out
    (module docstring), so the null space is exactly :meth:`Band.rigid_dofs` and rank is
    ndof - 3; ``project=False`` returns the raw assembled matrix.
    """
    w, h = band.width, band.height
    EA, EI = E * w * h, E * h * w**3 / 12.0
    m = band.m
    ke = element_stiffness(band.du, band.jac, np.roll(band.jac, -1), band.qJ, band.qJu,
                           band.qkappa, band.qkappa_u, EA, EI, membrane_points)
    k = np.arange(m)
    dofs = np.concatenate([4 * k[:, None] + np.arange(4), 4 * ((k[:, None] + 1) % m) + np.arange(4)], axis=1)
    K = np.zeros((4 * m, 4 * m))
    np.add.at(K, (dofs[:, :, None], dofs[:, None, :]), ke)
    K = 0.5 * (K + K.T)
    if project:
        D = band._dof_scale()
        R = D[:, None] * band.rigid_dofs()
        Ks = K / np.outer(D, D)
        KR = Ks @ R
        RKR = R.T @ KR
        tau = 1e-15 * np.linalg.norm(Ks, 2) * np.eye(3) * np.sum(R**2, axis=0)
        Ks = Ks - KR @ np.linalg.solve(RKR + tau, KR.T)           # energy-optimal removal
        Q, _ = np.linalg.qr(R)
        Ks = Ks - Q @ (Q.T @ Ks)                                  # exact null space (round-off level)
        Ks = Ks - (Ks @ Q) @ Q.T
        K = 0.5 * (Ks + Ks.T) * np.outer(D, D)
    return K


def band_pinv(band: Band, K: np.ndarray) -> np.ndarray:
    """Generalized inverse (ndof, ndof) of the projected ``K``: K X b = b for every b orthogonal
    to the rigid DOF vectors (so X b is a displacement answering any self-equilibrated load)."""
    D = band._dof_scale()
    Q, _ = np.linalg.qr(D[:, None] * band.rigid_dofs())
    Ks = K / np.outer(D, D)
    c = np.trace(Ks) / Ks.shape[0]
    Xs = np.linalg.inv(Ks + c * (Q @ Q.T)) - (Q @ Q.T) / c
    return 0.5 * (Xs + Xs.T) / np.outer(D, D)


def band_compliance(band: Band, E: float, dtype=None) -> Compliance:
    """Compliance operator (method "band") of ``band`` with Young's modulus ``E`` [Pa].

    All m nodes are contact-capable (``nodes = arange(m)``). Scaled units: L = larger bounding
    box side [m], stiffness = E h [N/m]; ``G`` (2m, 2m) = E h T K^+ T^T, exact on
    self-equilibrated loads up to a rigid motion; ``N = rigid_modes(points)``. The field map
    is G itself (every node of a band is a contact-capable node).
    """
    if not E > 0:
        raise ValueError(f"Young's modulus E must be > 0 Pa, got {E!r}")
    K = band_stiffness(band, E)
    T = band.to_xy()
    G = (E * band.height) * (T @ band_pinv(band, K) @ T.T)
    G = 0.5 * (G + G.T)
    L = float(np.max(np.ptp(band.points, axis=0)))
    pts = (band.points - band.points.mean(axis=0)) / L
    return Compliance(
        points=jnp.asarray(pts, dtype), normals=jnp.asarray(band.normals, dtype), G=jnp.asarray(G, dtype),
        N=rigid_modes(jnp.asarray(pts, dtype)), length=jnp.asarray(L, dtype),
        stiffness=jnp.asarray(E * band.height, dtype), nodes=jnp.arange(band.m),
        method="band", loops=(band.m,), field=FieldMap(lambda f, G=G: G @ f, pts))
