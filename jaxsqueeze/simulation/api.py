"""The user-facing squeeze: :func:`squeeze` turns a :class:`Scene` into a :class:`SqueezeResult`."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .engine import Config, Grasp, simulate
from .laws import CONE_SLACK
from .result import EventLog, SqueezeResult, to_result, trim  # noqa: F401
from ..tracing import is_concrete
from ..mechanics.operator import Compliance, field_displacement
from .scene import Scene
from .status import Status



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
    if is_concrete(scene.grip) and is_concrete(scene.friction):
        check_grip(scene, op)
    cfg = config_of(scene)
    res, F_hat, g_hat = _run(dataclasses.replace(op, field=None), grasp_of(scene, op), cfg)
    if op.field is not None:
        res = dataclasses.replace(res, displacement=field_displacement(op, F_hat, g_hat) * op.length)
    if np.ndim(res.count) == 0 and all(map(is_concrete, jax.tree.leaves(res))):   # eager, unbatched
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


