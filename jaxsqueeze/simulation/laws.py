"""Contact laws: per-node modes, event kinds, the friction cone and the grip feasibility test.

One home for each of these (DESIGN 4): the engine, the eager checks, the scene-file loader and
the views all read them from here.
"""
from __future__ import annotations

import jax.numpy as jnp
import numpy as np

FREE, STICK, SLIP_POS, SLIP_NEG = 0, 1, 2, 3   # per-node modes; SLIP_POS slides toward larger θ
MODE_NAMES = {FREE: "free", STICK: "stick", SLIP_POS: "slip+", SLIP_NEG: "slip-"}
EVENT_KINDS = "ABCD"                           # new contact, break, stick→slip, slip→stick
EVENT_MEANING = {"A": "new contact", "B": "contact break", "C": "stick to slip", "D": "slip to stick"}
CONE_SLACK = 1e-7   # [rad] a force this close to its cone edge counts as inside (round-off)
FRICTION_MODELS = ("coulomb", "frictionless", "stick")
CONTACT_MODELS = ("segment", "point")


def friction_angle(mu, friction_model: str):
    """Half-angle φ of the friction cone [rad]: atan(μ) for Coulomb, 0 when frictionless, π/2 for
    full stick (the cone is the half-plane: a sticking contact only needs to push)."""
    mu = jnp.asarray(mu)
    if friction_model == "coulomb":
        return jnp.arctan(mu)
    if friction_model == "frictionless":
        return jnp.zeros_like(mu)
    return jnp.full_like(mu, 0.5 * jnp.pi)


def cone_margin(phi, fn, ft):
    """|f| sin(φ + slack − ψ), ψ the force's angle from the contact normal: > 0 inside the cone.

    ``fn`` normal (pushing > 0) and ``ft`` tangential force components. Written with sines and
    cosines so μ → ∞ (φ → π/2) stays finite; ``CONE_SLACK`` absorbs round-off.
    """
    a = phi + CONE_SLACK
    return jnp.sin(a) * fn - jnp.cos(a) * jnp.abs(ft)


def grip_cone_angles(p, inward, xp=jnp):
    """Angles [rad] between the segment joining two initial contacts and their inward normals.

    Args:
        p: (..., 2, 2) the two contact points; inward: (..., 2, 2) their inward unit normals.
    Returns:
        (..., 2): the angle at contact 0 between ``inward[0]`` and p1 − p0, and at contact 1
        between ``inward[1]`` and p0 − p1. The grip is feasible (Section I-A) when both are at
        most the friction angle φ (+ ``CONE_SLACK``). ``xp`` is ``jnp`` (traced) or ``np``.
    """
    seg = p[..., 1, :] - p[..., 0, :]
    seg = seg / xp.linalg.norm(seg, axis=-1, keepdims=True)
    c = xp.stack([xp.sum(inward[..., 0, :] * seg, -1), -xp.sum(inward[..., 1, :] * seg, -1)], -1)
    return xp.arccos(xp.clip(c, -1.0, 1.0))


def grip_feasible(p, inward, phi, xp=jnp):
    """True when the segment between the two contacts lies inside both friction cones."""
    return xp.all(grip_cone_angles(p, inward, xp) <= phi + CONE_SLACK, axis=-1)


__all__ = ["FREE", "STICK", "SLIP_POS", "SLIP_NEG", "MODE_NAMES", "EVENT_KINDS", "EVENT_MEANING", "CONE_SLACK",
           "FRICTION_MODELS", "CONTACT_MODELS", "friction_angle", "cone_margin", "grip_cone_angles",
           "grip_feasible"]
