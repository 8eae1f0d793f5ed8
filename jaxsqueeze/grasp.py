"""The user-facing squeeze: :func:`squeeze` turns a :class:`Scene` into a :class:`SqueezeResult`."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .engine import CONE_SLACK, EVENT_KINDS, Config, Grasp, simulate  # noqa: F401  (simulate: the jittable core)
from .material import _concrete
from .operator import Compliance, field_displacement
from .scene import Scene
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


# ----------------------------------------------------------------------------- scene → core inputs
def config_of(scene: Scene) -> Config:
    s = scene.settings
    return Config(friction_model=scene.friction_model, contact=scene.contact,
                  rotation=scene.fingers.rotation is not None, capacity=int(s.capacity),
                  max_steps=int(s.max_steps), max_events=int(s.max_events),
                  newton_iters=int(s.newton_iters), bisect_iters=int(s.bisect_iters))


def grasp_of(scene: Scene, op: Compliance) -> Grasp:
    dt = op.G.dtype
    f64 = dt == jnp.float64
    L = float(op.length)
    s = scene.settings
    depth = jnp.asarray(scene.depth, dt)
    step = jnp.asarray(s.step, dt) if s.step is not None else depth / 50
    event_tol = jnp.asarray(s.event_tol, dt) if s.event_tol is not None else step * 1e-4
    newton_tol = s.newton_tol if s.newton_tol is not None else (1e-11 if f64 else 1e-5)
    gap_tol = s.gap_tol if s.gap_tol is not None else (1e-9 if f64 else 1e-5) * L
    pos = np.full(int(np.max(np.asarray(op.nodes))) + 1, -1)
    pos[np.asarray(op.nodes)] = np.arange(op.m)
    grip = jnp.asarray(pos)[jnp.asarray(scene.grip)]
    rot = scene.fingers.rotation
    rot = jnp.zeros((2, 1), dt) if rot is None else jnp.asarray(rot, dt)
    return Grasp(grip=grip, radius=jnp.asarray(scene.fingers.radius, dt), mu=jnp.asarray(scene.friction, dt),
                 depth=depth, step=step, event_tol=event_tol, newton_tol=jnp.asarray(newton_tol, dt),
                 gap_tol=jnp.asarray(gap_tol, dt), rotation=rot)


@partial(jax.jit, static_argnames=("cfg",))
def _run(op: Compliance, grasp: Grasp, cfg: Config):
    """The compiled squeeze: (SqueezeResult in SI without the full field, scaled final forces, g)."""
    st = simulate(op, grasp, cfg)
    return to_result(st, op, grasp.radius), st.F.reshape(-1), st.g


def squeeze(scene: Scene) -> SqueezeResult:
    """Follow a two-finger squeeze from first touch to the target depth (Section IV).

    Runs one compiled ``lax.while_loop``; a second call with new numbers (grip, friction,
    depth, radius, material E) reuses the compiled program. Works under ``jax.vmap`` and
    forward-mode differentiation (``jax.jvp``/``jax.jacfwd``) over the scene's numbers.
    Inspect ``result.status`` (or call ``result.raise_for_status()``): a failed grasp is an
    outcome, not an exception.
    """
    op = scene.operator()
    if _concrete(scene.grip) and _concrete(scene.friction):
        check_grip(scene, op)
    cfg = config_of(scene)
    res, F_hat, g_hat = _run(dataclasses.replace(op, field=None), grasp_of(scene, op), cfg)
    if op.field is not None:
        res = dataclasses.replace(res, displacement=field_displacement(op, F_hat, g_hat) * op.length)
    if np.ndim(res.count) == 0 and all(map(_concrete, jax.tree.leaves(res))):   # eager, unbatched
        res = trim(res)
    return res


def check_grip(scene: Scene, op: Compliance) -> None:
    """Raise if the segment between the initial contacts leaves either friction cone."""
    g = np.asarray(scene.grip)
    if g.ndim != 1 or scene.friction_model == "stick":   # full stick: the cones are half-planes
        return
    pos = {int(v): k for k, v in enumerate(np.asarray(op.nodes))}
    i, j = pos[int(g[0])], pos[int(g[1])]
    P, N = np.asarray(op.points), np.asarray(op.normals)
    seg = (P[j] - P[i]) / np.linalg.norm(P[j] - P[i])
    ang = np.degrees(np.arccos(np.clip([-N[i] @ seg, N[j] @ seg], -1, 1)))
    half = np.degrees(np.arctan(float(scene.friction))) if scene.friction_model == "coulomb" else 0.0
    if np.any(ang > half + np.degrees(CONE_SLACK)):
        raise ValueError(
            f"grip {tuple(int(v) for v in g)}: the segment between the two contacts makes {ang[0]:.3g}° and "
            f"{ang[1]:.3g}° with the inward normals, but the friction cones only allow {half:.3g}° "
            f"(mu={float(scene.friction):.3g}, friction_model={scene.friction_model!r}). Pick more nearly "
            "opposite nodes (e.g. Scene.nearest_boundary_node) or raise the friction.")


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
