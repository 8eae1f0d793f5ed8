"""Rotation of the contact friction cones during a squeeze (Section V-A, Fig. 3).

Under a squeeze "the two contact friction cones sometimes rotate toward each other, making the
applied forces more aligned with the axes of the cones, and the grasp more stable (Fig. 3(b)).
In some other cases, the two cones rotate away from each other, breaking the grasp (Fig. 3(c))."
This module measures that rotation on a :class:`~jaxsqueeze.grasp.SqueezeResult`. Pure numpy
on the recorded rows (no JAX code), like :mod:`jaxsqueeze.views`.

Definitions (per recorded row k and finger i = 0, 1; centroid frame, as the result):

* **contact point** ``c_i``: the deformed position of finger i's contact node (point
  contacts); with several contact nodes (segment contacts) the force-weighted mean.
* **grasp line** ``l_i``: the unit vector from ``c_i`` toward the other finger's contact
  ``c_j``. The squeezing force of finger i on the object points along ``+l_i``.
* **cone axis** ``a_i``: the inward contact normal, the axis of the friction cone (half
  angle ``atan(mu)``), a unit vector pointing into the object. Two definitions (``axis=``):

  - ``"surface"`` (default): the inward normal of the *deformed object* at the contact.
    For a :class:`~jaxsqueeze.band.Band` it is exact: the undeformed inward normal rotated by
    the band's cross-section rotation ``phi`` at the contact node (the Hermite slope DOFs of
    the band solution for the row's recorded contact forces, plus the rigid rotation fitted
    to the recorded displacements). For a mesh (or when only the operator is given) it is the
    inward bisector normal of the two deformed boundary edges at the node (the discrete
    analogue of ``Mesh.normals``). This is the cone a small spherical fingertip sees (its
    contact normal is the object's surface normal), the one Fig. 3 draws.
  - ``"fingertip"``: the direction from the fingertip centre to the contact node,
    ``unit(theta + alpha)``: the cone the squeeze engine enforces for segment contacts
    (events C/D). A sticking node keeps its polar angle in the fingertip frame, so this axis
    only turns when the node slides or the fingertip rotates (``Fingers.rotation``).

* **misalignment** ``psi_i = angle(a_i, l_i)`` in [0, pi].
* **rotation toward the other finger** ``toward_i(k) = psi_i(0) - psi_i(k)``: positive when
  the cone axis has turned toward the grasp line, i.e. toward the other finger (Fig. 3(b)),
  negative when it turned away (Fig. 3(c)). Its magnitude equals the signed rotation
  ``rotation_i`` (counterclockwise angle from ``a_i(0)`` to ``a_i(k)``) whenever the axis does
  not cross the grasp line and the line itself does not turn.
* **cone margin** ``margin_i = atan(mu) - angle(F_i, a_i)`` with ``F_i`` finger i's total force
  on the object: the angle by which the force stays inside its cone (> 0 inside, 0 on the
  edge, < 0 outside: it would slip). Two contacts on a linear-elastic body form a two-force
  member, so ``F_i`` stays along the initial grasp line, and ``margin_i(k) - margin_i(0)``
  equals ``toward_i(k)`` up to the (small) turn of the grasp line.

Note on point contacts. With ``contact="point"`` the engine tests a sticking contact (event
C, and the grip check before the squeeze: ``laws.cone_normals``) against the cone about the
deformed object's polyline normal at the node, which turns as the object bends (Section V-A):
two contacts on a linear-elastic body form a two-force member whose forces stay along the
initial segment, so the grasp fails (SLIP_FAILURE) when a turning cone's edge reaches that
segment, and :func:`grasp_stability` reports the same depth from the recorded rows
(``surface_slip_depth``; for a band its ``"surface"`` axis is the band's own rotated normal,
within a fraction of a degree of the polyline one away from cusps). In that last row the
contact that slides has its force on the edge of the fingertip's cone (the sliding law,
eq. 6, is written about the fingertip normal), a few per cent of the tangential force off
the surface cone's edge; the squeeze ends there, so no later row depends on it.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..numbers import real_array
from ..simulation import validate
from . import views
from .views import FREE

AXES = ("surface", "fingertip")


class ConeAxes(NamedTuple):
    """Cone axes per recorded row (see the module docstring for the definitions).

    depth: (k,) [m]; relative_depth: (k,) d / D0.
    node: (k, 2) boundary position of each finger's contact node (point contacts; the
        largest force for several), -1 where the finger has no contact.
    contact: (k, 2, 2) contact points c_i [m] (centroid frame).
    axis: (k, 2, 2) unit inward cone axes a_i.
    line: (k, 2, 2) unit grasp-line directions l_i (from c_i toward the other contact).
    force: (k, 2, 2) total force of each finger on the object [N].
    psi: (k, 2) misalignment angle(a_i, l_i) [rad].
    rotation: (k, 2) counterclockwise rotation of a_i since row 0 [rad].
    toward: (k, 2) psi(0) - psi(k) [rad]: > 0 turned toward the other finger.
    margin: (k, 2) atan(mu) - angle(F_i, a_i) [rad] (NaN without friction given).
    kind: "surface" or "fingertip".
    """

    depth: np.ndarray
    relative_depth: np.ndarray
    node: np.ndarray
    contact: np.ndarray
    axis: np.ndarray
    line: np.ndarray
    force: np.ndarray
    psi: np.ndarray
    rotation: np.ndarray
    toward: np.ndarray
    margin: np.ndarray
    kind: str


class Stability(NamedTuple):
    """Result of :func:`grasp_stability`.

    label: "stabilizing" (the weaker contact's margin grew: the cones turned toward each
        other), "breaking" (it shrank: they turned away) or "neutral" (no turn above ``tol``).
    finger_labels: (label of finger 0, label of finger 1), by the sign of ``toward`` at the end.
    toward: (2,) final rotation toward the other finger [rad].
    margin: (k, 2) cone margin history [rad]; depth: (k,) [m]; relative_depth: (k,).
    margin_change: (2,) final minus initial margin [rad].
    surface_slip_depth: first depth [m] (linear interpolation between rows) at which a
        margin reaches 0, i.e. the force reaches the cone edge, or None if it never does.
    cones: the :class:`ConeAxes` it was computed from.
    """

    label: str
    finger_labels: tuple
    toward: np.ndarray
    margin: np.ndarray
    depth: np.ndarray
    relative_depth: np.ndarray
    margin_change: np.ndarray
    surface_slip_depth: float | None
    cones: ConeAxes


def _unit(v):
    v = np.asarray(v, float)
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def _angle(a, b):
    """Unsigned angle between unit vectors (..., 2) [rad], robust near 0 and pi."""
    return np.arctan2(np.abs(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]), np.sum(a * b, axis=-1))


def _signed(a, b):
    """Counterclockwise angle from a to b [rad] in (-pi, pi]."""
    return np.arctan2(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0], np.sum(a * b, axis=-1))


def _rot(v, phi):
    c, s = np.cos(phi), np.sin(phi)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def _unpack(obj):
    """(object geometry or None, operator or None, E or None, mu or None) from a Scene, a
    Band/Mesh, or a Compliance."""
    from ..mechanics.operator import Compliance

    if isinstance(obj, Compliance):
        return None, obj, None, None
    if hasattr(obj, "mesh") and hasattr(obj, "material"):          # a Scene
        # full stick: cones of half angle π/2 (atan ∞; only pushing is needed), frictionless: 0
        mu = {"coulomb": float(obj.friction), "stick": np.inf}.get(obj.friction_model, 0.0)
        return obj.mesh, None, float(obj.material.E), mu
    from ..geometry.mesh import Mesh
    from ..mechanics.band import Band
    if not isinstance(obj, (Mesh, Band)):
        raise TypeError(f"expected the jsq.Scene the result was computed for (or its Mesh, Band or compliance "
                        f"operator), got {type(obj).__name__}")
    return obj, None, None, None


def _geometry(obj, op):
    """(points (m, 2) centroid frame [m], loops) of the contact-capable nodes."""
    if obj is not None:
        B = np.asarray(obj.boundary)
        return np.asarray(obj.points, float)[B], tuple(obj.loops)
    return np.asarray(op.points, float) * float(op.length), tuple(op.loops)


def _bisector_normals(x, loops):
    """Outward bisector normals (m, 2) of closed loops of points x (m, 2) (material on the left)."""
    out = np.zeros_like(x)
    start = 0
    for n in loops:
        q = x[start:start + n]
        e_next, e_prev = np.roll(q, -1, 0) - q, q - np.roll(q, 1, 0)
        nrm = lambda e: _unit(np.stack([e[:, 1], -e[:, 0]], 1))   # noqa: E731  right normal
        out[start:start + n] = _unit(nrm(e_next) + nrm(e_prev))
        start += n
    return out


def _band_rotations(band, E, res):
    """(k, m) cross-section rotation phi [rad] of a band at every row (exact, see docstring)."""
    from ..mechanics.band import band_pinv, band_stiffness

    K = band_stiffness(band, E)
    X = band_pinv(band, K, check=False)             # checked where the squeeze built the operator
    T = band.to_xy()
    F = np.asarray(res.forces, float).reshape(len(np.asarray(res.depth)), -1)       # (k, 2m)
    dofs = (X @ (T.T @ F.T)).T                                                   # (k, 4m)
    phi = np.stack([band.rotation(d) for d in dofs])
    return phi + np.asarray(res.rigid, float)[:, 2:3]                            # + the recorded rigid rotation


def cone_axes(res, obj, axis: str = "surface", friction: float | None = None) -> ConeAxes:
    """Friction-cone axes of both contacts at every recorded row (Fig. 3).

    Args:
        res: a squeeze result (eager, trimmed).
        obj: the :class:`~jaxsqueeze.scene.Scene` (preferred: exact band rotations and the
            friction), the object (:class:`~jaxsqueeze.band.Band` needs ``friction`` and uses
            E only for the rotation: pass a Scene), or the compliance operator.
        axis: "surface" (inward normal of the deformed object) or "fingertip" (fingertip
            centre to contact node); see the module docstring.
        friction: Coulomb mu for the margin (default: the scene's; under full stick cones of half angle
            pi/2, frictionless 0; NaN margins without it).
    Returns:
        :class:`ConeAxes`.
    """
    res = views.trimmed(res)
    if axis not in AXES:
        raise ValueError(f"axis={axis!r}; choose one of {AXES}")
    geo, op, E, mu = _unpack(obj)
    if friction is not None:
        mu = real_array(friction, "friction (a Coulomb coefficient, or None for the scene's)")
        if mu.shape:
            raise ValueError(f"friction={friction!r}: expected one Coulomb coefficient mu >= 0")
        validate.raise_if_invalid({"friction": float(mu)})
        mu = float(mu)
    P, loops = _geometry(geo, op)
    depth = np.asarray(res.depth, float)
    if depth[0] != 0:        # rotation, toward and the margin's change are measured from the touch
        raise ValueError(f"this result's first row is at depth {depth[0]:g} m, not the touch (d = 0): it was squeezed "
                         "with history=False, which keeps only the last rows, and the cones' turn is measured from "
                         "the touch; squeeze with the full history (the default)")
    k = len(depth)
    modes, fg = np.asarray(res.modes), np.asarray(res.finger)
    F = np.asarray(res.forces, float)
    U = np.asarray(res.boundary_displacement, float)
    if P.shape[0] != modes.shape[1]:
        raise ValueError(f"the object has {P.shape[0]} boundary nodes but the result {modes.shape[1]}; "
                         "pass the scene (or object) the result was computed for")
    X = P[None] + U                                                  # (k, m, 2) deformed nodes
    if axis == "surface":
        from ..mechanics.band import Band

        n0 = _bisector_normals(P, loops) if not isinstance(geo, Band) else np.asarray(geo.normals, float)
        if isinstance(geo, Band):
            if E is None:
                raise ValueError("the exact band rotation needs Young's modulus: pass the Scene, not the Band")
            nk = _rot(n0[None], _band_rotations(geo, E, res))
        else:
            nk = np.stack([_bisector_normals(X[r], loops) for r in range(k)])
        inward = -nk                                                  # (k, m, 2)
    else:
        ang = np.asarray(res.theta, float) + np.take_along_axis(np.asarray(res.alpha, float), fg.astype(int), 1)
        inward = np.stack([np.cos(ang), np.sin(ang)], -1)             # centre → node
    node = np.full((k, 2), -1)
    contact = np.full((k, 2, 2), np.nan)
    ax = np.full((k, 2, 2), np.nan)
    force = np.zeros((k, 2, 2))
    for r in range(k):
        for f in (0, 1):
            on = np.flatnonzero((modes[r] > FREE) & (fg[r] == f))
            if not on.size:
                continue
            w = np.linalg.norm(F[r, on], axis=1)
            node[r, f] = on[int(np.argmax(w))]
            w = w / w.sum() if w.sum() > 0 else np.full(len(on), 1.0 / len(on))
            contact[r, f] = w @ X[r, on]
            ax[r, f] = _unit(w @ inward[r, on])
            force[r, f] = F[r, on].sum(0)
    line = _unit(np.stack([contact[:, 1] - contact[:, 0], contact[:, 0] - contact[:, 1]], 1))
    psi = _angle(ax, line)
    rotation = _signed(ax[:1], ax)
    toward = psi[:1] - psi
    fdir = _unit(force)
    # the first row (initial touch) carries no force yet: use the direction it takes at 0+
    # (the next row with a force; the response is linear in d until the first event)
    fmag = np.linalg.norm(force, axis=-1)
    has = fmag > 1e-9 * max(float(np.max(fmag)), 1e-300)     # round-off forces have no direction
    for f in (0, 1):
        nxt = np.flatnonzero(has[:, f])
        for r in np.flatnonzero(~has[:, f]):
            later = nxt[nxt > r]
            # no later row with a force (none at all: an infeasible grip): no direction; a zero
            # vector read as along the axis, inside the cone
            fdir[r, f] = fdir[later[0], f] if later.size else np.nan
    margin = (np.arctan(mu) - _angle(fdir, ax)) if mu is not None else np.full((k, 2), np.nan)
    rel = depth / views.grip_distance(res)
    return ConeAxes(depth, rel, node, contact, ax, line, force, psi, rotation, toward, margin, axis)


def grasp_stability(res, obj, axis: str = "surface", friction: float | None = None,
                    tol: float = 1e-6) -> Stability:
    """Do the friction cones turn toward each other (stabilizing) or away (breaking)?

    The overall label follows the *weaker* contact (the one with the smaller final margin):
    "stabilizing" if its margin grew over the squeeze by more than ``tol`` [rad], "breaking"
    if it shrank by more than ``tol``, else "neutral". Each finger's own label follows the sign
    of its final ``toward`` rotation. See :func:`cone_axes` for the arguments.
    """
    res = views.trimmed(res)
    if isinstance(tol, (bool, np.bool_)) or not isinstance(tol, (int, float, np.integer, np.floating)) \
            or not (np.isfinite(tol) and tol >= 0):          # (tol = -1 labelled any grasp "stabilizing")
        raise ValueError(f"tol={tol!r}: expected a finite angle >= 0 [rad]")
    c = cone_axes(res, obj, axis=axis, friction=friction)
    if friction is None and _unpack(obj)[3] is None:
        raise ValueError("grasp_stability needs the friction coefficient: pass the Scene or friction=")
    if np.all(np.isnan(c.margin[-1])):
        from ..simulation.status import Status
        raise ValueError(f"grasp_stability: the last row of this {Status(int(res.status)).name} result has no "
                         "contact with a finite force, so its friction cones have no margin; a stability label "
                         "needs a squeeze that holds the object at its last row")

    def lab(x):
        return "stabilizing" if x > tol else ("breaking" if x < -tol else "neutral")

    change = c.margin[-1] - c.margin[0]
    weak = int(np.nanargmin(c.margin[-1]))
    slip = None
    low = np.nanmin(c.margin, axis=1)
    below = np.flatnonzero(low <= 0)
    if below.size:
        r = int(below[0])
        if r == 0:
            slip = float(c.depth[0])
        else:
            t = low[r - 1] / (low[r - 1] - low[r])
            slip = float(c.depth[r - 1] + t * (c.depth[r] - c.depth[r - 1]))
    return Stability(lab(change[weak]), tuple(lab(v) for v in c.toward[-1]), c.toward[-1].copy(), c.margin,
                     c.depth, c.relative_depth, change, slip, c)


# public names for the plot in jaxsqueeze.post.plots (no private name crosses modules)
unpack = _unpack
boundary_geometry = _geometry
rotate = _rot
unit_vector = _unit
