"""Grasp quality measures: pure functions of a :class:`~jaxsqueeze.SqueezeResult` (DESIGN 2.9).

Each works on an eager (trimmed) result, a padded one from ``jit``, inside ``vmap`` and under
``jax.jacfwd``: it reads only the valid rows (``count``) and uses array operations. Given a
batched result (of ``jax.vmap(squeeze)``) it returns one value per member (:func:`per_result`). Formulas
(rows k of the result; F_i(k) the total force of finger i on the object, x_i(k) its centre):

* :func:`squeeze_work` — the strain energy stored by the squeeze, ½ Σ_nodes F·u at the last
  squeeze row (the work the fingers did on the object, less what friction dissipated; IJRR
  2014's "stable squeeze" maximizes it for the same amount of squeezing) [J].
* :func:`grip_force` — |F_0| at the last squeeze row [N].
* :func:`slip_margin` — how far the grasp is from total slip at the last squeeze row: each
  contact node's cone margin m = sin(φ − ψ) (ψ the angle of its force f from the cone axis:
  the fingertip normal, or for point contacts the deformed surface normal, given the scene;
  1 on the axis, 0 on the cone edge, < 0 outside); for each finger its friction reserve
  relative to its load, M_f = Σ_k |f_k| m_k / Σ_k |f_k| = Σ_k (sin φ f_n,k − cos φ |f_t,k|) /
  Σ_k |f_k| (positive while any of its contacts sticks, 0 when all slide), and a smooth
  minimum over the two fingers (the grasp holds while both do): −τ log Σ_f exp(−M_f/τ),
  temperature ``tau`` (τ → 0 gives the minimum exactly; the smooth one lies below it by at
  most τ log 2, so a grasp that failed is never positive) [–]. Weighting each contact by its
  force keeps the margin continuous where a contact joins or lets go (with zero force): a
  plain maximum over the contacts jumped there (0.09 → 0.27 as a contact joined).
* :func:`adversary_work` — the work the pusher does on the object during the adversary
  phase, W = Σ_k ½ (F_2(k) + F_2(k+1)) · (x_2(k+1) − x_2(k)) [J]: the energy the grasp absorbs
  in resisting the push (Jia, Guo and Lin, IJRR 2014); larger is better. ``push=p``: the
  work up to the push displacement p [m], the increment that holds p cut there (its slope in
  p is the pusher's force along its motion).
* :func:`finger_work` — (2,) the share of that work each grasping finger resists:
  W_i = −Σ_k ½ (ΔF_i(k) + ΔF_i(k+1)) · (x_2(k+1) − x_2(k)), ΔF_i the change of finger i's force
  since the push began; W_0 + W_1 = W by equilibrium.
* :func:`failure_push` — the push displacement at which the grasp failed (the final push
  when it held) [m].
"""
from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ..compiler import precise
from ..geometry import boundary
from ..geometry.mesh import Mesh
from ..numbers import positive, real_array
from ..simulation.laws import FREE, SLIP_POS
from ..simulation.result import SqueezeResult, norm
from ..tracing import is_concrete, own_transfers


def _check_result(res, name: str):
    """A quality takes what :func:`jaxsqueeze.squeeze` returns; anything else (a scene passed
    for its squeeze, a dict) is a TypeError that says so, not an error deep inside."""
    if not isinstance(res, SqueezeResult):
        hint = f": squeeze it first, {name}(jsq.squeeze(scene))" if type(res).__name__ == "Scene" else ""
        raise TypeError(f"{name} takes a SqueezeResult (what jsq.squeeze returns), got {type(res).__name__}{hint}")


def per_result(fn):
    """``fn`` of one result, mapped (``jax.vmap``) over a batched one: a result of
    ``jax.vmap(squeeze)`` (``depth`` of shape (B, k)) gives one value per member, (B, ...).
    The quality runs as one compiled program (under an eager ``jax.jacfwd`` its ~25 small
    operations would each be compiled on their own)."""
    whole = jax.jit(precise(fn))

    @functools.wraps(fn)
    @own_transfers
    def wrapped(res, *args):          # (args: shared by every member of a batch)
        _check_result(res, fn.__name__)
        if jnp.ndim(res.depth) == 2:
            return jax.vmap(whole, in_axes=(0,) + (None,) * len(args))(res, *args)
        return whole(res, *args)
    return wrapped


def _rows(res: SqueezeResult):
    """(valid (k,), squeeze (k,), push (k,)) row masks: recorded rows, squeeze-phase rows, push rows."""
    k = jnp.arange(jnp.shape(res.depth)[-1], dtype=jnp.asarray(res.count).dtype)
    valid = k < res.count
    squeeze = valid & (jnp.asarray(res.push) == 0)
    return valid, squeeze, valid & ~squeeze


def _squeeze_row(res: SqueezeResult):
    """Index of the last squeeze-phase row."""
    return jnp.sum(_rows(res)[1]) - 1


@per_result
def squeeze_work(res: SqueezeResult):
    """() strain energy stored by the squeeze at its last row [J] (see module docstring)."""
    r = _squeeze_row(res)
    F, u = jnp.asarray(res.forces)[r], jnp.asarray(res.boundary_displacement)[r]
    return 0.5 * jnp.sum(F * u)


@per_result
def grip_force(res: SqueezeResult):
    """() magnitude of the still finger's total force at the last squeeze row [N]."""
    return norm(jnp.asarray(res.finger_forces)[_squeeze_row(res), 0])


def _softmax(x, tau):
    """τ log Σ exp(x/τ) (≥ the maximum, by at most τ log k)."""
    big = jnp.max(x)
    return big + tau * jnp.log(jnp.sum(jnp.exp((x - big) / tau)))


@own_transfers
def slip_margin(res: SqueezeResult, friction, tau: float = 0.01, scene=None):
    """() smooth slip margin of the grasp at its last squeeze row (see module docstring); (B,)
    for a batched result.

    ``friction``: the Coulomb μ of the squeeze (``scene.friction``); for a batched result one
    shared μ or (B,), one per member. −1 when a finger has no contact.
    ``scene``: the squeezed scene; needed for point contacts (``contact="point"``, e.g. bands),
    whose cone axis is the object's deformed surface normal, as in the squeeze (without it the
    margin is taken about the fingertip normal, which is the cone axis of segment contacts only).
    Given the scene, its friction model also sets the cones, as in the squeeze: full stick
    measures against cones of half angle π/2 (μ = ∞), frictionless against μ = 0 (every
    contact slides: margin 0), whatever ``friction`` says (μ measured a full-stick map against
    cones the squeeze never applied: margins down to −0.77).
    """
    _check_result(res, "slip_margin")
    if is_concrete(tau):
        positive(tau, "slip_margin's tau (the smooth minimum's temperature)")
    model = getattr(scene, "friction_model", "coulomb")
    if model != "coulomb":
        friction = jnp.inf if model == "stick" else 0.0
    if is_concrete(friction):
        mu = real_array(friction, "slip_margin's friction (the Coulomb μ of the squeeze)")
        if not np.all(mu >= 0):                      # NaN too; μ = ∞ (full stick) is allowed
            raise ValueError(f"slip_margin's friction must be ≥ 0 (μ = ∞ for full stick); got {mu.tolist()}")
    x0, loops = _surface(scene) or (None, None)
    if x0 is not None and len(x0) != jnp.shape(res.forces)[-2]:
        raise ValueError(f"slip_margin's scene has {len(x0)} boundary nodes, the result {jnp.shape(res.forces)[-2]}: "
                         "pass the scene that was squeezed")
    batch = jnp.shape(res.depth)[:-1]
    dt = jnp.result_type(res.forces)           # (a Python μ and an array μ: one program)
    friction, tau = jnp.asarray(friction, dt), jnp.asarray(tau, dt)
    one = lambda r, mu: _slip_margin(r, mu, tau, x0, loops=loops)  # noqa: E731
    if jnp.ndim(friction) == 0:
        return jax.vmap(one, in_axes=(0, None))(res, friction) if len(batch) == 1 else one(res, friction)
    if len(batch) == 1 and jnp.shape(friction) == batch:
        return jax.vmap(one)(res, friction)
    raise ValueError(f"friction of shape {jnp.shape(friction)}: expected one μ" +
                     (f", or one per member of the batched result (shape {batch})" if batch else " for one result"))


def _surface(scene):
    """(points (m, 2) [m], loops) of a point-contact scene's boundary nodes in the result's
    frame and order; None for segment contacts (or no scene)."""
    if scene is None or getattr(scene, "contact", "segment") != "point":
        return None
    obj = scene.mesh
    if isinstance(obj, Mesh):
        return obj.points[obj.boundary], obj.loops
    return obj.points, (obj.m,)


@functools.partial(jax.jit, static_argnames="loops")     # one program (op by op, a first call took 2 s)
@precise
def _slip_margin(res: SqueezeResult, friction, tau, x0=None, loops=None):
    r = _squeeze_row(res)
    F = jnp.asarray(res.forces)[r]
    mode, fg = jnp.asarray(res.modes)[r], jnp.asarray(res.finger)[r]
    if x0 is None:           # segment contacts: the fingertip normal at the contact (from its centre)
        ang = jnp.asarray(res.theta)[r] + jnp.take_along_axis(jnp.asarray(res.alpha)[r], fg.astype(jnp.int32), 0)
        axis = jnp.stack([jnp.cos(ang), jnp.sin(ang)], -1)
    else:                    # point contacts: the inward normal of the deformed surface
        axis = -boundary.normals(jnp.asarray(x0, F.dtype) + jnp.asarray(res.boundary_displacement)[r], loops)
    fn = jnp.sum(F * axis, -1)
    ft = axis[:, 0] * F[:, 1] - axis[:, 1] * F[:, 0]
    size = norm(jnp.stack([fn, ft], -1))
    phi = jnp.arctan(jnp.asarray(friction, F.dtype))
    reserve = jnp.sin(phi) * fn - jnp.cos(phi) * jnp.abs(ft)    # sin(φ − ψ) |f|, exactly 0 on the edge (no CONE_SLACK)
    reserve = jnp.where(mode >= SLIP_POS, 0.0, reserve)        # sliding: on the edge (round-off made a failure positive)
    per = []
    for f in (0, 1):
        on = (mode > FREE) & (fg == f) & (size > 0)
        load = jnp.sum(jnp.where(on, size, 0.0))
        per.append(jnp.where(jnp.any(on), jnp.sum(jnp.where(on, reserve, 0.0)) / jnp.where(load > 0, load, 1.0), -1.0))
    return -_softmax(-jnp.stack(per), tau)


def _push_work(res: SqueezeResult):
    """(3,) [J]: the pusher's work and each grasping finger's share, summed by the engine over
    every push increment (the trapezoid rule above), so also for results that keep only their
    last rows (``jsq.squeeze(scene, history=False)``: a sum over the recorded rows saw one increment)."""
    if jnp.asarray(res.centres).shape[-2] < 3:
        raise ValueError("this result has no adversary phase: give the scene an Adversary")
    return jnp.asarray(res.push_work)


@per_result
def _whole_push(res: SqueezeResult):
    return _push_work(res)


@per_result
def _push_until(res: SqueezeResult, push):
    """(3,) the works of :func:`_push_work` up to the push displacement ``push`` [m]: the
    trapezoid rule over the recorded increments, the one that holds ``push`` cut there (the
    forces linear in the push within an increment, as the rule assumes); from the last row's
    push on, the engine's whole sums. NaN below it for a result that kept two rows
    (``history=False``), whose increments are gone."""
    total = _push_work(res)
    _, _, pushed = _rows(res)
    p = jnp.asarray(res.push)
    push = jnp.asarray(push, p.dtype)
    F = res.finger_forces                                    # (k, 3, 2)
    x = jnp.asarray(res.centres)[:, 2]                       # (k, 2) the pusher's centre
    F0 = F[_squeeze_row(res)]                                # the forces as the push began
    dp = p[1:] - p[:-1]
    moved = dp > 0                                           # (rows at one push move nothing)
    t = jnp.where(moved, jnp.clip((push - p[:-1]) / jnp.where(moved, dp, 1.0), 0.0, 1.0), 0.0)
    mid = F[:-1] + 0.5 * t[:, None, None] * (F[1:] - F[:-1])  # the mean force over the cut increment
    dx = t[:, None] * (x[1:] - x[:-1])
    on = pushed[1:]
    inc = jnp.stack([jnp.sum(mid[:, 2] * dx, -1), -jnp.sum((mid[:, 0] - F0[0]) * dx, -1),
                     -jnp.sum((mid[:, 1] - F0[1]) * dx, -1)], -1)
    part = jnp.sum(jnp.where(on[:, None], inc, 0.0), 0)
    last = p[res.count - 1]
    # two rows with a push are a history=False result (with its history a push takes >= 3)
    return jnp.where(push >= last, total, jnp.where(res.count != 2, part, jnp.nan))


def _push_arg(res: SqueezeResult, push, name: str):
    """``push`` checked where it is concrete: one finite number >= 0 [m], and a result that
    kept its rows when it lies below the last row's push."""
    if not is_concrete(push):
        return push
    p = real_array(push, f"{name}'s push (the push displacement to integrate up to)", "m")
    if p.ndim or not (np.isfinite(p) and p >= 0):
        raise ValueError(f"{name}'s push must be one finite push displacement >= 0 [m]; got {push!r:.80}")
    if is_concrete(res.count) and jnp.ndim(res.count) == 0 and int(res.count) == 2 and \
            p < float(jnp.asarray(res.push)[1]):
        raise ValueError(f"{name}(res, push={float(p)!r}): this result kept two rows (history=False), "
                         "so the work up to a push short of its last one is gone; squeeze with the "
                         "history (the default) or leave push out for the whole push's work")
    return p


@own_transfers
def adversary_work(res: SqueezeResult, push=None):
    """() work the pusher does on the object during the adversary phase [J] (module
    docstring); (B,) for a batched result. ``push`` [m]: only up to that push displacement
    (the increment that holds it cut there; a push at or beyond the last row's, where the grasp
    failed or the push ended, gives the whole work)."""
    _check_result(res, "adversary_work")
    if push is None:
        return _whole_push(res)[..., 0]
    return _push_until(res, _push_arg(res, push, "adversary_work"))[..., 0]


@own_transfers
def finger_work(res: SqueezeResult, push=None):
    """(2,) work each grasping finger resists during the push [J]; they sum to
    :func:`adversary_work` (``push`` likewise); (B, 2) for a batched result."""
    _check_result(res, "finger_work")
    if push is None:
        return _whole_push(res)[..., 1:]
    return _push_until(res, _push_arg(res, push, "finger_work"))[..., 1:]


@per_result
def failure_push(res: SqueezeResult):
    """() push displacement [m] at the last row: where the grasp failed, or the full push."""
    _push_work(res)                  # a result without an adversary phase has no push to report
    return jnp.asarray(res.push)[res.count - 1]
