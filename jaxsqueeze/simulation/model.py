"""What stays fixed during one loading phase of a squeeze: static configuration, traced grasp
numbers and the finger kinematics (Section IV, IV-D; DESIGN 2.4, 2.7, 2.9).

Units inside are scaled (DESIGN 2.3): lengths / L, forces / (E h L).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import jax
import jax.numpy as jnp

from ..geometry import boundary
from ..mechanics.operator import Compliance
from . import laws
from .validate import FIELDS, OVERLAP_TOL, fingertip_overlap, tip_directions


# ----------------------------------------------------------------------------- configuration
@dataclass(frozen=True)
class Config:
    """Static configuration: which effects are compiled in (DESIGN 2.7) and capacities."""

    friction_model: str = "coulomb"   # "coulomb" | "frictionless" | "stick"
    contact: str = "segment"          # "segment" | "point"
    rotation: bool = False
    capacity: int = 64
    sliding: int = 0                  # one Newton system of this many sliding slots; 0: COMPACT + all slots
    max_steps: int = 400
    max_events: int = 256
    newton_iters: int = 30
    bisect_iters: int = 40
    placement: bool = False           # fingers placed by arc length (an approach finds first touch)
    adversary: bool = False           # a third finger pushes after the squeeze (a second phase)
    history: bool = True              # record every row; False keeps two (end of squeeze, last)
    fused: bool = False               # the loop as one CPU kernel (engine.run; top-level programs only)

    @property
    def rows(self) -> int:
        """Rows of the recorded history."""
        return self.max_steps + 1 if self.history else 2

    @property
    def fingers(self) -> int:
        return 3 if self.adversary else 2

    @property
    def newton(self) -> bool:
        return self.friction_model != "stick"

    @property
    def sliding_limited(self) -> bool:
        """One Newton system of ``sliding`` slots, fewer than the contact slots: more sliding
        nodes stop the squeeze with an overflow (:func:`engine.reconcile`)."""
        return self.newton and 0 < self.sliding < self.capacity

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
    axis: jax.Array      # (2,) the squeeze direction (unit, finger 1's motion in the squeeze phase)

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
    w = x - o[None, :]
    b = w @ v
    disc = b * b - jnp.sum(w * w, axis=1) + r * r
    t = jnp.where(disc > 0, b - jnp.sqrt(jnp.where(disc > 0, disc, 1.0)), jnp.inf)
    t = jnp.where(present, t, jnp.inf)
    k = jnp.argmin(t)
    return t[k], k


def gap_to_fingers(model: Model, x, d):
    """(m, F) gap of points x (m, 2) to each fingertip circle at λ = d (+inf for absent fingers)."""
    g = jnp.linalg.norm(x[:, None, :] - model.centres(d)[None], axis=-1) - model.r[None, :]
    return jnp.where(model.present, g, jnp.inf)


def make_model(op: Compliance, grasp: Grasp, cfg: Config) -> Model:
    """The squeeze phase's model: finger centres from the grip nodes (each one radius out along
    the node's normal, squeezing along the line between the nodes), or from a continuous
    placement (each touching the smooth boundary at p(s_i), squeezing along
    p(s_0) − p(s_1) turned by the angle offset, then closed in along that line until each
    first touches a node). Frictionless fingertips sit on the line through their two first
    contacts instead, so the initial forces, radial on the tips, are along it."""
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
        # (two coincident placements squeeze along no line: finger 0 closes in along its normal
        # and the pair gets the node it touches and the next, as a placement that touches nothing)
        apart = jnp.linalg.norm(q[0] - q[1])
        e0 = jnp.where(apart > 0, (q[0] - q[1]) / jnp.where(apart > 0, apart, 1.0), n[0])
        e = _turn(e0, angle)
        o = q + r[:2, None] * n
        t0, k0 = first_touch(op.points, o[0], -e, r[0])
        t1, k1 = first_touch(op.points, o[1], e, r[1])
        # each tip closes in from where it was placed: a touch more than a radius behind it
        # (t < -r) is the object's far side, reached through the object (|angle| near π)
        touches = (apart > 0) & jnp.isfinite(t0) & jnp.isfinite(t1) & (k0 != k1) & (t0 > -r[0]) & (t1 > -r[1])
        t0, t1 = jnp.where(touches, t0, 0.0), jnp.where(touches, t1, 0.0)
        o = jnp.stack([o[0] - t0 * e, o[1] + t1 * e])
        # a fingertip narrower than the node spacing can slip between two nodes and first
        # touch a node from inside the object: no grip (and never a SUCCESS through the object)
        touches = touches & ~jnp.any(boundary.inside(op.points, op.loops, o))
        # a placement that touches nothing still gets two distinct nodes, so that the first
        # solve (reported as INFEASIBLE_GRIP) stays finite
        k1 = jnp.where(apart > 0, k1, k0)
        grip = jnp.stack([k0, jnp.where(k1 == k0, (k0 + 1) % op.m, k1)])
    else:
        grip = jnp.clip(grasp.grip, 0, op.m - 1)      # an invalid grip is reported, never silently used
    p = op.points[grip]
    if not cfg.placement or cfg.friction_model == "frictionless":
        e = (p[0] - p[1]) / jnp.linalg.norm(p[0] - p[1])
        toward = tip_directions(p, op.normals[grip], cfg.friction_model == "frictionless")
        o = p + r[:2, None] * toward
    if cfg.placement and cfg.friction_model == "frictionless":
        # re-seated on the line through its first contacts, a placed fingertip may reach past
        # other nodes at d = 0: beyond grip.overlap's limit no first touch, no grip (an integer
        # grip's overlap is validated before the squeeze)
        reach = fingertip_overlap(op.points, grip, toward, r[0])
        touches = touches & jnp.all(reach <= OVERLAP_TOL * jnp.minimum(r[0], 1.0))
    # smooth feasibility margin (Section I-A), −π when a placed finger cannot touch the object.
    # The cone is the fingertip's: around its normal at the contact, from the centre to the node
    # (the object's normal there for an integer grip, whose fingertip sits along it; not for a
    # placed fingertip, which closes in along the squeeze line and may touch a node obliquely)
    inward = -laws.cone_normals(op.points, op.normals, op.loops, cfg.contact)[grip]
    if cfg.placement and cfg.friction_model != "frictionless" and cfg.contact != "point":
        inward = (p - o) / jnp.linalg.norm(p - o, axis=1, keepdims=True)
    margin = jnp.where(touches, laws.grip_margin(p, inward, mu, cfg.friction_model), -jnp.pi)
    base = jnp.zeros((F, 2), dt).at[:2].set(o)
    dirn = jnp.zeros((F, 2), dt).at[1].set(e)
    present = jnp.arange(F) < 2
    h = grasp.step / L
    eta = jnp.maximum(1e-2 * h, 1e3 * jnp.finfo(dt).eps)   # probe offset, above round-off in float32
    invalid = jnp.asarray(grasp.invalid, jnp.int32)
    if cfg.placement:
        # the depth must stay below the distance between the first contacts (checked before the
        # squeeze for an integer grip; a placement knows its contacts only after the approach)
        far = touches & (grasp.depth / L >= jnp.linalg.norm(p[0] - p[1]))
        invalid = jnp.where((invalid < 0) & far, FIELDS.index("depth"), invalid).astype(jnp.int32)
    return Model(op, cfg, base, dirn, present, r, phi, mu, L, jnp.asarray(grasp.rotation, dt),
                 jnp.array([0.0, 1.0], dt), grip, grasp.depth / L, h, grasp.event_tol / L, grasp.newton_tol,
                 grasp.gap_tol / L, eta, invalid, margin, jnp.array(0, jnp.int32), e)


def _scaled_curve(c, L):
    """A curve in metres as one in scaled lengths (knots / L; coefficients of t^k scale as L^(1-k))."""
    return boundary.Curve(jnp.asarray(c.knots) / L, jnp.asarray(c.coef) * (L ** jnp.arange(2.0, -2.0, -1.0))[None, :, None])


def _turn(n, a):
    """(2,) the vector n turned by the angle a [rad]."""
    ca, sa = jnp.cos(a), jnp.sin(a)
    return jnp.array([ca * n[0] - sa * n[1], sa * n[0] + ca * n[1]])


def push_model(model: Model, grasp: Grasp, st) -> Model:
    """The adversary phase's model, from the squeeze model and its final state: the grasping
    fingers hold still at the final depth, and a third fingertip, placed tangent to the smooth
    boundary at arc length s and closed in along its push direction (the inward normal turned
    by the angle offset) until it touches the deformed object, pushes by λ along that direction.
    The pushed point is the material point at arc length s on the squeezed object (its node
    displacements interpolated), and its normal turns with the outline there (the turns of the
    boundary spans, interpolated between nodes so that the push is continuous in s)."""
    op, L = model.op, model.L
    dt = op.G.dtype
    s3, angle, radius, push, step = grasp.adversary
    crv = _scaled_curve(grasp.curve, L)
    s3 = jnp.asarray(s3, dt) / L
    q, n = boundary.point(crv, s3)
    # the material point at arc length s3 on the squeezed object: interpolate the outer loop's
    # node displacements along the span that holds s3. Turn the normal by the boundary's
    # rotation there, interpolated the same way between its values at the span's two nodes
    # (each the mean of the turns of the two spans that meet there), so that the push and its
    # qualities are continuous in s3 across nodes
    k = crv.knots
    nk = k.shape[0] - 1                      # nodes on the outer loop
    sm = jnp.mod(s3, k[-1])
    i = jnp.clip(jnp.searchsorted(k, sm, side="right") - 1, 0, nk - 1)
    j = jnp.mod(i + 1, nk)
    w = (sm - k[i]) / (k[i + 1] - k[i])
    q = q + (1 - w) * st.u[i] + w * st.u[j]

    def turned(a):                           # the rotation [rad] of the span from node a to a + 1
        b = jnp.mod(a + 1, nk)
        chord0 = op.points[b] - op.points[a]
        chord = chord0 + st.u[b] - st.u[a]
        return jnp.arctan2(cross2(chord0, chord), jnp.sum(chord0 * chord))

    before, here, after = turned(jnp.mod(i - 1, nk)), turned(i), turned(j)
    nd = _turn(n, (1 - w) * 0.5 * (before + here) + w * 0.5 * (here + after))
    v = -_turn(nd, angle)
    # the pusher starts on the boundary point (tangent there, as a placed grasping fingertip)
    r3 = radius / L
    o = q + r3 * nd
    x = op.points + st.u
    t, _ = first_touch(x, o, v, r3)
    # the pusher must touch the squeezed object from outside, as a placed grasping fingertip
    # must (make_model): not miss it, not reach it through the object (a touch more than a
    # radius behind the start, |angle| near π/2 or beyond), not start inside it, and not
    # overlap a grasping fingertip (a push on a finger's own contact). Otherwise the push
    # phase ends at once with INFEASIBLE_GRIP (margin −π) and pushes nothing
    touches = jnp.isfinite(t) & (t > -r3) & (jnp.cos(angle) > 0)
    t = jnp.where(touches, t, 0.0)
    c3 = o + t * v
    held = model.centres(st.d)[:2]
    clear = jnp.linalg.norm(held - c3[None, :], axis=1) > model.r[:2] + r3
    touches = touches & jnp.all(clear) & ~boundary.inside(x, op.loops, c3[None])[0]
    base = model.centres(st.d).at[2].set(c3)
    dirn = jnp.zeros_like(model.dirn).at[2].set(v)
    h = step / L
    return dataclasses.replace(model, base=base, dirn=dirn, present=jnp.ones_like(model.present), r=model.r.at[2].set(r3),
                          rot_depth=jnp.stack([st.d, jnp.zeros((), dt)]), D=push / L, h=h,
                          ev_tol=h * 1e-4, eta=jnp.maximum(1e-2 * h, 1e3 * jnp.finfo(dt).eps),
                          margin=jnp.where(touches, model.margin, -jnp.pi), phase=jnp.array(1, jnp.int32))


