"""One validation layer for the numbers of a squeeze (issue 12).

Every rule is written once, as a function of the input values and an array namespace
``xp`` (``numpy`` eagerly, ``jax.numpy`` under tracing), so the eager path and its traced
twin cannot disagree:

* :func:`problems` (eager) lists every problem at once, one line each, naming the field,
  the value and the fix; :func:`raise_if_invalid` raises ``ValueError`` with that list.
* :func:`invalid_index` (traced, pure ``jnp``; works under ``jit``, ``vmap`` and ``jvp``)
  returns the int32 index into :data:`FIELDS` of the first invalid value, ``-1`` when all
  are valid. The engine reports it as ``Status.INVALID_INPUT`` plus that index, so a batch
  shows which lanes were bad and why.

``values`` is a dict keyed by the names in :data:`FIELDS`, plus optional context keys:

* ``"grip_distance"``: distance between the grip nodes [m] (depth must be smaller);
* ``"grip_slots"``: the two positions of the grip nodes among the boundary nodes, ``-1``
  for a node that is not a boundary node (the value checked for the field ``"grip"``);
* ``"n_boundary"``: number of boundary nodes (slots must be smaller);
* ``"eps"``: machine epsilon of the run's precision (default: that of the step's dtype).

Values missing from the dict (or ``None``) are skipped. NaN anywhere is invalid.

Cost guards (eager only, before any work): :func:`history_bytes`, :func:`compliance_bytes`
and :func:`check_costs` estimate the memory of the fixed-capacity history and event log and
of the compliance build, and refuse above :data:`MEMORY_LIMIT` bytes (a setting: the
environment variable ``JAXSQUEEZE_MEMORY_LIMIT`` or assignment to this module's attribute).
:func:`unit_problems` catches mixed units (object size, fingertip radius, depth and E that
differ by orders of magnitude).
"""
from __future__ import annotations

import math
import os
from typing import Callable, NamedTuple

import numpy as np

from ..numbers import gib, kind
from .status import Status

FIELDS: tuple[str, ...] = (
    "material.E",
    "material.nu",
    "material.thickness",
    "fingers.radius",
    "friction",
    "depth",
    "settings.step",
    "settings.event_tol",
    "settings.newton_tol",
    "settings.gap_tol",
    "grip",
    "fingers.rotation",
    "grip.overlap",
    "placement",
    "adversary",
)
"""The checked values; a value's position here is the index reported in results."""

MEMORY_LIMIT: int = int(float(os.environ.get("JAXSQUEEZE_MEMORY_LIMIT", 2 * 1024 ** 3)))
"""Largest estimated memory [bytes] of the history/event log or of a compliance build that
is accepted before any work (default 2 GiB; env ``JAXSQUEEZE_MEMORY_LIMIT``)."""

STEP_RESOLUTION = 1e3
"""A step must exceed ``STEP_RESOLUTION * eps * depth``: smaller steps are lost in the
round-off of the depth itself."""



# ----------------------------------------------------------------------------- the rules
def _get(values, key):
    v = values.get(key)
    return None if v is None else v


def _finite_pos(xp, x):
    return xp.isfinite(x) & (x > 0)


def _r_positive(name):
    def rule(values, xp):
        x = _get(values, name)
        return None if x is None else _finite_pos(xp, xp.asarray(x))
    return rule


#: the largest fingertip radius, in object sizes: a flat finger. The squeeze converges as the
#: radius grows (the grip force of a 0.1 m square at 1e4 sizes is within 2e-5 of that at 1e7);
#: far beyond, the fingertip's squared distances overflow
RADIUS_SHARE = 1e6


def _r_radius(values, xp):
    r = _get(values, "fingers.radius")
    if r is None:
        return None
    r = xp.asarray(r)
    size = _get(values, "size")
    return _finite_pos(xp, r) & (True if size is None else r <= RADIUS_SHARE * xp.asarray(size))


def force_limit(eps: float) -> float:
    """The largest force scale E h L [N] of a precision with machine epsilon ``eps``: forces are
    squared in magnitudes, so (1000 E h L)^2 must stay finite."""
    return 1e-3 * float(np.sqrt(np.finfo(np.float32 if eps > 1e-10 else np.float64).max))


def _r_E(values, xp):
    E = _get(values, "material.E")
    if E is None:
        return None
    E = xp.asarray(E)
    ok = _finite_pos(xp, E)
    h, size = _get(values, "material.thickness"), _get(values, "size")
    if h is not None and size is not None:    # compared only with a valid thickness (reported once, as itself)
        h = xp.asarray(h)
        ok = ok & ((E * h * xp.asarray(size) < force_limit(_eps(values, E, xp))) | ~_finite_pos(xp, h))
    return ok


def _r_nu(values, xp):
    nu = _get(values, "material.nu")
    if nu is None:
        return None
    nu = xp.asarray(nu)
    ok = (nu > -1.0) & (nu <= 0.5)
    op_nu = _get(values, "op_nu")            # the ν of a given operator (scene.operator() or op=)
    if op_nu is not None:
        ok = ok & (xp.abs(nu - xp.asarray(op_nu)) <= 1e3 * _eps(values, nu, xp))
    return ok


def _r_friction(values, xp):
    mu = _get(values, "friction")
    if mu is None:
        return None
    mu = xp.asarray(mu)
    return xp.isfinite(mu) & (mu >= 0)


def _r_depth(values, xp):
    d = _get(values, "depth")
    if d is None:
        return None
    d = xp.asarray(d)
    ok = _finite_pos(xp, d)
    size = _get(values, "size")
    if size is not None:     # as deep as the object is across: the squeeze would crush it
        ok = ok & (d < xp.asarray(size))
    gd = _get(values, "grip_distance")
    if gd is not None:       # compared only with a valid grip (a bad grip is reported once, as grip)
        grip_ok = _r_grip(values, xp)
        ok = ok & ((d < xp.asarray(gd)) | (False if grip_ok is None else ~grip_ok))
    return ok


#: the largest penetration tolerance, as a fraction of the object's size (the default is 1e-9
#: of it in float64, 1e-5 in float32): beyond it nodes sink visibly into the fingertips unseen
GAP_SHARE = 1e-2

OVERLAP_TOL = 1e-3
"""A fingertip at its grip node may reach at most this fraction of its radius, or of the
object's size where that is smaller, past another boundary node at first touch (d = 0);
past ``gap_tol`` such a node joins at d = 0 with a force, and the squeeze warns
(:func:`overlap_warning`)."""


def default_gap_tol(size, eps: float):
    """The default penetration tolerance [m] (``Settings.gap_tol=None``) of an object ``size`` [m]
    across, in the precision with machine epsilon ``eps``: 1e-9 of the size in float64, 1e-5 in
    float32."""
    return (1e-9 if eps < 1e-10 else 1e-5) * size


def _r_gap_tol(values, xp):
    t = _get(values, "settings.gap_tol")
    if t is None:
        return None
    t = xp.asarray(t)
    ok = _finite_pos(xp, t)
    size = _get(values, "size")
    return ok if size is None else ok & _at_most(values, t, GAP_SHARE * xp.asarray(size))


def _eps(values, step, xp):
    e = _get(values, "eps")
    if e is not None:
        return e
    dt = step.dtype if np.issubdtype(np.dtype(step.dtype), np.floating) else np.float64
    return float(np.finfo(dt).eps)


def _at_most(values, t, limit):
    """t <= limit, with a few ulps of slack: a tolerance set to exactly its limit (a tenth of
    the step, 1 % of the size) must not be refused for the limit's own rounding."""
    return t <= limit * (1 + 4 * _eps(values, t, None))


def _r_step(values, xp):
    s = _get(values, "settings.step")
    if s is None:
        return None
    s = xp.asarray(s)
    ok = _finite_pos(xp, s)
    d = _get(values, "depth")
    if d is not None:
        d = xp.asarray(d)     # compared only with a valid depth (a bad depth is reported once, as depth)
        ok = ok & ((s <= d) & (s > STEP_RESOLUTION * _eps(values, s, xp) * d) | ~_finite_pos(xp, d))
    return ok


#: the widest event bracket, as a share of the step: wider, events are placed anywhere in a step
#: and a step can hold several unresolved ones (they came back as spurious A/B pairs)
EVENT_SHARE = 0.1
#: the loosest slip-angle Newton tolerance [rad]
NEWTON_MAX = 1e-2


def _r_event_tol(values, xp):
    t = _get(values, "settings.event_tol")
    if t is None:
        return None
    t = xp.asarray(t)
    ok = _finite_pos(xp, t)
    s = _get(values, "settings.step")
    if s is not None:             # compared only with a valid step (a bad step is reported once, as step)
        ok = ok & (_at_most(values, t, EVENT_SHARE * xp.asarray(s)) | ~_r_step(values, xp))
    return ok


def _r_newton_tol(values, xp):
    t = _get(values, "settings.newton_tol")
    if t is None:
        return None
    t = xp.asarray(t)
    return _finite_pos(xp, t) & (t > 10 * _eps(values, t, xp)) & (t <= NEWTON_MAX)


def _r_grip(values, xp):
    slots = _get(values, "grip_slots")
    if slots is None:
        return None
    g = xp.asarray(slots)
    a, b = g[..., 0], g[..., 1]
    ok = (a >= 0) & (b >= 0) & (a != b)
    m = _get(values, "n_boundary")
    if m is not None:
        ok = ok & (a < m) & (b < m)
    return ok


#: the largest fingertip rotation [rad] over a squeeze (ten turns): beyond it a tip rolls its
#: contacts off within a step or two and the contact solve loses every contact at once
MAX_ROTATION = 20 * math.pi


def _r_rotation(values, xp):
    r = _get(values, "fingers.rotation")
    if r is None:
        return None
    r = xp.asarray(r)
    ok = xp.all(xp.isfinite(r), axis=(-2, -1)) if r.ndim >= 2 else xp.all(xp.isfinite(r))
    d = _get(values, "depth")
    if d is None or r.ndim < 2:
        return ok
    # max over 0 <= d' <= depth of |alpha(d')| is at most sum_k |c_k| depth^k (polyval order)
    d = xp.asarray(d)
    d = xp.where(_finite_pos(xp, d), d, 0.0)[..., None, None]       # a bad depth is reported as such
    e = xp.arange(r.shape[-1] - 1, -1, -1).astype(d.dtype)
    powers = d ** xp.reshape(e, (1,) * (d.ndim - 1) + e.shape)
    turn = xp.sum(xp.where(xp.isfinite(r), xp.abs(r), 0.0) * powers, axis=-1)
    return ok & xp.all(turn <= MAX_ROTATION, axis=-1)


#: the largest |arc length| of a placement or adversary, in object sizes, and the largest
#: |angle| [rad]: both wrap (round the perimeter, round the circle), and wrapping a value X
#: keeps it only to X * eps (at 1e15 m the wrapped position of a 0.1 m square is noise)
MAX_WRAP = 1e3


def _wrappable(xp, values, s, angle):
    """s [m] and angle [rad] finite and within MAX_WRAP object sizes / radians of zero."""
    s, angle = xp.asarray(s), xp.asarray(angle)
    ok = xp.isfinite(s) & xp.isfinite(angle) & (xp.abs(angle) <= MAX_WRAP)
    size = _get(values, "size")
    return ok if size is None else ok & (xp.abs(s) <= MAX_WRAP * xp.asarray(size))


def _r_placement(values, xp):
    s, a = _get(values, "placement.s"), _get(values, "placement.angle")
    if s is None:
        return None
    return xp.all(_wrappable(xp, values, s, xp.asarray(a)[..., None]), axis=-1)


def _r_adversary(values, xp):
    push = _get(values, "adversary.push")
    if push is None:
        return None
    push, r, h = (xp.asarray(values[k]) for k in ("adversary.push", "adversary.radius", "adversary.step"))
    ok = _wrappable(xp, values, values["adversary.s"], values["adversary.angle"])
    ok = ok & _finite_pos(xp, push) & _finite_pos(xp, r) & _finite_pos(xp, h)
    # a step longer than the pusher's radius could carry it across a boundary node unseen
    # (the gap is checked at the ends of a step), and a push as long as the object crushes it
    ok = ok & (h <= push) & (h <= r) & (h > STEP_RESOLUTION * _eps(values, h, xp) * push)
    size = _get(values, "size")
    return ok if size is None else ok & (push < xp.asarray(size))


def _r_overlap(values, xp):
    ov = _get(values, "grip.overlap")
    if ov is None:
        return None
    ov = xp.asarray(ov)
    ov = xp.max(ov, axis=-1) if ov.ndim >= 1 else ov
    r = _get(values, "fingers.radius")
    r = 0.0 if r is None else xp.asarray(r)
    size = _get(values, "size")
    r = xp.where(_finite_pos(xp, r), r, 0.0)
    tol = OVERLAP_TOL * (r if size is None else xp.minimum(r, xp.asarray(size)))
    bad_r = _r_radius(values, xp)                                 # a bad radius is reported as such
    return xp.isfinite(ov) & (ov <= tol) | (False if bad_r is None else ~bad_r)


class Rule(NamedTuple):
    field: str
    valid: Callable          # (values, xp) -> bool array or None (value absent)
    requirement: str         # what a valid value is
    fix: str                 # what to do


RULES: tuple[Rule, ...] = (
    Rule("material.E", _r_E, "a finite Young's modulus > 0 Pa whose force scale E * thickness * size [N] the "
         f"precision holds (its square times 1e6 finite: below {force_limit(1e-16):.3g} N in float64, "
         f"{force_limit(1e-7):.3g} N in float32)",
         "set Material(E=...) to the material's modulus in Pa (foam ~1e5, rubber ~1e6) and the thickness in m"),
    Rule("material.nu", _r_nu, "a Poisson's ratio with -1 < nu <= 0.5, and the nu of the operator given as op=",
         "use e.g. nu = 0.3; with op= given, the nu it was built for (or omit op=)"),
    Rule("material.thickness", _r_positive("material.thickness"), "a finite thickness > 0 m",
         "set Material(thickness=...) in metres"),
    Rule("fingers.radius", _r_radius, f"a finite fingertip radius > 0 m, at most {RADIUS_SHARE:g} times the "
         "object's size (a flat finger)", "set Fingers(radius=...) in metres"),
    Rule("friction", _r_friction, "a finite Coulomb coefficient mu >= 0", "use e.g. friction = 0.5"),
    Rule("depth", _r_depth, "a finite depth > 0 m, smaller than the object's size (deeper, the squeeze would "
         "crush it) and than the distance between the grip nodes (deeper, the fingertips pass through each other)",
         "lower the depth (the paper's squeezes stop near 15 % of the size) or grip farther apart"),
    Rule("settings.step", _r_step, "a finite step > 0 m, at most the depth, and above what the depth's "
         f"round-off can resolve ({STEP_RESOLUTION:g} * eps * depth)",
         "use the default (Settings.step=None, depth / 50) or a step of about depth / 50"),
    Rule("settings.event_tol", _r_event_tol, f"a finite tolerance > 0 m, at most {EVENT_SHARE:g} of the step "
         "(a wider bracket places events anywhere in a step)", "use the default (None: step * 1e-4)"),
    Rule("settings.newton_tol", _r_newton_tol, f"a finite tolerance [rad] above 10 * eps (reachable in this "
         f"precision) and at most {NEWTON_MAX:g} rad", "use the default (None: 1e-11 in float64, 1e-5 in float32)"),
    Rule("settings.gap_tol", _r_gap_tol, f"a finite tolerance > 0 m, at most {GAP_SHARE:.0%} of the object's size",
         "use the default (None: 1e-9 of the object's size in float64)"),
    Rule("grip", _r_grip, "two different boundary nodes",
         "pick nodes from mesh.boundary (e.g. Scene.nearest_boundary_node)"),
    Rule("fingers.rotation", _r_rotation, "finite polynomial coefficients [rad / m^k] that turn a fingertip by at "
         f"most {MAX_ROTATION:.4g} rad (ten turns) over the squeeze (sum of |c_k| depth^k)",
         "replace NaN/inf coefficients; rotation is in radians against depth in metres (1 rad per mm is 1e3 rad/m)"),
    Rule("grip.overlap", _r_overlap, f"a fingertip that touches the object only at its grip node at d = 0 "
         f"(no other boundary node more than {OVERLAP_TOL:g} * the radius or the object's size, the smaller, inside "
         "it)",
         "grip away from re-entrant (concave) corners or use a smaller fingertip radius; a frictionless "
         "fingertip sits on the line through both grip nodes, so with a broad one pick grip nodes more "
         "nearly opposite (on a flat face, exactly opposite) or use Coulomb friction with a small mu"),
    Rule("placement", _r_placement, f"finite arc lengths Placement.s [m] within {MAX_WRAP:,.0f} object sizes of "
         f"the boundary's start and a finite Placement.angle within {MAX_WRAP:,.0f} rad (both wrap; farther out "
         "the wrapped value is round-off)",
         "replace NaN/inf positions; s wraps around the boundary: take a large s modulo the perimeter "
         "(scene.curve().perimeter) and the angle modulo 2 pi"),
    Rule("adversary", _r_adversary, f"a finite Adversary.s [m] within {MAX_WRAP:,.0f} object sizes of the "
         f"boundary's start and a finite angle within {MAX_WRAP:,.0f} rad, a push [m] > 0 shorter than the "
         "object, a radius [m] > 0 and a step [m] > 0 at most the push and the pusher's radius",
         "use a push below the object's size and the default step (None: push / 50, at most the radius), or a "
         "step below the pusher's radius; take a large s modulo the perimeter and the angle modulo 2 pi"),
)
assert tuple(r.field for r in RULES) == FIELDS


# ----------------------------------------------------------------------------- traced twin
def invalid_index(values: dict):
    """Index into :data:`FIELDS` of the first invalid value, ``-1`` when all are valid.

    Pure ``jax.numpy``: works under ``jit``, ``vmap`` and ``jvp`` (integer output, no
    tangent). Scalar fields may carry leading batch axes; they broadcast together.
    """
    import jax
    import jax.numpy as jnp

    values = {k: (jax.lax.stop_gradient(v) if v is not None and not isinstance(v, (int, float)) else v)
              for k, v in values.items()}
    bad, idx = [], []
    for k, rule in enumerate(RULES):
        with jax.numpy_dtype_promotion("standard"):     # the caller's numbers, of whatever types
            ok = rule.valid(values, jnp)
        if ok is not None:
            bad.append(~jnp.asarray(ok, bool))
            idx.append(k)
    if not bad:
        return jnp.asarray(-1, jnp.int32)
    bad = jnp.broadcast_arrays(*bad)
    stacked = jnp.stack(bad, axis=-1)
    first = jnp.asarray(idx, jnp.int32)[jnp.argmax(stacked, axis=-1)]
    return jnp.where(jnp.any(stacked, axis=-1), first, jnp.int32(-1)).astype(jnp.int32)


# ----------------------------------------------------------------------------- eager path
def _show(v) -> str:
    a = np.asarray(v)
    if a.ndim == 0:
        return f"{a.item()!r}"
    return " ".join(np.array2string(a, threshold=8, precision=6, separator=", ").split())     # one line


def _context(rule: Rule, values) -> str:
    f = rule.field
    if f == "depth":
        said = [f"{name} {_show(values[key])} m" for key, name in (("grip_distance", "grip distance"),
                                                                  ("size", "object size")) if values.get(key) is not None]
        return f" ({', '.join(said)})" if said else ""
    if f == "settings.event_tol" and values.get("settings.step") is not None:
        return f" (step {_show(values['settings.step'])} m)"
    if f == "settings.step" and values.get("depth") is not None:
        return f" (depth {_show(values['depth'])} m)"
    if f == "grip":
        return f" (positions among the boundary nodes: {_show(values['grip_slots'])}; -1 = not on the boundary)"
    if f == "adversary":
        return " (s, angle; " + ", ".join(f"{k.split('.')[1]} {_show(values.get(k))}" for k in
                                ("adversary.push", "adversary.radius", "adversary.step")) + \
            ("" if values.get("size") is None else f", object size {_show(values['size'])} m") + ")"
    if f == "placement" and values.get("size") is not None:
        return f" (object size {_show(values['size'])} m)"
    if f == "grip.overlap" and values.get("fingers.radius") is not None:
        return (" (how far [m] fingertip 0 and fingertip 1 reach past another boundary node, > 0 inside "
                f"the object; fingertip radius {_show(values['fingers.radius'])} m"
                + ("" if values.get("size") is None else f", object size {_show(values['size'])} m") + ")")
    return ""


def problems(values: dict) -> list[str]:
    """Every problem at once: one line per invalid field naming it, its value and the fix."""
    out = []
    with np.errstate(invalid="ignore", over="ignore"):
        for rule in RULES:
            ok = rule.valid(values, np)
            if ok is None or bool(np.all(ok)):
                continue
            shown = values.get("grip" if rule.field == "grip" and "grip" in values else rule.field)
            if rule.field == "grip" and shown is None:
                shown = values.get("grip_slots")
            if rule.field == "adversary":
                shown = (values.get("adversary.s"), values.get("adversary.angle"))
            text = f"{rule.field} = {_show(shown)}" if rule.field != "placement" else \
                f"placement = s {_show(values['placement.s'])}, angle {_show(values['placement.angle'])}"
            out.append(f"{text}{_context(rule, values)}: expected {rule.requirement}; {rule.fix}.")
    return out


def raise_if_invalid(values: dict) -> None:
    """Raise ``ValueError`` listing every problem of :func:`problems` (nothing if none)."""
    p = problems(values)
    if p:
        raise ValueError("invalid input:\n  " + "\n  ".join(p) if len(p) > 1 else p[0])


# ----------------------------------------------------------------------------- from a scene
def tip_directions(p, normals, frictionless: bool, xp=None):
    """(..., 2, 2) unit vectors from the two grip nodes p (..., 2, 2) to their fingertips' centres
    at first touch: the nodes' outward normals (..., 2, 2), or, frictionless, along the line
    through the two nodes (the initial forces, radial on the tips, are then along it;
    ``laws.FRICTIONLESS_TILT`` bounds its tilt from the normals)."""
    if xp is None:
        import jax.numpy as xp  # noqa: N812
    if not frictionless:
        return xp.asarray(normals)
    e = p[..., 0, :] - p[..., 1, :]
    e = e / xp.hypot(e[..., 0], e[..., 1])[..., None]
    return xp.stack([e, -e], axis=-2)


def fingertip_overlap(points, slots, directions, radius, xp=None):
    """Overlap [m] of each fingertip with the other boundary nodes at first touch (d = 0).

    Args:
        points: (m, 2) boundary node positions [m].
        slots: (2,) int positions of the grip nodes among them.
        directions: (2, 2) unit vectors from the grip nodes to their fingertips' centres
            (:func:`tip_directions`).
        radius: fingertip radius [m].
    Returns:
        (2,) the largest ``radius - distance`` from each fingertip centre (one radius along its
        direction) to a boundary node other than its grip node; > 0 means the fingertip
        overlaps the object (a re-entrant corner, a concave part tighter than it, a broad
        frictionless fingertip tilted against a flat face). Computed as
        (2 r n·w − |w|²) / (r + |w − r n|) with w the node's offset from the grip node: no
        cancellation at a radius far beyond the object (a flat pad's overlap in float32).
    """
    if xp is None:
        import jax.numpy as xp  # noqa: N812
    P, n = xp.asarray(points), xp.asarray(directions)
    s = xp.clip(xp.asarray(slots), 0, P.shape[0] - 1)
    W = P[None, :, :] - P[s][:, None, :]                         # (2, m, 2) offsets from the grip nodes
    D = W - radius * n[:, None, :]                               # from the centres
    reach = (2 * radius * xp.sum(W * n[:, None, :], -1) - xp.sum(W * W, -1)) / (radius + xp.hypot(D[..., 0], D[..., 1]))
    own = xp.arange(P.shape[0])[None, :] == s[:, None]
    return xp.max(xp.where(own, -xp.inf, reach), axis=-1)


def overlap_warning(overlap, gap_tol: float, depth: float) -> str | None:
    """The warning for fingertips that reach ``overlap`` (2,) [m] past another boundary node at
    first touch, more than ``gap_tol`` [m] but within ``grip.overlap``'s limit, or None: such a
    node joins at d = 0 with a force before any squeeze, an error of about overlap / depth."""
    deepest = float(np.max(overlap))
    if not deepest > gap_tol:
        return None
    return (f"at first touch a fingertip reaches {deepest:.3g} m past another boundary node (gap_tol "
            f"{gap_tol:.3g} m): that node joins at d = 0 with a force before any squeeze, an error of about "
            f"{deepest / depth:.2g} of the squeeze's forces ({deepest:.3g} m of {depth:.3g} m depth). A frictionless "
            "fingertip sits on the line through both grip nodes: grip nodes exactly opposite (a mirror-symmetric "
            "mesh), or Coulomb friction with a small mu, avoid it (docs/numerics.md §5.1)")


def _boundary_geometry(obj):
    from ..geometry.mesh import Mesh

    if isinstance(obj, Mesh):
        return np.asarray(obj.points)[obj.boundary], np.asarray(obj.normals), np.asarray(obj.boundary), obj.n
    return np.asarray(obj.points), np.asarray(obj.normals), np.arange(obj.m), obj.m


def boundary_points(obj) -> np.ndarray:
    """(m, 2) positions of a mesh's boundary nodes or a band's nodes [m]."""
    return _boundary_geometry(obj)[0]


def values_of(scene, eps: float | None = None) -> dict:
    """The :func:`invalid_index` / :func:`problems` inputs of a :class:`~jaxsqueeze.Scene`.

    Works with concrete or traced scene numbers (numpy when concrete, ``jnp`` otherwise).
    """
    from ..tracing import is_concrete

    pts_b, nrm_b, bnodes, n = _boundary_geometry(scene.mesh)
    m = len(bnodes)
    grip = scene.grip
    if is_concrete(grip) and is_concrete(scene.fingers.radius):
        xp = np
    else:
        import jax.numpy as xp  # noqa: N812
    lookup = np.full(n, -1, np.int64)
    lookup[bnodes] = np.arange(m)
    g = xp.asarray(grip)
    if xp is np and not np.issubdtype(g.dtype, np.integer):
        g = np.full(2, -1)
    inside = (g >= 0) & (g < n)
    slots = xp.where(inside, xp.asarray(lookup)[xp.clip(g, 0, n - 1)], -1)
    allp = np.asarray(scene.mesh.points)
    pa, pb = xp.asarray(allp)[xp.clip(g[..., 0], 0, n - 1)], xp.asarray(allp)[xp.clip(g[..., 1], 0, n - 1)]
    s = scene.settings
    v = {"material.E": scene.material.E, "material.nu": scene.material.nu,
         "material.thickness": scene.material.thickness, "fingers.radius": scene.fingers.radius,
         "friction": scene.friction, "depth": scene.depth,
         "settings.step": s.step if s.step is not None or s.event_tol is None else scene.depth / 50,   # (its default)
         "settings.event_tol": s.event_tol, "settings.newton_tol": s.newton_tol, "settings.gap_tol": s.gap_tol,
         "fingers.rotation": scene.fingers.rotation, "grip": grip, "grip_slots": slots, "n_boundary": m,
         "size": float(np.max(np.ptp(pts_b, axis=0))),
         "grip_distance": xp.sqrt(xp.sum((pa - pb) ** 2, axis=-1))}
    if g.ndim == 1 or xp is not np:
        s_ = xp.clip(slots, 0, m - 1)
        dirs = tip_directions(xp.asarray(pts_b)[s_], xp.asarray(nrm_b)[s_], scene.friction_model == "frictionless",
                              xp=xp)
        v["grip.overlap"] = fingertip_overlap(pts_b, slots, dirs, scene.fingers.radius, xp=xp)
    if not hasattr(scene.mesh, "triangles") or type(scene.mesh).__name__ == "Band":
        v.pop("material.nu")                      # a band has no nu
    if eps is not None:
        v["eps"] = eps
    return v


def check_scene(scene, eps: float | None = None) -> None:
    """Eager check of a scene's numbers: ``ValueError`` listing every problem (skipped when
    any number is traced: the engine then reports ``Status.INVALID_INPUT``)."""
    from ..tracing import is_concrete

    v = values_of(scene, eps)
    if all(is_concrete(x) for x in v.values() if x is not None):
        raise_if_invalid(v)


# ----------------------------------------------------------------------------- cost guards
def history_bytes(m: int, capacity: int, max_steps: int, max_events: int, dtype=np.float64) -> int:
    """Estimated memory [bytes] of the fixed-capacity history, event log and contact slots.

    History: ``max_steps + 1`` rows of depth, mode and finger (int32), theta, forces and
    displacements at ``m`` boundary nodes, fingertip centres and angles; event log:
    ``max_events`` rows of (depth, node, kind, finger); slots: the bordered system and the
    Newton Jacobian of ``capacity`` contacts (a few working copies).
    """
    f = np.dtype(dtype).itemsize
    H, E, S, m = int(max_steps) + 1, int(max_events), int(capacity), int(m)
    row = f * (1 + m + 4 * m + 4 + 2) + 4 * 2 * m
    hist = H * row * 2                            # the state and the padded result
    events = E * (f + 3 * 4)
    slots = 4 * f * ((2 * S + 3) ** 2 + S * S + 2 * m * 2 * S)
    return int(hist + events + slots)


def compliance_bytes(n_boundary: int, n_nodes: int, method: str = "sparse", dtype=np.float64) -> int:
    """Estimated peak memory [bytes] of building the compliance operator.

    ``sparse``: the boundary block G_bb (2m x 2m), the (2n x 2m) boundary solves, the 128-column
    chunks and the sparse factor (~ 8 log2(2n) entries per DOF); ``dense``: K and its Cholesky factor (2n x 2n each) plus the
    (2n x 2m) field map; ``spectral``: K and its eigenvectors (2n x 2n each) plus the field map;
    ``band``: the band stiffness and pseudo-inverse (3m x 3m each).
    """
    f = np.dtype(dtype).itemsize
    m, n = int(n_boundary), int(n_nodes)
    G = 4 * m * m * f
    if method == "sparse":
        factor = 2 * n * 8 * math.log2(max(2 * n, 2)) * 12      # nested-dissection-like fill, value + index
        return int(G + 2 * n * 2 * m * f + factor + 2 * n * 128 * 8)
    if method in ("dense", "spectral"):
        return int(G + 2 * (2 * n) ** 2 * f + 2 * n * 2 * m * f)
    return int(G + 2 * (3 * m) ** 2 * 8)       # band


def check_costs(m: int, n: int, method: str, capacity: int, max_steps: int, max_events: int,
                dtype=np.float64, limit: int | None = None) -> list[str]:
    """Problems (one line each) of runs whose estimated memory exceeds ``limit``
    (default :data:`MEMORY_LIMIT`), naming the estimate and the setting to change."""
    limit = MEMORY_LIMIT if limit is None else int(limit)
    out = []
    hb = history_bytes(m, capacity, max_steps, max_events, dtype)
    if hb > limit:
        parts = {"max_steps": history_bytes(m, 0, max_steps, 0, dtype),
                 "max_events": history_bytes(m, 0, 0, max_events, dtype),
                 "capacity": history_bytes(m, capacity, 0, 0, dtype)}
        dom = max(parts, key=parts.get)
        value = {"max_steps": max_steps, "max_events": max_events, "capacity": capacity}
        default = {"max_steps": "None: 400, grown", "max_events": "None: 256, grown",
                   "capacity": "None: chosen"}
        out.append(f"settings.{dom} = {value[dom]}: the history, event log and contact slots would take about "
                   f"{gib(hb)} (max_steps = {max_steps}, max_events = {max_events}, capacity = {capacity}; limit "
                   f"{gib(limit)}, jaxsqueeze.simulation.validate.MEMORY_LIMIT / env JAXSQUEEZE_MEMORY_LIMIT); "
                   f"lower {dom} (default {default[dom]})")
    cb = compliance_bytes(m, n, method, dtype)
    if cb > limit:
        out.append(f"the {method} compliance build of {n} nodes ({m} on the boundary) would take about "
                   f"{gib(cb)} (limit {gib(limit)}, jaxsqueeze.simulation.validate.MEMORY_LIMIT / env "
                   "JAXSQUEEZE_MEMORY_LIMIT); use a coarser mesh"
                   + ("" if method == "sparse" else " or method = 'sparse'"))
    return out


def scene_cost_problems(scene, dtype=np.float64, limit: int | None = None) -> list[str]:
    """:func:`check_costs` of a :class:`~jaxsqueeze.Scene` (before the operator is built)."""
    s = scene.settings
    _, _, bnodes, n = _boundary_geometry(scene.mesh)
    method = scene.method if hasattr(scene.mesh, "triangles") and type(scene.mesh).__name__ != "Band" else "band"
    return check_costs(len(bnodes), n, method, s.slots(len(bnodes)), *s.bounds(), dtype, limit)


# ----------------------------------------------------------------------------- shapes
def shape_problems(scene) -> list[str]:
    """Eager check that a :class:`~jaxsqueeze.Scene`'s numbers are numbers of the shape one
    squeeze takes (a scalar each, a placement of shape (2,) and a scalar angle;
    :class:`~jaxsqueeze.Fingers` checks its rotation itself): one line per field that is not,
    naming it (True and False are not numbers: E=True was 1 Pa). An array where a scalar
    belongs is a batch, for ``jax.vmap``."""
    s, a = scene.settings, scene.adversary
    fields = {"material.E": scene.material.E, "material.nu": scene.material.nu,
              "material.thickness": scene.material.thickness, "fingers.radius": scene.fingers.radius,
              "friction": scene.friction, "depth": scene.depth,
         "settings.step": s.step if s.step is not None or s.event_tol is None else scene.depth / 50,   # (its default)
              "settings.event_tol": s.event_tol, "settings.newton_tol": s.newton_tol, "settings.gap_tol": s.gap_tol}
    if a is not None:
        fields.update({"adversary.s": a.s, "adversary.push": a.push, "adversary.angle": a.angle,
                       "adversary.radius": a.radius, "adversary.step": a.step})
    out = []
    for name, value in fields.items():
        if value is None and "." in name and name.split(".")[0] in ("settings", "adversary"):
            continue                                    # None: the default
        if value is None or isinstance(value, (str, bytes)) or kind(value) not in "iuf":
            band = name == "material.nu" and type(scene.mesh).__name__ == "Band"
            out.append(f"{name} = {value!r}: expected a number" + (
                " (a band ignores nu, but a Material holds one: pass any valid value, e.g. nu=0.3)" if band else ""))
            continue
        x = np.asarray(value, float)
        if x.ndim:
            out.append(f"{name} has shape {x.shape}: one squeeze takes a single number; for many values use "
                       "jax.vmap over the scene")
    if scene.grip is not None:
        if isinstance(scene.grip, (str, bytes)) or kind(scene.grip) not in "iuf":
            out.append(f"grip = {scene.grip!r}: expected two integer node indices (e.g. from "
                       "Scene.nearest_boundary_node)")
        elif np.ndim(scene.grip) > 1:
            out.append(f"grip has shape {np.shape(scene.grip)}: one squeeze takes one grip (i, j); for many grips use "
                       "jax.vmap over the scene (or jsq.grasp_map)")
    if scene.placement is not None:
        for name in ("s", "angle"):
            v = getattr(scene.placement, name)
            if isinstance(v, (str, bytes)) or kind(v) not in "iuf":
                out.append(f"placement.{name} = {v!r}: expected " + ("two arc lengths [m]" if name == "s" else
                                                                       "a number [rad]"))
                return out
        shapes = np.shape(scene.placement.s), np.shape(scene.placement.angle)
        if shapes != ((2,), ()):
            out.append(f"an eager squeeze takes one placement: Placement.s of shape (2,) and a scalar angle [rad], "
                       f"got shapes {shapes[0]} and {shapes[1]}; for many placements use jax.vmap (or jsq.grasp_map)")
    return out


# ----------------------------------------------------------------------------- mixed units
#: a depth beyond this share of the object's size gets a warning (linear elasticity far from true)
DEEP = 0.5


def deep_warning(size: float | None, depth: float, between: float | None = None) -> str | None:
    """The warning for a squeeze deeper than :data:`DEEP` of the object's size [m], or (given)
    of ``between``, the distance between the fingers' first contacts [m] (a narrow part
    squeezed across, in an object long the other way); or None."""
    for length, what in ((size, "the object ({:g} m across)"),
                         (between, "the distance between the fingers' first contacts ({:g} m)")):
        if length is not None and DEEP * length < depth < length:
            return (f"depth = {depth:g} m is more than {DEEP:.0%} of {what.format(length)}: linear elasticity "
                    "(small strains) is far from true there, and elements may turn inside out; the paper's "
                    "squeezes stop near 15 %")
    return None


class PlacementResolutionWarning(UserWarning):
    """Boundary edges too long for placed fingertips: between the nodes, the first contacts
    leave their friction cones (:func:`placement_warning`)."""


def placement_warning(edge: float, radius: float, mu: float) -> str | None:
    """The warning for fingertips of ``radius`` [m] placed on boundary edges ``edge`` [m] long,
    under Coulomb friction ``mu``, or None.

    A placed fingertip first touches the node nearest its pole. Between two nodes h apart it
    touches one up to h/2 off the pole, where its normal is turned by up to asin(h / 2r) from
    the object's. Beyond the friction cone's half angle atan(mu), a placement between the nodes
    comes out ``INFEASIBLE_GRIP`` (its first contacts leave the cones) where a finer boundary
    would hold (docs/planning.md, "Continuous placement", 4)."""
    tilt, cone = np.degrees(np.arcsin(min(1.0, edge / (2 * radius)))), np.degrees(np.arctan(mu))
    if tilt <= cone:
        return None
    return (f"boundary edges {edge:.3g} m long under fingertips of radius {radius:.3g} m: a placed fingertip that "
            f"lands between two nodes first touches one of them up to {tilt:.1f} deg off its normal, beyond the "
            f"friction cone's {cone:.1f} deg (mu={mu:g}), so such placements come out INFEASIBLE_GRIP where a finer "
            f"boundary would hold; refine the outer boundary where the fingers go to edges of at most "
            f"2 r sin(atan mu) = {2 * radius * np.sin(np.arctan(mu)):.3g} m (max_edge, or refine_near)")


def inverted_warning(points, triangles, u, depth: float) -> str | None:
    """The warning for triangles that a squeeze to ``depth`` [m] turned inside out, or None:
    ``points`` (n, 2) and ``triangles`` (t, 3) of the mesh (counterclockwise), ``u`` (n, 2)
    the final displacement [m]. Linear elasticity does not see it (its energy is that of the
    mirrored element), so the squeeze itself reports no failure."""
    from ..geometry.mesh import signed_areas
    points, triangles = np.asarray(points, float), np.asarray(triangles)
    ratio = signed_areas(points + np.asarray(u, float), triangles) / signed_areas(points, triangles)
    flipped = int(np.sum(ratio <= 0))
    if not flipped:
        return None
    return (f"at depth = {depth:g} m {flipped} of {len(triangles)} triangles are turned inside out (area ratio down "
            f"to {float(np.min(ratio)):.2g}): the squeeze is far beyond small strains; squeeze less deep "
            "(result.depth gives the rows before), or grip where the object is wider")


def inside_tip_warning(res, points, tol: float, contact: str = "segment") -> str | None:
    """The warning for a boundary node that a squeeze ``res`` left more than ``tol`` [m] inside
    a grasping fingertip it is not a contact of, or None; ``points`` (m, 2) are the boundary
    nodes' positions [m] (``res.nodes`` order, the frame of ``res.centres``).

    * A contact node inside the other tip: where both tips close on one node (an object's
      corner between them) it stays on its own tip, since a node holds one contact, and the
      other tip passes through it (docs/numerics.md §2, 27).
    * A free node inside a tip, with ``contact="point"``: a point contact is one node per
      tip and has no event A, so an object that meets a tip along a segment (a solid under a
      large tip) lets the tip pass through its other nodes.

    Rows where a finger holds no contact (the object let go) are not checked. With segment
    contacts event A keeps free nodes out (to 10 ``gap_tol``: the
    ``engine.SUNK_TOLS`` that the caller's ``tol`` is)."""
    k = int(res.count)                                  # (rows past it are padding in an untrimmed result)
    modes, fg = np.asarray(res.modes)[:k], np.asarray(res.finger)[:k]
    x = np.asarray(points, float)[None] + np.asarray(res.boundary_displacement, float)[:k]     # (k, m, 2)
    C, r = np.asarray(res.centres, float)[:k, None, :2], float(res.radius)                    # (k, 1, 2, 2)
    dx, dy = x[:, :, None, 0] - C[..., 0], x[:, :, None, 1] - C[..., 1]
    dist2 = dx * dx + dy * dy                           # (k, m, 2) [m²]: node to tip centre, squared
    on = modes > 0
    own = np.stack([on & (fg == 0), on & (fg == 1)], axis=-1)
    held = (own[..., 0].any(axis=1) & own[..., 1].any(axis=1))[:, None, None]   # (a LOST_CONTACT's last row: let go)
    reach = r - tol                                     # more than tol inside: nearer than r - tol (NaN: never)
    bad = (dist2 < reach * reach) & (reach > 0) & ~own & held
    if not bad.any():
        return None
    inside = np.where(~own & held & ~np.isnan(dist2), r - np.sqrt(dist2), -np.inf)           # (k, m, 2) [m]
    i = int(np.argmax(bad.any(axis=(1, 2))))
    pos, tip = np.unravel_index(int(np.argmax(np.where(bad[i], inside[i], -np.inf))), bad[i].shape)
    node, deepest = int(np.asarray(res.nodes)[pos]), float(np.max(inside))
    where = f"from depth = {float(np.asarray(res.depth)[i]):g} m node {node}"
    if modes[i, pos] > 0:
        return (f"{where}, a contact of finger {int(fg[i, pos])}, lies inside fingertip {tip} (by {deepest:.3g} m at most): "
                "both tips close on it (an object's corner between them), and a node holds one contact, so the rows "
                "from there on let the other tip pass through it (docs/numerics.md §2, 27); grip farther from the "
                "corner, with smaller fingertips, or squeeze less deep (result.depth gives the rows before)")
    stalled = int(np.asarray(res.status)) == int(Status.STALLED)
    why = ("with contact='point' a fingertip touches one node (no event A), and this object meets it along a "
           "segment; use contact='segment' or smaller fingertips" if contact == "point" else
           "the squeeze stopped there, STALLED: the contact set did not settle at that depth (docs/errors.md)"
           if stalled else "event A should have made it a contact: please report the scene")
    return (f"{where}, free, lies inside fingertip {tip} (by {deepest:.3g} m at most, rows from there on): {why} "
            "(result.depth gives the rows before)")


def resolution_warning(res, points, loops, E: float, thickness: float) -> str | None:
    """The warning for a fingertip whose segment contact stayed one node wide through the
    squeeze ``res``, or None. ``points`` (m, 2) are the boundary nodes [m] in ``res.nodes``
    order, ``loops`` the boundary loop sizes (``Mesh.loops``); for a solid mesh.

    One node cannot resolve a contact: the squeeze is then a point load's, whose force does
    not depend on the radius while the node sticks and changes with the mesh (on the foam
    square by 32 % for a 2 mm tip on 10 mm edges, docs/numerics.md §2, 29). The advice uses
    the 2D Hertz width of a rigid cylinder on a plane-stress half-plane, 2a with
    a² = 4 F r / (π E t), F the largest force [N] the finger exerted; it matched the contact
    width of converged meshes within 10 %. A grip at a corner (the boundary turning by more
    than 30° at it) is not judged: there the contact is a point."""
    k = int(res.count)
    modes, fg = np.asarray(res.modes)[:k], np.asarray(res.finger)[:k]
    forces, nodes, x = np.asarray(res.forces, float)[:k], np.asarray(res.nodes), np.asarray(points, float)
    ends = np.cumsum(loops)
    said = []
    for f in (0, 1):
        own = (modes > 0) & (fg == f)                                       # (k, m)
        if own.sum(axis=1).max(initial=0) != 1:
            continue
        at = np.flatnonzero(nodes == int(np.asarray(res.grip)[f]))
        if at.size == 0:
            continue
        p = int(at[0])
        loop = int(np.searchsorted(ends, p, side="right"))
        start, size = int(ends[loop]) - int(loops[loop]), int(loops[loop])
        e1 = x[p] - x[start + (p - start - 1) % size]
        e2 = x[start + (p - start + 1) % size] - x[p]
        h1, h2 = float(np.hypot(*e1)), float(np.hypot(*e2))
        if np.dot(e1, e2) < math.cos(math.radians(30.0)) * h1 * h2:      # a corner
            continue
        F = float(np.max(np.hypot(*np.where(own[..., None], forces, 0.0).sum(axis=1).T)))     # [N]
        width = 4.0 * math.sqrt(F * float(res.radius) / (math.pi * E * thickness))              # 2a [m]
        said.append((f, int(nodes[p]), 0.5 * (h1 + h2), F, width))
    if not said:
        return None
    where = " and ".join(f"finger {f} (node {n}, edges {h:.2g} m, at most {F:.3g} N: about {w:.2g} m wide)"
                         for f, n, h, F, w in said)
    return (f"the contact stayed one node wide on {where}: the boundary edges there are too long to resolve the "
            f"contact (its width: the 2D Hertz estimate for radius {float(res.radius):g} m), so these are a point "
            "load's forces on this mesh (while the node sticks, independent of the radius), off by up to tens of "
            "percent (docs/numerics.md §2, 29); mesh the boundary near the grip with edges of at most "
            f"{min(w for *_, w in said) / 4:.2g} m (jsq.shapes: refine_near=[grip points], refine_edge=...; a scene "
            "file: object.refine_edge), or use contact='point' to ask for a point load")


def unit_problems(size=None, radius=None, depth=None, E=None, max_edge=None,
                  thickness=None, between=None) -> tuple[list[str], list[str]]:
    """Sanity checks for mixed units: (errors, warnings), one line each with a suggestion.

    ``size`` is the object's extent [m] (the larger bounding-box side), ``between`` the
    distance between the fingers' first contacts [m] where known (:func:`deep_warning`). Errors where the
    result would be meaningless (a depth as large as the object); warnings where the numbers
    differ by orders of magnitude from each other (a length in millimetres among metres, E in
    MPa): a fingertip more than 10 times the object or under a thousandth of it, a plate
    more than 10 times thicker than it is wide.
    """
    errors, warns = [], []
    hint = "every length is in metres (a length in millimetres is 1000 times too large)"
    vals = [x for x in (size, radius, depth, E, max_edge, thickness) if x is not None]
    if not all(math.isfinite(float(x)) and float(x) > 0 for x in vals):
        return errors, warns                       # the field checks report those
    if size is not None and depth is not None and depth >= size:
        errors.append(f"depth = {depth:g} m is not smaller than the object ({size:g} m across): the squeeze "
                      f"would crush it; {hint}")
    if size is not None and radius is not None and not 1e-3 <= radius / size <= 10:
        pad = ("; a fingertip this large is a near-flat pad, which works, but positions are taken about its "
               "centre, so the forces of the first nanometres of a squeeze carry round-off about radius/size times "
               "larger (docs/numerics.md §2, 31)") if radius > 10 * size else ""
        warns.append(f"the fingertip radius ({radius:g} m) and the object ({size:g} m across) differ by a factor "
                     f"{max(radius / size, size / radius):.3g}; {hint}{pad}")
    if size is not None and thickness is not None and thickness > 10 * size:
        warns.append(f"thickness = {thickness:g} m is {thickness / size:.3g} times the object's size ({size:g} m "
                     f"across), where plane stress describes a thin plate; {hint}")
    if size is not None and size > 10:
        warns.append(f"the object is {size:g} m across; {hint}")
    deep = deep_warning(size, depth, between) if size is not None and depth is not None else None
    if deep:
        warns.append(deep)
    if size is not None and depth is not None and depth < 1e-6 * size:
        warns.append(f"depth = {depth:g} m is below a millionth of the object ({size:g} m); {hint}")
    if size is not None and max_edge is not None and max_edge > size:
        warns.append(f"max_edge = {max_edge:g} m exceeds the object ({size:g} m across); {hint}")
    if E is not None and not 1e2 <= E <= 1e13:
        warns.append(f"E = {E:g} Pa is outside the range of real materials (1e2 .. 1e13 Pa); E is in pascals "
                     "(1 MPa = 1e6 Pa)")
    return errors, warns


__all__ = ["FIELDS", "RULES", "MEMORY_LIMIT", "RADIUS_SHARE", "STEP_RESOLUTION", "OVERLAP_TOL", "GAP_SHARE", "EVENT_SHARE",
           "NEWTON_MAX", "MAX_ROTATION", "DEEP", "invalid_index", "problems", "raise_if_invalid", "fingertip_overlap",
           "tip_directions", "default_gap_tol", "overlap_warning",
           "values_of", "check_scene", "history_bytes", "compliance_bytes", "check_costs", "scene_cost_problems",
           "shape_problems", "unit_problems", "deep_warning", "PlacementResolutionWarning", "placement_warning",
           "inverted_warning", "boundary_points", "force_limit"]
