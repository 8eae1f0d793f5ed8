"""The event-driven squeeze (Section IV, DESIGN 2.1 and 2.4–2.7).

One finger stays still, the other translates toward it by the depth d. Every boundary node is
free, sticking to a fingertip at a fixed anchor angle, or sliding on it with its force on a
friction-cone edge. Each step solves the *total* equations from the undeformed state for the
current contact configuration (DESIGN 2.1): prescribed positions of the contact nodes on the
fingertip circles, the bordered system (eq. 4) for the forces, and Newton on the slip angles
(system S, eq. 6) with ``jax.jacobian``. Signed event functions detect events A–D; the
earliest crossing is bracketed (Illinois regula falsi, safeguarded by bisection) and refined by
one implicit-function step, so the event depth carries its derivative.

Units inside are scaled (DESIGN 2.3): lengths / L, forces / (E h L).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

from ..mechanics import linalg
from ..mechanics.bordered import bordered_matrix, slot_dofs
from ..mechanics.operator import Compliance
from . import laws
from .laws import CONE_SLACK, EVENT_KINDS, FREE, SLIP_NEG, SLIP_POS, STICK  # noqa: F401
from ..geometry import boundary
from .status import Status

RUNNING = -1


# ----------------------------------------------------------------------------- configuration
@dataclass(frozen=True)
class Config:
    """Static configuration: which effects are compiled in (DESIGN 2.7) and capacities."""

    friction_model: str = "coulomb"   # "coulomb" | "frictionless" | "stick"
    contact: str = "segment"          # "segment" | "point"
    rotation: bool = False
    capacity: int = 64
    max_steps: int = 400
    max_events: int = 256
    newton_iters: int = 30
    bisect_iters: int = 40
    placement: bool = False           # fingers placed by arc length (an approach finds first touch)
    adversary: bool = False           # a third finger pushes after the squeeze (a second phase)

    @property
    def fingers(self) -> int:
        return 3 if self.adversary else 2

    @property
    def newton(self) -> bool:
        return self.friction_model != "stick"

    @property
    def slip_events(self) -> bool:   # events C and D
        return self.friction_model == "coulomb"


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Grasp:
    """Traced grasp parameters in SI units (they become scaled inside :func:`simulate`).

    grip: (2,) int positions of the two grip nodes among the operator's nodes (ignored when
        ``placement`` is given: the approach finds the first-touch nodes).
    radius: fingertip radius [m]; mu: friction coefficient; depth: target depth [m];
    step: squeeze step [m]; event_tol: event bracket width [m]; newton_tol: [rad];
    gap_tol: penetration tolerance [m]; rotation: (2, k) polynomial coefficients of α_i(d).
    invalid: () int32 index of the first invalid input (``validate.FIELDS``), -1 when valid.
    """

    grip: jax.Array
    radius: jax.Array
    mu: jax.Array
    depth: jax.Array
    step: jax.Array
    event_tol: jax.Array
    newton_tol: jax.Array
    gap_tol: jax.Array
    rotation: jax.Array
    invalid: jax.Array
    placement: tuple = ()     # (s (2,) [m], angle () [rad]) when placed by arc length
    adversary: tuple = ()     # (s () [m], angle () [rad], radius () [m], push () [m], step () [m])
    curve: tuple = ()         # boundary.Curve of the outer loop [m], when placed or pushed


def unit(a):
    return jnp.stack([jnp.cos(a), jnp.sin(a)], axis=-1)


def cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Model:
    """Everything fixed during one loading phase, in scaled units (lengths / L). A pytree: the
    configuration is static, everything else an array leaf.

    The fingertip centres move linearly with the phase's load parameter λ (the squeeze depth
    d in the squeeze phase, the push displacement in the adversary phase):
    ``centres(λ) = base + λ · dirn``. Finger 0 is still, finger 1 squeezes, finger 2 (when
    ``cfg.adversary``) pushes.
    """

    op: Compliance
    cfg: Config = dataclasses.field(metadata=dict(static=True))
    base: jax.Array      # (F, 2) centres at λ = 0
    dirn: jax.Array      # (F, 2) centre velocity per unit λ
    present: jax.Array   # (F,) bool: the finger takes part in contact in this phase
    r: jax.Array         # (F,) radii
    phi: jax.Array       # friction angle atan(mu)
    mu: jax.Array
    L: jax.Array
    rotation: jax.Array  # (2, k), SI
    rot_depth: jax.Array  # (2,): the depth at λ is rot_depth[0] + rot_depth[1] λ (rotation schedule)
    grip: jax.Array      # (2,) boundary positions of the first contacts (clipped to a valid index)
    D: jax.Array         # target of λ
    h: jax.Array         # step of λ
    ev_tol: jax.Array    # event bracket width
    newton_tol: jax.Array  # [rad]
    gap_tol: jax.Array
    eta: jax.Array       # probe offset past an event (stick-first hypothesis test)
    invalid: jax.Array   # () int32: index of the first invalid input (-1: all valid)
    margin: jax.Array    # () smooth feasibility margin of the grip [rad] (> 0 feasible)
    phase: jax.Array     # () int32: 0 squeeze, 1 adversary push

    def centres(self, d):
        return self.base + d * self.dirn

    def angles(self, d):
        F = self.cfg.fingers
        if not self.cfg.rotation:
            return jnp.zeros(F, self.r.dtype)
        a = jax.vmap(jnp.polyval, (0, None))(self.rotation, (self.rot_depth[0] + self.rot_depth[1] * d) * self.L)
        return jnp.concatenate([a, jnp.zeros(F - 2, a.dtype)])


def first_touch(x, o, v, r, present=True):
    """Where a circle of radius r moving along the unit direction v (from far behind) first
    touches one of the points x (m, 2): (t, k) with the centre at o + t v at touch and k the
    touched point; t = +inf when the circle's path misses every point. This is event A's gap
    function solved along the approach (the object is rigid before first touch)."""
    w = x - o
    b = w @ v
    disc = b * b - jnp.sum(w * w, axis=1) + r * r
    t = jnp.where(disc > 0, b - jnp.sqrt(jnp.where(disc > 0, disc, 1.0)), jnp.inf)
    t = jnp.where(present, t, jnp.inf)
    k = jnp.argmin(t)
    return t[k], k


def gap_to_fingers(model: Model, x, d):
    """(m, F) gap of points x (m, 2) to each fingertip circle at λ = d (+inf for absent fingers)."""
    g = jnp.linalg.norm(x[:, None, :] - model.centres(d)[None], axis=-1) - model.r
    return jnp.where(model.present, g, jnp.inf)


def make_model(op: Compliance, grasp: Grasp, cfg: Config) -> Model:
    """The squeeze phase's model: finger centres from the grip nodes (each one radius out along
    the node's normal, squeezing along the line between the nodes), or from a continuous
    placement (each touching the smooth boundary at p(s_i), squeezing along
    p(s_0) − p(s_1) turned by the angle offset, then closed in along that line until each
    first touches a node)."""
    L = op.length
    dt = op.G.dtype
    F = cfg.fingers
    r = jnp.full(F, grasp.radius / L, dt)
    mu = jnp.asarray(grasp.mu, dt)
    phi = jnp.arctan(mu) if cfg.friction_model == "coulomb" else jnp.zeros_like(mu)
    touches = jnp.array(True)
    if cfg.placement:
        s, angle = grasp.placement
        q, n = boundary.point(_scaled_curve(grasp.curve, L), jnp.asarray(s, dt) / L)
        e0 = (q[0] - q[1]) / jnp.linalg.norm(q[0] - q[1])
        ca, sa = jnp.cos(angle), jnp.sin(angle)
        e = jnp.array([ca * e0[0] - sa * e0[1], sa * e0[0] + ca * e0[1]])
        o = q + r[:2, None] * n
        t0, k0 = first_touch(op.points, o[0], -e, r[0])
        t1, k1 = first_touch(op.points, o[1], e, r[1])
        touches = jnp.isfinite(t0) & jnp.isfinite(t1) & (k0 != k1)
        t0, t1 = jnp.where(touches, t0, 0.0), jnp.where(touches, t1, 0.0)
        o = jnp.stack([o[0] - t0 * e, o[1] + t1 * e])
        grip = jnp.stack([k0, k1])
    else:
        grip = jnp.clip(grasp.grip, 0, op.m - 1)      # an invalid grip is reported, never silently used
        p = op.points[grip]
        o = p + r[:2, None] * op.normals[grip]
        e = (p[0] - p[1]) / jnp.linalg.norm(p[0] - p[1])
    # smooth feasibility margin: the friction angle minus the larger angle between the segment
    # joining the first contacts and their inward normals (Section I-A), −π when a finger misses
    ang = laws.grip_cone_angles(op.points[grip], -op.normals[grip])
    half = phi if cfg.friction_model != "stick" else jnp.asarray(0.5 * jnp.pi, dt)
    margin = jnp.where(touches, half + laws.CONE_SLACK - jnp.max(ang), -jnp.pi)
    base = jnp.zeros((F, 2), dt).at[:2].set(o)
    dirn = jnp.zeros((F, 2), dt).at[1].set(e)
    present = jnp.arange(F) < 2
    h = grasp.step / L
    eta = jnp.maximum(1e-2 * h, 1e3 * jnp.finfo(dt).eps)   # probe offset, above round-off in float32
    return Model(op, cfg, base, dirn, present, r, phi, mu, L, jnp.asarray(grasp.rotation, dt),
                 jnp.array([0.0, 1.0], dt), grip, grasp.depth / L, h, grasp.event_tol / L, grasp.newton_tol,
                 grasp.gap_tol / L, eta, jnp.asarray(grasp.invalid, jnp.int32), margin, jnp.array(0, jnp.int32))


def _scaled_curve(c, L):
    """A curve in metres as one in scaled lengths (knots / L; coefficients of t^k scale as L^(1-k))."""
    return boundary.Curve(jnp.asarray(c.knots) / L, jnp.asarray(c.coef) * (L ** (2.0 - jnp.arange(4)))[None, :, None])


def push_model(model: Model, grasp: Grasp, st) -> Model:
    """The adversary phase's model, from the squeeze model and its final state: the grasping
    fingers hold still at the final depth, and a third fingertip, placed on the smooth boundary
    at arc length s and closed in along its push direction (the inward normal turned by the
    angle offset) until it touches the deformed object, pushes by λ along that direction.
    The pushed point is the material point at arc length s on the squeezed object (its node
    displacements interpolated), and its normal turns as the boundary span there turned."""
    op, L = model.op, model.L
    dt = op.G.dtype
    s3, angle, radius, push, step = grasp.adversary
    crv = _scaled_curve(grasp.curve, L)
    s3 = jnp.asarray(s3, dt) / L
    q, n = boundary.point(crv, s3)
    # the material point at arc length s3 on the squeezed object: interpolate the outer loop's
    # node displacements along the span that holds s3; turn the normal as that span turned
    k = crv.knots
    sm = jnp.mod(s3, k[-1])
    i = jnp.clip(jnp.searchsorted(k, sm, side="right") - 1, 0, k.shape[0] - 2)
    j = jnp.mod(i + 1, k.shape[0] - 1)
    w = (sm - k[i]) / (k[i + 1] - k[i])
    q = q + (1 - w) * st.u[i] + w * st.u[j]
    chord0 = op.points[j] - op.points[i]
    chord = chord0 + st.u[j] - st.u[i]
    turn = angle + jnp.arctan2(cross2(chord0, chord), jnp.sum(chord0 * chord))
    ca, sa = jnp.cos(turn), jnp.sin(turn)
    v = -jnp.array([ca * n[0] - sa * n[1], sa * n[0] + ca * n[1]])
    r3 = radius / L
    o = q - r3 * v
    t, _ = first_touch(op.points + st.u, o, v, r3)
    t = jnp.where(jnp.isfinite(t), t, 0.0)
    base = model.centres(st.d).at[2].set(o + t * v)
    dirn = jnp.zeros_like(model.dirn).at[2].set(v)
    h = step / L
    return dataclasses.replace(model, base=base, dirn=dirn, present=jnp.ones_like(model.present), r=model.r.at[2].set(r3),
                          rot_depth=jnp.stack([st.d, jnp.zeros((), dt)]), D=push / L, h=h,
                          ev_tol=h * 1e-4, eta=jnp.maximum(1e-2 * h, 1e3 * jnp.finfo(dt).eps),
                          phase=jnp.array(1, jnp.int32))


# ----------------------------------------------------------------------------- one configuration
class Contacts(NamedTuple):
    """The contact set packed into fixed slots, with the bordered matrix factored once."""

    idx: jax.Array      # (S,) node positions (padding points at node 0)
    active: jax.Array   # (S,) bool
    mode: jax.Array     # (S,)
    finger: jax.Array   # (S,)
    theta0: jax.Array   # (S,) anchors (stick) or initial guesses (slip)
    dofs: jax.Array     # (2S,)
    Minv: jax.Array     # (2S + 3, 2S + 3) inverse of the bordered matrix (eq. 4)
    armed: jax.Array    # (S,) bool: event D may fire (the slip rate was consistent)


def pack(model: Model, mode, finger, theta, armed=None) -> Contacts:
    S = model.cfg.capacity
    idx = jnp.nonzero(mode > FREE, size=S, fill_value=0)[0]
    active = jnp.arange(S) < jnp.sum(mode > FREE)
    dofs = slot_dofs(idx)
    G = model.op.G
    M = bordered_matrix(G[dofs][:, dofs], model.op.N[dofs], active)
    armed = jnp.ones(S, bool) if armed is None else armed[idx]
    return Contacts(idx, active, jnp.where(active, mode[idx], FREE), finger[idx], theta[idx], dofs,
                    linalg.inv(M), armed)


def slot_forces(model: Model, c: Contacts, th, d):
    """Forces (S, 2) and rigid amplitudes g (3,) with slot nodes at polar angles ``th``."""
    S = c.idx.shape[0]
    pos = model.centres(d)[c.finger] + model.r[c.finger, None] * unit(th + model.angles(d)[c.finger])
    disp = (pos - model.op.points[c.idx]).reshape(-1)
    rhs = jnp.concatenate([jnp.where(jnp.repeat(c.active, 2), disp, 0.0), jnp.zeros(3, disp.dtype)])
    x = c.Minv @ rhs
    return x[: 2 * S].reshape(S, 2), x[2 * S:]


def slip_residual(model: Model, c: Contacts, th, d):
    """System S (eq. 6): sliding forces on their cone edge; other slots keep their angle."""
    f, _ = slot_forces(model, c, th, d)
    sliding = c.active & (c.mode >= SLIP_POS)
    sign = jnp.where(c.mode == SLIP_POS, 1.0, -1.0)
    edge = th + model.angles(d)[c.finger] - sign * model.phi
    return jnp.where(sliding, cross2(f, unit(edge)), th - c.theta0)


def _lin_solve(model: Model, J, r):
    if model.cfg.friction_model == "frictionless":
        # Neutral modes (docs/numerics.md): a frictionless object between round tips can spin
        # or drift sideways at (almost) no cost. A truncated pseudo-inverse leaves every
        # direction the contacts resist less than linalg.NEUTRAL_RTOL of the stiffest one
        # where it is, so such a mode stays unexcited instead of swinging.
        return linalg.lstsq(J, r)
    return linalg.solve(J, r)


def slip_angles(model: Model, c: Contacts, d):
    """Newton on system S with the Jacobian from ``jax.jacobian``; implicit derivatives.

    Returns (theta (S,), converged bool, iterations (), last update [rad] ()).
    """
    zero = jnp.zeros((), c.theta0.dtype)
    if not model.cfg.newton:
        return c.theta0, jnp.array(True), jnp.array(0, jnp.int32), zero
    tol = lax.stop_gradient(model.newton_tol)

    def newton(R, x0):
        def cond(s):
            return (s[1] < model.cfg.newton_iters) & (s[2] > tol)

        def body(s):
            x, it, _ = s
            dx = _lin_solve(model, jax.jacobian(R)(x), R(x))
            return x - dx, it + 1, jnp.max(jnp.abs(dx))

        x, it, dx = lax.while_loop(cond, body, (x0, jnp.array(0, jnp.int32), jnp.array(jnp.inf, x0.dtype)))
        return x, (dx, it.astype(x0.dtype))     # aux in float: it passes through custom_root's jvp

    def tangent_solve(g, y):
        return _lin_solve(model, jax.jacobian(g)(y), y)

    def solve_s():
        th, (last, it) = lax.custom_root(lambda th: slip_residual(model, c, th, d), c.theta0, newton,
                                         tangent_solve, has_aux=True)
        last = lax.stop_gradient(last)
        return th, last <= tol, lax.stop_gradient(it).astype(jnp.int32), last

    # without sliding contacts system S is empty: every angle is its anchor
    return lax.cond(jnp.any(c.active & (c.mode >= SLIP_POS)), solve_s,
                    lambda: (c.theta0, jnp.array(True), jnp.array(0, jnp.int32), zero))


def slip_rates(model: Model, c: Contacts, th, d):
    """dθ/dε by the implicit function theorem on system S, both Jacobians from ``jax.jacobian``."""
    if not model.cfg.slip_events:
        return jnp.zeros_like(th)

    def rates():
        J_th = jax.jacobian(slip_residual, 2)(model, c, th, d)
        J_d = jax.jacobian(slip_residual, 3)(model, c, th, d)
        return -_lin_solve(model, J_th, J_d)

    return lax.cond(jnp.any(c.active & (c.mode >= SLIP_POS)), rates, lambda: jnp.zeros_like(th))


class Solution(NamedTuple):
    th: jax.Array       # (S,) slot polar angles (finger frame)
    f: jax.Array        # (S, 2) slot forces
    g: jax.Array        # (3,)
    ok: jax.Array       # Newton converged
    u: jax.Array        # (m, 2) boundary displacements
    F: jax.Array        # (m, 2) boundary forces
    e: jax.Array        # (m,) event functions: an event crossed where e < 0
    kind: jax.Array     # (m,) which event each node's function stands for
    ft: jax.Array       # (m,) tangential force (for the slip sign)
    fn: jax.Array       # (m,) normal force
    rate: jax.Array     # (m,) slip rate along the sliding direction, s·dθ/dε (0 where not sliding)
    iters: jax.Array    # () Newton iterations
    resid: jax.Array    # () last Newton update [rad]


def solve_at(model: Model, c: Contacts, mode, d) -> Solution:
    """Solve the configuration at depth ``d`` and evaluate every event function."""
    op, m = model.op, model.op.m
    th, ok, iters, resid = slip_angles(model, c, d)
    f, g = slot_forces(model, c, th, d)
    f = jnp.where(c.active[:, None], f, 0.0)
    u = (op.G[:, c.dofs] @ f.reshape(-1) + op.N @ g).reshape(m, 2)
    F = jnp.zeros((m, 2), f.dtype).at[c.idx].add(f)

    # event A: gap of each free node to the nearest fingertip
    x = op.points + u
    gaps = gap_to_fingers(model, x, d)
    eA = jnp.min(gaps, axis=1) + model.gap_tol
    if model.cfg.contact == "point":
        eA = jnp.full_like(eA, jnp.inf)

    # events B, C, D at the contact slots
    axis = unit(th + model.angles(d)[c.finger])    # cone axis: from the tip centre to the node
    if model.cfg.contact == "point":
        # a point contact (Section V-A) has the object's own deformed surface normal as its cone
        # axis: it turns as the band bends (Fig. 3), while the node stays put on the tip
        axis = -boundary.normals(x, op.loops)[c.idx]
    fn = jnp.sum(f * axis, -1)
    ft = cross2(axis, f)            # f · t, t the axis turned by +90°
    stick = c.mode == STICK
    rate = jnp.zeros_like(th)
    if model.cfg.slip_events:
        margin = laws.cone_margin(model.phi, fn, ft)
        rate = jnp.where(c.mode == SLIP_POS, 1.0, jnp.where(c.mode == SLIP_NEG, -1.0, 0.0)) * slip_rates(model, c, th, d)
        other = jnp.where(stick, margin, jnp.where(c.armed, rate, jnp.inf))
        e_slot = jnp.minimum(fn, other)
        k_slot = jnp.where(fn < other, 1, jnp.where(stick, 2, 3))
    else:
        e_slot, k_slot = fn, jnp.ones_like(c.mode)
    safe = jnp.where(c.active, c.idx, m)
    e = eA.at[safe].set(e_slot, mode="drop")
    kind = jnp.zeros(m, jnp.int32).at[safe].set(k_slot, mode="drop")
    fn_full = jnp.zeros(m, f.dtype).at[safe].set(fn, mode="drop")
    ft_full = jnp.zeros(m, f.dtype).at[safe].set(ft, mode="drop")
    rate_full = jnp.zeros(m, f.dtype).at[safe].set(rate, mode="drop")
    e = jnp.where((mode == FREE) | (kind > 0), e, jnp.inf)
    return Solution(th, f, g, ok, u, F, e, kind, ft_full, fn_full, rate_full, iters, resid)


# ----------------------------------------------------------------------------- loop state
class Stats(NamedTuple):
    """What a user needs to trust or tune a run (all () arrays)."""

    steps: jax.Array           # squeeze steps taken (rows without an event)
    events: jax.Array          # event resolutions (rows with one or more events)
    newton_iters: jax.Array    # Newton iterations, summed over every solve
    newton_max: jax.Array      # largest Newton iteration count of one solve
    bracket_iters: jax.Array   # event-location iterations, summed
    residual: jax.Array        # largest final Newton update [rad] of an accepted solve


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class State:
    """The squeeze loop's state (scaled units). Stages read a state and return a new one."""

    d: jax.Array
    mode: jax.Array         # (m,)
    finger: jax.Array       # (m,)
    theta: jax.Array        # (m,) anchor (stick) or current (slip) polar angle, finger frame
    armed: jax.Array        # (m,) bool, event D armed (see _arm)
    F: jax.Array            # (m, 2)
    u: jax.Array            # (m, 2)
    g: jax.Array            # (3,)
    it: jax.Array
    status: jax.Array       # RUNNING or a Status, decided by finish() only
    fault: jax.Array        # RUNNING or a structural Status raised by a stage (overflow, stall, ...)
    n_ev: jax.Array
    events: tuple           # depth (E,), node (E,), kind (E,), finger (E,)
    hist: tuple             # depth (H,), mode, finger, theta (H, m), F, u (H, m, 2), centres (H, F, 2), alpha (H, F), g (H, 3), push (H,)
    count: jax.Array
    stats: Stats
    squeeze_status: jax.Array   # the status the squeeze phase ended with
    margin: jax.Array           # the grip's smooth feasibility margin [rad] (Model.margin)
    grip: jax.Array             # (2,) boundary positions of the first contacts


def _record(model: Model, st: State, row) -> tuple:
    depth, push = jnp.where(model.phase == 0, st.d, model.rot_depth[0]), jnp.where(model.phase == 0, 0.0, st.d)
    vals = (depth, st.mode.astype(jnp.int8), st.finger.astype(jnp.int8), st.theta, st.F, st.u,
            model.centres(st.d), model.angles(st.d), st.g, push)
    return tuple(h.at[row].set(v) for h, v in zip(st.hist, vals))


def _settle(model: Model, st: State, c: Contacts, sol: Solution, d) -> State:
    """Adopt a solved configuration at depth d (slip angles move, anchors stay)."""
    safe = jnp.where(c.active, c.idx, model.op.m)
    theta = st.theta.at[safe].set(sol.th, mode="drop")
    s = st.stats
    stats = s._replace(newton_iters=s.newton_iters + sol.iters, newton_max=jnp.maximum(s.newton_max, sol.iters),
                       residual=jnp.maximum(s.residual, jnp.where(sol.iters > 0, sol.resid, 0.0)))
    return _with(st, d=d, theta=theta, F=sol.F, u=sol.u, g=sol.g, armed=_arm(st.armed, sol), stats=stats)


def _arm(armed, sol: Solution):
    """Event D fires when the slip rate *crosses* zero. A node whose slip starts with an
    inconsistent rate (a jam: neither sticking nor sliding is consistent there) keeps
    sliding with its force on the cone edge until its rate has been consistent once.
    This keeps every force admissible and rules out C/D chatter at one depth."""
    return armed | (sol.rate > 0)


def _per_finger(model: Model, mode, finger):
    """(contacts per finger (2,), sliding contacts per finger (2,))."""
    contact = mode > FREE
    per = jnp.stack([jnp.sum(contact & (finger == k)) for k in (0, 1)])
    slid = jnp.stack([jnp.sum((mode >= SLIP_POS) & (finger == k)) for k in (0, 1)])
    return per, slid


def _new_contacts(model: Model, st: State, sol: Solution, kind, d, flag):
    """Apply the flagged events of ``kind`` (0–3 for A–D) at depth d.

    Returns (mode, finger, theta, added).
    """
    # A: attach at the polar angle where the node meets the fingertip
    x = model.op.points + sol.u
    C = model.centres(d)
    near = jnp.argmin(gap_to_fingers(model, x, d), axis=1)
    ang = jnp.arctan2(*(x - C[near]).T[::-1]) - model.angles(d)[near]
    added = flag & (kind == 0)
    first = STICK if model.cfg.friction_model != "frictionless" else SLIP_POS
    mode = jnp.where(added, first, st.mode)
    finger = jnp.where(added, near, st.finger)
    theta = jnp.where(added, ang, st.theta)
    # B: release
    mode = jnp.where(flag & (kind == 1), FREE, mode)
    # C: stick → slip, sliding opposite to the tangential force
    slip_mode = jnp.where(sol.ft < 0, SLIP_POS, SLIP_NEG)
    mode = jnp.where(flag & (kind == 2), slip_mode, mode)
    # D: slip → stick at the current angle (theta already holds it)
    mode = jnp.where(flag & (kind == 3), STICK, mode)
    return mode.astype(jnp.int32), finger.astype(jnp.int32), theta, added


def _test_hypothesis(model: Model, mode, finger, theta, added, d):
    """New contacts stick first; one whose force leaves the cone (or pulls) is changed.

    Frictionless squeezes settle the whole contact set instead (:func:`_settle_frictionless`).
    A contact that found no slot (overflow) is left alone: the caller reports
    ``Status.OVERFLOW``. Returns (mode, finger, theta, unsettled).
    """
    if model.cfg.friction_model == "frictionless":
        return _settle_frictionless(model, mode, finger, theta, d)
    c = pack(model, mode, finger, theta)
    sol = solve_at(model, c, mode, d + model.eta)
    slotted = jnp.zeros(mode.shape, bool).at[jnp.where(c.active, c.idx, mode.shape[0])].set(True, mode="drop")
    pull = added & slotted & (sol.fn <= 0)
    mode = jnp.where(pull, FREE, mode)
    if model.cfg.slip_events:
        out = added & slotted & ~pull & (laws.cone_margin(model.phi, sol.fn, sol.ft) < 0)
        mode = jnp.where(out, jnp.where(sol.ft < 0, SLIP_POS, SLIP_NEG), mode)
    return mode.astype(jnp.int32), finger, theta, jnp.array(False)


SETTLE_ITERS = 6   # active-set passes of a frictionless contact set at one depth


def _settle_frictionless(model: Model, mode, finger, theta, d):
    """The frictionless contact set just past depth d, by an active-set iteration at the probe
    depth d + η: every free node inside a fingertip joins (at the angle where it is), then the
    most-pulling contact leaves, until the set is consistent (every contact pushes, no free
    node penetrates) or ``SETTLE_ITERS`` passes. Neighbouring nodes that touch within η of
    each other join together; without that, a node joining alone beside one on the same side
    of the centre line would have to pull (a frictionless point-on-circle pair can only push
    when it straddles that line), be dropped, touch again at once, and stall the squeeze."""
    dp = d + model.eta
    m = mode.shape[0]

    def body(_, carry):
        mode, finger, theta, _ = carry
        c = pack(model, mode, finger, theta)
        sol = solve_at(model, c, mode, dp)
        x = model.op.points + sol.u
        C = model.centres(dp)
        gaps = gap_to_fingers(model, x, dp)
        near = jnp.argmin(gaps, axis=1)
        inside = (mode == FREE) & (jnp.min(gaps, axis=1) < -model.gap_tol)
        ang = jnp.arctan2(*(x - C[near]).T[::-1]) - model.angles(dp)[near]
        slotted = jnp.zeros(m, bool).at[jnp.where(c.active, c.idx, m)].set(True, mode="drop")
        fn = jnp.where(slotted & (mode > FREE), sol.fn, jnp.inf)
        worst = jnp.argmin(fn)
        drop = (jnp.arange(m) == worst) & (fn[worst] <= 0) & ~jnp.any(inside)
        mode = jnp.where(inside, SLIP_POS, jnp.where(drop, FREE, mode)).astype(jnp.int32)
        finger = jnp.where(inside, near, finger).astype(jnp.int32)
        theta = jnp.where(inside, ang, theta)
        return mode, finger, theta, jnp.any(inside) | jnp.any(drop)

    mode, finger, theta, unsettled = lax.fori_loop(0, SETTLE_ITERS, body, (mode, finger, theta, jnp.array(False)))
    return mode, finger, theta, unsettled


# ----------------------------------------------------------------------------- the stages
def init(model: Model) -> State:
    """First touch (d = 0): the grip nodes in contact (stick first, or sliding when frictionless),
    the grip's cone test, the first solve and the first recorded row."""
    op, cfg = model.op, model.cfg
    dt = op.G.dtype
    m = op.m
    i, j = model.grip[0], model.grip[1]
    P = op.points
    C0 = model.centres(jnp.zeros((), dt))
    a0 = model.angles(jnp.zeros((), dt))
    first = STICK if cfg.friction_model != "frictionless" else SLIP_POS
    mode = jnp.zeros(m, jnp.int32).at[i].set(first).at[j].set(first)
    finger = jnp.zeros(m, jnp.int32).at[j].set(1)
    ang = lambda k, f: jnp.arctan2(*(P[k] - C0[f])[::-1]) - a0[f]  # noqa: E731
    theta = jnp.zeros(m, dt).at[i].set(ang(i, 0)).at[j].set(ang(j, 1))
    added = jnp.zeros(m, bool).at[i].set(True).at[j].set(True)
    if cfg.slip_events:
        mode, finger, theta, _ = _test_hypothesis(model, mode, finger, theta, added, jnp.zeros((), dt))

    # the segment between the initial contacts must lie inside both friction cones (Section I-A),
    # and with a continuous placement both fingers must have touched the object
    feasible = model.margin >= 0

    E, H = cfg.max_events, cfg.max_steps + 1
    z = jnp.zeros
    i32 = lambda v: jnp.array(v, jnp.int32)  # noqa: E731
    zero = z((), dt)
    st = State(zero, mode, finger, theta, z(m, bool), z((m, 2), dt), z((m, 2), dt), z(3, dt),
               i32(0), i32(RUNNING), i32(RUNNING), i32(0),
               (z(E, dt), z(E, jnp.int32), z(E, jnp.int32), z(E, jnp.int32)),
               (z(H, dt), z((H, m), jnp.int8), z((H, m), jnp.int8), z((H, m), dt), z((H, m, 2), dt),
                z((H, m, 2), dt), z((H, cfg.fingers, 2), dt), z((H, cfg.fingers), dt), z((H, 3), dt), z(H, dt)),
               i32(0), Stats(i32(0), i32(0), i32(0), i32(0), i32(0), zero), i32(RUNNING), model.margin, model.grip)
    c = pack(model, st.mode, st.finger, st.theta)
    sol = solve_at(model, c, st.mode, st.d)
    st = _settle(model, st, c, sol, st.d)
    fault = jnp.where(model.invalid >= 0, Status.INVALID_INPUT, jnp.where(~feasible, Status.INFEASIBLE_GRIP, RUNNING))
    return finish(model, _with(st, fault=jnp.asarray(fault, jnp.int32), it=i32(-1)), sol.ok)


def step(model: Model, st: State) -> State:
    """One iteration: propose the next depth; advance to it, or resolve the earliest event."""
    d0 = st.d
    d1 = jnp.minimum(d0 + model.h, model.D)
    c = pack(model, st.mode, st.finger, st.theta, st.armed)
    s1 = solve_at(model, c, st.mode, d1)
    crossed = jnp.any(s1.e < 0)

    def advance():
        st1 = _settle(model, st, c, s1, d1)
        st1 = _with(st1, stats=st1.stats._replace(steps=st1.stats.steps + 1))
        return finish(model, st1, s1.ok)

    def event():
        lo, hi, iters = locate_event(model, c, st.mode, d0, d1, jnp.min(s1.e))
        st1 = _with(st, stats=st.stats._replace(bracket_iters=st.stats.bracket_iters + iters,
                                                  events=st.stats.events + 1))
        return apply_event(model, st1, c, lo, hi)

    return lax.cond(crossed, event, advance)


def locate_event(model: Model, c: Contacts, mode, d0, d1, e1):
    """Bracket the earliest sign change of min_k e_k(d) in [d0, d1] to ``event_tol``.

    Illinois regula falsi (superlinear on smooth crossings) safeguarded by bisection.
    Returns (lo, hi, iterations).
    """
    E = lambda dd: jnp.min(solve_at(model, c, mode, dd).e)  # noqa: E731
    e0 = E(d0)

    def cond(s):
        lo, hi, *_, it = s
        return (hi - lo > model.ev_tol) & (it < model.cfg.bisect_iters)

    def body(s):
        lo, hi, elo, ehi, side, it = s
        t = elo / (elo - ehi)
        t = jnp.where(jnp.isfinite(t) & (it % 4 != 3), jnp.clip(t, 0.01, 0.99), 0.5)
        mid = lo + t * (hi - lo)
        em = E(mid)
        hit = em < 0
        # Illinois: when the same end survives twice, halve its value
        elo2 = jnp.where(hit, jnp.where(side == -1, 0.5 * elo, elo), em)
        ehi2 = jnp.where(hit, em, jnp.where(side == 1, 0.5 * ehi, ehi))
        return (jnp.where(hit, lo, mid), jnp.where(hit, mid, hi), elo2, ehi2,
                jnp.where(hit, -1, 1), it + 1)

    lo, hi, _, _, _, it = lax.while_loop(cond, body, (d0, d1, jnp.maximum(e0, 0.0), e1, 0, jnp.array(0, jnp.int32)))
    return lo, hi, it


def apply_event(model: Model, st: State, c: Contacts, lo, hi) -> State:
    """Refine the event depth by one implicit-function step (so d* carries dd*/dp), apply every
    event flagged there, test new contacts by hypothesis, log them and re-solve at d*."""
    op, m, E = model.op, model.op.m, model.cfg.max_events
    d0 = st.d
    # one solve at hi gives the event functions and their rate (its primal is the solution)
    s_hi, ds_hi = jax.jvp(lambda dd: solve_at(model, c, st.mode, dd), (hi,), (jnp.ones_like(hi),))
    e_hi, de_hi = s_hi.e, ds_hi.e
    flag = e_hi < 0
    est = jnp.where(flag & (de_hi < 0), hi - e_hi / jnp.where(de_hi < 0, de_hi, -1.0), hi)
    d_star = jnp.clip(jnp.min(jnp.where(flag, est, jnp.inf)), lo, hi)
    s_star = solve_at(model, c, st.mode, d_star)
    st = _settle(model, st, c, s_star, d_star)
    kinds = jnp.where(st.mode == FREE, 0, s_hi.kind)
    mode, finger, theta, added = _new_contacts(model, st, s_star, kinds, d_star, flag)
    overflow = jnp.sum(mode > FREE) > model.cfg.capacity
    unsettled = jnp.array(False)
    if model.cfg.slip_events or model.cfg.friction_model == "frictionless":
        mode, finger, theta, unsettled = _test_hypothesis(model, mode, finger, theta, added, d_star)
    # log the events
    order = jnp.cumsum(flag) - 1 + st.n_ev
    slot = jnp.where(flag & (order < E), order, E)
    ev_d, ev_n, ev_k, ev_f = st.events
    events = (ev_d.at[slot].set(d_star, mode="drop"), ev_n.at[slot].set(op.nodes.astype(jnp.int32), mode="drop"),
              ev_k.at[slot].set(kinds.astype(jnp.int32), mode="drop"), ev_f.at[slot].set(finger, mode="drop"))
    n_ev = (st.n_ev + jnp.sum(flag)).astype(jnp.int32)
    # re-solve with the new modes at d*
    c2 = pack(model, mode, finger, theta)
    changed = mode != st.mode
    st2 = _with(st, mode=mode, finger=finger, theta=theta, events=events, n_ev=n_ev, armed=st.armed & ~changed)
    s2 = solve_at(model, c2, mode, d_star)
    st2 = _settle(model, st2, c2, s2, d_star)
    # an event that undid itself at the depth it started from (a new contact that pulls at
    # once) would repeat forever: stop with a status instead
    stalled = (jnp.all(mode == st.mode) & (d_star <= d0)) | unsettled
    fault = jnp.where(overflow, Status.OVERFLOW, jnp.where(n_ev > E, Status.EVENT_OVERFLOW,
                      jnp.where(stalled, Status.STALLED, st2.fault)))
    return finish(model, _with(st2, fault=fault.astype(jnp.int32)), s2.ok & s_star.ok)


def finish(model: Model, st: State, ok) -> State:
    """Record the row and decide the status: the one place where a status is set.

    Precedence: a structural fault raised by a stage (invalid input, infeasible grip,
    overflow, event-log overflow, stall), then non-finite values, Newton failure, a finger
    without contact, a finger whose contacts all slide, the target depth, the step bound.
    """
    it = st.it + 1
    hist = _record(model, st, st.count)
    finite = jnp.all(jnp.isfinite(st.F)) & jnp.all(jnp.isfinite(st.u))
    per, slid = _per_finger(model, st.mode, st.finger)
    lost = jnp.any(per == 0)
    slip = jnp.any(slid == per) if model.cfg.slip_events else jnp.array(False)
    status = jnp.where(st.fault != RUNNING, st.fault,
             jnp.where(~finite, Status.NONFINITE,
             jnp.where(~ok, Status.NEWTON_FAILURE,
             jnp.where(lost, Status.LOST_CONTACT,
             jnp.where(slip, Status.SLIP_FAILURE,
             jnp.where(st.d >= model.D * (1 - 1e-12), Status.SUCCESS,
             jnp.where(it >= model.cfg.max_steps, Status.MAX_STEPS, RUNNING)))))))
    return _with(st, it=it, hist=hist, count=st.count + 1, status=status.astype(jnp.int32))


def run(model: Model, st: State) -> State:
    """``step`` in a ``lax.while_loop`` until ``finish`` sets a status."""
    return lax.while_loop(lambda s: s.status == RUNNING, lambda s: step(model, s), st)


def start_push(model: Model, st: State) -> State:
    """Hand a finished squeeze to the adversary phase: λ restarts at 0 from the squeezed state
    (contacts, anchors and forces carry over); only a squeeze that succeeded is pushed."""
    status = jnp.where(st.status == Status.SUCCESS, RUNNING, st.status).astype(jnp.int32)
    hist = list(st.hist)
    hist[6] = hist[6].at[:, 2].set(model.base[2])       # the pusher waits at its start in squeeze rows
    return _with(st, d=jnp.zeros_like(st.d), status=status, squeeze_status=st.status, hist=tuple(hist))


def simulate(op: Compliance, grasp: Grasp, cfg: Config) -> State:
    """The jittable core of :func:`jaxsqueeze.squeeze`: ``init``, then ``step`` in a
    ``lax.while_loop`` until ``finish`` sets a status; with an adversary, a second loop of the
    same stages pushes the squeezed object (:func:`push_model`).

    Returns the final :class:`State` (scaled units; history and event log padded).
    """
    model = make_model(op, grasp, cfg)
    with jax.named_scope("init"):
        st = init(model)
    with jax.named_scope("squeeze"):
        st = run(model, st)
    st = _with(st, squeeze_status=st.status)
    if cfg.adversary:
        with jax.named_scope("push"):
            pm = push_model(model, grasp, st)
            st = run(pm, start_push(pm, st))
    return st


def _with(st: State, **kw) -> State:
    return dataclasses.replace(st, **kw)
