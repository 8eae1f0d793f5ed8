"""The outcome of a squeeze: :class:`SqueezeResult` (one type, eager or traced) and its event log."""
from __future__ import annotations

import collections
import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..mechanics.operator import Compliance
from ..tracing import is_concrete, own_transfers
from .engine import Stats
from .laws import EVENT_KINDS
from .status import Status
from .validate import RULES


def norm(v, xp=jnp):
    """|v| over the last axis, with derivative 0 (not NaN) at v = 0: a grip that never started
    (forces 0) must not poison a gradient step of a placement search."""
    s = xp.sum(v * v, axis=-1)
    pos = s > 0
    return xp.where(pos, xp.sqrt(xp.where(pos, s, 1.0)), 0.0)


class EventLog(NamedTuple):
    """Contact events in the order they happened.

    depth: (E,) squeeze depth of each event [m] (for an event of an adversary's push: the
    push displacement, as the result's ``push`` rows); node: (E,) mesh node index;
    kind: (E,) 0–3 for events A (new contact), B (break), C (stick→slip), D (slip→stick);
    finger: (E,) 0 for the still finger, 1 for the moving one, 2 for the adversary's.

    The log is the whole history of the contact modes: replayed from the grip (A joins
    sticking, or sliding when frictionless; B lets go; C slides; D sticks) it gives the
    contact set and the stick/slip modes of every row (where rows share a depth, an event
    located at the depth of the one before, of the last of them). A new contact whose force
    leaves its friction cone as it grows from zero slides from the start: its A is followed
    by a C at the same depth (a grip node's C is at depth 0). A squeeze that ended with
    ``EVENT_OVERFLOW`` had no room for its last events: its last row holds the set they made.

    An eager squeeze's log holds its events only. The log of a result from ``jax.jit`` or
    ``squeeze(..., trim=False)`` keeps its fixed capacity (the ``max_events`` it ran with:
    ``Settings.bounds()``, or more where an eager squeeze grew it; the first
    ``result.n_events`` valid; the padding has node, kind and finger -1): read
    ``result.trim().events``.
    """

    depth: jax.Array
    node: jax.Array
    kind: jax.Array
    finger: jax.Array

    def __len__(self):
        return int(np.shape(self.depth)[0])

    def __repr__(self) -> str:
        """One line: the valid events by kind and the depths they span (``rows()`` lists them);
        a batch's or a traced log's shape."""
        try:
            if not is_concrete(tuple(self)):
                return f"EventLog(traced, {np.shape(self.depth)[-1]} slots)"
            if np.ndim(self.depth) != 1:
                return f"EventLog(batch of {np.shape(self.depth)[0]} logs × {np.shape(self.depth)[-1]} slots)"
            valid = np.asarray(self.kind) >= 0
            kinds = collections.Counter(EVENT_KINDS[int(k)] for k in np.asarray(self.kind)[valid])
            depth = np.asarray(self.depth)[valid]
            n = int(valid.sum())
            said = f"{n} event{'s' * (n != 1)}"
            if n:
                said += (" (" + ", ".join(f"{k} {kinds[k]}" for k in sorted(kinds)) + f") at depths "
                         f"{depth.min():.4g} to {depth.max():.4g} m; .rows() lists them")
            return f"EventLog({said})"
        except Exception:  # noqa: BLE001  (a repr must not raise)
            return f"EventLog(depth of shape {np.shape(self.depth)})"

    def rows(self):
        """List of (depth [m], node, 'A'..'D', finger 0|1|2) for printing, the valid events
        only (a padded log's padding is left out); one squeeze's log, not a batch's."""
        if np.ndim(self.depth) != 1:
            raise ValueError(f"this event log holds a batch (depth shape {np.shape(self.depth)}): take one squeeze "
                             "first, e.g. jax.tree.map(lambda a: a[i], result).events.rows()")
        return [(float(d), int(n), EVENT_KINDS[int(k)], int(f))
                for d, n, k, f in zip(*(np.asarray(a) for a in self)) if k >= 0]


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class SqueezeResult:
    """Outcome of a squeeze, in SI units, frame of ``mesh.points`` (node centroid at the origin).

    One type however it was computed. Rows k index the recorded states: the initial touch,
    every step and every event. The arrays have a fixed capacity (``max_steps + 1`` rows and
    ``max_events`` events of ``Settings.bounds()``, or more where an eager squeeze grew them);
    ``count`` and ``n_events`` say how many are valid and padding rows repeat the last valid one. :func:`jaxsqueeze.squeeze` called eagerly on
    one scene returns the result *trimmed* to its valid rows as numpy arrays (``trim=False``
    keeps the padding); under ``jit``/``vmap``/``jvp`` it is padded. The properties below
    (``final_depth``, ``final_forces``, ``total_force``, ``outcome``) honour ``count`` and
    work on both, and under tracing (they return arrays, batched when the result is).

    Fingers are numbered 0 (the still finger, the paper's finger 1) and 1 (the moving
    finger, the paper's finger 2) everywhere: arrays, event tables and JSON.

    status: () int, a :class:`Status` value.
    depth: (k,) squeeze depth [m].
    modes: (k, m) int8 per boundary node: 0 free, 1 stick, 2 slip toward larger polar
        angle, 3 slip toward smaller polar angle. Frictionless contacts are all 2: without
        friction a contact's force does not depend on its direction of sliding, which is
        not tracked (``theta`` says where it went).
    finger: (k, m) int8 finger (0 or 1) of contact nodes.
    theta: (k, m) polar angle of contact nodes about their fingertip centre, finger frame [rad].
    forces: (k, m, 2) contact force each fingertip exerts on the object [N].
    boundary_displacement: (k, m, 2) displacement of the boundary nodes [m].
    centres: (k, F, 2) fingertip centres [m]; alpha: (k, F) fingertip rotations [rad]; F = 2,
        or 3 with an adversary (finger 2 pushes).
    push: (k,) adversary push displacement [m] (0 during the squeeze; the squeeze phase's rows
        are those with push 0 before the first positive one).
    rigid: (k, 3) rigid part g of every row (t_x [m], t_y [m], rotation [rad]), in the
        compliance build's gauge (README, "Compliance builds").
    events: :class:`EventLog`.
    displacement: (n, 2) displacement of every node at the final depth [m] (None for an
        operator without a field map, or when the operator itself is traced).
    g: (3,) final rigid part (t_x [m], t_y [m], rotation [rad]).
    count, n_events: () valid rows of the history and of the event log.
    nodes: (m,) mesh node index of each boundary position.
    grip: (2,) mesh node indices of the two initial contacts (finger 0, finger 1).
    radius: () fingertip radius [m].
    stats: :class:`~jaxsqueeze.simulation.engine.Stats` (steps, events, Newton and bracket
        iterations, largest Newton residual, solves, recomputations of the kept bordered
        inverse, and the most contact and sliding nodes at once: the smallest
        ``Settings.capacity`` and ``sliding_capacity`` that run this squeeze without overflow;
        ``refined``: times an event was resolved again with ``event_tol`` / 10, see
        ``engine.REFINE``).
    invalid: () int, index into ``validate.FIELDS`` of the first invalid input, -1 if none.
    margin: () smooth feasibility margin of the grip [rad]: the friction angle minus the larger
        angle between the segment joining the first contacts and their inward normals; < 0
        infeasible (−π when a placed finger cannot touch the object; its one row then has no contact).
    squeeze_status: () the status the squeeze phase ended with (``status`` is the final one,
        after the adversary push when there is one).
    push_work: (3,) work during the adversary push [J]: done by the pusher on the object, and
        resisted by finger 0 and by finger 1 (trapezoid rule over the recorded rows; zeros
        without an adversary). See :mod:`jaxsqueeze.plan.quality`.
    squeeze_events: () events logged by the squeeze phase: the first ``squeeze_events`` of the
        event log are the squeeze's (at squeeze depths), the rest the push's (at push
        displacements).

    A result computed with ``history=False`` (a few kilobytes per grasp) holds two rows: row 0 the
    last squeeze-phase row, row 1 the last row; ``stats`` still counts every step and event.
    """

    status: jax.Array
    depth: jax.Array
    modes: jax.Array
    finger: jax.Array
    theta: jax.Array
    forces: jax.Array
    boundary_displacement: jax.Array
    centres: jax.Array
    alpha: jax.Array
    rigid: jax.Array
    events: EventLog
    displacement: jax.Array | None
    g: jax.Array
    count: jax.Array
    n_events: jax.Array
    nodes: jax.Array
    grip: jax.Array
    radius: jax.Array
    stats: Stats
    invalid: jax.Array
    push: jax.Array
    margin: jax.Array
    squeeze_status: jax.Array
    push_work: jax.Array
    squeeze_events: jax.Array

    def __repr__(self) -> str:
        """One line (``print(res)``, a notebook cell): the outcome, the depth reached, the rows,
        the events by kind and the grip force; a batch's outcomes; a traced result's sizes.
        The arrays are the fields (``res.forces``, ...)."""
        try:
            return f"SqueezeResult({self._in_words()})"
        except Exception:  # noqa: BLE001  (a repr must not raise, whatever JAX's tree code put in the fields)
            return f"SqueezeResult(forces of shape {np.shape(self.forces)})"

    def _in_words(self) -> str:
        rows, m = np.shape(self.forces)[-3:-1]
        if not is_concrete((self.status, self.count, self.depth, self.forces)):
            return f"traced, {rows} rows × {m} boundary nodes"
        if np.ndim(self.count) != 0:
            said = collections.Counter(Status(int(k)).name for k in np.ravel(self.status))
            d = np.asarray(self.final_depth)
            return (f"batch of {np.size(self.status)}: " + ", ".join(f"{k} {v}" for k, v in said.items())
                    + f"; final depth {d.min():.4g} to {d.max():.4g} m")
        kinds = collections.Counter(EVENT_KINDS[int(k)] for k in np.asarray(self.events.kind)[:int(self.n_events)])
        events = ", ".join(f"{k} {kinds[k]}" for k in sorted(kinds))
        rows, n = int(self.count), int(self.n_events)
        said = (f"{self.outcome.name} at depth {float(self.final_depth):.4g} m, {rows} row{'s' * (rows != 1)}, "
                f"{n} event{'s' * (n != 1)}{f' ({events})' if events else ''}, grip force {float(self.grip_force):.4g} N")
        push = float(self._last(self.push))
        return said + (f", pushed {push:.4g} m" if push > 0 else "")

    def _one(self, what: str) -> None:
        """ValueError unless this is one concrete squeeze (not batched, not traced)."""
        if np.ndim(self.count) != 0:
            raise ValueError(f"{what} takes one squeeze, but this result is batched (count has shape "
                             f"{np.shape(self.count)}); pick one lane first, e.g. jax.tree.map(lambda a: a[i], res)")
        if not is_concrete(self.status):
            raise ValueError(f"{what} needs a concrete result; under jax.jit, vmap or jacfwd the status is traced: "
                             "return the result (or result.status) from the traced function and read it outside")

    @property
    def outcome(self) -> Status:
        """The status as a :class:`Status` (eager, unbatched results only)."""
        self._one("result.outcome")
        return Status(int(self.status))

    @property
    def _xp(self):
        """numpy for a trimmed or host result, jax.numpy for arrays on a device or traced."""
        return np if isinstance(self.count, (np.ndarray, np.generic, int)) else jnp

    def _last(self, a):
        """Row ``count - 1`` of a history array (k, ...) or a batch of them (B, k, ...)."""
        xp = self._xp
        a = xp.asarray(a)
        lead = np.ndim(self.count)
        idx = (xp.asarray(self.count) - 1).reshape(np.shape(self.count) + (1,) * (a.ndim - lead))
        return xp.take_along_axis(a, idx, axis=lead)[(slice(None),) * lead + (0,)]

    @property
    @own_transfers
    def final_depth(self):
        """() depth reached [m] (batched: one per member)."""
        return self._last(self.depth)

    @property
    @own_transfers
    def final_forces(self):
        """(m, 2) contact forces at the final row [N]."""
        return self._last(self.forces)

    @property
    @own_transfers
    def finger_forces(self):
        """(k, F, 2) total force of every finger on the object [N], per row (F = 3 with an adversary)."""
        xp = self._xp
        F = xp.asarray(self.forces)
        fg = xp.asarray(self.finger)
        on = xp.asarray(self.modes) > 0
        n = np.shape(self.centres)[-2]
        return xp.stack([xp.sum(xp.where((on & (fg == k))[..., None], F, 0.0), axis=-2) for k in range(n)], -2)

    @property
    @own_transfers
    def total_force(self):
        """(k, 2, 2) total force of each grasping finger (axis -2: finger 0, 1) on the object [N], per row."""
        return self.finger_forces[..., :2, :]

    @property
    @own_transfers
    def grip_force(self):
        """() magnitude of the total force of the still finger at the final row [N]."""
        return norm(self._last(self.total_force)[..., 0, :], self._xp)

    def raise_for_status(self) -> "SqueezeResult":
        """Raise ``RuntimeError`` with advice unless the squeeze reached its target depth."""
        self._one("result.raise_for_status()")
        if self.outcome != Status.SUCCESS:
            said = ""
            k = int(np.asarray(self.invalid)) if self.invalid is not None else -1
            if self.outcome == Status.INVALID_INPUT and 0 <= k < len(RULES):     # the field, in words
                said = f" Here it is {RULES[k].field} (result.invalid = {k}): expected {RULES[k].requirement}; " \
                       f"{RULES[k].fix}."
            raise RuntimeError(f"squeeze ended with {self.outcome.name} at depth {float(self.final_depth):.6g} m: "
                               f"{self.outcome.advice}{said}")
        return self

    def trim(self) -> "SqueezeResult":
        """This result without its padding rows, as numpy arrays (eager, unbatched only)."""
        self._one("result.trim()")
        return trim(self)


def to_result(st, op: Compliance, grasp) -> SqueezeResult:
    """Convert the engine's final state (scaled) into a :class:`SqueezeResult` (SI), padded
    with the last valid row; the full displacement field is left to the caller (None)."""
    L, Fs = op.length, op.force_scale
    # refused under tracing: no force, whatever a NaN modulus or thickness made of the scale
    Fs = jnp.where(st.invalid >= 0, 0.0, Fs)
    depth, mode, finger, theta, F, u, C, alpha, g, push = st.hist
    k = jnp.minimum(st.count, depth.shape[0])
    rows = jnp.arange(depth.shape[0], dtype=k.dtype)
    last = jnp.minimum(rows, k - 1)                  # pad with the last valid row
    pad = lambda a: a[last]  # noqa: E731
    ev_d, ev_n, ev_k, ev_f = st.events
    n_ev = jnp.minimum(st.n_ev, ev_d.shape[0])
    ev_n, ev_k, ev_f = (jnp.where(jnp.arange(ev_d.shape[0], dtype=n_ev.dtype) < n_ev, a, -1) for a in (ev_n, ev_k, ev_f))   # padding
    gs = jnp.array([L, L, 1.0], st.g.dtype)
    # a placed finger that cannot touch the object (margin −π, INFEASIBLE_GRIP): its one row
    # records where the fingertips were placed, so no node is in contact
    mode = jnp.where(st.margin <= -jnp.pi, jnp.zeros_like(mode), mode)
    return SqueezeResult(
        status=st.status, depth=pad(depth) * L, modes=pad(mode), finger=pad(finger), theta=pad(theta),
        forces=pad(F) * Fs, boundary_displacement=pad(u) * L, centres=pad(C) * L, alpha=pad(alpha),
        rigid=pad(g) * gs[None, :], events=EventLog(ev_d * L, ev_n, ev_k, ev_f), displacement=None,
        g=st.g * gs, count=k, n_events=n_ev, nodes=op.nodes,
        grip=op.nodes[st.grip], radius=grasp.radius,
        stats=st.stats, invalid=st.invalid, push=pad(push) * L, margin=st.margin,
        squeeze_status=st.squeeze_status, push_work=st.work * Fs * L,
        squeeze_events=jnp.minimum(st.squeeze_events, ev_d.shape[0]))


HISTORY = ("depth", "modes", "finger", "theta", "forces", "boundary_displacement", "centres", "alpha", "rigid",
           "push")


def trim(res: SqueezeResult) -> SqueezeResult:
    """Drop the padding rows of an unbatched result (as numpy arrays: slicing JAX arrays to a
    new length would compile a small program per length). Idempotent."""
    res = jax.tree.map(np.asarray, res)
    k, e = int(res.count), int(res.n_events)
    hist = {f: getattr(res, f)[:k] for f in HISTORY}
    return dataclasses.replace(res, events=EventLog(*(a[:e] for a in res.events)), **hist)
