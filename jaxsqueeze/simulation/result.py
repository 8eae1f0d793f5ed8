"""The outcome of a squeeze: :class:`SqueezeResult` (one type, eager or traced) and its event log."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..mechanics.operator import Compliance
from .laws import EVENT_KINDS
from .status import Status


class EventLog(NamedTuple):
    """Contact events in the order they happened.

    depth: (E,) squeeze depth of each event [m]; node: (E,) mesh node index;
    kind: (E,) 0–3 for events A (new contact), B (break), C (stick→slip), D (slip→stick);
    finger: (E,) 0 for finger 1, 1 for finger 2.
    """

    depth: jax.Array
    node: jax.Array
    kind: jax.Array
    finger: jax.Array

    def __len__(self):
        return int(np.shape(self.depth)[0])

    def rows(self):
        """List of (depth [m], node, 'A'..'D', finger 1|2) for printing."""
        return [(float(d), int(n), EVENT_KINDS[int(k)], int(f) + 1)
                for d, n, k, f in zip(*(np.asarray(a) for a in self))]


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class SqueezeResult:
    """Outcome of a squeeze, in SI units, frame of ``mesh.points`` (node centroid at the origin).

    Rows k index the recorded states: the initial touch, every step and every event.
    Under ``jit``/``vmap`` the arrays keep their fixed capacity and ``count`` / ``n_events``
    say how many rows are valid (the rest repeat the last state); :func:`squeeze` called
    eagerly trims them.

    status: () int, a :class:`Status` value.
    depth: (k,) squeeze depth [m].
    modes: (k, m) int8 per boundary node: 0 free, 1 stick, 2 slip toward larger polar
        angle, 3 slip toward smaller polar angle.
    finger: (k, m) int8 finger (0 or 1) of contact nodes.
    theta: (k, m) polar angle of contact nodes about their fingertip centre, finger frame [rad].
    forces: (k, m, 2) contact force each fingertip exerts on the object [N].
    boundary_displacement: (k, m, 2) displacement of the boundary nodes [m].
    centres: (k, 2, 2) fingertip centres [m]; alpha: (k, 2) fingertip rotations [rad].
    events: :class:`EventLog`.
    displacement: (n, 2) displacement of every node at the final depth [m] (None for an
        operator without a field map).
    g: (3,) final rigid part (t_x [m], t_y [m], rotation [rad]).
    count, n_events: () valid rows of the history and of the event log.
    nodes: (m,) mesh node index of each boundary position.
    radius: () fingertip radius [m].
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
    events: EventLog
    displacement: jax.Array | None
    g: jax.Array
    count: jax.Array
    n_events: jax.Array
    nodes: jax.Array
    radius: jax.Array

    @property
    def outcome(self) -> Status:
        return Status(int(self.status))

    @property
    def final_depth(self) -> float:
        return float(np.asarray(self.depth)[int(self.count) - 1])

    @property
    def total_force(self) -> np.ndarray:
        """(k, 2, 2) total force of each finger on the object [N], per recorded state."""
        F = np.asarray(self.forces)
        fg = np.asarray(self.finger)
        on = np.asarray(self.modes) > 0
        return np.stack([np.sum(np.where((on & (fg == k))[..., None], F, 0.0), axis=1) for k in (0, 1)], 1)

    def raise_for_status(self) -> "SqueezeResult":
        """Raise ``RuntimeError`` with advice unless the squeeze reached its target depth."""
        if self.outcome != Status.SUCCESS:
            raise RuntimeError(f"squeeze ended with {self.outcome.name} at depth {self.final_depth:.6g} m: "
                               f"{self.outcome.advice}")
        return self



def to_result(st, op: Compliance, radius) -> SqueezeResult:
    """Convert the engine's final state (scaled) into a :class:`SqueezeResult` (SI), padded
    with the last valid row; the full displacement field is left to the caller (None)."""
    L, Fs = op.length, op.force_scale
    depth, mode, finger, theta, F, u, C, alpha = st.hist
    k = st.count
    rows = jnp.arange(depth.shape[0])
    last = jnp.minimum(rows, k - 1)                  # pad with the last valid row
    pad = lambda a: a[last]  # noqa: E731
    ev_d, ev_n, ev_k, ev_f = st.events
    return SqueezeResult(
        status=st.status, depth=pad(depth) * L, modes=pad(mode), finger=pad(finger), theta=pad(theta),
        forces=pad(F) * Fs, boundary_displacement=pad(u) * L, centres=pad(C) * L, alpha=pad(alpha),
        events=EventLog(ev_d * L, ev_n, ev_k, ev_f), displacement=None,
        g=st.g * jnp.array([L, L, 1.0], st.g.dtype), count=k, n_events=st.n_ev, nodes=op.nodes,
        radius=radius)


def trim(res: SqueezeResult) -> SqueezeResult:
    """Drop the padding rows of an unbatched result (as numpy arrays: slicing JAX arrays to a
    new length would compile a small program per length)."""
    res = jax.tree.map(np.asarray, res)
    k, e = int(res.count), min(int(res.n_events), len(res.events))
    hist = {f: getattr(res, f)[:k] for f in ("depth", "modes", "finger", "theta", "forces",
                                              "boundary_displacement", "centres", "alpha")}
    return dataclasses.replace(res, events=EventLog(*(a[:e] for a in res.events)), **hist)
