"""One contact configuration: the contact set in fixed slots with its factored bordered matrix,
and the solve at one depth (Section IV-A; DESIGN 2.1, 2.4, 2.10).

The contact set lives in ``capacity`` slots (:class:`Slots`). A slot holds one boundary node and
its two DOFs of the bordered system (eq. 4); an empty slot has an identity block, so its force
is 0. The inverse of the bordered matrix is kept with the slots and updated by bordering when a
contact is made or broken (:func:`~jaxsqueeze.mechanics.bordered.inverse_activate`), so a
squeeze step costs O(S^2), not O(S^3); it is recomputed from the matrix only when a check after
a change finds that the updates' round-off has built up (:func:`drift`, ``DRIFT_TOL``).

:func:`solve` evaluates a configuration at a depth d: the prescribed positions of the contact
nodes on the fingertips, the slip angles of sliding nodes (system S, eq. 6, by Newton with the
Jacobian from ``jax.jacobian``, and its implicit derivative dθ/dε), the forces and the rigid
part g, the boundary displacements and every event function. Everything is a pure function of
the model, the slots, the per-node contact state and d, so ``jax.jvp`` over d gives the rates
the event location uses.

Three contact laws, compiled by ``Config.friction_model`` (DESIGN 2.7):

* ``coulomb``: a sticking node stays at its anchor angle θ0 on its fingertip; a sliding node
  moves along the fingertip circle with its force on one cone edge (eq. 6).
* ``stick``: every contact sticks; no Newton solve, no slip events.
* ``frictionless``: every contact slides with its force along the fingertip radius; the
  object's indeterminate drift and spin are held by a stated rule (:func:`_slip_angles`,
  ``docs/numerics.md`` §5.1).

Units are scaled (DESIGN 2.3).
"""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

from ..geometry import boundary
from ..mechanics import linalg
from ..mechanics.bordered import bordered_matrix, inverse_activate, inverse_deactivate, slot_dofs
from ..mechanics.operator import Compliance
from . import laws
from .laws import FREE, SLIP_NEG, SLIP_POS, STICK
from .model import Model, gap_to_fingers

#: the rule that holds a frictionless object's indeterminate drift and spin: the weight of
#: ½|ĝ⊥|² relative to the mean contact stiffness (:func:`_slip_angles`). It must exceed the
#: drift mode's negative stiffness (~F/r) at every depth: at 1 the two cancelled 2.5 and 10 mm
#: into a symmetric square squeeze (a singular Newton system there); 1, 10 and 100 give the
#: same forces to 5e-6 (docs/numerics.md, 5.1)
NEUTRAL_REG = 100.0
#: sliding slots solved in a compact system of this size when they fit (else all S slots),
#: under Coulomb friction. 8 covers the demo squeeze's sliding set (at most 8); at 16 a traced
#: squeeze of it ran ~16 % slower (plain ``vmap`` of 64 foam-square grips: 8.3 against 7.0 ms
#: per grasp, 2026-12-03)
COMPACT = 8
#: the same when every contact slides (frictionless): the contact set outgrows 8 within a few
#: rows, and at 8 a frictionless foam-square squeeze ran 20 % slower than at 16
COMPACT_ALL = 16
#: the kept inverse is recomputed from the bordered matrix (an O(S³) LU) when its backward
#: error (:func:`drift`) exceeds this after a contact set change (float64, float32). Each
#: bordering update subtracts the part of a node's compliance that the nodes in contact
#: already explain; on fine meshes neighbours explain almost all of it, digits are lost and the
#: loss compounds from update to update. The demo square with 0.4 mm contact zones had its
#: contact nodes 0.1 µm off their fingertips after 140 rows without this, a new contact pulled
#: by that much stiffness, was dropped, and the squeeze STALLED at 13 mm; the default demo
#: ends at 3e-13 and never recomputes.
DRIFT_TOL = (1e-12, 1e-4)


def unit(a):
    """(cos a, sin a) stacked on a last axis. Computed once and kept: without the barrier
    XLA recomputes the cosine and sine inside every fusion that reads them (seven times per
    solve for the slots' cone axes, the costliest operations of a one-kernel loop)."""
    return lax.optimization_barrier(jnp.stack([jnp.cos(a), jnp.sin(a)], axis=-1))


def cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


# ----------------------------------------------------------------------------- the contact set
class Slots(NamedTuple):
    """The contact set in S fixed slots (DESIGN 2.4).

    node: (S,) int32 boundary position of each slot's node, −1 for an empty slot.
    slot: (m,) int32 the slot of each boundary node, S for a node without one.
    Minv: (2S + 3, 2S + 3) inverse of the bordered matrix of eq. (4) over the slots (empty
        slots: identity block).
    Gc: (2m, 2S) compliance columns G[:, slot DOFs] (zero for empty slots): the boundary
        displacement under slot forces is Gc f + N g.
    """

    node: jax.Array
    slot: jax.Array
    Minv: jax.Array
    Gc: jax.Array

    @property
    def active(self):
        return self.node >= 0

    def spread(self):
        """``put(a, fill=0)``: slot values a (S, ...) placed at their nodes, (m, ...) with ``fill``
        (a scalar or (m, ...)) at the other nodes.

        A gather through the node → slot map, not a scatter of the slots: on the CPU XLA runs a
        scatter as a small loop with its own buffers, and the ``jvp`` of a scatter whose indices
        may repeat is three of them; a gather fuses with what uses it."""
        S = self.node.shape[0]
        return _gather(jnp.minimum(self.slot, S - 1), self.slot < S)


def _gather(src, on):
    """``put(a, fill=0)``: (n, ...) with a[src] where ``on`` (n,) and ``fill`` elsewhere."""
    def put(a, fill=0):
        a = jnp.asarray(a)
        mask = on.reshape(on.shape + (1,) * (a.ndim - 1))
        return jnp.where(mask, a[src], jnp.asarray(fill, a.dtype))

    return put


def _dofs(pos):
    return jnp.stack([2 * pos, 2 * pos + 1])


def pair(op: Compliance, S: int, i, j) -> Slots:
    """Slots 0 and 1 holding boundary positions i and j (the first touch), the rest empty.

    The 7 × 7 bordered matrix of the pair is nonsingular by Theorem 3 (s = 2); it is inverted
    directly and embedded in the identity of the empty slots.
    """
    dt = op.G.dtype
    n = 2 * S + 3
    d4 = jnp.concatenate([_dofs(i), _dofs(j)])
    A = op.G[d4][:, d4]
    B = op.N[d4]
    M7 = jnp.block([[A, B], [B.T, jnp.zeros((3, 3), dt)]])
    inv7 = linalg.solve(M7, jnp.eye(7, dtype=dt))
    where = jnp.array([0, 1, 2, 3, 2 * S, 2 * S + 1, 2 * S + 2])
    Minv = jnp.eye(n, dtype=dt).at[2 * S:, 2 * S:].set(0.0).at[where[:, None], where[None, :]].set(inv7)
    Gc = jnp.zeros((op.G.shape[0], 2 * S), dt).at[:, :4].set(op.G[:, d4])
    node = jnp.full(S, -1, jnp.int32).at[0].set(jnp.int32(i)).at[1].set(jnp.int32(j))
    slot = jnp.full(op.m, S, jnp.int32).at[i].set(0).at[j].set(1)
    return Slots(node, slot, Minv, Gc)


def activate(op: Compliance, sl: Slots, k, pos) -> Slots:
    """Slot k (empty) takes boundary position ``pos``: the inverse updated by bordering."""
    return _with_columns(sl, k, *_activated(op, sl, k, pos))


def deactivate(sl: Slots, k) -> Slots:
    """Slot k (active) is emptied: the inverse downdated by the Schur complement."""
    return _with_columns(sl, k, *_deactivated(sl, k))


def _activated(op: Compliance, sl: Slots, k, pos):
    """(node, slot, Minv, the compliance columns of slot k (2m, 2)) once slot k takes ``pos``."""
    d = _dofs(pos)
    b = jnp.concatenate([sl.Gc[d].T, op.N[d].T], axis=0)          # (2S + 3, 2)
    Minv = inverse_activate(sl.Minv, k, b, op.G[d][:, d])
    return sl.node.at[k].set(jnp.int32(pos)), sl.slot.at[pos].set(jnp.int32(k)), Minv, op.G[:, d]


def _deactivated(sl: Slots, k):
    """(node, slot, Minv, the compliance columns of slot k (2m, 2)) once slot k is emptied."""
    S = sl.node.shape[0]
    return (sl.node.at[k].set(-1), sl.slot.at[sl.node[k]].set(S), inverse_deactivate(sl.Minv, k),
            jnp.zeros((sl.Gc.shape[0], 2), sl.Gc.dtype))


def _with_columns(sl: Slots, k, node, slot, Minv, cols) -> Slots:
    return Slots(node, slot, Minv, lax.dynamic_update_slice(sl.Gc, cols, (0, 2 * k)))


def update(op: Compliance, sl: Slots, old_on, new_on):
    """Slots for the contact set ``new_on`` (m,) bool, from the slots of ``old_on``: every node
    that left is deactivated and every node that joined takes the first empty slot, one update
    each; then, if anything changed, the kept inverse is checked and recomputed if it has
    drifted (:func:`drift`). Returns (slots, overflow, refreshed): overflow when a joining node
    found no empty slot (it is then left out, and the caller reports ``Status.OVERFLOW``);
    refreshed when the inverse was recomputed.

    One ``while_loop`` whose iterations are the stages (drop, add, full, check, refresh) keeps
    the slots in place: a ``cond`` around a stage would copy them."""
    leave = old_on & ~new_on
    join = new_on & ~old_on
    tol = DRIFT_TOL[1] if sl.Minv.dtype == jnp.float32 else DRIFT_TOL[0]

    def cond(c):
        _, leave, join, _, todo, _ = c
        return jnp.any(leave) | jnp.any(join) | (todo > 0)

    def body(c):
        sl, leave, join, over, todo, fresh = c
        # each stage returns the new (node, slot, Minv), the slot k whose compliance columns
        # change and their new values; Gc itself (2m × 2S) is written after the switch, in
        # place: a stage returning it would copy it on every stage
        ix = jax.dtypes.canonicalize_dtype(jnp.int_)    # the index type of Python ints (int32 without x64)
        same = (sl.node, sl.slot, sl.Minv, jnp.asarray(0, ix), lax.dynamic_slice_in_dim(sl.Gc, 0, 2, axis=1))

        def drop():
            p = jnp.argmax(leave)
            k = sl.slot[p].astype(ix)
            node, slot, Minv, cols = _deactivated(sl, k)
            return (node, slot, Minv, k, cols), leave.at[p].set(False), join, over, todo, fresh

        def add():
            p = jnp.argmax(join)
            k = jnp.argmax(sl.node < 0).astype(ix)
            node, slot, Minv, cols = _activated(op, sl, k, p)
            return (node, slot, Minv, k, cols), leave, join.at[p].set(False), over, todo, fresh

        def full():         # no empty slot left for the nodes still joining: they stay out
            return same, leave, jnp.zeros_like(join), jnp.array(True), todo, fresh

        def check():
            return same, leave, join, over, jnp.where(drift(op, sl) > tol, 2, 0).astype(jnp.int32), fresh

        def refresh():
            Minv = linalg.inv(bordered_matrix_of(op, sl))
            return same[:2] + (Minv,) + same[3:], leave, join, over, jnp.array(0, jnp.int32), jnp.array(True)

        stage = jnp.where(jnp.any(leave), 0, jnp.where(jnp.any(join), jnp.where(jnp.any(sl.node < 0), 1, 2), todo + 2))
        (node, slot, Minv, k, cols), *rest = lax.switch(stage, [drop, add, full, check, refresh])
        return (_with_columns(sl, k, node, slot, Minv, cols), *rest)

    todo = jnp.where(jnp.any(leave | join), 1, 0).astype(jnp.int32)     # 1: check the inverse, 2: recompute it
    sl, _, _, over, _, fresh = lax.while_loop(cond, body, (sl, leave, join, jnp.array(False), todo, jnp.array(False)))
    return sl, over, fresh


def drift(op: Compliance, sl: Slots):
    """() how far the kept inverse is from the inverse of the bordered matrix M: the
    componentwise backward error max |M z − y| / (|M| |z| + |y|) of z = M⁻¹ y for a fixed
    probe y (0 for an exact inverse, a small multiple of eps for a fresh LU inverse)."""
    n = sl.Minv.shape[0]
    y = jnp.cos(jnp.arange(n, dtype=sl.Minv.dtype))
    z = sl.Minv @ y
    r = bordered_times(op, sl, z) - y
    scale = bordered_times(op, sl, jnp.abs(z), jnp.abs) + jnp.abs(y)
    return jnp.max(jnp.abs(r) / scale)


def bordered_matrix_of(op: Compliance, sl: Slots):
    """(2S + 3, 2S + 3) the bordered matrix M of eq. (4) over the slots (identity blocks at
    empty slots)."""
    dofs = slot_dofs(jnp.where(sl.active, sl.node, 0))
    return bordered_matrix(sl.Gc[dofs], op.N[dofs], sl.active)


def bordered_times(op: Compliance, sl: Slots, z, elementwise=lambda a: a):
    """M z for the bordered matrix M of eq. (4) over the slots, without forming M
    (``elementwise=jnp.abs``: |M| z)."""
    S = sl.node.shape[0]
    f, g = z[: 2 * S], z[2 * S:]
    dofs = slot_dofs(jnp.where(sl.active, sl.node, 0))
    on = jnp.repeat(sl.active, 2)
    A = elementwise(sl.Gc[dofs])
    B = elementwise(jnp.where(on[:, None], op.N[dofs], 0.0))
    return jnp.concatenate([jnp.where(on, A @ f + B @ g, f), B.T @ f])


# ----------------------------------------------------------------------------- one configuration
class Nodes(NamedTuple):
    """The per-node contact state (m,): mode (``laws`` FREE/STICK/SLIP_POS/SLIP_NEG), finger,
    theta (the anchor angle of a sticking node and the current angle of a sliding one, finger
    frame; for frictionless contacts the world-frame normal angle where the node touched) and
    armed (event D may fire, see :func:`engine._arm`)."""

    mode: jax.Array
    finger: jax.Array
    theta: jax.Array
    armed: jax.Array


class Solution(NamedTuple):
    """A configuration solved at one depth (scaled units).

    th: (S,) polar angle of each slot's node about its fingertip centre, finger frame.
    f: (S, 2) slot forces; g: (3,) rigid part; ok: () Newton converged.
    u, F: (m, 2) boundary displacements and forces.
    e: (m,) event functions (an event has happened where e < 0); kind: (m,) 0–3 for A–D.
    fn, ft: (m,) normal (pushing > 0) and tangential force of contact nodes.
    rate: (m,) slip rate s·dθ/dε of sliding nodes (0 elsewhere).
    gap: (m,) gap of every node to its nearest fingertip.
    iters: () Newton iterations; resid: () last Newton update [rad].
    """

    th: jax.Array
    f: jax.Array
    g: jax.Array
    ok: jax.Array
    u: jax.Array
    F: jax.Array
    e: jax.Array
    kind: jax.Array
    fn: jax.Array
    ft: jax.Array
    rate: jax.Array
    gap: jax.Array
    iters: jax.Array
    resid: jax.Array


class _View(NamedTuple):
    """The per-node state gathered into the slots."""

    idx: jax.Array      # (S,) node positions (0 for empty slots)
    active: jax.Array   # (S,)
    mode: jax.Array     # (S,) FREE for empty slots
    finger: jax.Array
    theta0: jax.Array
    armed: jax.Array


def _view(sl: Slots, ns: Nodes) -> _View:
    act = sl.active
    idx = jnp.where(act, sl.node, 0)
    return _View(idx, act, jnp.where(act, ns.mode[idx], FREE), ns.finger[idx], ns.theta[idx], ns.armed[idx])


def _linear(model: Model, sl: Slots, v: _View, p):
    """Slot forces (S, 2) and g (3,) for prescribed slot displacements p (S, 2) (eq. 4)."""
    S = v.idx.shape[0]
    # the whole inverse times [p; 0]: a column slice Minv[:, :2S] would be a copy of the
    # matrix on every call (on the CPU a sliced dot operand is materialised first)
    rhs = jnp.concatenate([jnp.where(v.active[:, None], p, 0.0).reshape(-1), jnp.zeros(3, p.dtype)])
    z = sl.Minv @ rhs
    if rhs.dtype == jnp.float32:
        # the inverse kept by bordering updates drifts in float32 (3e-4 after ~60 contacts made
        # and broken, docs/numerics.md §3): one step of iterative refinement against M itself
        z = z + sl.Minv @ (rhs - bordered_times(model.op, sl, z))
    return z[: 2 * S].reshape(S, 2), z[2 * S:]


def _block_form(sl: Slots, sel):
    """P (Q, 2, Q, 2): the slot-force block of the inverse between the slots ``sel`` (Q,),
    f_k = Σ_j P[k, :, j, :] p_j, gathered straight from the inverse (out-of-range slots
    clipped: callers mask them)."""
    S = (sl.Minv.shape[0] - 3) // 2
    dofs = (2 * jnp.clip(sel, 0, S - 1)[:, None] + jnp.arange(2)[None, :]).reshape(-1)
    Q = sel.shape[0]
    return sl.Minv[dofs[:, None], dofs[None, :]].reshape(Q, 2, Q, 2)


def _slip_angles(model: Model, sl: Slots, v: _View, d):
    """Slot angles θ (S,): anchors for sticking slots, system S (eq. 6) for sliding ones, by
    Newton. Returns (θ, ok, iterations, last update, dθ/dε (S,)).

    Newton's Jacobian is assembled from ``jax.jacobian`` of the per-slot laws by the chain rule
    through the exact linear map f = P p (O(S²) instead of S forward passes through P):
    ∂R_k/∂θ_j = ∂φ_k/∂f_k · P_kj · ∂p_j/∂θ_j + δ_kj ∂φ_k/∂θ_k. The converged angles are
    differentiated implicitly: the loop runs on constants, and one Newton step from its result,
    taken on the traced inputs, carries exactly the implicit-function tangent −J⁻¹ ∂R (at
    convergence the step itself is below the tolerance). dθ/dε = −J⁻¹ ∂R/∂ε the same way.

    Frictionless contacts slide with their force along the radius (φ = 0). Their equilibrium is
    the stationary point of the strain energy E(θ) over the contact angles; where the object's
    position is indeterminate (a drift along flat faces, a disk's spin) E is flat or, with
    material points pinned to the tips, slightly concave, and the stated rule holds it: the
    stationary point of E + ½ ε |ĝ⊥|², ĝ⊥ the rigid drift across the squeeze line and the spin
    (times the boundary's RMS radius) of the boundary displacement since the first touch (its
    least-squares rigid fit), and
    ε = ``NEUTRAL_REG`` × the mean contact stiffness: a spring anchored at the touch, stiff
    against the drift mode's negative stiffness (``docs/numerics.md`` §5.1). ĝ⊥ is continuous
    at a contact change (a node joins unloaded), but its sensitivity to the slots is not: a
    joining node may carry a small transient pull (§5.1, "Known imperfection").

    The unknowns are only the sliding slots: gathered into ``Config.sliding`` positions (one
    system; more sliding slots stop the squeeze with an overflow), or with ``sliding = 0`` into
    ``COMPACT`` positions (``COMPACT_ALL`` frictionless) when they fit (an 8 × 8 system
    instead of S × S), all S slots otherwise (two systems in the program).
    """
    S = v.idx.shape[0]
    cfg = model.cfg
    sliding = v.active & (v.mode >= SLIP_POS)
    zero = jnp.zeros((), v.theta0.dtype)
    if cfg.friction_model == "stick":
        return v.theta0, jnp.array(True), jnp.array(0, jnp.int32), zero, jnp.zeros_like(v.theta0)
    held = cfg.friction_model == "frictionless"

    def prescribed_k(th, c, r, a):
        return c + r * unit(th + a)

    def law_k(f, th, a, s, phi):       # eq. (6): the force on the cone edge θ + α − s φ
        return cross2(f, unit(th + a - s * phi))

    # the rule of frictionless contacts: ĝ⊥ = K p (2,) for slot displacements p, and its weight
    K = eps = None
    if held:
        N = model.op.N
        lift = jnp.concatenate([linalg.solve(N.T @ N, N.T @ sl.Gc), jnp.eye(3, dtype=N.dtype)], axis=1)
        fit = (lift @ sl.Minv)[:, : 2 * S]
        e = model.axis
        # the spin weighed by the boundary's RMS radius: the boundary's RMS displacement by it, a
        # length as the drift is (the rule must not change with the scaled unit of length, the
        # bounding box, which changes as the object turns in the plane)
        rho = jnp.sqrt(jnp.mean(jnp.sum(model.op.points * model.op.points, axis=-1)))
        K = jnp.stack([-e[1] * fit[0] + e[0] * fit[1], rho * fit[2]]).reshape(2, S, 2)
        diag = jnp.diagonal(sl.Minv)[: 2 * S].reshape(S, 2).sum(1)
        eps = NEUTRAL_REG * jnp.sum(jnp.where(v.active, diag, 0.0)) / jnp.maximum(2 * jnp.sum(v.active, dtype=diag.dtype), 1)

    def solve_for(sel, mask, back, on):
        """Newton on the slots ``sel`` (Q,) whose ``mask`` is set; the others stay at θ0.
        ``back`` (S,): each slot's position in ``sel``, where ``on`` (S,)."""
        take = lambda a: jnp.take(a, sel, axis=0, mode="clip")  # noqa: E731
        put = _gather(back, on)

        def angles(x, v):
            return put(x, v.theta0)

        @jax.jit     # traced once: the Newton loop, the implicit step and the rates reuse it
        def system(x, m, sl, v, dd, Psel, K, eps, ix):
            """(R (Q,), J (Q, Q)) of system S at the unknowns x; ix = (sel, mask, back, on)."""
            sel, mask, back, on = ix
            take = lambda a: jnp.take(a, sel, axis=0, mode="clip")  # noqa: E731
            th = _gather(back, on)(x, v.theta0)
            C = m.centres(dd)[v.finger]
            r = m.r[v.finger]
            a = m.angles(dd)[v.finger]
            p = jnp.where(v.active[:, None], jax.vmap(prescribed_k)(th, C, r, a) - m.op.points[v.idx], 0.0)
            f, _ = _linear(m, sl, v, p)
            sign = jnp.where(v.mode == SLIP_POS, 1.0, -1.0)
            phi = jnp.broadcast_to(m.phi, th.shape)
            f, th, C, r, a, sign, phi = map(take, (f, th, C, r, a, sign, phi))
            R = jax.vmap(law_k)(f, th, a, sign, phi)
            dp = jax.vmap(jax.jacobian(prescribed_k))(th, C, r, a)                          # (Q, 2)
            dlf, dlt = jax.vmap(jax.jacobian(law_k, argnums=(0, 1)))(f, th, a, sign, phi)   # (Q, 2), (Q,)
            J = jnp.einsum("ka,kajb,jb->kj", dlf, Psel, dp) + jnp.diag(dlt)
            if held:      # the gradient of ½ ε |ĝ⊥|² over r·θ, added to the tangential balance
                g = jnp.einsum("gkb,kb->g", K, p)
                Ks = jnp.take(K, sel, axis=1, mode="clip")
                H = jnp.einsum("gkb,kb->gk", Ks, dp)
                d2p = jax.vmap(jax.jacobian(jax.jacobian(prescribed_k)))(th, C, r, a)
                w = eps / r
                R = R - w * (g @ H)
                J = J - w[:, None] * (H.T @ H + jnp.diag(g @ jnp.einsum("gkb,kb->gk", Ks, d2p)))
            R = jnp.where(mask, R, x - take(v.theta0))
            # R depends on the unknowns of ``mask`` only (the other slots take θ0, not x): the
            # Jacobian's other columns are zero. Left in, a slot that sticks at an anchor carrying
            # a tangent added its effect on R a second time in the implicit step (dθ/dμ 7 % off)
            both = mask[:, None] & mask[None, :]
            return R, jnp.where(both, J, 0.0) + jnp.diag(jnp.where(mask, 0.0, 1.0))

        Psel = _block_form(sl, sel)
        args = (model, sl, v, d, Psel, K, eps, (sel, mask, back, on))
        consts = lax.stop_gradient(args)
        tol = consts[0].newton_tol

        def cond(c):
            return (c[1] < cfg.newton_iters) & (c[2] > tol)

        def body(c):
            x, it, last = c
            R, J = system(x, *consts)
            step = linalg.solve(J, R)
            dx = jnp.max(jnp.abs(step))
            # the loop ends once the next update is predicted below tol (this one times its
            # ratio to the one before, an over-estimate while Newton converges quadratically):
            # the implicit-function step below is then that next update
            return x - step, it + 1, jnp.where((it > 0) & (dx * dx <= tol * last), 0.0, dx)

        start = jnp.where(jnp.any(mask), jnp.array(jnp.inf, zero.dtype), zero)
        with jax.named_scope("newton"):
            x_c, it, _ = lax.while_loop(cond, body, (take(consts[2].theta0), jnp.array(0, jnp.int32), start))
        # the implicit-function step (see the docstring), then dθ/dε at the solution: its
        # Jacobian has the value at x_c but the tangent of x, so d(dθ/dε)/dε is exact too
        R, J = system(x_c, *args)
        x = x_c - linalg.solve(J, R)
        last = jnp.max(jnp.abs(lax.stop_gradient(x - x_c)))
        rate = jnp.zeros_like(v.theta0)
        if cfg.slip_events:
            _, J_t = system(_value_and_tangent(x_c, x), *args)
            _, R_eps = jax.jvp(lambda dd: system(x, *args[:3], dd, *args[4:])[0], (d,), (jnp.ones_like(d),))
            rate = put(-linalg.solve(J_t, R_eps))
        return angles(x, v), last <= tol, it, last, rate

    n = jnp.sum(sliding)
    still = lambda: (v.theta0, jnp.array(True), jnp.array(0, jnp.int32), zero, jnp.zeros_like(v.theta0))  # noqa: E731
    full = lambda: solve_for(jnp.arange(S), sliding, jnp.arange(S), sliding)  # noqa: E731

    def compact(Q):
        return lambda: solve_for(jnp.nonzero(sliding, size=Q, fill_value=S)[0], jnp.arange(Q) < n,
                                 jnp.clip(jnp.cumsum(sliding) - 1, 0, Q - 1), sliding)

    if cfg.sliding_limited:     # one system; more sliding slots are an overflow
        return lax.cond(n > 0, compact(cfg.sliding), still)
    Q = COMPACT_ALL if held else COMPACT
    if cfg.sliding or S <= Q:
        return lax.cond(n > 0, full, still)
    return lax.switch(jnp.where(n == 0, 0, jnp.where(n <= Q, 1, 2)), [still, compact(Q), full])


@jax.custom_jvp
def _value_and_tangent(a, b):
    """a, carrying the tangent of b (same shape)."""
    return a


@_value_and_tangent.defjvp
def _value_and_tangent_jvp(primals, tangents):
    return primals[0], tangents[1]


def solve(model: Model, sl: Slots, ns: Nodes, d) -> Solution:
    """Solve the configuration (slots, per-node state) at depth ``d`` and evaluate every event
    function (Section IV-B):

    * A (free nodes): gap to the nearest fingertip + ``gap_tol`` (segment contacts only);
    * B (contacts): the normal force;
    * C (sticking nodes): the cone margin (:func:`laws.cone_margin`);
    * D (sliding nodes whose rate was consistent once): the slip rate s·dθ/dε.
    """
    op, m, cfg = model.op, model.op.m, model.cfg
    v = _view(sl, ns)
    S = v.idx.shape[0]
    alpha = model.angles(d)[v.finger]
    C = model.centres(d)[v.finger]
    r = model.r[v.finger]
    rate = jnp.zeros_like(v.theta0)
    iters, resid, ok = jnp.array(0, jnp.int32), jnp.zeros((), v.theta0.dtype), jnp.array(True)
    th, ok, iters, resid, rate = _slip_angles(model, sl, v, d)
    axis = unit(th + alpha)                # cone axis: from the tip centre to the node
    p = C + r[:, None] * axis - op.points[v.idx]
    f, g = _linear(model, sl, v, p)
    f = jnp.where(v.active[:, None], f, 0.0)
    u = (sl.Gc @ f.reshape(-1) + op.N @ g).reshape(m, 2)
    put = sl.spread()
    F = put(f)

    x = op.points + u
    gaps = jnp.min(gap_to_fingers(model, x, d), axis=1)
    eA = gaps + model.gap_tol
    if cfg.contact == "point":
        eA = jnp.full_like(eA, jnp.inf)
        # a point contact (Section V-A) has the object's own deformed surface normal as its cone
        # axis: it turns as the band bends (Fig. 3), while the node stays put on the tip
        axis = -boundary.normals(x, op.loops)[v.idx]
    fn = jnp.sum(f * axis, -1)
    ft = cross2(axis, f)                   # f · t, t the axis turned by +90°
    srate = jnp.where(v.mode == SLIP_POS, 1.0, jnp.where(v.mode == SLIP_NEG, -1.0, 0.0)) * rate
    if cfg.slip_events:
        margin = laws.cone_margin(model.phi, fn, ft)
        other = jnp.where(v.mode == STICK, margin, jnp.where(v.armed, srate, jnp.inf))
        e_slot = jnp.minimum(fn, other)
        # B first: a normal force that has fallen below zero releases the contact even where
        # the cone margin or the slip rate is lower (a force through the cone's apex)
        k_slot = jnp.where((fn < other) | (fn < 0), 1, jnp.where(v.mode == STICK, 2, 3))
    else:
        e_slot, k_slot = fn, jnp.ones_like(v.mode)
    e = put(e_slot, eA)
    kind = put(k_slot.astype(jnp.int32))
    e = jnp.where((ns.mode == FREE) | (kind > 0), e, jnp.inf)
    del S
    return Solution(th, f, g, ok, u, F, e, kind, put(fn), put(ft), put(srate), gaps, iters, resid)
