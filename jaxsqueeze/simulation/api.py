"""The user-facing squeeze: :func:`squeeze` turns a :class:`Scene` into a :class:`SqueezeResult`."""
from __future__ import annotations

import dataclasses
import functools
import warnings

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jax.custom_batching import custom_vmap
from jax.custom_derivatives import SymbolicZero

from .engine import SUNK_TOLS, Config, Grasp, floating, simulate
from . import laws
from . import validate
from ..geometry import boundary
from .result import EventLog, SqueezeResult, to_result  # noqa: F401
from .result import trim as trim_result
from .. import compiler
from ..tracing import (as_array, caller_level, differentiated, forward_levels, is_concrete, own_transfers, reverse_mode,
                       staged)
from ..mechanics.operator import Compliance, field_displacement, field_on_host
from ..geometry.mesh import Mesh
from ..numbers import flag
from .scene import EVENTS, LOG_GROWTH, STEPS, Scene, stiffness_of
from .status import Status



# ----------------------------------------------------------------------------- scene → core inputs
def config_of(scene: Scene, history: bool = True, eager: bool = False) -> Config:
    """The static configuration of a scene; its contact slots are ``Settings.slots`` (the
    automatic capacity of an ``eager`` squeeze starts smaller and grows, :func:`squeeze`).
    ``Settings.fused`` holds where the program is compiled at the top level with the options
    a one-kernel loop needs: ``eager`` squeezes, and squeezes traced inside the library's own
    top-level programs (:func:`jaxsqueeze.compiler.top_level_trace`: ``split_vmap``, the
    planner); not inside a user's ``jit``/``vmap``/``jacfwd``."""
    s = scene.settings
    capacity = s.slots(len(scene.boundary_nodes()), eager)
    # every frictionless contact slides: without a sliding capacity it keeps both systems
    auto_all = scene.friction_model == "frictionless" and s.sliding_capacity is None
    sliding = 0 if scene.friction_model == "stick" or auto_all else s.sliding(capacity, eager)
    max_steps, max_events = s.bounds()
    return Config(friction_model=scene.friction_model, contact=scene.contact,
                  rotation=scene.fingers.rotation is not None, capacity=capacity, sliding=sliding,
                  max_steps=max_steps, max_events=max_events,
                  newton_iters=int(s.newton_iters), bisect_iters=int(s.bisect_iters),
                  placement=scene.placement is not None, adversary=scene.adversary is not None,
                  history=history,
                  fused=bool(s.fused and compiler.can_fuse() and (eager or compiler.top_level_trace())))


def grasp_of(scene: Scene, op: Compliance, validated: bool = False) -> Grasp:
    """The traced numbers of a scene in SI, with the defaults of :class:`Settings` filled in
    and the grip as boundary positions (−1 for a node that is not on the boundary).

    ``invalid`` is the traced validation (:func:`invalid_index`), or −1 with ``validated``:
    the caller raises on every problem itself (an eager :func:`squeeze` does, with the same
    rules evaluated in numpy)."""
    dt = op.G.dtype
    f64 = dt == jnp.float64
    # eager (validated) numbers stay numpy until the compiled call takes them: a device array
    # per number would cost ~50 µs each
    xp = np if validated else jnp
    L = xp.asarray(op.length)
    s = scene.settings
    depth = xp.asarray(scene.depth, dt)
    step = xp.asarray(s.step, dt) if s.step is not None else depth / 50
    event_tol = xp.asarray(s.event_tol, dt) if s.event_tol is not None else step * 1e-4
    newton_tol = s.newton_tol if s.newton_tol is not None else (1e-11 if f64 else 1e-5)
    gap_tol = s.gap_tol if s.gap_tol is not None else validate.default_gap_tol(L, float(jnp.finfo(dt).eps))
    nodes = scene.boundary_nodes()
    table = boundary.position_table(nodes, int(np.max(nodes)) + 1)
    grip = xp.asarray(boundary.lookup(table, scene.grip)) if scene.grip is not None else xp.zeros(2, np.int32)
    placement = adversary = curve = ()
    if scene.placement is not None or scene.adversary is not None:
        curve = scene.curve()
    if scene.placement is not None:
        placement = (xp.asarray(scene.placement.s, dt), xp.asarray(scene.placement.angle, dt))
    if scene.adversary is not None:
        a = scene.adversary
        radius = xp.asarray(a.radius if a.radius is not None else scene.fingers.radius, dt)
        push = xp.asarray(a.push, dt)
        adversary = (xp.asarray(a.s, dt), xp.asarray(a.angle, dt), radius, push,
                     xp.asarray(a.step, dt) if a.step is not None else xp.minimum(push / 50, radius))
    rot = scene.fingers.rotation
    rot = xp.zeros((2, 1), dt) if rot is None else xp.asarray(rot, dt)
    g = Grasp(grip=grip, radius=xp.asarray(scene.fingers.radius, dt), mu=xp.asarray(scene.friction, dt),
              depth=depth, step=step, event_tol=event_tol, newton_tol=xp.asarray(newton_tol, dt),
              gap_tol=xp.asarray(gap_tol, dt), rotation=rot, invalid=xp.asarray(-1, np.int32),
              placement=placement, adversary=adversary, curve=curve)
    if validated:
        return g
    return dataclasses.replace(g, invalid=invalid_index(g, scene, op))


#: :func:`grasp_of` of a traced scene as one program: under an eager ``jax.jacfwd`` or
#: ``jax.vmap`` its ~70 small operations (the conversions and the traced validation) would
#: each be compiled on its own the first time (~3 s on 2 cores)
_traced_grasp = jax.jit(compiler.precise(functools.partial(grasp_of, validated=False)))


def invalid_index(grasp: Grasp, scene: Scene, op: Compliance) -> jax.Array:
    """The traced validation of a scene's numbers (see :mod:`jaxsqueeze.simulation.validate`)."""
    return validate.invalid_index(validate_values(grasp, scene, op))


def validate_values(grasp: Grasp, scene: Scene, op: Compliance) -> dict:
    """The numbers :mod:`~jaxsqueeze.simulation.validate` checks, by field name."""
    values = {"material.E": scene.material.E, "material.nu": scene.material.nu,
              "material.thickness": scene.material.thickness, "fingers.radius": grasp.radius,
              "friction": grasp.mu, "depth": grasp.depth, "settings.step": grasp.step,
              "settings.event_tol": grasp.event_tol, "settings.newton_tol": grasp.newton_tol,
              "settings.gap_tol": grasp.gap_tol, "fingers.rotation": grasp.rotation}
    values["eps"] = float(jnp.finfo(op.G.dtype).eps)
    values["size"] = op.length
    if not isinstance(scene.mesh, Mesh):
        values.pop("material.nu")                      # a band has no ν
    elif op.nu is not None:
        values["op_nu"] = op.nu                        # a given op fixes ν (traced: checked here)
    if scene.placement is None:
        xp = np if is_concrete((grasp.grip, grasp.radius, op.points)) else jnp    # eager: no tiny device ops
        P, grip = xp.asarray(op.points) * xp.asarray(op.length), xp.asarray(grasp.grip)
        slot = xp.clip(grip, 0, op.m - 1)
        gp = P[slot]
        dirs = validate.tip_directions(gp, xp.asarray(op.normals)[slot], scene.friction_model == "frictionless", xp=xp)
        values.update({"grip_slots": grip, "n_boundary": op.m, "grip_distance": xp.linalg.norm(gp[1] - gp[0]),
                       "grip.overlap": validate.fingertip_overlap(P, grip, dirs, xp.asarray(grasp.radius), xp=xp)})
    else:
        values.update({"placement.s": grasp.placement[0], "placement.angle": grasp.placement[1]})
    if scene.adversary is not None:
        s3, angle, radius, push, step = grasp.adversary
        values.update({"adversary.s": s3, "adversary.angle": angle, "adversary.radius": radius,
                       "adversary.push": push, "adversary.step": step})
    return values


def batched_simulate(op: Compliance, grasp: Grasp, cfg: Config) -> State:
    """:func:`simulate` with a batching rule: under ``vmap`` on the CPU the members run one
    after another (``lax.map``), each with its own number of steps, so a batch costs what a
    loop of single squeezes costs. (A batched ``lax.while_loop`` runs every member's event
    location at every step, and its small solves one lane at a time: 10–20× slower per grasp.)
    On an accelerator the batch is vmapped. When only forward-mode tangents are batched
    (``jax.jacfwd``) it is one squeeze, and a ``vmap`` of ``jacfwd`` runs its members one
    after another in the same way.

    Its derivative is its own rule (:func:`_jvp_of`): the ``jvp`` of :func:`simulate` in the
    inputs that carry a tangent (``custom_vmap``'s own rule would give every input a tangent
    of zeros, and derive the whole program once more before the batching rule replaces it),
    batched by the same rule. The rules see the arguments as a flat list of arrays:
    ``custom_vmap`` cannot take a pytree with an empty (None) node, such as a band's ``nu``
    or an absent placement."""
    leaves, tree = jax.tree.flatten((op, grasp))

    @jax.jit                  # traced once: the rules below reuse its trace (under precise's context)
    @compiler.precise
    def sim(*xs):
        return simulate(*jax.tree.unflatten(tree, xs), cfg)

    run = jax.custom_jvp(_one_at_a_time(sim))
    run.defjvp(_jvp_of(sim), symbolic_zeros=True)
    return run(*leaves)


def _one_at_a_time(fn, primals: int | None = None):
    """``fn`` (flat arrays → pytree) with the batching rule of :func:`batched_simulate`.
    ``primals``: for ``fn(*primals, *tangents)``, how many arguments are primals; a batch of
    tangents alone is then vmapped (one squeeze, its tangents batched)."""
    @custom_vmap
    def run(*xs):
        return fn(*xs)

    @run.def_vmap
    @compiler.precise         # (the context fn's trace is cached under: it is not traced again)
    def rule(axis_size, flags, *xs):
        every = lambda out, b: jax.tree.map(lambda _: b, out)  # noqa: E731
        if not any(flags):
            out = fn(*xs)
            return out, every(out, False)
        if primals is not None and not any(flags[:primals]):
            # one squeeze with its tangents batched; a batch of members around it (vmap of
            # jacfwd) comes back through this rule
            tangents = jax.vmap(fn, in_axes=[0 if f else None for f in flags], out_axes=(None, 0))
            out = _one_at_a_time(tangents)(*xs)
            return out, (every(out[0], False), every(out[1], True))
        if compiler.platform() != "cpu":
            full = [x if f else jnp.broadcast_to(x, (axis_size,) + jnp.shape(x)) for x, f in zip(xs, flags)]
            out = jax.vmap(fn)(*full)
            return out, every(out, True)

        def one(batched):
            it = iter(batched)
            return fn(*[next(it) if f else x for x, f in zip(xs, flags)])

        out = lax.map(one, [x for x, f in zip(xs, flags) if f])
        return out, every(out, True)

    return run


def _jvp_of(fn):
    """The ``custom_jvp`` rule (with symbolic zeros) of ``fn`` (flat arrays → pytree): the
    ``jvp`` in the arguments whose tangent is not a symbolic zero, batched by
    :func:`_one_at_a_time`; integer outputs get ``float0`` tangents (outside the batching
    rule: ``lax.map`` cannot carry ``float0``, so a placeholder passes through it)."""
    @compiler.precise         # (the context fn's trace is cached under: it is not traced again)
    def rule(primals, tangents):
        moving = [not isinstance(t, SymbolicZero) for t in tangents]
        n = len(primals)     # (jvp keeps no tracer of this trace: its batching rule outlives it)

        def jvp(*xs):
            ps, ts = xs[:n], xs[n:]

            def of_moving(*ys):
                it = iter(ys)
                return fn(*[next(it) if m else p for p, m in zip(ps, moving)])

            out, dout = jax.jvp(of_moving, tuple(p for p, m in zip(ps, moving) if m), ts)
            return out, jax.tree.map(lambda o, t: t if floating(o) else jnp.zeros((), jnp.int8), out, dout)

        out, dout = _one_at_a_time(jvp, n)(*primals, *(t for t, m in zip(tangents, moving) if m))
        return out, jax.tree.map(lambda o, t: t if floating(o) else np.zeros(jnp.shape(o), jax.dtypes.float0), out, dout)

    return rule


#: the contact and sliding slots an eager squeeze grew to, by object size, capacity settings
#: and the rest of its configuration
_GROWN: dict = {}


def eager_config(scene: Scene, op: Compliance, history: bool = True) -> Config:
    """The configuration an eager :func:`squeeze` of ``scene`` starts with: its automatic
    capacities, or what an earlier squeeze of the same object in this process grew them to."""
    cfg = config_of(scene, history, eager=True)
    slots = _GROWN.get(_grow_key(scene, op, cfg))
    return cfg if slots is None else dataclasses.replace(cfg, capacity=slots[0], sliding=slots[1])


def _grow_key(scene: Scene, op: Compliance, cfg: Config):
    s = scene.settings
    return op.G.shape, s.capacity, s.sliding_capacity, dataclasses.replace(cfg, capacity=0, sliding=0)


def _grown(scene: Scene, op: Compliance, cfg: Config, res: SqueezeResult) -> Config | None:
    """The configuration to squeeze again with after an eager squeeze ``res`` ran out of an
    automatic bound (:func:`_more_slots`, :func:`_longer`), or None."""
    status = int(res.status)
    if status == Status.OVERFLOW:
        return _more_slots(scene, op, cfg, res)
    if status in (Status.MAX_STEPS, Status.EVENT_OVERFLOW):
        return _longer(scene, cfg, status, float(res.final_depth))
    return None


def _more_slots(scene: Scene, op: Compliance, cfg: Config, res: SqueezeResult) -> Config | None:
    """``cfg`` with the automatic capacities that ran out grown to at least twice their size
    and to what ``res`` asked for (``res.stats.contacts`` / ``sliding``: the set that
    overflowed; contact slots up to the boundary node count and the memory limit, sliding
    slots up to the contact slots), or None when they are fixed by the settings or cannot
    grow. Both grow when neither count exceeds its slots."""
    s = scene.settings
    contacts, sliding = int(res.stats.contacts), int(res.stats.sliding)
    pow2 = lambda k: 1 << max(int(k) - 1, 1).bit_length()  # noqa: E731
    full_c = contacts > cfg.capacity
    full_s = 0 < cfg.sliding < sliding
    if not (full_c or full_s):
        full_c = full_s = True
    capacity = cfg.capacity
    if s.capacity is None and full_c:
        more = min(max(2 * capacity, pow2(contacts)), op.m)
        if not validate.scene_cost_problems(scene.replace(settings=dataclasses.replace(s, capacity=more))):
            capacity = more
    slide = cfg.sliding
    if s.sliding_capacity is None and 0 < slide < capacity and full_s:
        slide = min(max(2 * slide, pow2(sliding)), capacity)
    if (capacity, slide) == (cfg.capacity, cfg.sliding):
        return None
    return dataclasses.replace(cfg, capacity=capacity, sliding=slide)


def _longer(scene: Scene, cfg: Config, status: int, reached: float) -> Config | None:
    """``cfg`` with its automatic loop and event-log bounds (``Settings.max_steps`` /
    ``max_events`` of ``scene`` at None) ``LOG_GROWTH`` times longer (loop bound: enough for
    the target depth at the rows per metre of a squeeze that reached the depth ``reached``
    [m]) after a squeeze with ``cfg`` stopped with ``status`` MAX_STEPS or EVENT_OVERFLOW;
    None when the bound that ran out is set by the settings, or would pass ``LOG_GROWTH ** 2``
    times its start (a step far too small for the depth) or the memory limit. (Also the
    planner's rule: ``plan.search``.)"""
    s = scene.settings
    steps_out = int(status) == Status.MAX_STEPS
    if (s.max_steps if steps_out else s.max_events) is not None:
        return None
    grow = LOG_GROWTH
    if steps_out:
        need = (cfg.max_steps + 1) * float(scene.depth) / reached if reached > 0 else np.inf
        while cfg.max_steps * grow < need and grow <= LOG_GROWTH ** 2:
            grow *= LOG_GROWTH
    steps = cfg.max_steps * grow if s.max_steps is None else cfg.max_steps
    events = cfg.max_events * grow if s.max_events is None else cfg.max_events
    if max(steps / STEPS, events / EVENTS) > LOG_GROWTH ** 2:
        return None
    if validate.scene_cost_problems(scene.replace(settings=dataclasses.replace(
            s, capacity=cfg.capacity, max_steps=steps, max_events=events))):
        return None
    return dataclasses.replace(cfg, max_steps=steps, max_events=events)


REVERSE_MODE = (
    "jsq.squeeze is differentiable in forward mode only (jax.jvp, jax.jacfwd): it is a lax.while_loop over a "
    "data-dependent number of steps, which JAX cannot differentiate in reverse (jax.grad, jax.vjp, jax.jacrev, "
    "jax.linearize, jax.hessian). For the gradient of a number in a few inputs use jax.jacfwd (one forward pass "
    "per input), e.g. jax.jacfwd(loss)(params) in place of jax.grad(loss)(params).")


SECOND_ORDER = (
    "jsq.squeeze gives exact first derivatives only (jax.jvp, jax.jacfwd): the slip angles and the event "
    "depths carry their derivatives by one implicit-function step, exact to first order, so a second "
    "derivative by nested forward mode (jax.jacfwd of jax.jacfwd, a jvp inside a jvp) would be "
    "wrong (0.5 % on a sliding square). For a second derivative take central differences of jax.jacfwd, "
    "e.g. (g(p + h) - g(p - h)) / (2 * h) with g = jax.jacfwd(loss) and h ~ 1e-6 * p in float64.")


@jax.custom_jvp
def _no_second_order(xs):
    return xs


@_no_second_order.defjvp
def _(primals, tangents):
    raise TypeError(SECOND_ORDER)


@jax.custom_jvp
def _first_order_only(xs):
    """``xs`` (a tuple of arrays) unchanged. Its derivative passes the tangents on, but its
    primal output there is :func:`_no_second_order`, whose derivative raises: a second
    forward-mode level over the squeeze's inputs, also one staged through a user's ``jit``
    (where :func:`squeeze` sees no tracers of its own), is refused while it is traced.
    Symbolic zeros keep the inputs that carry no tangent out of the derivative program."""
    return xs


def _pass_tangents(primals, tangents):
    return _no_second_order(*primals), tangents[0]


_first_order_only.defjvp(_pass_tangents, symbolic_zeros=True)


@compiler.jit(static_argnames=("cfg",))
def _run(op: Compliance, grasp: Grasp, cfg: Config):
    """The compiled squeeze: (SqueezeResult in SI without the full field, scaled final forces, g)."""
    leaves, tree = jax.tree.flatten((op, grasp))
    real = [floating(x) for x in leaves]
    guarded = iter(_first_order_only(tuple(x for x, r in zip(leaves, real) if r)))
    op, grasp = jax.tree.unflatten(tree, [next(guarded) if r else x for x, r in zip(leaves, real)])
    st = batched_simulate(op, grasp, cfg)
    return to_result(st, op, grasp), st.F.reshape(-1), st.g


@own_transfers
def squeeze(scene: Scene, op: Compliance | None = None, *, throw: bool = False, trim: bool = True,
            history: bool = True) -> SqueezeResult:
    """Follow a two-finger squeeze from first touch to the target depth (Section IV).

    Args:
        scene: the :class:`Scene`.
        op: its compliance operator, if already built (``scene.operator()``); built (and
            cached per object) when omitted. A given operator fixes ν: for derivatives in ν
            omit it (the operator is then built inside the trace with the dense build).
        throw: raise ``RuntimeError`` with advice unless the squeeze reached its target
            depth (``result.raise_for_status()``); only for eager calls.
        trim: eager calls return the valid rows only, as numpy arrays (see
            :class:`SqueezeResult`); ``False`` keeps the fixed-capacity padding.
        history: record every row (default); ``False`` keeps two rows (the end of the
            squeeze and the last row), what qualities need: a batch of grasps then carries a
            few kilobytes per grasp instead of the whole history.

    Runs one compiled ``lax.while_loop``. With ``Settings.capacity`` and ``sliding_capacity``
    at ``None`` an eager squeeze starts with few contact and sliding slots and, if they run
    out, squeezes again with more (:class:`Settings`). A second call with new numbers (grip,
    friction, depth, radius, material, tolerances) reuses the compiled program. Works under ``jax.jit``,
    ``jax.vmap`` and forward-mode differentiation (``jax.jvp``/``jax.jacfwd``) over every
    number of the scene (E, ν, thickness, μ, radius, depth, rotation coefficients): exact
    first derivatives; nested forward mode (a second derivative) raises ``TypeError``.
    Eagerly, invalid input raises ``ValueError`` naming every bad field; under tracing it
    gives ``Status.INVALID_INPUT`` with ``result.invalid`` naming the field.
    """
    check_types(scene, op)
    throw, trim, history = flag(throw, "throw"), flag(trim, "trim"), flag(history, "history")
    if reverse_mode((scene, op)):
        raise TypeError(REVERSE_MODE)
    if forward_levels((scene, op)) > 1:      # (through a user's jit: _first_order_only, in _run)
        raise TypeError(SECOND_ORDER)
    concrete = is_concrete(scene) and not staged()       # (a concrete scene in a user's jit is traced there)
    if throw and not concrete:
        raise ValueError("throw=True raises on the status, which is traced under jax.jit, vmap and jacfwd: "
                         "leave it out there and read result.status (Status.SUCCESS is 0) or result.outcome "
                         "after the call")
    op, grasp = _prepare(scene, op, concrete)
    cfg = eager_config(scene, op, history) if concrete else config_of(scene, history)
    res, F_hat, g_hat = _run(dataclasses.replace(op, field=None), grasp, cfg)
    key = _grow_key(scene, op, cfg) if concrete else None
    while concrete and np.ndim(res.status) == 0:
        # an automatic bound ran out: squeeze again with more (a new program); more slots are
        # remembered for the next squeeze of this object in this process, a longer loop is not
        bigger = _grown(scene, op, cfg, res)
        if bigger is None:
            break
        if int(res.status) == Status.OVERFLOW:
            _GROWN[key] = (bigger.capacity, bigger.sliding)
        cfg = bigger
        res, F_hat, g_hat = _run(dataclasses.replace(op, field=None), grasp, cfg)
    if concrete and np.ndim(res.status) == 0:
        if trim:                            # numpy, as the trimmed result will be: the checks below read it there
            res = jax.tree.map(np.asarray, res)
        a, b = np.asarray(op.points)[boundary.positions(op.nodes, res.grip)] * float(op.length)
        between, depth = float(np.linalg.norm(a - b)), float(scene.depth)
        if scene.placement is not None and int(res.status) == Status.INVALID_INPUT:
            raise ValueError(f"depth = {depth:g} m: expected a depth smaller than the distance between the "
                             f"fingers' first contacts, {between:.4g} m for this placement; "
                             "squeeze less deep, or place the fingers farther apart.")
        # (the object-size one was said before the run; an infeasible grip squeezed nothing)
        if validate.deep_warning(float(op.length), depth) is None and int(res.status) != Status.INFEASIBLE_GRIP:
            deep = validate.deep_warning(None, depth, between)
            if deep:
                warnings.warn(deep, stacklevel=caller_level())
        inside = validate.inside_tip_warning(res, np.asarray(scene.mesh.points)[np.asarray(res.nodes)],
                                             SUNK_TOLS[op.G.dtype == np.float32] * float(grasp.gap_tol), scene.contact)
        if inside:
            warnings.warn(inside, stacklevel=caller_level())
        if isinstance(scene.mesh, Mesh) and scene.contact == "segment":
            coarse = validate.resolution_warning(res, np.asarray(scene.mesh.points)[np.asarray(res.nodes)],
                                                 scene.mesh.loops, float(scene.material.E),
                                                 float(scene.material.thickness))
            if coarse:
                warnings.warn(coarse, stacklevel=caller_level())
    if op.field is not None:
        if is_concrete((F_hat, g_hat)) and np.ndim(F_hat) == 1:    # one eager squeeze: solved and kept on the host
            u = field_on_host(op, F_hat, g_hat) * np.asarray(op.length, np.dtype(F_hat.dtype))
            u = u if trim else as_array(u)
        else:
            u = field_displacement(op, F_hat, g_hat) * op.length
        res = dataclasses.replace(res, displacement=u)
        if concrete and np.ndim(res.count) == 0 and isinstance(scene.mesh, Mesh):
            flipped = validate.inverted_warning(scene.mesh.points, scene.mesh.triangles, u, float(res.final_depth))
            if flipped:
                warnings.warn(flipped, stacklevel=caller_level())
    if trim and np.ndim(res.count) == 0 and is_concrete(res):   # eager, unbatched
        res = trim_result(res)
    if throw:
        res.raise_for_status()
    return res


def compile_ahead(scene: Scene, op: Compliance | None = None, history: bool = True) -> None:
    """Start compiling the program of an eager ``squeeze(scene, op=op, history=history)`` in a
    background thread (:meth:`jaxsqueeze.compiler.TopLevelJit.compile_ahead`), while the
    caller goes on: that squeeze (or one of another grip or placement of the same object and
    settings) then finds it compiled. A scene that the squeeze would reject starts nothing
    (the squeeze says why)."""
    history = flag(history, "history")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")         # (the squeeze says them)
            op, grasp = _prepare(scene, op, True)
    except (ValueError, TypeError):
        return
    _run.compile_ahead(dataclasses.replace(op, field=None), grasp, eager_config(scene, op, history))


def _prepare(scene: Scene, op: Compliance | None, concrete: bool):
    """(operator, grasp) of a squeeze of ``scene``; with ``concrete`` (an eager call) after
    every eager check, each raising ``ValueError`` that names the field (and warning of mixed
    units or a squeeze deeper than half the object: :func:`validate.unit_problems`)."""
    if concrete:
        bad = validate.shape_problems(scene) or validate.scene_cost_problems(scene)
        if bad:
            raise ValueError("\n".join(bad))
    if op is None:
        op = scene.operator()
    else:
        if is_concrete((scene.material.nu, op)):
            check_operator(scene, op)
        elif op.nu is not None and isinstance(scene.mesh, Mesh) and differentiated(scene.material.nu):
            raise TypeError("the scene's nu is differentiated (jax.jvp / jax.jacfwd), but the given op fixes nu "
                            f"(the operator of one nu, {op.nu}): its derivative would be zero. Omit op=: with nu "
                            "traced the operator is built inside the trace (dense build), nu's derivative included.")
        # E and the thickness are the scene's: they only scale the operator (and carry its derivatives)
        op = dataclasses.replace(op, stiffness=stiffness_of(scene.mesh, scene.material, op.G.dtype))
    if concrete:
        check_force_scale(op)
        _, said = validate.unit_problems(size=float(op.length), radius=float(scene.fingers.radius),
                                         depth=float(scene.depth), E=float(scene.material.E),
                                         thickness=float(scene.material.thickness))
        for line in said:                  # mixed units, a squeeze deeper than half the object
            warnings.warn(line, stacklevel=caller_level())
        if scene.placement is None:
            check_grip(scene, op)
    grasp = grasp_of(scene, op, validated=True) if concrete else _traced_grasp(scene, op)
    if concrete:
        values = validate_values(grasp, scene, op)
        validate.raise_if_invalid(values)
        if "grip.overlap" in values and scene.contact != "point":       # (point contacts join no node)
            said = validate.overlap_warning(values["grip.overlap"], float(grasp.gap_tol), float(scene.depth))
            if said:
                warnings.warn(said, stacklevel=caller_level())
    return op, grasp


def check_scene(scene: Scene, op: Compliance | None = None) -> Compliance:
    """Every check an eager :func:`squeeze` of ``scene`` makes before it runs, raising as that
    squeeze would; returns the operator (built when ``op`` is None). For code that squeezes
    the scene only under tracing (maps and searches), where a bad number would only be a
    status."""
    check_types(scene, op)
    return _prepare(scene, op, True)[0]


def check_types(scene, op) -> None:
    """Raise ``TypeError`` unless ``scene`` is a :class:`Scene` of the library's types and ``op``
    is None or a :class:`Compliance`."""
    from ..mechanics.band import Band
    from ..mechanics.material import Material
    from .scene import Adversary, Fingers, Placement, Settings
    if not isinstance(scene, Scene):
        raise TypeError(f"squeeze takes a jsq.Scene, got {type(scene).__name__}: build one with "
                        "jsq.Scene(mesh=..., material=jsq.Material(...), fingers=jsq.Fingers(...), grip=...)")
    for name, kinds in (("mesh", (Mesh, Band)), ("material", Material), ("fingers", Fingers), ("settings", Settings)):
        value = getattr(scene, name)
        if not isinstance(value, kinds):
            want = " or ".join(f"jsq.{k.__name__}" for k in (kinds if isinstance(kinds, tuple) else (kinds,)))
            raise TypeError(f"Scene.{name} must be a {want}, got {type(value).__name__} ({value!r:.60})")
    for name, kind in (("placement", Placement), ("adversary", Adversary)):
        value = getattr(scene, name)
        if value is not None and not isinstance(value, kind):
            raise TypeError(f"Scene.{name} must be a jsq.{kind.__name__} or None, got {type(value).__name__} "
                            f"({value!r:.60}): e.g. {name}=jsq.{kind.__name__}(s=...)")
    if scene.grip is not None and not is_concrete(scene.grip):     # traced: its dtype is all there is to check
        kinds = {jnp.result_type(g).kind for g in jax.tree.leaves(scene.grip)}
        if not kinds <= {"i", "u"}:
            raise TypeError(f"Scene.grip must be integer node indices, got a traced {sorted(kinds)} array: pass "
                            "int32 indices (for a continuous position use jsq.Placement)")
    if op is not None and not isinstance(op, Compliance):
        raise TypeError(f"op must be the scene's compliance operator (op = scene.operator()) or None, "
                        f"got {type(op).__name__} ({op!r:.60})")


def check_operator(scene: Scene, op: Compliance) -> None:
    """Raise ``ValueError`` unless ``op`` was built for the scene's object (its boundary nodes
    and their positions) and ν: a compliance operator fixes both (E and the thickness are
    taken from the scene)."""
    nodes = np.asarray(scene.boundary_nodes())
    fix = "build it from this scene (op = scene.operator()) or omit op"
    if op.m != len(nodes) or not np.array_equal(np.asarray(op.nodes), nodes):
        raise ValueError(f"op was built for another object: its {op.m} contact-capable nodes are not this scene's "
                         f"{len(nodes)} boundary nodes; {fix}.")
    pts = np.asarray(validate.boundary_points(scene.mesh), float)
    L = float(op.length)
    tol = 100 * float(np.finfo(op.G.dtype).eps) * L
    if not np.allclose(np.asarray(op.points, float) * L, pts, rtol=0.0, atol=tol):
        raise ValueError(f"op was built for another object: its node positions differ from this scene's mesh; {fix}.")
    if op.nu is not None and scene.mesh.__class__ is Mesh:
        nu, op_nu = float(scene.material.nu), float(op.nu)
        if abs(nu - op_nu) > 1e3 * float(np.finfo(op.G.dtype).eps):
            raise ValueError(f"op was built for nu = {op_nu:g}, but the scene's material has nu = {nu:g}; {fix} "
                             "(a given op fixes nu: E and the thickness are taken from the scene).")


def check_force_scale(op: Compliance) -> None:
    """Raise ``ValueError`` when forces of the scale E h L [N] would overflow the operator's
    precision (:func:`validate.force_limit`; traced, the ``material.E`` rule)."""
    dt = np.dtype(op.G.dtype)
    scale = float(np.asarray(op.stiffness, dt) * np.asarray(op.length, dt))
    if not scale < validate.force_limit(float(np.finfo(dt).eps)):
        raise ValueError(f"the force scale E * thickness * size = {scale:.3g} N is too large for {dt.name} (forces "
                         f"are squared in magnitudes, largest {float(np.finfo(dt).max):.3g}): check the units of E (Pa) "
                         "and the thickness (m)" + (", or compute in float64 (jax.config.update('jax_enable_x64', "
                                                    "True))." if dt.itemsize < 8 else "."))


def check_grip(scene: Scene, op: Compliance) -> None:
    """Raise ``ValueError`` if the segment between the initial contacts leaves either friction
    cone (Section I-A; the test is :func:`laws.grip_margin`, the one the engine runs)."""
    g = np.asarray(scene.grip)
    if g.ndim != 1:
        return
    k = boundary.positions(scene.boundary_nodes(), g)
    P = np.asarray(op.points, float)
    N = laws.cone_normals(P, np.asarray(op.normals, float), op.loops, scene.contact, xp=np)
    mu = float(scene.friction)
    if laws.grip_margin(P[k], -N[k], mu, scene.friction_model, xp=np) < 0:
        a, b = np.degrees(laws.grip_cone_angles(P[k], -N[k], xp=np))
        half = np.degrees(float(laws.grip_half_angle(mu, scene.friction_model, xp=np)))
        why, fix = ((f"frictionless fingertips sit on the segment, which may turn at most {half:.3f}° from the "
                     "normals", "") if scene.friction_model == "frictionless" else
                    (f"the friction cones only allow {half:.3f}° (mu={mu:.3g}, friction_model="
                     f"{scene.friction_model!r})", " or raise the friction"))
        raise ValueError(
            f"grip {tuple(int(v) for v in g)}: the segment between the two contacts makes {a:.3f}° and "
            f"{b:.3f}° with the inward normals, but {why}. Pick more nearly opposite nodes "
            f"(e.g. Scene.nearest_boundary_node){fix}.")
