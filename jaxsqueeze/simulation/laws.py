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
#: [rad] frictionless grips: how far the line through the two grip nodes (along which the
#: fingertips are placed) may turn from the nodes' inward normals; a fingertip then dips at most
#: 1e-3 of its radius below a flat face (cos(tilt) = 1 - 1e-3)
FRICTIONLESS_TILT = float(np.arccos(1.0 - 1e-3))
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

    def angle(n, v):    # atan2(|n × v|, n · v): exact near 0, and its derivative is finite there
        return xp.arctan2(xp.abs(n[..., 0] * v[..., 1] - n[..., 1] * v[..., 0]), xp.sum(n * v, -1))

    return xp.stack([angle(inward[..., 0, :], seg), angle(inward[..., 1, :], -seg)], -1)


def grip_half_angle(mu, friction_model: str, xp=jnp):
    """The largest angle [rad] the segment between the two initial contacts may make with their
    inward normals (Section I-A): the friction angle atan(μ) for Coulomb friction, π/2 for full
    stick (only pushing is needed), and ``FRICTIONLESS_TILT`` frictionless (the fingertips then
    sit on the segment's line, so the initial forces are along it)."""
    mu = xp.asarray(mu)
    if friction_model == "coulomb":
        return xp.arctan(mu)
    return xp.full_like(mu, 0.5 * np.pi if friction_model == "stick" else FRICTIONLESS_TILT)


def cone_normals(points, normals, loops, contact: str, xp=jnp):
    """(m, 2) the outward normals the cones of a first touch are built around, as the engine
    builds them at d = 0 (contacts.solve): for segment contacts the object's normals (an
    integer grip's fingertip sits along them, so they are its own normal at the touch); for
    point contacts the object's polyline normals (:func:`~jaxsqueeze.geometry.boundary.normals`),
    the cone axis that turns as the object deforms (a band's own normals differ slightly)."""
    if contact != "point":
        return normals
    from ..geometry import boundary
    return boundary.normals(points, loops, xp=xp)


def grip_margin(p, inward, mu, friction_model: str, xp=jnp):
    """The grip's smooth feasibility margin [rad] (> 0 feasible, 0 on the edge within
    ``CONE_SLACK``): :func:`grip_half_angle` + slack − the larger of :func:`grip_cone_angles`.
    The one feasibility test of an initial grip: the engine (traced), the squeeze's eager check
    and the scene-file loader all call it."""
    return grip_half_angle(mu, friction_model, xp) + CONE_SLACK - xp.max(grip_cone_angles(p, inward, xp), axis=-1)


__all__ = ["FREE", "STICK", "SLIP_POS", "SLIP_NEG", "MODE_NAMES", "EVENT_KINDS", "EVENT_MEANING", "CONE_SLACK",
           "FRICTION_MODELS", "CONTACT_MODELS", "FRICTIONLESS_TILT", "friction_angle", "cone_margin",
           "grip_cone_angles", "grip_half_angle", "grip_margin", "cone_normals"]
