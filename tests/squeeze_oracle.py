"""An independent NumPy oracle of a two-finger squeeze (Guo, Lin and Jia, Sections II-IV).

Written from the paper alone (it shares no code with jaxsqueeze's engine, contacts, laws,
bordered, operator or linalg modules); it only follows the library's documented conventions
(README, DESIGN.md, docs/numerics.md, the docstrings of Scene/Fingers/SqueezeResult):

* Plane-stress constant-strain triangles, energy (1); K is (2n, 2n), DOFs interleaved
  x0, y0, x1, y1, ...; the physical matrix is E * thickness * K_hat.
* Compliance the paper's way (Section III-A): a dense symmetric eigendecomposition of K,
  dropping its three smallest (rigid, zero) eigenvalues; A = sum_k v_k v_k^T / lambda_k on
  the contact DOFs and B = the normalized rigid modes w_x, w_y, w_r (node centroid at the
  origin) at the contact DOFs. The bordered system (4) [[A, B], [B^T, 0]] (f, g) = (d, 0)
  gives the contact forces f and the rigid part g; the displacement of any node is (3).
* Fingers (Section IV): finger 0 is still, finger 1 moves by the depth d along the unit
  vector from its grip node to finger 0's grip node (undeformed positions); each centre
  starts one radius out along the outward boundary normal at its grip node (the normalized
  sum of the unit normals of the two adjacent boundary edges).
* Fingertip rotation (Section IV-D): optional schedules alpha_f(d) [rad], polynomials in d [m]
  (``rotation`` (2, k), highest power first, numpy.polyval order); each tip turns about its
  own centre. Every polar angle t is in the finger's local frame; its world angle is
  t + alpha_f(d), which replaces t in the position below, in eqs. (5), (6) and in the C/D
  conditions. Without ``rotation`` alpha = 0 (the code path is the same).
* A contact node on finger f lies on the tip circle: x = C_f(d) + r (cos(t + a_f), sin(t + a_f)).
  A sticking node keeps its anchor angle t in the finger frame (it turns with the tip); a
  sliding node's local angle is an unknown fixed by eq. (6): its force on the edge of the
  friction cone that opposes its slip relative to the tip, i.e. the rate of its LOCAL angle.
  Modes: 1 stick, 2 slip toward larger polar angle (tangential force f.t = -mu f.n),
  3 slip toward smaller polar angle (f.t = +mu f.n); n = (cos w, sin w), t = (-sin w, cos w),
  w = t + alpha_f the world angle; "larger/smaller" refer to the local angle (slip relative to
  the tip).
  Frictionless contacts slide with f.t = 0 (labelled 2 or 3 by the sign of their angle rate).
* Events: A a free boundary node enters a tip circle (gap < -gap_tol); B a contact's normal
  force f.n becomes negative (n the cone axis: the tip normal, or the surface normal of a point contact); C a sticking force leaves its cone (mu f.n - |f.t| < 0);
  D a sliding node's slip rate s * dtheta/dd becomes negative (s = +1 for mode 2, -1 for 3;
  theta the finger-frame angle, so the rate is the slip relative to the rotating tip),
  (with the documented slack of 1e-7 rad outside the cone, CONE_SLACK),
  evaluated only once the node's rate has been positive (the documented "armed" rule,
  docs/numerics.md section 6). A new contact is hypothesized sticking (Section IV-B.1): if
  the rate of its force (from two probes slightly deeper) leaves the cone it slides on the
  edge it leaves through, a C event at the depth it joined (a grip node: at d = 0); a new
  slider whose force still pulls and does not rise takes the other edge (no event). Events found in one bisection bracket are applied together (mirror-
  symmetric pairs share a depth); a contact that pulls lets go (B) and takes no C or D there,
  and a finger left without contacts ends the squeeze (LOST_CONTACT).
* Settling at an event depth: right after the events of one depth, a contact that pulls by
  more than PULL of the largest force lets go, and a free node inside a tip by more than SUNK
  gap_tol joins (a release can drop a stuck contact's shear), at that depth, with the other
  triggers there; a set still changing after SETTLE such passes -> "STALLED".
* D at an event depth: after the events of one depth are applied (and the new contacts'
  hypotheses settled), armed sliding nodes whose rate is negative stick there (D events at
  that depth), one at a time, the most negative rate first, re-solving after each, until no
  armed rate is negative or the squeeze fails.
* Failure: every contact on one finger sliding (Coulomb only) -> "SLIP_FAILURE"; a finger
  without contacts -> "LOST_CONTACT"; no consistent set at one depth -> "STALLED"; else
  "SUCCESS" at the target depth.

Units: everything is computed in scaled units (lengths / L, forces / (E h L), L the largest
extent of the object) and returned in SI.

Models: "coulomb" (friction mu), "stick" (mu = inf: contacts never slide), "frictionless"
(mu = 0: contacts always slide). The slip angles are solved by Newton's method with an
analytic Jacobian; dtheta/dd comes from the implicit function theorem; events are located by
bisection on the depth to ``depth_tol``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

KINDS = "ABCD"
#: a force within this angle [rad] outside its friction cone still counts as inside (the library's
#: documented convention, docs/numerics.md finding 2: a grip exactly on the cone edge is inside)
CONE_SLACK = 1e-7


def cone_margin(fn, ft, mu):
    """|f| sin(phi + CONE_SLACK - psi): > 0 inside the cone, psi the force's angle from the normal."""
    phi = np.arctan(mu)
    psi = np.arctan2(np.abs(ft), fn)
    return np.hypot(fn, ft) * np.sin(phi + CONE_SLACK - psi)


# ----------------------------------------------------------------------------- FEM
def cst_stiffness(points, triangles, nu):
    """Dense plane-stress CST stiffness (2n, 2n) for E = 1, thickness = 1 (any length unit)."""
    P = np.asarray(points, float)
    T = np.asarray(triangles, int)
    n = len(P)
    K = np.zeros((2 * n, 2 * n))
    D = np.array([[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]]) / (1 - nu ** 2)
    for tri in T:
        x, y = P[tri, 0], P[tri, 1]
        area = 0.5 * ((x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]))
        if area <= 0:
            raise ValueError("triangles must be counterclockwise with positive area")
        b = np.array([y[1] - y[2], y[2] - y[0], y[0] - y[1]])
        c = np.array([x[2] - x[1], x[0] - x[2], x[1] - x[0]])
        Bm = np.zeros((3, 6))
        Bm[0, 0::2] = b
        Bm[1, 1::2] = c
        Bm[2, 0::2] = c
        Bm[2, 1::2] = b
        Bm /= 2 * area
        k = area * Bm.T @ D @ Bm
        dofs = np.ravel(np.c_[2 * tri, 2 * tri + 1])
        K[np.ix_(dofs, dofs)] += k
    return K


def rigid_basis(points):
    """Orthonormal null-space basis (2n, 3): normalized w_x, w_y, w_r (Section II), points centred."""
    P = np.asarray(points, float)
    n = len(P)
    W = np.zeros((2 * n, 3))
    W[0::2, 0] = 1
    W[1::2, 1] = 1
    W[0::2, 2] = -P[:, 1]
    W[1::2, 2] = P[:, 0]
    return W / np.linalg.norm(W, axis=0)


def spectral_compliance(K, points):
    """The paper's pseudo-inverse of K (2n, 2n): eigendecomposition, the three smallest
    (rigid) eigenvalues dropped; and the normalized rigid basis (2n, 3)."""
    lam, V = np.linalg.eigh(K)
    order = np.argsort(lam)
    lam, V = lam[order], V[:, order]
    if not (np.all(np.abs(lam[:3]) < 1e-9 * lam[-1]) and lam[3] > 1e-9 * lam[-1]):
        raise ValueError(f"K must have exactly 3 zero eigenvalues (got {lam[:5]})")
    Vp = V[:, 3:]
    G = (Vp / lam[3:]) @ Vp.T
    return G, rigid_basis(points)


def loop_normals(p):
    """Outward unit normals at the nodes of a closed ccw loop (k, 2): normalized sum of the
    unit outward normals of the two adjacent edges."""
    e = np.roll(p, -1, axis=0) - p                      # edge i: p_i -> p_{i+1}
    ne = np.c_[e[:, 1], -e[:, 0]] / np.linalg.norm(e, axis=1)[:, None]   # outward for ccw
    s = ne + np.roll(ne, 1, axis=0)
    return s / np.linalg.norm(s, axis=1)[:, None]


def loops_normals(P, loops):
    """:func:`loop_normals` loop by loop (boundary points ordered as the loops)."""
    out, start = [], 0
    for size in loops:
        out.append(loop_normals(P[start:start + size]))
        start += size
    return np.concatenate(out)


def _unit(v):
    return v / np.linalg.norm(v)


def _turn(n, a):
    c, s = np.cos(a), np.sin(a)
    return np.array([c * n[0] - s * n[1], s * n[0] + c * n[1]])


def first_touch(x, o, v, r):
    """(t, k): a circle of radius r whose centre moves along o + t v (unit v, from far behind)
    first touches point k of x (m, 2) at t (the smaller root of |x_k - o - t v| = r, smallest
    over the points; inf when it misses them all): docs/planning.md, "Approach"."""
    w = x - o
    b = w @ v
    disc = b * b - np.sum(w * w, axis=1) + r * r
    t = np.where(disc > 0, b - np.sqrt(np.where(disc > 0, disc, 1.0)), np.inf)
    k = int(np.argmin(t))
    return float(t[k]), k


def inside_loops(P, loops, q):
    """(k,) bool: points q (k, 2) inside the object bounded by the loops of P (even-odd rule)."""
    q = np.atleast_2d(q)
    nxt, start = [], 0
    for size in loops:
        nxt.append(start + (np.arange(size) + 1) % size)
        start += size
    nxt = np.concatenate(nxt)
    a, b = P[None], P[nxt][None]
    qq = q[:, None, :]
    st = (a[..., 1] > qq[..., 1]) != (b[..., 1] > qq[..., 1])
    dy = np.where(st, b[..., 1] - a[..., 1], 1.0)
    xc = a[..., 0] + (qq[..., 1] - a[..., 1]) * (b[..., 0] - a[..., 0]) / dy
    return np.sum(st & (qq[..., 0] < xc), axis=1) % 2 == 1


# ----------------------------------------------------------------------------- configuration
@dataclass
class Contact:
    finger: int
    mode: int            # 1 stick, 2 slip +, 3 slip -
    angle: float         # anchor (stick) or current angle (slip) [rad]
    armed: bool = True   # D may fire (the rate was consistent once)


@dataclass
class Event:
    kind: str
    node: int            # mesh index
    depth: float         # [m]
    finger: int


@dataclass
class OracleResult:
    status: str
    final_depth: float
    forces: np.ndarray        # (m, 2) [N] per boundary position (mesh.boundary order)
    modes: np.ndarray         # (m,) 0 free, 1 stick, 2/3 slip
    finger: np.ndarray        # (m,) finger of contact nodes (-1 free)
    theta: np.ndarray         # (m,) polar angle of contact nodes, finger frame (nan free)
    boundary_displacement: np.ndarray   # (m, 2) [m]
    events: list = field(default_factory=list)
    total_force: np.ndarray = None      # (2, 2) [N] per finger
    g: np.ndarray = None
    centres: np.ndarray = None          # (2, 2) [m]
    nodes: np.ndarray = None            # (m,) mesh indices
    alpha: np.ndarray = None            # (F,) fingertip rotations [rad] at the final depth
    grip: tuple = None                  # mesh indices of the first contacts (finger 0, finger 1)
    # the adversary's push (squeeze_oracle(adversary=...)); squeeze_status/events set on every result
    squeeze_status: str = None
    squeeze_events: int = 0
    final_push: float = 0.0
    adversary_work: float = None
    finger_work: np.ndarray = None
    failure_push: float = None

    def contact_set(self):
        return {int(self.nodes[k]): (int(self.finger[k]), int(self.modes[k])) for k in np.flatnonzero(self.modes > 0)}


class Squeeze:
    """One squeeze in scaled units. ``P`` (m, 2) boundary points / L; ``Gbb`` (2m, 2m) the
    boundary block of K^+ (scaled); ``Nb`` (2m, 3) the rigid basis on the boundary."""

    def __init__(self, points, triangles, boundary, nu, radius, grip, model, mu, normals=None, rotation=None,
                 contact="segment", placement=None, loops=None):
        pts = np.asarray(points, float)
        pts = pts - pts.mean(0)
        self.L = float(np.ptp(pts, axis=0).max())
        self.pts = pts / self.L
        self.bnd = np.asarray(boundary, int)
        self.m = len(self.bnd)
        self.loops = tuple(int(v) for v in loops) if loops is not None else (self.m,)
        K = cst_stiffness(self.pts, triangles, nu)
        G, W = spectral_compliance(K, self.pts)
        dofs = np.ravel(np.c_[2 * self.bnd, 2 * self.bnd + 1])
        self.Gbb = G[np.ix_(dofs, dofs)]
        self.Nb = W[dofs]
        self.P = self.pts[self.bnd]
        self.normals = loops_normals(self.P, self.loops) if normals is None else np.asarray(normals, float)
        self.r = radius / self.L
        if contact not in ("segment", "point"):
            raise ValueError(f"contact={contact!r}")
        self.contact = contact
        self.F = 2                                  # fingers present (3 in the adversary's push)
        self.rv = np.array([self.r, self.r])        # radius of each finger (scaled)
        self.hold = None                            # scaled depth at which the rotation is held (push phase)
        self._curve = None
        if placement is None:
            pos = {int(v): k for k, v in enumerate(self.bnd)}
            self.grip = (pos[int(grip[0])], pos[int(grip[1])])
            i, j = self.grip
            self.C0 = np.array([self.P[i] + self.r * self.normals[i], self.P[j] + self.r * self.normals[j]])
            u = self.P[i] - self.P[j]
            self.u = u / np.linalg.norm(u)
        else:
            # continuous placement (docs/planning.md, "Continuous placement"): centres at
            # p(s_i) + r n(s_i) on the periodic chord-length C2 spline of the outer loop, squeeze
            # direction e = unit(p(s0) - p(s1)) turned by angle, each tip closed in along -e / +e
            # until it first touches a node (the smaller root of |x - o - t v| = r)
            s01, ang = placement
            q, n = self.spline_point(np.asarray(s01, float) / self.L)
            e = _turn(_unit(q[0] - q[1]), float(ang))
            o = q + self.r * n
            t0, k0 = first_touch(self.P, o[0], -e, self.r)
            t1, k1 = first_touch(self.P, o[1], e, self.r)
            if not (np.isfinite(t0) and np.isfinite(t1) and k0 != k1 and t0 > -self.r and t1 > -self.r):
                raise ValueError("placement: a fingertip cannot touch the object")
            self.C0 = np.array([o[0] - t0 * e, o[1] + t1 * e])
            if inside_loops(self.P, self.loops, self.C0).any():
                raise ValueError("placement: a fingertip centre lies inside the object")
            self.grip = (int(k0), int(k1))
            self.u = e
        self.base = self.C0.copy()
        self.dirn = np.array([[0.0, 0.0], self.u])
        self.model = model
        self.mu = mu
        # rotation schedules: coefficients in d [m] (highest power first); evaluated at d * L
        self.rot = None if rotation is None else np.atleast_2d(np.asarray(rotation, float))
        if self.rot is not None and self.rot.shape[0] != 2:
            raise ValueError("rotation must have shape (2, k)")

    # --------------------------------------------------------------- smooth outer loop
    def spline(self):
        """(knots (k+1,), scipy CubicSpline) of the outer loop, scaled units: periodic, C2, by chord length
        (jaxsqueeze.geometry.boundary.curve's documented definition)."""
        if self._curve is None:
            from scipy.interpolate import CubicSpline
            p = self.P[:self.loops[0]]
            closed = np.vstack([p, p[:1]])
            knots = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
            self._curve = (knots, CubicSpline(knots, closed, bc_type="periodic"))
        return self._curve

    def spline_point(self, s):
        """Point(s) and outward unit normal(s) at scaled arc length s (periodic)."""
        knots, cs = self.spline()
        s = np.mod(s, knots[-1])
        p, dp = cs(s), cs(s, 1)
        tan = dp / np.linalg.norm(dp, axis=-1, keepdims=True)
        return p, np.stack([tan[..., 1], -tan[..., 0]], axis=-1)

    def alpha(self, d):
        """(F,) fingertip rotations [rad] at scaled load d (held at the squeeze depth in the push)."""
        out = np.zeros(self.F)
        if self.rot is not None:
            dd = self.hold if self.hold is not None else d
            out[:2] = [np.polyval(c, dd * self.L) for c in self.rot]
        return out

    def dalpha(self, d):
        """(F,) d alpha / d load per scaled unit (rad per L); 0 while the rotation is held."""
        out = np.zeros(self.F)
        if self.rot is not None and self.hold is None:
            out[:2] = [np.polyval(np.polyder(c), d * self.L) * self.L if len(c) > 1 else 0.0 for c in self.rot]
        return out

    def centres(self, d):
        return self.base + d * self.dirn

    def surface_axes(self, U):
        """(m, 2) inward unit normals of the deformed object (boundary points P + U): minus the
        normalized sum of the two adjacent deformed edges' outward normals (the point contact's
        cone axis; jaxsqueeze.geometry.boundary.normals on deformed positions)."""
        return -loops_normals(self.P + U, self.loops)

    def cone_components(self, st, a, k):
        """(fn, ft) of contact a (key k) in its cone's frame: the fingertip normal (segment
        contacts) or the deformed object's inward surface normal (point contacts)."""
        if self.contact == "segment":
            return st["fn"][a], st["ft"][a]
        ax = self.surface_axes(st["U"])[k]
        f = st["f"][a]
        return f @ ax, ax[0] * f[1] - ax[1] * f[0]

    # --------------------------------------------------------------- one configuration
    def _system(self, keys, cfg):
        idx = np.ravel([[2 * k, 2 * k + 1] for k in keys])
        A = self.Gbb[np.ix_(idx, idx)]
        B = self.Nb[idx]
        s2 = len(idx)
        M = np.zeros((s2 + 3, s2 + 3))
        M[:s2, :s2] = A
        M[:s2, s2:] = B
        M[s2:, :s2] = B.T
        return M, idx

    def solve(self, cfg, d, guess=None, tol=1e-13, iters=60):
        """Forces (s, 2), g (3,), angles (s,), angle rates dtheta/dd (s,) of configuration
        ``cfg`` (dict pos -> Contact) at depth d (scaled); Newton on the sliding angles."""
        keys = sorted(cfg)
        s = len(keys)
        M, idx = self._system(keys, cfg)
        C = self.centres(d)
        fing = np.array([cfg[k].finger for k in keys], int).reshape(-1)
        al = self.alpha(d)[fing]            # world angle = local angle + al
        dal = self.dalpha(d)[fing]
        th = np.array([cfg[k].angle for k in keys], float)
        if guess is not None:
            th = np.array([guess.get(k, cfg[k].angle) if cfg[k].mode >= 2 else cfg[k].angle for k in keys])
        slip = np.array([cfg[k].mode >= 2 for k in keys], bool)
        sgn = np.array([1.0 if cfg[k].mode == 2 else -1.0 for k in keys])
        mu = 0.0 if self.model == "frictionless" else self.mu
        Pk = self.P[keys]
        rk = self.rv[fing]                  # radius of each contact's finger
        lu = np.linalg.inv(M)      # small (2s + 3); fine for an oracle
        sl = np.flatnonzero(slip)

        def forces(th):
            e = np.c_[np.cos(th + al), np.sin(th + al)]
            dvec = C[fing] + rk[:, None] * e - Pk
            z = lu @ np.r_[dvec.ravel(), np.zeros(3)]
            return z[:2 * s].reshape(s, 2), z[2 * s:], e

        def resid(f, e):
            t = np.c_[-e[:, 1], e[:, 0]]
            fn = np.sum(f * e, 1)
            ft = np.sum(f * t, 1)
            return ft[sl] + sgn[sl] * mu * fn[sl], fn, ft, t      # only sliding nodes (full stick: mu = inf)

        def jacobian(e, t, fn, ft):
            """dR_k/dtheta_j of the sliding nodes (eq. 6 differentiated through the bordered solve)."""
            cols = np.zeros((2 * s + 3, len(sl)))
            for a, k in enumerate(sl):
                cols[2 * k:2 * k + 2, a] = rk[k] * t[k]
            dF = (lu @ cols)[:2 * s].reshape(s, 2, len(sl))
            w = t + (sgn * mu)[:, None] * e
            J = np.einsum("kc,kca->ka", w, dF)[sl]
            J[np.arange(len(sl)), np.arange(len(sl))] += (-fn + sgn * mu * ft)[sl]
            return J

        ok = True
        for it in range(iters):
            f, g, e = forces(th)
            R, fn, ft, t = resid(f, e)
            if len(sl) == 0:
                break
            J = jacobian(e, t, fn, ft)
            step = np.linalg.solve(J, -R)
            th[sl] += step
            if np.abs(step).max() < tol:
                f, g, e = forces(th)
                R, fn, ft, t = resid(f, e)
                break
        else:
            ok = False
        # angle rates by the implicit function theorem
        rate = np.zeros(s)
        if len(sl):
            J = jacobian(e, t, fn, ft)
            w = t + (sgn * mu)[:, None] * e
            # partial d/dd at fixed local angles: the centre's motion, every node turning with
            # its tip (r t alpha'), and the cone's own turn through n, t (same term as J's diagonal)
            rd = np.zeros(2 * s + 3)
            for k in range(s):
                rd[2 * k:2 * k + 2] = self.dirn[fing[k]]
                rd[2 * k:2 * k + 2] += rk[k] * t[k] * dal[k]
            dFd = (lu @ rd)[:2 * s].reshape(s, 2)
            Rd = (np.sum(w * dFd, 1) + (-fn + sgn * mu * ft) * dal)[sl]
            rate[sl] = -np.linalg.solve(J, Rd)
        U = (self.Gbb[:, idx] @ f.ravel() + self.Nb @ g).reshape(-1, 2)
        return dict(keys=keys, f=f, g=g, theta=th, rate=rate, fn=fn, ft=ft, U=U, C=C, ok=ok, alpha=self.alpha(d),
                    resid=np.abs(R).max(initial=0.0))

    # --------------------------------------------------------------- event functions
    def triggers(self, cfg, st, gap_tol, ftol, rtol):
        """Events whose condition holds in solution ``st`` of ``cfg``: list of (kind, pos, finger, value)."""
        out = []
        X = self.P + st["U"]
        if self.contact == "segment":           # point contacts: no event A
            for f in range(self.F):
                gap = np.linalg.norm(X - st["C"][f], axis=1) - self.rv[f]
                for k in np.flatnonzero(gap < -gap_tol):
                    if int(k) not in cfg:
                        out.append(("A", int(k), f, gap[k]))
        for a, k in enumerate(st["keys"]):
            c = cfg[k]
            fn, ft = self.cone_components(st, a, k)
            if fn < -ftol:
                out.append(("B", k, c.finger, fn))     # it lets go: no C or D for it
                continue
            if self.model == "coulomb" and c.mode == 1:
                marg = cone_margin(fn, ft, self.mu)
                if marg < -ftol:
                    out.append(("C", k, c.finger, marg))
            if self.model == "coulomb" and c.mode >= 2 and c.armed:
                s = 1.0 if c.mode == 2 else -1.0
                if s * st["rate"][a] < -rtol:
                    out.append(("D", k, c.finger, s * st["rate"][a]))
        return out


def squeeze_oracle(points, triangles, boundary, E, nu, thickness, radius, grip, friction, depth,
                   model="coulomb", normals=None, step=None, depth_tol=1e-12, gap_tol=1e-9,
                   probe=1e-6, max_events=500, rotation=None, contact="segment", placement=None,
                   adversary=None, loops=None):
    """Simulate a squeeze (see the module docstring) and return an :class:`OracleResult`.

    Args:
        points (n, 2) [m], triangles (t, 3) ccw, boundary (m,) outer loop ccw (mesh indices).
        E [Pa], nu, thickness [m]: material; radius [m]: fingertip radius.
        grip (i, j): mesh node indices touched by finger 0 (still) and finger 1 (moving).
        friction: mu (``inf`` selects the all-stick model, 0 the frictionless one).
        depth [m]: target squeeze depth.
        model: "coulomb", "stick" or "frictionless" (forced by friction = inf / 0).
        normals: (m, 2) outward normals at the boundary nodes; default: own loop normals.
        step: depth step [m] between event checks (default depth / 50).
        depth_tol: bracket width of an event depth, relative to the object size L.
        gap_tol: penetration relative to L at which event A fires.
        probe: extra squeeze (relative to L) at which a new contact's stick hypothesis is tested.
        rotation: None or (2, k) polynomial coefficients of alpha_0(d), alpha_1(d) [rad], d in
            metres, highest power first (the library's ``Fingers.rotation``).
        contact: "segment" (event A: contact regions grow) or "point" (one contact per finger,
            no event A; the cone is about the deformed object's inward surface normal at the
            node, so the stick test (C) and the break test (B: the normal force along that axis
            turns negative, the force leaving the cone through its apex, Section IV-B.2) turn
            with the surface; a sliding node's force (eq. 6) stays about the fingertip normal).
        placement: None or (s (2,) [m], angle [rad]): a continuous placement (docs/planning.md);
            ``grip`` is then ignored (pass None).
        adversary: None or dict(s=[m], push=[m], angle=0.0, radius=None, step=None): after a
            successful squeeze a third fingertip pushes (docs/planning.md, "The adversary push").
            The pusher's s refers to the outer loop's spline (as a Placement's).
        loops: the mesh's boundary loop sizes (default: one loop).
    """
    if np.isinf(friction):
        model = "stick"
    if friction == 0 and model == "coulomb":
        model = "frictionless"
    sq = Squeeze(points, triangles, boundary, nu, radius, grip, model, friction, normals, rotation, contact,
                 placement, loops)
    L = sq.L
    D = depth / L
    h = (step / L) if step is not None else D / 50
    ftol, rtol = 1e-14, 1e-10

    # initial contacts: the grip nodes, touching at d = 0 (force 0); stick unless frictionless
    cfg = {}
    for f, k in enumerate(sq.grip):
        v = sq.P[k] - sq.C0[f]
        mode = 2 if model == "frictionless" else 1
        cfg[k] = Contact(f, mode, float(np.arctan2(v[1], v[0]) - sq.alpha(0.0)[f]))
    d = 0.0
    st = sq.solve(cfg, d)
    status = "SUCCESS"
    slid = []
    if model == "coulomb" and sq.rot is None:
        # a grip inside both cones sticks; test at a probe depth as for any new contact
        cfg, st, slid = _hypothesis(sq, cfg, set(cfg), d, probe, ftol)
        status = _failure(sq, cfg)
    # with rotating tips the grip forces turn as d grows (the tip's twist adds a tangential
    # push), so a grip on its cone edge may leave the cone after a few nm, at a depth the probe
    # cannot resolve: the grip starts sticking and event C locates the exit by bisection
    # (fuzz seed 1 #51: grip within CONE_SLACK of the edge, C at 1e-7 rad / alpha' = 4.2e-9 m)
    cfg, st, status, d, events, rows = _run(sq, cfg, st, status, 0.0, D, h, depth_tol, gap_tol, probe, ftol, rtol,
                                            max_events)
    events = slid + events
    res = _result(sq, cfg, st, status, d, events, E, thickness)
    res.squeeze_status = status
    res.squeeze_events = len(events)
    res.final_push = 0.0
    if adversary is None:
        return res
    res.push_status = None
    if status != "SUCCESS":
        return res
    # ------------------------------------------------------------------ the adversary's push
    adv = dict(angle=0.0, radius=None, step=None)
    adv.update(adversary)
    r3 = (adv["radius"] if adv["radius"] is not None else radius) / L
    P3 = adv["push"] / L
    h3 = adv["step"] / L if adv["step"] is not None else min(P3 / 50, r3)
    knots, _ = sq.spline()
    s3 = adv["s"] / L
    q, n = sq.spline_point(s3)
    # the material point at arc length s on the squeezed object: node displacements interpolated
    # along the span that holds it; the spline normal turned by the outline's rotation there,
    # interpolated the same way between node rotations (the mean of the two chords' turns at
    # each outer-loop node)
    nk = len(knots) - 1
    sm = np.mod(s3, knots[-1])
    i = int(np.clip(np.searchsorted(knots, sm, side="right") - 1, 0, nk - 1))
    j = (i + 1) % nk
    w = (sm - knots[i]) / (knots[i + 1] - knots[i])
    U = st["U"]
    q = q + (1 - w) * U[i] + w * U[j]
    c0 = np.roll(sq.P[:nk], -1, axis=0) - sq.P[:nk]                  # chord k: node k -> k + 1
    c1 = c0 + np.roll(U[:nk], -1, axis=0) - U[:nk]
    spin = np.arctan2(c0[:, 0] * c1[:, 1] - c0[:, 1] * c1[:, 0], np.sum(c0 * c1, axis=1))
    at_node = 0.5 * (spin + np.roll(spin, 1))                          # node k: chords k - 1 and k
    nd = _turn(n, (1 - w) * at_node[i] + w * at_node[j])
    v = -_turn(nd, adv["angle"])
    o = q + r3 * nd
    X = sq.P + U
    t, k3 = first_touch(X, o, v, r3)
    touches = np.isfinite(t) and t > -r3
    c3 = o + (t if touches else 0.0) * v
    held = sq.centres(d)
    clear = np.all(np.linalg.norm(held - c3, axis=1) > sq.rv + r3)
    touches = touches and clear and not inside_loops(X, sq.loops, c3)[0]
    res.pusher_start = c3 * L
    res.pusher_node = int(sq.bnd[k3])
    if not touches:
        res.status = "INFEASIBLE_GRIP"
        return res
    sq.hold = d
    sq.base = np.vstack([held, c3])
    sq.dirn = np.vstack([np.zeros((2, 2)), v])
    sq.rv = np.r_[sq.rv, r3]
    sq.F = 3
    st = sq.solve(cfg, 0.0)
    cfg, st, status, lam, ev2, rows2 = _run(sq, cfg, st, "SUCCESS", 0.0, P3, h3, depth_tol, gap_tol, probe, ftol,
                                            rtol, max_events)
    out = _result(sq, cfg, st, status, d, events + ev2, E, thickness)
    out.squeeze_status, out.squeeze_events, out.final_push = res.squeeze_status, len(events), lam * L
    out.squeeze_result = res
    out.pusher_start, out.pusher_node, out.push_dir = res.pusher_start, res.pusher_node, v
    # qualities from the recorded rows (trapezoid rule, plan/quality.py): the pusher waits at its
    # start (force 0) in the squeeze's last row; rows of the push at every step and event
    Fs = E * thickness * L
    tot = [np.vstack([res.total_force, np.zeros((1, 2))])] + [r["tot"] * Fs for r in rows2]
    x2 = [c3 * L] + [r["C"][2] * L for r in rows2]
    tot, x2 = np.array(tot), np.array(x2)
    dx = np.diff(x2, axis=0)
    out.adversary_work = float(np.sum(0.5 * (tot[1:, 2] + tot[:-1, 2]) * dx))
    dF = tot[:, :2] - tot[0, :2]
    out.finger_work = np.array([-np.sum(0.5 * (dF[1:, i] + dF[:-1, i]) * dx) for i in (0, 1)])
    out.failure_push = lam * L
    out.push_rows = np.array([r["d"] * L for r in rows2])
    return out


#: a contact pulling by more than this share of the largest force right after an event pass lets go there
PULL = 1e-8
#: a free node inside a fingertip by more than this many gap_tol right after an event pass joins there
SUNK = 10
#: event passes at one depth after which a set that still changes is no consistent set: STALLED
SETTLE = 16


def _run(sq, cfg, st, status, d, D, h, depth_tol, gap_tol, probe, ftol, rtol, max_events):
    """One loading phase from load d to D (scaled): steps, event location by bisection, events
    applied, new contacts' hypotheses, D at an event depth. Returns (cfg, st, status, d, events,
    rows), rows a list of dict(d, tot (F, 2) scaled finger totals, C) at every step and event."""
    L = sq.L
    model = sq.model
    events, rows = [], []

    def record(d, st):
        tot = np.zeros((sq.F, 2))
        for a, k in enumerate(st["keys"]):
            tot[cfg[k].finger] += st["f"][a]
        rows.append(dict(d=d, tot=tot, C=st["C"].copy()))

    guard = 0
    pulled = []     # contacts that pull, and free nodes sunk into a tip, in the set an event pass left
    passes = 0      # event passes at the current depth
    while status == "SUCCESS" and d < D * (1 - 1e-14):
        passes = passes + 1 if pulled else 1
        if pulled:
            trig, st_hi, hi = pulled, st, d
        else:
            d1 = min(d + h, D)
            guess = {k: th for k, th in zip(st["keys"], st["theta"])}
            st1 = sq.solve(cfg, d1, guess)
            trig = sq.triggers(cfg, st1, gap_tol, ftol * _fscale(st1), rtol)
            if not trig:
                d, st = d1, st1
                _arm(cfg, st, rtol)
                _update_angles(cfg, st)
                record(d, st)
                continue
            lo, hi = d, d1
            st_hi = st1
            while hi - lo > depth_tol:
                mid = 0.5 * (lo + hi)
                sm = sq.solve(cfg, mid, guess)
                if sq.triggers(cfg, sm, gap_tol, ftol * _fscale(sm), rtol):
                    hi, st_hi = mid, sm
                else:
                    lo = mid
            trig = sq.triggers(cfg, st_hi, gap_tol, ftol * _fscale(st_hi), rtol)
        d = hi
        _update_angles(cfg, st_hi)
        new = set()
        for kind, k, f, _ in trig:
            events.append(Event(kind, int(sq.bnd[k]), d * L, f))
            if kind == "A":
                v = sq.P[k] + st_hi["U"][k] - st_hi["C"][f]
                cfg[k] = Contact(f, 2 if model == "frictionless" else 1,
                                 float(np.arctan2(v[1], v[0]) - st_hi["alpha"][f]), armed=False)
                new.add(k)
            elif kind == "B":
                del cfg[k]
            elif kind == "C":
                a = st_hi["keys"].index(k)
                # the side of the cone the force leaves through (point contacts: the surface cone)
                ft = sq.cone_components(st_hi, a, k)[1]
                cfg[k].mode = 2 if ft < 0 else 3
                cfg[k].armed = False
            elif kind == "D":
                cfg[k].mode = 1
        if _failure(sq, cfg) == "LOST_CONTACT":
            # a finger let go of its last contact: the squeeze ends at this depth, the object free
            status = "LOST_CONTACT"
            st = sq.solve(cfg, d) if cfg else dict(keys=[], f=np.zeros((0, 2)), g=np.zeros(3), theta=np.zeros(0),
                                                   U=np.zeros_like(sq.P), C=sq.centres(d), alpha=sq.alpha(d))
            record(d, st)
            break
        cfg, st, slid = _hypothesis(sq, cfg, new, d, probe, ftol)
        events += slid
        status = _failure(sq, cfg)
        if status == "SUCCESS" and model == "coulomb":
            # D at an event depth (docs/numerics.md section 6): the events changed every rate; an
            # armed sliding node whose slip rate is now negative sticks here. (Without this, a rate
            # that is negative just after the event and positive again at the next step's end was
            # never seen: found with rotating tips, fuzz seed 0 #37.)
            # One node at a time, the most negative rate first, re-solving in between: sticking
            # one node changes the others' rates (compare_rot.py case 04 at d = 9.67 mm: nodes 6 and 7
            # both negative; with 7 stuck, 6's rate is +2.3e-2, while sticking both left 6 on its
            # cone edge with its force turning out, C 6 1.2e-8 m later; the library sticks 7 only).
            while status == "SUCCESS":
                cand = [(s * st["rate"][a], a, k) for a, k in enumerate(st["keys"])
                        for c in [cfg[k]] for s in [1.0 if c.mode == 2 else -1.0]
                        if c.mode >= 2 and c.armed and s * st["rate"][a] < -rtol]
                if not cand:
                    break
                _, a, k = min(cand)
                c = cfg[k]
                events.append(Event("D", int(sq.bnd[k]), d * L, c.finger))
                c.mode = 1
                c.angle = float(st["theta"][a])
                st = sq.solve(cfg, d)
                status = _failure(sq, cfg)
        # a contact that pulls in the new set by more than round-off (a release that loaded it
        # into tension) lets go here, and a free node that a release left inside a tip (full
        # stick: a dropped shear force) joins here, each with the other contacts that pull or
        # nodes that sink meanwhile, at this depth, not at the next step's end, where the force
        # may have recovered or the node come out again; a set that still changes after SETTLE
        # passes at one depth (it pulls in contact and sinks when free) is no consistent set
        now = sq.triggers(cfg, st, gap_tol, ftol * _fscale(st), rtol) if status == "SUCCESS" else []
        settle = any((t[0] == "B" and t[3] < -PULL * _fscale(st)) or (t[0] == "A" and t[3] < -SUNK * gap_tol)
                     for t in now)
        pulled = [t for t in now if t[0] in "AB"] if settle else []
        record(d, st)
        if pulled and passes >= SETTLE:
            status = "STALLED"
            break
        guard += 1
        if guard > max_events:
            status = "EVENT_OVERFLOW"
    return cfg, st, status, d, events, rows


def _fscale(st):
    return max(np.abs(st["f"]).max(initial=0.0), 1e-300)


def _update_angles(cfg, st):
    for k, th in zip(st["keys"], st["theta"]):
        if cfg[k].mode >= 2:
            cfg[k].angle = float(th)


def _arm(cfg, st, rtol):
    for a, k in enumerate(st["keys"]):
        c = cfg[k]
        if c.mode >= 2 and not c.armed:
            s = 1.0 if c.mode == 2 else -1.0
            if s * st["rate"][a] > 0:
                c.armed = True


def _hypothesis(sq, cfg, new, d, probe, ftol):
    """New contacts start sticking. Their force grows from zero: a force rate (the difference of
    the forces at d + probe and d + 2 probe, which drops the tiny push of the gap_tol
    penetration the contact was found at) outside the cone turns the node into a slider on
    the edge it leaves through, a C event at d (frictionless contacts: labelled by their angle
    rate, no event). The cone is the fingertip's (segment contacts) or the deformed surface's
    (point contacts). Returns (cfg, st, the C events)."""
    slid = []
    if new:
        st1 = sq.solve(cfg, d + probe)
        st2 = sq.solve(cfg, d + 2 * probe)
        ax_s = sq.surface_axes(st1["U"]) if sq.contact == "point" else None
        for a, k in enumerate(st1["keys"]):
            if k not in new:
                continue
            c = cfg[k]
            # the force difference, resolved in st1's frame (the cone turns with the tip)
            df = st2["f"][a] - st1["f"][a]
            if ax_s is None:
                w1 = st1["theta"][a] + st1["alpha"][c.finger]
            else:
                w1 = np.arctan2(ax_s[k, 1], ax_s[k, 0])
            dfn = df[0] * np.cos(w1) + df[1] * np.sin(w1)
            dft = -df[0] * np.sin(w1) + df[1] * np.cos(w1)
            if sq.model == "coulomb" and c.mode == 1:
                if cone_margin(dfn, dft, sq.mu) < 0:
                    c.mode = 2 if dft < 0 else 3
                    slid.append(Event("C", int(sq.bnd[k]), d * sq.L, c.finger))
        if slid:
            # the edge is a guess from the stick trial's force rate: a new slider whose force
            # still pulls at the probe and does not rise takes the other edge, once (no event:
            # it slides either way); if that pulls too, it lets go by event B
            s1, s2 = sq.solve(cfg, d + probe), sq.solve(cfg, d + 2 * probe)
            for a, k in enumerate(s1["keys"]):
                if k in new and cfg[k].mode >= 2:
                    fn1, fn2 = sq.cone_components(s1, a, k)[0], sq.cone_components(s2, a, k)[0]
                    if fn1 <= 0 and fn2 <= fn1:
                        cfg[k].mode = 5 - cfg[k].mode
        if sq.model == "frictionless":
            st = sq.solve(cfg, d + probe)
            for a, k in enumerate(st["keys"]):
                if k in new:
                    cfg[k].mode = 2 if st["rate"][a] >= 0 else 3
    st = sq.solve(cfg, d)
    _arm(cfg, st, 0)
    return cfg, st, slid


def _failure(sq, cfg):
    for f in (0, 1):
        mine = [c for c in cfg.values() if c.finger == f]
        if not mine:
            return "LOST_CONTACT"
        if sq.model == "coulomb" and all(c.mode >= 2 for c in mine):
            return "SLIP_FAILURE"
    return "SUCCESS"


def _result(sq, cfg, st, status, d, events, E, h):
    L, Fs = sq.L, E * h * sq.L
    m = sq.m
    F = np.zeros((m, 2))
    modes = np.zeros(m, int)
    finger = -np.ones(m, int)
    theta = np.full(m, np.nan)
    for a, k in enumerate(st["keys"]):
        F[k] = st["f"][a] * Fs
        modes[k] = cfg[k].mode
        finger[k] = cfg[k].finger
        theta[k] = st["theta"][a]
    tot = np.array([F[finger == f].sum(0) for f in range(sq.F)])
    return OracleResult(status=status, final_depth=d * L, forces=F, modes=modes, finger=finger, theta=theta,
                        boundary_displacement=st["U"] * L, events=events, total_force=tot, g=st["g"],
                        centres=st["C"] * L, nodes=sq.bnd.copy(), alpha=st["alpha"], grip=tuple(int(sq.bnd[k]) for k in sq.grip))


def from_mesh(mesh, E, nu, thickness, radius, grip, friction, depth, **kw):
    """:func:`squeeze_oracle` on a jaxsqueeze ``Mesh`` (points, triangles, boundary loop)."""
    kw.setdefault("loops", tuple(int(v) for v in getattr(mesh, "loops", (len(mesh.boundary),))))
    return squeeze_oracle(np.asarray(mesh.points), np.asarray(mesh.triangles), np.asarray(mesh.boundary),
                          E, nu, thickness, radius, grip, friction, depth, **kw)
