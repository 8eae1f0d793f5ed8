"""A squeeze scene: object, material, fingers, grip, friction, depth and effects (DESIGN 2.5, 2.7)."""
from __future__ import annotations

import dataclasses
import warnings
import weakref
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import jax
import numpy as np

from ..mechanics.fem import METHODS
from ..mechanics.material import Material, checked
from ..tracing import as_array, caller_level, is_concrete, numeric, own_transfers
from .laws import CONTACT_MODELS, FRICTION_MODELS
from ..geometry import boundary
from ..geometry.mesh import Mesh
from ..mechanics.operator import Compliance
from ..numbers import holds_bool, kind, real_array


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Fingers:
    """Two identical round fingertips of radius ``radius`` [m] (Section IV).

    Finger 1 touches grip node ``grip[0]`` and stays still; finger 2 touches ``grip[1]`` and
    translates by the squeeze depth d toward finger 1 along p_i − p_j. Each centre lies on
    the outward normal at its node, one radius away.

    rotation: optional fingertip rotation schedules α1(d), α2(d) [rad] (Section IV-D), as
        polynomial coefficients in d [m], highest power first (``numpy.polyval`` order),
        shape (2, k). Fingertips rotate about their own centres. ``None`` compiles no
        rotation code at all.

    A pytree: ``radius`` and ``rotation`` are leaves (traceable, differentiable).
    """

    radius: Any
    rotation: Any = None

    def __post_init__(self):
        if numeric(self.radius):
            r = np.asarray(self.radius, float)
            if not (np.all(np.isfinite(r)) and np.all(r > 0)):
                raise ValueError(f"Fingers.radius={self.radius!r} must be a finite length > 0 m.")
        rows = [(len(r),) if isinstance(r, (list, tuple)) else np.shape(r) for r in self.rotation] \
            if isinstance(self.rotation, (list, tuple)) else []      # (no numpy conversion: rows may hold tracers)
        if len(set(rows)) > 1:
            raise ValueError(f"Fingers.rotation rows have different lengths {rows}: "
                             "give both fingers k coefficients, padding the shorter polynomial with leading zeros "
                             "(highest power first).")
        rot_kind = kind(self.rotation) if self.rotation is not None and is_concrete(self.rotation) else "f"
        ragged = rot_kind == "O" and isinstance(self.rotation, (list, tuple, dict))     # (not JAX's placeholders)
        if ragged or rot_kind in "bcSU" or holds_bool(self.rotation):
            shown = self.rotation if ragged else np.asarray(self.rotation).tolist()
            raise ValueError(f"Fingers.rotation = {shown!r:.60}: expected real polynomial coefficients [rad] of "
                             "shape (2, k)")
        if self.rotation is not None and numeric(self.rotation):
            rot = np.asarray(self.rotation, float)
            if rot.ndim != 2 or rot.shape[0] != 2:
                raise ValueError("Fingers.rotation must be finite polynomial coefficients of shape (2, k): "
                                 f"one row per finger, highest power first; got shape {rot.shape}.")
            if not np.all(np.isfinite(rot)):
                raise ValueError(f"Fingers.rotation = {rot.tolist()!r:.80} holds NaN or infinite coefficients: "
                                 "give finite ones [rad / m^k] (zeros for a tip that does not turn).")


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Placement:
    """Where the two fingertips touch, as continuous coordinates (grasp planning, DESIGN 2.9).

    s: (2,) arc length [m] of finger 0 (still) and finger 1 (squeezing) along the outer
        boundary loop, measured from its first node (``mesh.boundary[0]``) with the material
        on the left (counterclockwise); periodic in the perimeter: any value within 1,000
        object sizes of 0 is a position (``validate.MAX_WRAP``; farther, the wrapped position
        would be round-off, and the squeeze refuses it).
    angle: () offset [rad] of the squeeze direction, counterclockwise, from the paper's
        (along the line from p(s_1) to p(s_0): finger 1 moves toward finger 0); within
        1,000 rad of 0.

    Each fingertip centre starts at p(s_i) + r n(s_i) on a C² spline through the boundary
    nodes (:func:`jaxsqueeze.geometry.boundary.curve`), then both close in along the squeeze
    line until each first touches a node: that node is its first contact (event A's gap
    function along the approach). Outcomes are piecewise smooth in (s, angle); a placement
    whose fingers cannot both touch, or whose first contacts leave a friction cone, gives
    ``Status.INFEASIBLE_GRIP`` and a negative ``result.margin``. A pytree of two leaves.
    """

    s: Any
    angle: Any = 0.0

    def __post_init__(self):
        if numeric(self.s) and np.shape(self.s)[-1:] != (2,):
            raise ValueError(f"Placement.s={self.s!r} must hold two arc lengths [m] (finger 0, finger 1).")
        for name in ("s", "angle"):
            v = getattr(self, name)
            if numeric(v) and not np.all(np.isfinite(np.asarray(v, float))):
                raise ValueError(f"Placement.{name}={v!r} must be finite.")


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Adversary:
    """A third round fingertip that pushes the grasped object after the squeeze (the adversary
    of Jia, Guo and Lin, IJRR 2014), as a second loading phase of the same event loop.

    s: () arc length [m] of the pushed boundary point (as in :class:`Placement`, within
        1,000 object sizes of 0).
    push: () push displacement [m] > 0, shorter than the object.
    angle: () push direction offset [rad] from the inward normal at s; a direction, so
        periodic in 2π (angle and angle + 2π push alike, within 1,000 rad of 0); pushing
        needs it within a right angle of the inward normal (cos angle > 0).
    radius: () fingertip radius [m]; None: the grasping fingers' radius.
    step: () push step [m], at most the push and the pusher's radius; None: push / 50, or
        the pusher's radius where that is smaller.

    The grasping fingers hold still at the squeeze depth; the pusher starts on the boundary
    point (tangent to the deformed object there), closes in along its push direction until it
    touches, then moves by the push. Only a squeeze that succeeded is pushed. A pusher that
    cannot touch the object there from outside (its path misses the object or reaches it
    through the object, as at cos angle ≤ 0, or it would overlap a grasping fingertip) pushes
    nothing: the result's status is ``INFEASIBLE_GRIP`` and ``squeeze_status`` the squeeze's.
    The pusher is placed on the smooth boundary curve of a :class:`Placement`; the squeeze
    itself keeps the scene's grip (or placement), so its rows are those of the same scene
    without an adversary.
    """

    s: Any
    push: Any
    angle: Any = 0.0
    radius: Any = None
    step: Any = None

    def __post_init__(self):
        for name in ("s", "angle"):
            v = getattr(self, name)
            if numeric(v) and not np.all(np.isfinite(np.asarray(v, float))):
                raise ValueError(f"Adversary.{name}={v!r} must be finite.")
        for name in ("push", "radius", "step"):
            v = getattr(self, name)
            if numeric(v) and not (np.all(np.isfinite(np.asarray(v, float))) and np.all(np.asarray(v, float) > 0)):
                raise ValueError(f"Adversary.{name}={v!r} must be a finite length > 0 m.")


#: contact slots an eager squeeze starts with under ``Settings.capacity = None`` (doubled on overflow)
EAGER_SLOTS = 32
#: contact slots of a traced squeeze under ``Settings.capacity = None`` (it cannot rerun)
TRACED_SLOTS = 64
#: sliding contacts an eager Coulomb squeeze solves for under ``Settings.sliding_capacity = None``
#: (doubled on overflow)
EAGER_SLIDING = 8
#: loop iterations and event-log rows of a squeeze under ``Settings.max_steps`` / ``max_events``
#: ``= None``; an eager squeeze multiplies them by ``LOG_GROWTH`` when they run out, up to
#: ``LOG_GROWTH ** 2`` times (6,400 and 4,096)
STEPS, EVENTS, LOG_GROWTH = 400, 256, 4
#: the largest ``Settings.newton_iters`` and ``bisect_iters``: a bisection from one metre
#: reaches float64's smallest numbers in ~1,100 halvings (the loops count in int32)
MAX_ITERS = 10_000


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Settings:
    """Accuracy and capacity settings of a squeeze. Each is an explicit knob (DESIGN 2.8).

    step: squeeze step [m]; default ``depth / 50``.
    event_tol: width [m] to which an event's depth is bracketed before the final
        implicit-function refinement, or 1e-4 of the event's depth where that is finer;
        default ``step * 1e-4``. Events found in one bracket happen together, but a touch
        (event A) more than ``gap_tol`` past the first is taken at its own depth.
    newton_tol: slip-angle Newton tolerance on the update [rad]; default 1e-11 in float64,
        1e-5 in float32.
    gap_tol: penetration [m] a free node may reach before event A fires; default
        ``1e-9 * L`` (float64) or ``1e-5 * L`` (float32), with L the object length.
    capacity: number of contact slots (static). Contact nodes beyond it give ``Status.OVERFLOW``.
        ``None`` (default) chooses: an eager :func:`~jaxsqueeze.squeeze` starts with 32 slots
        (at most the boundary node count) and, when they run out, doubles them and squeezes
        again (a program per capacity, the same result); a traced squeeze (``jit``, ``vmap``,
        ``jacfwd``) cannot rerun and keeps 64, also at most the boundary node count (the
        planner squeezes with 32 and redoes what overflows: ``plan.search.quick``). Fewer
        slots are faster: the bordered inverse is (2·capacity + 3)².
    sliding_capacity: sliding contacts in the slip-angle Newton system (static; at most
        ``capacity``). More sliding nodes give ``Status.OVERFLOW``. ``None`` (default): an
        eager Coulomb squeeze starts with 8 and grows them like ``capacity``; a traced one
        solves up to 8 (a frictionless one, eager or traced, 16) in a compact system and falls
        back to one over all slots (both compiled). One system is a smaller program (compiles
        faster) and a smaller one runs faster.
    max_steps: bound on loop iterations (steps plus event resolutions), static; more give
        ``Status.MAX_STEPS``. ``None`` (default): 400, and an eager squeeze that runs out of
        them (or of ``max_events``) squeezes again with 4 times as many, up to 16 times
        (6,400; the same result, a program per size); a traced one keeps 400 (the planner
        squeezes a candidate that runs out again, as an eager squeeze would).
    max_events: capacity of the event log, static; more events give
        ``Status.EVENT_OVERFLOW``. ``None`` (default): 256, grown like ``max_steps`` (up
        to 4,096) eagerly. Some full-stick squeezes, where a few nodes touch and leave again
        and again, need hundreds.
    newton_iters: Newton iteration bound, static, at most ``MAX_ITERS``.
    bisect_iters: iteration bound for locating an event (regula falsi + bisection), static,
        at most ``MAX_ITERS``.
    fused: compile the squeeze loop into one CPU kernel (static; default False): the same
        result, each squeeze ~35 % faster (the foam square: 3.4 against 5.3 ms) for ~1.9 s
        more compile (4.5 against 2.5 s), which pays off from ~1,000 squeezes
        of one object or with the persistent compilation cache. Honoured wherever the
        library compiles the program itself (eager squeezes,
        :func:`~jaxsqueeze.batch.split_vmap` batches, the planner's maps and searches;
        forward-mode derivatives there are computed outside the kernel); ignored inside your
        own ``jit``, ``vmap`` or ``jacfwd`` (the program is then yours, compiled without the
        options a kernel needs) and off the CPU (:func:`jaxsqueeze.compiler.one_kernel`).

    A pytree: the four tolerances are leaves (None = the default), the integers are static
    (a changed capacity compiles a new program; a changed tolerance does not).
    """

    step: float | None = None
    event_tol: float | None = None
    newton_tol: float | None = None
    gap_tol: float | None = None
    capacity: int | None = field(default=None, metadata=dict(static=True))
    sliding_capacity: int | None = field(default=None, metadata=dict(static=True))
    max_steps: int | None = field(default=None, metadata=dict(static=True))
    max_events: int | None = field(default=None, metadata=dict(static=True))
    newton_iters: int = field(default=30, metadata=dict(static=True))
    bisect_iters: int = field(default=40, metadata=dict(static=True))
    fused: bool = field(default=False, metadata=dict(static=True))

    def slots(self, m: int, eager: bool = False) -> int:
        """The contact slots a squeeze of an object with m boundary nodes starts with:
        ``capacity``, or under ``None`` ``EAGER_SLOTS`` eagerly and ``TRACED_SLOTS`` traced;
        each at most m (no more contacts exist) and at least 2."""
        n = self.capacity if self.capacity is not None else EAGER_SLOTS if eager else TRACED_SLOTS
        return max(2, min(int(n), int(m)))

    def sliding(self, capacity: int, eager: bool = False) -> int:
        """The size of the one compact Newton system a squeeze with ``capacity`` slots starts
        with: ``sliding_capacity``, or under ``None`` min(``EAGER_SLIDING``, capacity) eagerly
        and 0 traced (0: a compact system of ``contacts.COMPACT`` with all slots as fallback)."""
        if self.sliding_capacity is not None:
            return min(int(self.sliding_capacity), int(capacity))
        return min(EAGER_SLIDING, int(capacity)) if eager else 0

    def bounds(self) -> tuple[int, int]:
        """(max_steps, max_events) a squeeze starts with: the settings', ``STEPS`` and
        ``EVENTS`` under ``None``."""
        return (STEPS if self.max_steps is None else int(self.max_steps),
                EVENTS if self.max_events is None else int(self.max_events))


@jax.tree_util.register_dataclass
@dataclass(frozen=True, eq=False)
class Scene:
    """Everything that defines one squeeze.

    Args:
        mesh: the object: a :class:`~jaxsqueeze.mesh.Mesh` (solid) or a
            :class:`~jaxsqueeze.band.Band` (ring-like object).
        material: :class:`~jaxsqueeze.material.Material`.
        fingers: :class:`Fingers`.
        grip: (i, j) mesh node indices on the boundary touched by finger 0 (still) and finger 1
            (squeezing); or None when ``placement`` is given.
        friction: Coulomb coefficient μ ≥ 0.
        depth: target squeeze depth d [m] > 0.
        friction_model: "coulomb" (stick/slip, events A–D), "frictionless" (every contact
            slides, no C/D events) or "stick" (full stick: no Newton solve, no slip events).
        contact: "segment" (contact regions grow: event A) or "point" (one contact per
            finger, no event A; for ring-like objects, Section V-A: nothing keeps other nodes
            out of the fingertips, so on a solid object the neighbours of a contact sink into
            them as it deforms).
        method: compliance build ("sparse", "dense", "spectral"); ignored for bands.
        settings: :class:`Settings`.
        placement: a continuous :class:`Placement` (instead of ``grip``: give one of them).
        adversary: an :class:`Adversary` pushing after the squeeze (grasp quality).

    A pytree (MJX's rule: a field is a leaf if and only if it is a number): material,
    fingers, grip, friction, depth and the settings' tolerances are leaves, so ``jax.jit``,
    ``jax.vmap`` and ``jax.jacfwd`` apply to a function of any of them and a changed number
    never recompiles; the object, the model choices and the capacities are static.
    """

    mesh: Any = field(metadata=dict(static=True))
    material: Material
    fingers: Fingers
    grip: Any = None
    friction: Any = 0.5
    depth: Any = 0.01
    friction_model: str = field(default="coulomb", metadata=dict(static=True))
    contact: str = field(default="segment", metadata=dict(static=True))
    method: str = field(default="sparse", metadata=dict(static=True))
    settings: Settings = field(default_factory=Settings)
    placement: Placement | None = None
    adversary: Adversary | None = None

    def replace(self, **changes) -> "Scene":
        """A copy with some fields changed (the cached compliance operator is shared)."""
        return dataclasses.replace(self, **changes)

    def __post_init__(self):
        from ..mechanics.band import Band

        if not isinstance(self.mesh, (Mesh, Band)):
            raise TypeError(f"Scene.mesh must be a jsq.Mesh (jsq.shapes.*, jsq.read_mesh) or a band "
                            f"(jsq.band.Band), got {type(self.mesh).__name__}")
        if self.friction_model not in FRICTION_MODELS:
            raise ValueError(f"friction_model={self.friction_model!r}; choose one of {FRICTION_MODELS}.")
        if self.contact not in CONTACT_MODELS:
            raise ValueError(f"contact={self.contact!r}; choose one of {CONTACT_MODELS}.")
        if numeric(self.friction):
            mu = np.asarray(self.friction, float)
            if not np.all(np.isfinite(mu)) or np.any(mu < 0):
                raise ValueError(f"friction={self.friction!r} must be a finite coefficient mu >= 0.")
        if numeric(self.depth):
            d = np.asarray(self.depth, float)
            if not np.all(np.isfinite(d)) or np.any(d <= 0):
                raise ValueError(f"depth={self.depth!r} must be a finite squeeze depth > 0 m.")
        if self.adversary is not None and self.contact == "point":
            raise ValueError("an Adversary needs contact='segment': point contacts compile out new contacts "
                             "(event A), so the pusher would pass through the object without touching it.")
        if self.grip is None and self.placement is None:
            raise ValueError("a Scene needs grip=(i, j) (two boundary nodes) or placement=Placement(s=(s0, s1)).")
        if isinstance(self.placement, Placement) and numeric(self.grip):
            raise ValueError(f"a Scene takes grip={self.grip!r} or placement={self.placement!r}, not both: "
                             "use scene.replace(grip=None, placement=...) or scene.replace(placement=None, grip=...).")
        if numeric(self.grip) and self.placement is None:
            g = np.asarray(self.grip)
            if isinstance(self.grip, (tuple, list)) and all(isinstance(v, (int, np.integer)) for v in self.grip):
                g = np.array([int(v) for v in self.grip])   # (int64 with uint64 promotes to float64)
            flags = isinstance(self.grip, (tuple, list)) and any(isinstance(v, (bool, np.bool_)) for v in self.grip)
            if g.shape[-1:] != (2,) or not np.issubdtype(g.dtype, np.integer) or flags:
                raise ValueError(f"grip={self.grip!r} must be two integer boundary node indices (i, j).")
            if g.ndim == 1:
                if g[0] == g[1]:
                    raise ValueError(f"grip={self.grip!r} names node {g[0]} twice; the fingers need two different nodes.")
                on = set(np.asarray(self.boundary_nodes()).tolist())
                bad = [int(v) for v in g if int(v) not in on]
                if bad:
                    raise ValueError(f"grip node(s) {bad} are not on the boundary; pick nodes from "
                                     "mesh.boundary (or use Scene.nearest_boundary_node).")
        s = self.settings
        if not isinstance(s, Settings):
            raise TypeError(f"Scene.settings must be a jsq.Settings, got {type(s).__name__} ({s!r:.60}); "
                            "leave it out for the defaults")
        if not isinstance(self.method, str) or self.method not in METHODS:
            raise ValueError(f"method={self.method!r}; choose one of {METHODS}.")
        if not isinstance(s.fused, (bool, np.bool_)):
            raise ValueError(f"Settings.fused={s.fused!r} must be True or False.")
        for name in ("capacity", "sliding_capacity", "max_steps", "max_events", "newton_iters", "bisect_iters"):
            v = getattr(s, name)
            if name in ("capacity", "sliding_capacity", "max_steps", "max_events") and v is None:
                continue
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"Settings.{name}={v!r} must be a positive integer.")
            if name.endswith("_iters") and v > MAX_ITERS:      # the loops count in int32: 2**31 wrapped to < 0
                raise ValueError(f"Settings.{name}={v!r} is more than {MAX_ITERS:,} iterations: Newton's method "
                                 "and the event bisection converge in tens (default 30 and 40); give a bound "
                                 f"from 1 to {MAX_ITERS}.")
        if s.capacity is not None and s.capacity < 2:
            raise ValueError("Settings.capacity must be at least 2 (one contact per finger).")
        for name in ("step", "event_tol", "newton_tol", "gap_tol"):
            v = getattr(s, name)
            a = np.asarray(v, float) if v is not None and numeric(v) else None
            if a is not None and not np.all(np.isfinite(a) & (a > 0)):
                raise ValueError(f"Settings.{name}={v!r} must be a finite value > 0 (or None for the default).")

    # ------------------------------------------------------------------ object helpers
    def boundary_nodes(self) -> np.ndarray:
        """(m,) node indices that can touch a finger (``arange(m)`` for a band)."""
        if isinstance(self.mesh, Mesh):
            return np.asarray(self.mesh.boundary)
        return np.arange(self.mesh.m)

    def curve(self):
        """The smooth arc-length parametrization of the outer boundary loop [m], centroid frame
        (:func:`jaxsqueeze.geometry.boundary.curve`); :class:`Placement` coordinates refer to it."""
        return boundary_curve(self.mesh)

    def arc_length(self, node) -> np.ndarray:
        """Arc-length coordinate(s) s [m] of outer-loop boundary node(s) ``node`` (mesh indices):
        ``Placement(s=scene.arc_length(grip))`` places the fingers at those nodes."""
        pos = boundary.positions(self.boundary_nodes(), node)
        outer = self.mesh.loops[0] if hasattr(self.mesh, "loops") else self.mesh.m
        if np.any(pos >= outer):
            off = np.atleast_1d(np.asarray(node))[np.atleast_1d(pos) >= outer].tolist()
            raise ValueError(f"node(s) {off} lie on a hole's boundary, not on the outer boundary loop that arc "
                             "lengths (and placements) run along.")
        return boundary.arc_length(self.curve(), pos)

    def nearest_boundary_node(self, xy) -> int:
        """Boundary node nearest to the point ``xy`` (2,) given in the user's frame [m]."""
        return nearest_boundary_node(self.mesh, xy)

    @own_transfers
    def operator(self) -> Compliance:
        """The compliance operator of the object (see :func:`compliance_of`).

        Build it once and pass it on (``jsq.squeeze(scene, op=op)``) to make the reuse
        explicit; calling this again for the same object, ν and method returns the cached one.
        """
        return compliance_of(self.mesh, self.material, self.method)


#: at most this many (nu, method) operators are kept per object; the cache entry of an object
#: goes when the object is garbage collected (a WeakKeyDictionary, never keyed by ``id``)
CACHE_PER_OBJECT = 4
_operators: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def compliance_of(obj, material: Material, method: str = "sparse") -> Compliance:
    """Compliance operator of a mesh or band, with E and thickness applied as a scale.

    Solid meshes: the scaled operator depends on ν and the build only, so it is cached per
    object (weakly: dropping the mesh frees its operators) and per (ν, method, precision: x64
    on or off), at most ``CACHE_PER_OBJECT`` of them. When ν is being traced (``jax.jvp``/``jacfwd``/``vmap`` over
    ν) the operator is built inside the trace with the differentiable ``"dense"`` build
    (JAX Cholesky), uncached, so derivatives in ν are exact.

    A band (:class:`~jaxsqueeze.band.Band`) is built once per band object (and precision): its scaled
    compliance ``E h T K^+ T^T`` does not depend on E (nor on nu, which a band does not
    have), so ``method`` and ``material.nu`` are ignored and the stiffness scale is
    ``material.E * material.thickness``. The band's out-of-plane extent is ``band.height``;
    ``material.thickness`` must equal it (raises ``ValueError`` otherwise, rather than
    silently using one of two different values). A traced thickness (``jax.vmap`` or
    ``jax.jacfwd`` over it) cannot be checked; it scales the band as a band of that height.
    """
    from ..mechanics.fem import compliance

    checked(material)
    solid = isinstance(obj, Mesh)
    if not solid:
        from ..mechanics.band import Band

        if not isinstance(obj, Band):
            raise TypeError(f"Scene.mesh must be a jaxsqueeze Mesh or Band, got {type(obj).__name__}")
        if numeric(material.thickness) and not np.allclose(np.asarray(material.thickness, float), obj.height,
                                                           rtol=1e-9, atol=0.0):
            raise ValueError(f"Material.thickness={material.thickness!r} differs from the band height "
                             f"{obj.height!r} m; for a band both are its out-of-plane extent h "
                             "(use Material(E, nu, thickness=band.height)).")
    if solid and not is_concrete(material.nu):
        op = compliance(obj, material, "dense")          # differentiable in nu; not cached
    else:
        # per precision too: an operator built with x64 on is float64 data, which a squeeze run
        # inside ``jax.enable_x64(False)`` cannot mix with its float32 state (and vice versa)
        precision = jax.dtypes.canonicalize_dtype(np.float64)
        key = (float(material.nu), method, precision) if solid else ("band", precision)
        per = _operators.setdefault(obj, {})
        op = per.get(key)
        if op is None:
            # built eagerly even when called under jit/vmap/jacfwd (the first squeeze of an object
            # may be a traced one): the host-side sparse build needs concrete arrays, and the
            # operator is cached for every later call, traced or not
            with jax.ensure_compile_time_eval():
                if solid:
                    op = compliance(obj, Material(1.0, float(material.nu), 1.0), method)
                else:
                    from ..mechanics.band import band_compliance
                    op = band_compliance(obj, 1.0)      # scaled G is independent of E
            if len(per) >= CACHE_PER_OBJECT:
                per.pop(next(iter(per)))
            per[key] = op
    return dataclasses.replace(op, stiffness=stiffness_of(obj, material, op.G.dtype))


def stiffness_of(obj, material: Material, dtype=None) -> jax.Array:
    """E h [N/m], h = ``material.thickness``: the force scale of a compliance operator, whose
    scaled G depends on the object and ν only. A band's stiffness is linear in its height
    (A = w h, I = h w³ / 12), so its thickness, which equals its height when checked eagerly,
    scales it exactly when traced too (derivatives in it included)."""
    return as_array(material.E * material.thickness, dtype)


def boundary_curve(obj) -> "boundary.Curve":
    """The outer loop's :class:`~jaxsqueeze.geometry.boundary.Curve` of a mesh or band [m]."""
    if isinstance(obj, Mesh):
        return boundary.curve(obj.points[obj.boundary], obj.loops)
    return boundary.curve(np.asarray(obj.points), (obj.m,))


def _boundary_edge_at(pts, loops, i: int) -> float:
    """The longer of the two boundary edges [m] at position ``i`` of the boundary order, for
    boundary points ``pts`` (m, 2) in loops of the lengths ``loops``."""
    ends = np.cumsum(loops)
    k = int(np.searchsorted(ends, i, side="right"))
    start, n = int(ends[k] - loops[k]), int(loops[k])
    pair = start + (i - start + np.array([1, -1])) % n
    return float(np.linalg.norm(pts[pair] - pts[i], axis=1).max())


class Snap(NamedTuple):
    """Where a point ``xy`` [m] lands on a boundary (:func:`snap`): the nearest boundary node,
    its position [m] in the caller's frame, its distance [m], the longer boundary edge there
    [m], and a node equally near (a tie broken by round-off) or None."""

    node: int
    at: list
    distance: float
    edge: float
    tie: int | None

    @property
    def off_outline(self) -> bool:
        """The point is farther from its node than twice the boundary edges there."""
        return self.distance > 2 * self.edge


def snap(obj, xy) -> Snap:
    """The boundary node of a mesh or band nearest to ``xy`` (2,) in the caller's frame [m]
    (``points + offset``; both :class:`Mesh` and :class:`~jaxsqueeze.band.Band` keep the node
    centroid at the origin and the caller's frame in ``offset``), with what a caller should
    say about it (:class:`Snap`). Among equally near nodes the first in boundary order wins.
    Raises ``ValueError`` unless ``xy`` is one finite (x, y) pair."""
    xy = real_array(xy, "the point xy", "m")
    if xy.shape != (2,) or not np.all(np.isfinite(xy)):
        raise ValueError(f"the point xy must be one finite (x, y) pair in metres, e.g. (0.005, 0.05); got {xy.tolist()}")
    if isinstance(obj, Mesh):
        pts, nodes, loops = obj.points[obj.boundary] + obj.offset, np.asarray(obj.boundary), obj.loops
    else:
        pts, nodes, loops = obj.points + obj.offset, np.arange(obj.m), (obj.m,)
    dist = np.linalg.norm(pts - xy, axis=1)
    # equally near within round-off (the offset's rounding depends on the node numbering): the
    # first in boundary order, which is geometric (Mesh.boundary), not the last bit's choice
    k = np.flatnonzero(dist <= dist.min() * (1 + 1e-6))[:2]
    tie = len(k) == 2
    return Snap(int(nodes[k[0]]), pts[k[0]].tolist(), float(dist[k[0]]), _boundary_edge_at(pts, loops, int(k[0])),
                int(nodes[k[1]]) if tie else None)


def nearest_boundary_node(obj, xy) -> int:
    """Boundary node of a mesh or band nearest to ``xy`` (2,) in the caller's frame [m]
    (:func:`snap`). Warns when the nearest is farther than twice the boundary edges there (a
    point off the outline, as the scene files refuse: e.g. millimetres among metres), and
    otherwise when two nodes are equally near (a point midway between nodes: which one is
    taken decides the grip's slant)."""
    s = snap(obj, xy)
    xy = np.asarray(xy, float)
    if s.off_outline:
        warnings.warn(f"{xy.tolist()} is {s.distance:.3g} m from the nearest boundary node {s.node} at "
                      f"{s.at}, more than twice the boundary edges there ({s.edge:.3g} m); it is "
                      "taken, but a grip point belongs on the object's outline (lengths in metres, in the mesh's "
                      "frame)", stacklevel=caller_level())
    elif s.tie is not None:
        warnings.warn(f"boundary nodes {s.node} and {s.tie} are equally near {xy.tolist()} ({s.distance:.3g} m), "
                      f"node {s.node} is taken; for a node at that point mesh with refine_near=[point] (shapes) "
                      "or pick the node yourself", stacklevel=caller_level())
    return s.node
