"""The event-driven squeeze (Section IV; DESIGN 2.1, 2.4–2.7, 2.10).

One finger stays still, the other translates toward it by the depth d. Every boundary node is
free, sticking to a fingertip at a fixed anchor angle, or sliding on it. Each solve is the
*total* problem from the undeformed state for the current contact configuration
(:func:`~jaxsqueeze.simulation.contacts.solve`); only modes and anchors carry history.

The loop is a driver over named stages, each a pure function of the model and a typed state:

* :func:`init` — the first touch: the two grip nodes in contact, to be checked at d = 0;
* :func:`step` — one loop iteration: **one** configuration solve, with its rate in d by
  ``jax.jvp``, at the depth the current phase asks for, then that phase's update:

  - :func:`advance` (phase ADVANCE): the solve at d + h, or just past the earliest crossing
    that the accepted row's event functions and rates predict within the step
    (:func:`ahead`). If no event function changed sign, the row is accepted; otherwise the
    bracket [d, target] is opened, and when Newton from its crossed end is already converged
    (the prediction was good) :func:`apply_event` follows in the same iteration.
  - :func:`locate_event` (phase LOCATE): the solve at the next estimate of the earliest
    crossing (the root of the cubic through the event function's values and rates at the
    bracket's ends, safeguarded by Newton, the secant and bisection), until the bracket is
    ``event_tol`` wide or Newton from its crossed end is converged; then :func:`apply_event`.
  - :func:`apply_event`: the event depth refined by one implicit-function step (so it carries
    its derivative), every event flagged there applied (A new contact, B break, C stick→slip,
    D slip→stick), the contact slots updated and the events logged.
  - :func:`check` (phase CHECK): the solve with the new contact set at the event depth; new
    contacts are tested by hypothesis (stick first; one that pulls is dropped, one whose force
    leaves its cone slides), frictionless sets settled; then the row is accepted.

* :func:`finish` — records an accepted row and decides the status, the one place it is set.

A single solve site keeps the compiled program small; a loop iteration costs one solve.
Units inside are scaled (DESIGN 2.3): lengths / L, forces / (E h L).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jax.custom_derivatives import SymbolicZero

from .. import compiler
from ..mechanics.operator import Compliance
from . import contacts, laws
from .contacts import Nodes, Slots, Solution
from .laws import FREE, SLIP_NEG, SLIP_POS, STICK
from .model import Config, Grasp, Model, gap_to_fingers, make_model, push_model  # noqa: F401
from .status import Status

RUNNING = -1
ADVANCE, LOCATE, CHECK, PRIME = 0, 1, 2, 3
SETTLE_ITERS = 16  # CHECK passes that may change a contact set at one depth (a cascade: 26 events seen)
#: a contact pulling by more than this fraction of the largest contact force in a CHECK solve
#: lets go at that depth (float64, float32): below it the pull is round-off, or a B event of its
#: own within ``event_tol`` that the next bracket resolves
PEEL_SHARE = (1e-8, 1e-3)
#: predicted steps (:func:`ahead`) that may fall short in a row before a plain step (at
#: event_tol = 1e-9 step the foam square takes 184 solves with 2, 203 with 1, 192 with none)
PREDICTIONS = 2
#: short ADVANCE solves in a row (predictions included) after which a dip of an event function
#: below zero within a step (:func:`advance`) is no longer chased: a bound on the extra solves
DIP_TRIES = 4
#: frictionless rows are accepted while the drift rule's tangential forces, and any pull, stay
#: below this fraction of the row's largest contact force (docs/numerics.md §5.1); beyond it the
#: object would slide away along its drift and the squeeze stops with STALLED
DRIFT_SHARE = 1e-2
#: a free node this many gap tolerances inside a fingertip after an event joins there (event A):
#: (float64, float32). float32's gap_tol (1e-5 L) is 1e4 times float64's: from 10 of them a
#: node that a release sank by a few µm stayed free inside its tip, and its finger could be left
#: empty (docs/numerics.md §3)
SUNK_TOLS = (10, 2)
#: an event that undid itself within ``event_tol`` of the row the last event made, or a contact set
#: that did not settle at one depth (a node that peels off in cycles shorter than the
#: tolerance), is resolved again with the tolerance divided by REFINE[0], at most REFINE[1]
#: times in a squeeze (float64, friction), before the squeeze stops STALLED (:func:`check`)
REFINE = (10.0, 6)
#: an event is located to event_tol or to this share of its depth, the finer: a flat pad's
#: first touches and slides come at a few nm, below the default tolerance of a mm squeeze
#: (step * 1e-4), and located to it they came in the wrong order (docs/numerics.md §2, 31)
EVENT_REL = 1e-4


# ----------------------------------------------------------------------------- loop state
class Stats(NamedTuple):
    """What a user needs to trust or tune a run (all () arrays)."""

    steps: jax.Array           # squeeze steps taken (rows without an event)
    events: jax.Array          # event resolutions (rows with one or more events)
    newton_iters: jax.Array    # Newton iterations, summed over every solve
    newton_max: jax.Array      # largest Newton iteration count of one solve
    bracket_iters: jax.Array   # event-location solves, summed
    residual: jax.Array        # largest final Newton update [rad] of an accepted solve
    solves: jax.Array          # configuration solves (loop iterations), all phases
    refreshes: jax.Array       # recomputations of the kept bordered inverse (contacts.update)
    contacts: jax.Array        # most contact nodes at once, the set that overflowed its slots included
    sliding: jax.Array         # most sliding contact nodes at once (likewise)
    refined: jax.Array         # times event_tol was divided by REFINE[0] to resolve an event (check)


class Bracket(NamedTuple):
    """An event being located: the ends lo (no crossing) and hi (crossed) with the event
    functions and their rates there, and what :func:`apply_event` needs of the solve at hi.

    Event functions are measured from ``floor`` = min(0, e) at the accepted row: one that
    round-off (or a contact just made with a vanishing force) left slightly negative there has
    crossed only when it falls below that value."""

    floor: jax.Array    # (m,)
    lo: jax.Array
    hi: jax.Array
    e_lo: jax.Array     # (m,)
    de_lo: jax.Array
    e_hi: jax.Array
    de_hi: jax.Array
    kind: jax.Array     # (m,) event kinds at hi
    ft: jax.Array       # (m,) tangential forces at hi (the direction of a C event)
    th: jax.Array       # (S,) slot angles at hi and their rate
    dth: jax.Array
    x: jax.Array        # (m, 2) deformed boundary at hi and its rate
    dx: jax.Array
    fmax: jax.Array     # () the largest contact force at hi: the scale of a pull in the CHECK after it
    iters: jax.Array


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class State:
    """The squeeze loop's state (scaled units). Stages read a state and return a new one."""

    d: jax.Array            # depth (load parameter) of the last accepted row
    nodes: Nodes            # per-node mode, finger, anchor angle, armed (m,)
    slots: Slots            # the contact set and its factored bordered matrix
    angle: jax.Array        # (m,) polar angle of contact nodes at the accepted row, finger frame
    F: jax.Array            # (m, 2) accepted forces
    u: jax.Array            # (m, 2) accepted boundary displacements
    g: jax.Array            # (3,)
    e: jax.Array            # (m,) accepted event functions and their rates in d
    de: jax.Array
    phase: jax.Array        # ADVANCE, LOCATE, CHECK or PRIME
    bracket: Bracket
    d_star: jax.Array       # the depth CHECK solves at
    added: jax.Array        # (m,) int: the CHECK pass at d_star a contact joined at (0: the event), -1 none
    checks: jax.Array       # CHECK passes at d_star
    before: jax.Array       # (m,) modes before the event being resolved (stall test)
    status: jax.Array       # RUNNING or a Status, decided by finish() (reconcile() ends an overflow)
    fault: jax.Array        # RUNNING or a structural Status raised by a stage (overflow, stall, ...)
    n_ev: jax.Array
    events: tuple           # depth (E,), node (E,), kind (E,), finger (E,)
    hist: tuple             # depth (H,), mode, finger, theta (H, m), F, u (H, m, 2), centres (H, F, 2), alpha (H, F), g (H, 3), push (H,)
    count: jax.Array        # rows recorded
    stats: Stats
    squeeze_status: jax.Array   # the status the squeeze phase ended with
    squeeze_events: jax.Array   # events the squeeze phase logged (the push's follow)
    margin: jax.Array           # the grip's smooth feasibility margin [rad] (Model.margin)
    grip: jax.Array             # (2,) boundary positions of the first contacts
    invalid: jax.Array          # () first invalid input (Model.invalid: the grasp's, or a placed grip's depth)
    work: jax.Array             # (3,) push work: by the pusher, resisted by finger 0, finger 1
    ff: jax.Array               # (F, 2) finger totals of the last recorded row
    ff0: jax.Array              # (F, 2) finger totals when the push began
    missed: jax.Array           # () int: ADVANCE solves in a row at a predicted crossing that found none
    limit: jax.Array            # () the next ADVANCE solve goes no deeper (a dip seen in a step), else +inf
    d_ev: jax.Array             # () depth of the last row an event made (accepted in CHECK)
    g_before: jax.Array         # (3,) g of the row recorded before the last (``Config.history`` off: :func:`let_go`)


def _with(st: State, **kw) -> State:
    return dataclasses.replace(st, **kw)


def _solve(model: Model, st: State, d):
    """The one configuration solve of a loop iteration, and its rate in d (``jax.jvp``)."""
    return jax.jvp(lambda dd: contacts.solve(model, st.slots, st.nodes, dd), (d,), (jnp.ones_like(d),))


def _finger_totals(model: Model, F, mode, finger):
    """(F, 2) total force of every finger on the object."""
    on = mode > FREE
    return jnp.stack([jnp.sum(jnp.where((on & (finger == k))[:, None], F, 0.0), 0) for k in range(model.cfg.fingers)])


# ----------------------------------------------------------------------------- init
def init(model: Model) -> State:
    """The first touch (d = 0): the grip nodes in contact (stick first, or sliding when
    frictionless), phase CHECK at d = 0, so the first loop iteration solves the touch, tests
    the grip contacts by hypothesis and records row 0. The grip's cone test (Section I-A) and
    the input checks become structural faults reported by that row."""
    op, cfg = model.op, model.cfg
    dt = op.G.dtype
    m, S = op.m, cfg.capacity
    i, j = model.grip[0], model.grip[1]
    P = op.points
    C0 = model.centres(jnp.zeros((), dt))
    a0 = model.angles(jnp.zeros((), dt))
    first = STICK if cfg.friction_model != "frictionless" else SLIP_POS
    mode = jnp.zeros(m, jnp.int32).at[i].set(first).at[j].set(first)
    finger = jnp.zeros(m, jnp.int32).at[j].set(1)
    ang = lambda k, f: jnp.arctan2(*(P[k] - C0[f])[::-1]) - a0[f]  # noqa: E731
    theta = jnp.zeros(m, dt).at[i].set(ang(i, 0)).at[j].set(ang(j, 1))
    added = jnp.full(m, -1, jnp.int32).at[i].set(0).at[j].set(0)
    nodes = Nodes(mode, finger, theta, jnp.zeros(m, bool))

    E, H, F = cfg.max_events, cfg.rows, cfg.fingers
    z = jnp.zeros
    i32 = lambda v: jnp.array(v, jnp.int32)  # noqa: E731
    zero = z((), dt)
    zm, zm2 = z(m, dt), z((m, 2), dt)
    bracket = Bracket(zm, zero, zero, zm, zm, zm, zm, z(m, jnp.int32), zm, z(S, dt), z(S, dt), zm2, zm2, zero, i32(0))
    fault = jnp.where(model.invalid >= 0, Status.INVALID_INPUT, jnp.where(model.margin < 0, Status.INFEASIBLE_GRIP, RUNNING))
    return State(
        d=zero, nodes=nodes, slots=contacts.pair(op, S, i, j), angle=theta, F=zm2, u=zm2, g=z(3, dt), e=zm, de=zm,
        phase=i32(CHECK), bracket=bracket, d_star=zero, added=added, checks=i32(0), before=z(m, jnp.int32),
        status=i32(RUNNING), fault=jnp.asarray(fault, jnp.int32), n_ev=i32(0),
        events=(z(E, dt), z(E, jnp.int32), z(E, jnp.int32), z(E, jnp.int32)),
        hist=(z(H, dt), z((H, m), jnp.int8), z((H, m), jnp.int8), z((H, m), dt), z((H, m, 2), dt),
              z((H, m, 2), dt), z((H, F, 2), dt), z((H, F), dt), z((H, 3), dt), z(H, dt)),
        count=i32(0), stats=Stats(*(i32(0),) * 5, zero, *(i32(0),) * 5), squeeze_status=i32(RUNNING),
        squeeze_events=i32(0),
        margin=model.margin, grip=model.grip, invalid=model.invalid, work=z(3, dt), ff=z((F, 2), dt), ff0=z((F, 2), dt),
        missed=jnp.array(0, jnp.int32), limit=jnp.array(jnp.inf, dt), d_ev=zero, g_before=z(3, dt))


# ----------------------------------------------------------------------------- one iteration
def target(model: Model, st: State):
    """The depth the current phase solves at."""
    return lax.switch(st.phase, [lambda: ahead(model, st),
                                 lambda: estimate(model, st.bracket),
                                 lambda: st.d_star,
                                 lambda: st.d])


def ahead(model: Model, st: State):
    """The depth of the next ADVANCE solve: d + h (at most the target depth D), or, when the
    accepted row's event functions and their rates put the earliest crossing within that step
    (linear extrapolation), a quarter of ``event_tol`` past it. A solve there usually lands
    within the tolerance past the event, so the bracket it opens is closed at once
    (:func:`_converged`) and the event costs no LOCATE solve (the foam square: 149 solves
    instead of 186, the same rows and events). A prediction that falls short is accepted as a
    row like any other step, and the next prediction starts closer (its error is quadratic in
    the distance); after ``PREDICTIONS`` short ones in a row the step is a plain one, so that a
    function that bends away from zero (a node grazing a fingertip) cannot shorten the steps
    again and again. A dip that :func:`advance` saw in the last step caps the depth."""
    plain = jnp.minimum(jnp.minimum(st.d + model.h, model.D), st.limit)
    e = st.e - jnp.minimum(st.e, 0.0)          # functions already below zero are floored (advance)
    fall = (e > 0) & (st.de < 0)
    cross = jnp.min(jnp.where(fall, st.d - e / jnp.where(fall, st.de, -1.0), jnp.inf)) + 0.25 * model.ev_tol
    return jnp.where((cross < plain) & (st.missed < PREDICTIONS), cross, plain)


def step(model: Model, st: State) -> State:
    """One loop iteration: one solve at :func:`target`, then the phase's update, which may
    accept the solve as the next row."""
    dt = model.ev_tol.dtype
    model = dataclasses.replace(model, ev_tol=model.ev_tol / jnp.asarray(REFINE[0], dt) ** st.stats.refined.astype(dt))
    # (LOCATE only: the check after an event keeps event_tol, whose probe of a new contact's
    # pull must stay above the round-off of forces near d = 0, where a grip node's force of
    # ~1e-16 judged 2e-13 past the touch read as a pull and both grip nodes let go)
    model = _near(model, st.bracket.hi, st.phase == LOCATE)
    with jax.named_scope("target"):      # (the scopes name the parts in profiles: profile_row.py)
        d = target(model, st)
    with jax.named_scope("solve"):
        sol, dsol = _solve(model, st, d)
    st = _with(st, stats=st.stats._replace(solves=st.stats.solves + 1))
    with jax.named_scope("phase"):
        # ADVANCE and LOCATE share one branch (one apply_event in the program)
        st, take = lax.switch(jnp.maximum(st.phase - 1, 0), [bracket, check, prime], model, st, sol, dsol, d)
    with jax.named_scope("accept"):
        st = lax.cond(take, lambda: _accept(model, st, sol, dsol, d), lambda: st)
    with jax.named_scope("reconcile"):
        return reconcile(model, st)


def _near(model: Model, hi, where=True) -> Model:
    """The model with ``event_tol`` at most ``EVENT_REL`` of the depth hi of the event being
    located (not below round-off), where ``where``."""
    rel = jnp.maximum(EVENT_REL * hi, 1e3 * jnp.finfo(hi.dtype).eps * model.h)
    return dataclasses.replace(model, ev_tol=jnp.where(where, jnp.minimum(model.ev_tol, rel), model.ev_tol))


def reconcile(model: Model, st: State) -> State:
    """Bring the contact slots to the contact set of the per-node modes (the one place where
    slots change: stages change modes; the slots follow, one bordering update per node)."""
    cfg = model.cfg
    was = st.slots.slot < cfg.capacity
    slots, over, fresh = contacts.update(model.op, st.slots, was, st.nodes.mode > FREE)
    if cfg.sliding_limited:
        over = over | (jnp.sum(st.nodes.mode >= SLIP_POS) > cfg.sliding)
    fault = jnp.where(over & (st.fault == RUNNING), Status.OVERFLOW, st.fault).astype(jnp.int32)
    s = st.stats
    stats = s._replace(refreshes=s.refreshes + fresh.astype(jnp.int32),
                       contacts=jnp.maximum(s.contacts, jnp.sum(st.nodes.mode > FREE, dtype=jnp.int32)),
                       sliding=jnp.maximum(s.sliding, jnp.sum(st.nodes.mode >= SLIP_POS, dtype=jnp.int32)))
    # the slots cannot hold the new contact set (apply_event or this update found more contacts
    # or sliding contacts than slots), so no solve of it is right: a running squeeze ends here,
    # and its last row stays the last one solved with every contact in its slot
    status = jnp.where((fault == Status.OVERFLOW) & (st.status == RUNNING), fault, st.status).astype(jnp.int32)
    return _with(st, slots=slots, fault=fault, stats=stats, status=status)


def largest(F):
    """() the largest magnitude among forces F (..., 2): the scale of the shares above, the
    same however the object is turned in the plane (a largest *component* is not). A threshold,
    so no tangent (nor sqrt's infinite one at zero)."""
    F = lax.stop_gradient(F)
    return jnp.sqrt(jnp.max(jnp.sum(F * F, axis=-1)))


def _accept(model: Model, st: State, sol: Solution, dsol: Solution, d) -> State:
    """Adopt a solved configuration at depth d as the next row (slip angles move, anchors stay),
    and record it (:func:`finish`)."""
    # a grip that cannot start (invalid input, infeasible grip) records its touch unloaded: the
    # solve of a placed finger that touches nothing means nothing, and may not even be finite
    start = (st.fault != Status.INVALID_INPUT) & (st.fault != Status.INFEASIBLE_GRIP)
    d = jnp.where(start & (d >= model.D * (1 - 1e-12)), model.D, d)   # an event located at the target ends there
    angle = st.slots.spread()(sol.th, st.nodes.theta)
    armed = _arm(st.nodes.armed, sol)
    s = st.stats
    stats = s._replace(newton_iters=s.newton_iters + sol.iters, newton_max=jnp.maximum(s.newton_max, sol.iters),
                       residual=jnp.maximum(s.residual, jnp.where(sol.iters > 0, sol.resid, 0.0)))
    fault = st.fault
    if model.cfg.friction_model == "frictionless":
        # forces at the touch (d = 0) are round-off, and their shares mean nothing; past it they
        # carry a relative error of about eps / d (scaled units). A floor on the force instead
        # (100 eps in E h L units) hid the drift of stiff thin bands in float32, whose scaled
        # forces lie below it at any depth (a heart band: SUCCESS at 49 times the force)
        on = (st.nodes.mode > FREE) & (d > 1e3 * jnp.finfo(sol.F.dtype).eps)
        big = DRIFT_SHARE * largest(sol.F)
        # a contact made at this event's depth carries the event location's error there (a
        # broad tip's neighbours joined at 6.8e-5 m pulling 1 % of the grip node's small force);
        # the hypothesis judged it by its rate, and the next row by its force
        new = (st.added >= 0) & (st.phase == CHECK)
        off = jnp.any(on & ((jnp.abs(sol.ft) > big) | ((sol.fn < -big) & ~new)))
        fault = jnp.where(off & (fault == RUNNING), Status.STALLED, fault).astype(jnp.int32)
    F, u, g = (jnp.where(start, a, 0.0) for a in (sol.F, sol.u, sol.g))
    st = _with(st, d=d, nodes=st.nodes._replace(theta=angle, armed=armed), angle=angle, F=F, u=u,
               g=g, e=sol.e, de=dsol.e, stats=stats, phase=jnp.array(ADVANCE, jnp.int32), fault=fault,
               d_ev=jnp.where(st.phase == CHECK, d, st.d_ev))
    return finish(model, st, sol.ok)


def _arm(armed, sol: Solution):
    """Event D fires when the slip rate *crosses* zero. A node whose slip starts with an
    inconsistent rate (a jam: neither sticking nor sliding is consistent there) keeps
    sliding with its force on the cone edge until its rate has been consistent once at an
    accepted row (a contact set that holds: not the trial sets a CHECK pass rejects). This
    keeps every force admissible and rules out C/D chatter at one depth."""
    return armed | (sol.rate > 0)


def bracket(model: Model, st: State, sol: Solution, dsol: Solution, d):
    """Phases ADVANCE and LOCATE, one branch of the phase switch so that the program holds one
    :func:`apply_event`: the phase's update (:func:`advance` or :func:`locate_event`), then
    :func:`apply_event` once the bracket is closed: ``event_tol`` wide, or Newton from its
    crossed end converged (:func:`_converged`; a bracket that ADVANCE just opened at a
    predicted crossing often is), or after ``bisect_iters`` solves. Returns (state, accept)."""
    was = st.phase
    stepped, take = advance(model, st, sol, dsol, d)
    located = locate_event(model, st, sol, dsol, d)
    st = jax.tree.map(lambda a, c: jnp.where(was == ADVANCE, a, c), stepped, located)
    b = st.bracket
    model = _near(model, b.hi)               # (a bracket ADVANCE just opened: its tolerance too)
    closed = (st.phase == LOCATE) & ((b.hi - b.lo <= model.ev_tol) | (b.iters >= model.cfg.bisect_iters)
                                     | _converged(model, b))
    return lax.cond(closed, lambda: apply_event(model, st), lambda: st), take & (was == ADVANCE)


def advance(model: Model, st: State, sol: Solution, dsol: Solution, d1):
    """Phase ADVANCE: accept the solve at the depth :func:`ahead` chose, or open the bracket of
    the earliest event. But where an event function is above zero at both ends of the step and
    its cubic Hermite interpolant dips below zero between them (:func:`_dip`: a crossing and
    its return within one step, e.g. a cone margin that turns back, which the ends alone do
    not show, nor a bracket opened by another node's crossing at the end), solve again at the
    deepest point of the dip first, up to ``DIP_TRIES`` short solves in a row (predictions that
    fell short count: a function that curves back is what makes them fall short).
    Returns (state, accept)."""
    floor = jnp.minimum(st.e, 0.0)
    crossed = jnp.any(sol.e < floor)
    b = Bracket(floor, st.d, d1, st.e - floor, st.de, sol.e - floor, dsol.e, sol.kind, sol.ft, sol.th, dsol.th,
                model.op.points + sol.u, dsol.u, largest(sol.F), jnp.array(0, jnp.int32))
    s = st.stats
    inf = jnp.full_like(st.d, jnp.inf)
    opened = _with(st, bracket=b, phase=jnp.array(LOCATE, jnp.int32), stats=s._replace(events=s.events + 1),
                   missed=jnp.array(0, jnp.int32), limit=inf)
    dip, deepest = _dip(b, model.ev_tol)
    again = jnp.any(dip) & (st.missed < DIP_TRIES)
    retried = _with(st, limit=jnp.min(jnp.where(dip, deepest, jnp.inf)), missed=st.missed + 1)
    short = d1 < jnp.minimum(st.d + model.h, model.D)         # a predicted crossing that was not there
    stepped = _with(st, stats=s._replace(steps=s.steps + 1), missed=jnp.where(short, st.missed + 1, 0).astype(jnp.int32),
                    limit=inf)
    pick = lambda a, c, r: jnp.where(again, r, jnp.where(crossed, a, c))  # noqa: E731
    return jax.tree.map(pick, opened, stepped, retried), ~crossed & ~again


def _dip(b: Bracket, tol):
    """((m,) bool, (m,) depth): whether each event function, above zero at both ends of the
    step [lo, hi] and falling at lo, rising at hi, has a cubic Hermite interpolant (values and
    rates at both ends) that falls below zero inside, more than ``tol`` from either end, and
    the depth of its minimum."""
    w = b.hi - b.lo
    a0, a1, b0, b1 = b.e_lo, w * b.de_lo, b.e_hi, w * b.de_hi
    ok = (a0 > 0) & (b0 > 0) & (a1 < 0) & (b1 > 0) & jnp.isfinite(a0 + a1 + b0 + b1)
    B = 3 * (b0 - a0) - 2 * a1 - b1              # p(t) = a0 + a1 t + B t^2 + A t^3 on t in [0, 1]
    A = 2 * (a0 - b0) + a1 + b1
    # p'(0) = a1 < 0 < b1 = p'(1): one minimum inside, the root of p' where it rises, written
    # without cancellation (B + S > 0 there)
    S = jnp.sqrt(jnp.maximum(B * B - 3 * A * a1, 0.0))
    t = jnp.clip(-a1 / jnp.where(ok, B + S, 1.0), 0.0, 1.0)
    p = a0 + t * (a1 + t * (B + t * A))
    inside = (t * w > tol) & ((1 - t) * w > tol)
    return ok & (p < 0) & inside, b.lo + t * w


def prime(model: Model, st: State, sol: Solution, dsol: Solution, d):
    """Phase PRIME (the start of a push): take the event functions at the current depth from a
    solve of the new phase's model, record nothing."""
    return _with(st, e=sol.e, de=dsol.e, phase=jnp.array(ADVANCE, jnp.int32)), jnp.array(False)


# ----------------------------------------------------------------------------- event location
def estimate(model: Model, b: Bracket):
    """The next depth to solve at while locating the earliest crossing in [lo, hi].

    For every node whose event function crossed by hi: the root of its cubic Hermite
    interpolant on [lo, hi] (values and rates at both ends, :func:`_hermite_root`); where that
    fails, a Newton step from hi with its rate there (from lo when that one lands inside the
    bracket instead), else the secant; the earliest candidate is taken. The solve goes a
    quarter tolerance past it, so that it lands on the crossed side and the bracket can close
    from there (:func:`_converged`); within two quarters of hi it goes a quarter before, to
    close the bracket from the other side. Every fourth iteration bisects.
    """
    lo, hi, tol = b.lo, b.hi, model.ev_tol
    w = hi - lo
    flag = b.e_hi < 0
    inside = lambda t: (t > lo) & (t < hi)  # noqa: E731
    n_hi = _newton_from_hi(b)
    n_lo = lo - b.e_lo / jnp.where(b.de_lo < 0, b.de_lo, -1.0)
    span = b.e_lo - b.e_hi
    sec = lo + w * b.e_lo / jnp.where(span > 0, span, 1.0)
    cand = jnp.where(inside(n_hi), n_hi,
                     jnp.where((b.de_lo < 0) & (b.e_lo > 0) & inside(n_lo), n_lo, sec))
    herm = _hermite_root(b)
    cand = jnp.where(inside(herm), herm, cand)
    est = jnp.min(jnp.where(flag, cand, jnp.inf))
    est = jnp.where(jnp.isfinite(est), est, lo + 0.5 * w)
    q = 0.25 * tol
    est = jnp.where(hi - est < 2 * q, est - q, est + q)
    est = jnp.where(b.iters % 4 == 3, lo + 0.5 * w, est)
    eps = 1e-3 * q
    return jnp.clip(est, lo + eps, hi - eps)


def _newton_from_hi(b: Bracket):
    """(m,) Newton's estimate of each event function's crossing from hi (−inf where its rate
    there does not fall)."""
    return jnp.where(b.de_hi < 0, b.hi - b.e_hi / jnp.where(b.de_hi < 0, b.de_hi, -1.0), -jnp.inf)


def _converged(model: Model, b: Bracket):
    """Every event function crossed at hi has a falling rate there and Newton puts its crossing
    within ``event_tol`` below hi: the event depth is then known to the tolerance from hi alone
    (the step of :func:`apply_event`; its error is O(δ²) for hi a distance δ ≤ ``event_tol``
    past the root), so no solve on the other side is needed to close the bracket."""
    flag = b.e_hi < 0
    return jnp.any(flag) & jnp.all(~flag | (_newton_from_hi(b) >= jnp.maximum(b.hi - model.ev_tol, b.lo)))


def _hermite_root(b: Bracket, iters: int = 4):
    """(m,) the crossing of each event function's cubic Hermite interpolant on [lo, hi] (its
    values and rates at both ends): Newton on the cubic from the secant; NaN where that leaves
    the bracket or the data are not a fall through zero (e_lo > 0 > e_hi)."""
    w = b.hi - b.lo
    a0, a1, b0, b1 = b.e_lo, w * b.de_lo, b.e_hi, w * b.de_hi
    span = a0 - b0
    t = jnp.clip(a0 / jnp.where(span > 0, span, 1.0), 0.0, 1.0)
    # the cubic a0 h00 + a1 h10 + b0 h01 + b1 h11 in powers of t, evaluated by Horner's rule.
    # Each step uses t six times: the Hermite basis written out used it ~37 times, and the
    # 37**4 use-def paths of the four unrolled steps made LLVM's CRC-loop recogniser
    # (LoopIdiomRecognize, on the min over the m nodes in estimate when m is a multiple of 8
    # up to 256) take seconds: the squeeze compiled 2.5 times slower (benchmarks/README.md)
    c3 = 2 * span + a1 + b1
    c2 = -3 * span - 2 * a1 - b1
    for _ in range(iters):
        p = ((c3 * t + c2) * t + a1) * t + a0
        dp = (3 * c3 * t + 2 * c2) * t + a1
        t = t - p / jnp.where(dp < 0, dp, -1.0)
    ok = (a0 > 0) & (b0 < 0) & (t > 0) & (t < 1)
    return jnp.where(ok, b.lo + t * w, jnp.nan)


def locate_event(model: Model, st: State, sol: Solution, dsol: Solution, dm) -> State:
    """Phase LOCATE: shrink the bracket with the solve at ``dm`` (:func:`bracket` then decides
    whether it is closed). A solve that does not cross moves lo up, which cannot make Newton
    from the unchanged hi converged; so the closing test needs no record of which end moved."""
    b = st.bracket
    e = sol.e - b.floor
    hit = jnp.any(e < 0)
    sel = lambda new, old: jax.tree.map(lambda a, c: jnp.where(hit, a, c), new, old)  # noqa: E731
    hi_part = sel((dm, e, dsol.e, sol.kind, sol.ft, sol.th, dsol.th, model.op.points + sol.u, dsol.u, largest(sol.F)),
                  (b.hi, b.e_hi, b.de_hi, b.kind, b.ft, b.th, b.dth, b.x, b.dx, b.fmax))
    lo_part = jax.tree.map(lambda a, c: jnp.where(hit, c, a), (dm, e, dsol.e), (b.lo, b.e_lo, b.de_lo))
    b = Bracket(b.floor, lo_part[0], hi_part[0], lo_part[1], lo_part[2], *hi_part[1:], b.iters + 1)
    return _with(st, bracket=b, stats=st.stats._replace(bracket_iters=st.stats.bracket_iters + 1))


# ----------------------------------------------------------------------------- event application
def _attach(model: Model, x, d):
    """(finger (m,), polar angle (m,)) where each point of x (m, 2) would attach at depth d:
    its nearest fingertip and its angle there (finger frame)."""
    C = model.centres(d)
    near = jnp.argmin(gap_to_fingers(model, x, d), axis=1)
    ang = jnp.arctan2(*(x - C[near]).T[::-1]) - model.angles(d)[near]
    return near.astype(jnp.int32), ang


def apply_event(model: Model, st: State) -> State:
    """Refine the event depth by one implicit-function step from hi (so d* carries dd*/dp),
    bring the state to d* (slip angles extrapolated from hi with their rate), apply every event
    flagged at hi, log the events and go to CHECK at d* (:func:`reconcile` then updates the
    contact slots)."""
    b = st.bracket
    flag = b.e_hi < 0
    est = jnp.where(flag & (b.de_hi < 0), _newton_from_hi(b), b.hi)
    d_star = jnp.clip(jnp.min(jnp.where(flag, est, jnp.inf)), b.lo, b.hi)
    # a free node flagged at hi whose own touch lies past d* by more than gap_tol (as a depth;
    # round-off at least) joins later: the next step locates it, a quarter event_tol past its
    # predicted touch (ahead). Joined at d*, a touch up to event_tol later pulled, and the
    # stick-slip hypothesis misread it (a flat pad, whose neighbours touch ~5e-9 L apart and
    # close in slowly, ended SLIP_FAILURE at once: docs/numerics.md §2, 31). Other kinds apply
    # at d* as located, to event_tol: a force that falls slowly crosses zero at a depth that
    # round-off moves by more than gap_tol (a mirror pair's two releases)
    tie = jnp.maximum(model.gap_tol, 1e3 * jnp.finfo(d_star.dtype).eps * jnp.maximum(jnp.abs(d_star), model.h))
    flag = flag & ((st.nodes.mode != FREE) | (b.de_hi >= 0) | (est <= d_star + tie))
    t = d_star - b.hi
    th = b.th + t * b.dth
    x = b.x + t * b.dx
    ns = st.nodes
    theta = st.slots.spread()(th, ns.theta)
    kinds = jnp.where(ns.mode == FREE, 0, b.kind)
    near, ang = _attach(model, x, d_star)
    added = flag & (kinds == 0)
    first = STICK if model.cfg.friction_model != "frictionless" else SLIP_POS
    mode = jnp.where(added, first, ns.mode)                                   # A: attach where it touches
    finger = jnp.where(added, near, ns.finger)
    theta = jnp.where(added, ang, theta)
    mode = jnp.where(flag & (kinds == 1), FREE, mode)                          # B: release
    mode = jnp.where(flag & (kinds == 2), jnp.where(b.ft < 0, SLIP_POS, SLIP_NEG), mode)   # C: slide against ft
    mode = jnp.where(flag & (kinds == 3), STICK, mode)                         # D: stick where it is
    mode = mode.astype(jnp.int32)
    overflow = jnp.sum(mode > FREE) > model.cfg.capacity
    events, n_ev, fault = _log(model, st, flag, kinds, finger, d_star)
    changed = mode != ns.mode
    nodes = Nodes(mode, finger.astype(jnp.int32), theta, ns.armed & ~changed)
    fault = jnp.where(overflow, Status.OVERFLOW, fault)
    return _with(st, nodes=nodes, events=events, n_ev=n_ev, phase=jnp.array(CHECK, jnp.int32),
                 d_star=d_star, added=jnp.where(added & (mode > FREE), 0, -1).astype(jnp.int32),
                 checks=jnp.array(0, jnp.int32), before=ns.mode,
                 fault=fault.astype(jnp.int32))


def _log(model: Model, st: State, flag, kinds, finger, d):
    """The event log with the events of the nodes ``flag`` (m,) appended (kinds and fingers
    (m,), all at depth d), their count, and the fault (EVENT_OVERFLOW past ``max_events``)."""
    # a gather, not a scatter: log entry n_ev + k takes the (k+1)-th flagged node (XLA:CPU runs
    # a scatter as a loop, one dispatch per node, once copy insertion puts copies in it)
    E = model.cfg.max_events
    count = jnp.cumsum(flag.astype(jnp.int32))              # (m,) flagged nodes up to each node
    k = jnp.arange(E, dtype=jnp.int32) - st.n_ev             # (E,) rank of an entry among the new ones
    new = (k >= 0) & (k < count[-1])
    src = jnp.searchsorted(count, k + 1).clip(0, flag.shape[0] - 1)
    ev_d, ev_n, ev_k, ev_f = st.events
    events = (jnp.where(new, d, ev_d), jnp.where(new, model.op.nodes.astype(jnp.int32)[src], ev_n),
              jnp.where(new, kinds.astype(jnp.int32)[src], ev_k), jnp.where(new, finger.astype(jnp.int32)[src], ev_f))
    n_ev = st.n_ev + jnp.sum(flag, dtype=jnp.int32)
    return events, n_ev, jnp.where(n_ev > E, Status.EVENT_OVERFLOW, st.fault).astype(jnp.int32)


def _reversed(model: Model, st: State, sol: Solution, mode):
    """(m,) the armed sliding contacts whose slip rate is inconsistent in ``sol``, a solve at an
    event depth: an event keeps every force (a contact starts and ends unloaded) but changes
    the other contacts' rates, so these stick there (event D; ADVANCE sees only rates that
    change sign within a step). None when a finger's contacts all slide in ``mode``: the
    squeeze fails at this row, and a stick would only start C/D chatter at one depth."""
    ns = st.nodes
    n_on, n_slid = _per_finger(model, mode, ns.finger)
    return (ns.mode >= SLIP_POS) & ns.armed & (sol.rate < 0) & ~jnp.any(n_slid == n_on)


def _hypothesis(model: Model, st: State, sol: Solution, dsol: Solution):
    """The contact set just past d*, judged from the solve at d* and its rate (the probe
    d* + η to first order; a new contact's pull at d* + min(event_tol, η)). Returns (mode,
    finger, theta, changed, unsettled, logged, kinds): ``logged`` (m,) the nodes whose change
    is an event of the log, of kinds ``kinds`` (m,).

    Coulomb and full stick: on the first pass a new contact that would pull at the probe (in
    float32: whose force's rate is not positive, as its value is round-off) is dropped, a B
    event, under full stick, and under Coulomb a grip node at the touch; under Coulomb, any
    other whose force (in float32: its rate) leaves its cone (a pull included) slides against
    its tangential force, a C event at the depth it joined (a grip node at d = 0); on the next
    pass, one that still pulls with a force not rising takes the other edge (unlogged). On every pass
    an older contact that pulls at d* (by more than ``PEEL_SHARE`` of the largest force: a
    release that loaded a neighbour into tension, a finger peeling off) lets go there too, a B
    event (``peeled``), for at most ``SETTLE_ITERS`` passes and while both fingers hold a
    contact (a finger left empty ends the squeeze, LOST_CONTACT, at that row) and neither
    slides whole (that set ends it, SLIP_FAILURE, pulls and all: no sunk node joins it
    either); a contact made at d* whose force is rising, by a pull its rate makes up within
    ``event_tol``, is joining (d* lies before its touch by up to ``event_tol``), not peeling.
    With segment contacts, a free node found inside a fingertip (a release that dropped a shear
    force) joins there, an A event tested as a new contact on the next pass (by its force at
    d*), for at most ``SETTLE_ITERS`` passes (more after a refinement, :func:`check`). A node
    still inside, or a contact still peeling, after them is ``unsettled``: the check resolves
    the set again with a finer ``event_tol`` or stops the squeeze with STALLED. Under Coulomb,
    once the new contacts hold, an older stick contact whose force lies outside its cone at d*,
    and still at the probe, by more than ``PEEL_SHARE`` of the largest force (the push of a
    contact that joined ``gap_tol`` inside its tip) slides there, a C event, the farthest out,
    one per pass; then
    the armed sliding contact whose slip rate is most reversed at d* sticks there, a D event
    (:func:`_reversed`), one per pass.
    Frictionless (every pass): free nodes that would penetrate join where they are, else the
    most-pulling contact leaves, until the set is consistent or ``SETTLE_ITERS`` passes.
    """
    ns = st.nodes
    eta = model.eta
    fn = sol.fn + eta * dsol.fn
    ft = sol.ft + eta * dsol.ft
    if model.cfg.friction_model == "frictionless":
        inside = (ns.mode == FREE) & (sol.gap + eta * dsol.gap < -model.gap_tol)
        pull = jnp.where(ns.mode > FREE, jnp.where(st.added >= 0, dsol.fn, fn), jnp.inf)
        worst = jnp.argmin(pull)
        drop = (jnp.arange(pull.shape[0]) == worst) & (pull[worst] <= 0) & ~jnp.any(inside)
        near, ang = _attach(model, model.op.points + sol.u, st.d_star)
        mode = jnp.where(inside, SLIP_POS, jnp.where(drop, FREE, ns.mode)).astype(jnp.int32)
        finger = jnp.where(inside, near, ns.finger).astype(jnp.int32)
        theta = jnp.where(inside, ang, ns.theta)
        changed = jnp.any(inside | drop)
        kinds = jnp.where(inside, 0, 1)                     # A: joins, B: lets go
        return mode, finger, theta, changed, changed & (st.checks + 1 >= SETTLE_ITERS), inside | drop, kinds
    test = st.added == st.checks                          # joined on the last pass (or by the event)
    # at d* a contact just made carries almost no force. In float32 that value is round-off
    # (the foam square's node 89 chattered in and out at 12.0 mm until STALLED), so the sign
    # of the force's rate decides; in float64 its value just past d*, at the event location's
    # error event_tol (at most η). A node that joined where a release sank it (a later pass)
    # carries a force of its own at d*, and is judged there, in either precision: it pushes at
    # d* and may pull again a little deeper, a cycle that shrinks as it repeats; judged past d*
    # (or in float32 by a rate of round-off sign) it pulled at once, and the cycle stalled at
    # one depth (docs/numerics.md §2, 21 and 22; §3)
    probe = jnp.where(st.added > 0, 0.0, jnp.clip(model.ev_tol, 1e3 * jnp.finfo(fn.dtype).eps, eta))
    by_force = sol.fn + probe * dsol.fn <= 0
    pull = test & (jnp.where(st.added > 0, by_force, dsol.fn <= 0) if fn.dtype == jnp.float32 else by_force)
    mode = jnp.where(pull, FREE, ns.mode)
    on = (ns.mode > FREE) & ~test
    theta, stuck, out, flip = ns.theta, jnp.zeros_like(on), jnp.zeros_like(on), jnp.zeros_like(on)
    held, slid = _per_finger(model, ns.mode, ns.finger)
    share = PEEL_SHARE[1] if fn.dtype == jnp.float32 else PEEL_SHARE[0]
    scale = jnp.maximum(largest(sol.F), st.bracket.fmax)
    # a set in which a finger's contacts all slide is the squeeze's end (SLIP_FAILURE, finish):
    # its pulls and sunk nodes are that failure, not a set to settle; let go, they made it a
    # LOST_CONTACT (a sliding point contact of a two-point grasp pulls, docs/numerics.md §2, 24)
    going = jnp.all(held > 0)
    if model.cfg.slip_events:
        going = going & ~jnp.any(slid == held)
    # a release that drops a tangential force (full stick: a fingertip that turns drags its
    # contacts until one pulls) can land a free node inside a fingertip: it joins where it is,
    # an A event at d* (as the next step's event location would find it at d*), while both
    # fingers hold a contact (else the squeeze ends, LOST_CONTACT) and for at most
    # SETTLE_ITERS passes; one still inside after that is ``unsettled``: STALLED. (Point
    # contacts let the other nodes sink by design.)
    sunk_tols = SUNK_TOLS[1] if fn.dtype == jnp.float32 else SUNK_TOLS[0]
    sunk = (ns.mode == FREE) & (sol.gap < -sunk_tols * model.gap_tol) & going \
        if model.cfg.contact == "segment" else jnp.zeros_like(on)
    budget = SETTLE_ITERS * (1 + st.stats.refined)                # (check: passes again after a refinement)
    join = sunk & (st.checks < budget)
    near, ang = _attach(model, model.op.points + sol.u, st.d_star)
    mode = jnp.where(join, STICK, mode)
    finger = jnp.where(join, near, ns.finger).astype(jnp.int32)
    theta = jnp.where(join, ang, theta)
    if model.cfg.slip_events:
        # a stick force that pulls lies outside the cone too (Section IV-B.1): a contact made by
        # event A whose stick force pulls and does not rise slides on the edge its tangential
        # force (its rate) points to, as released it would sit inside the tip (a sliding contact
        # that still pulls lets go on a later pass). One whose force rises lets go: d* lies
        # before its touch (within event_tol). So does a grip node at the touch: the tips leave it.
        # In float32 the force at the probe is mostly the normal push of the gap_tol penetration
        # the contact was found at, which reads as inside the cone: its rate decides, as for the pull
        cn, ct = (dsol.fn, dsol.ft) if fn.dtype == jnp.float32 else (fn, ft)
        side = jnp.where(pull, dsol.ft, ct)
        pull = pull & ((st.count == 0) | (dsol.fn > 0))
        out = test & ~pull & (laws.cone_margin(model.phi, cn, ct) < 0)
        mode = jnp.where(out, jnp.where(side < 0, SLIP_POS, SLIP_NEG), mode)
        # that edge is a guess from the stick trial: a new contact that slides and still pulls
        # (its force not rising) takes the other edge on the next pass, once (unlogged: it
        # slides either way); if that pulls too, the peel rule lets it go
        rising = dsol.fn > 0
        flip = (st.added >= 0) & (ns.mode >= SLIP_POS) & (st.checks == st.added + 1) & ~rising & \
            ((fn <= 0) if fn.dtype != jnp.float32 else True)
        mode = jnp.where(flip, SLIP_POS + SLIP_NEG - ns.mode, mode)
        # C at d* of an older stick contact, once the new contacts' hypotheses hold: an event
        # keeps every force only to its gap_tol (a contact joins that far inside its tip, and a
        # sunk one 10 times that far), and a larger gap_tol pushed a neighbour's stick force out
        # of its cone by a finite jump that ADVANCE, which sees only sign changes within a step,
        # left for many rows. Beyond PEEL_SHARE of the largest force (round-off below it), at d*
        # and still at the probe d* + η (the new contacts' horizon), the farthest-out one slides
        # there on the edge it leaves through, one per pass. One back inside its cone by the
        # probe is left stuck: at nm depths (a flat pad) the default gap_tol's push is 1e-3 of
        # the forces, passes within ~gap_tol of squeeze, and slid a node D had just stuck, then
        # its neighbours and the grip node: SLIP_FAILURE where the load holds (§2, 31)
        margin = laws.cone_margin(model.phi, sol.fn, sol.ft)
        over = on & (ns.mode == STICK) & going & ~jnp.any(pull | out | flip | join) & (sol.fn > 0) & \
            (margin < -share * scale) & (laws.cone_margin(model.phi, fn, ft) < -share * scale)   # (a pull: peel rule)
        farthest = jnp.argmin(jnp.where(over, margin, jnp.inf))
        slide = over & (jnp.arange(over.shape[0]) == farthest)
        mode = jnp.where(slide, jnp.where(sol.ft < 0, SLIP_POS, SLIP_NEG), mode)
        out = out | slide
        # D at d*, judged once the new contacts' hypotheses hold and no stick force lies outside
        # its cone; one node per pass, the most reversed (a stick changes its neighbours' rates again)
        cand = on & _reversed(model, st, sol, mode) & ~jnp.any(pull | out | flip | join)
        worst = jnp.argmin(jnp.where(cand, sol.rate, jnp.inf))
        stuck = cand & (jnp.arange(cand.shape[0]) == worst)
        mode = jnp.where(stuck, STICK, mode)
        theta = jnp.where(stuck, st.slots.spread()(sol.th, ns.theta), theta)
    # a contact made at this depth pulls at d* when d* lies before its true touch (an event is
    # located to event_tol); while it is being pressed harder (its force's rate positive) and
    # its pull is what that rate makes up within event_tol, it is joining, not peeling: letting
    # it go would only make the same A event again at d*. A larger pull (other contacts let go
    # at d*) is a peel. The share is of the largest force of this trial or, if larger, of the
    # set before the event at the bracket's crossed end: a trial set that carries nothing (the
    # sliding point contact of a two-point grasp lets the object go) has forces of round-off
    # size, and their signs are no pull (they made a SLIP_FAILURE a LOST_CONTACT by chance)
    joining = (st.added >= 0) & (dsol.fn > 0) & (sol.fn + model.ev_tol * dsol.fn >= 0)
    peeling = on & ~joining & ~flip & (sol.fn < -share * scale) & going
    peeled = peeling & (st.checks < budget)
    mode = jnp.where(peeled, FREE, mode).astype(jnp.int32)
    stuck = stuck & ~peeled
    # after SETTLE_ITERS passes a node still inside a tip, or a contact still pulling, leaves
    # the set inconsistent: STALLED, not a row accepted with a pull
    unsettled = jnp.any(sunk & ~join) | jnp.any(peeling & ~peeled)
    return (mode, finger, theta, jnp.any(mode != ns.mode), unsettled, pull | peeled | stuck | out | join,
            jnp.where(join, 0, jnp.where(stuck, 3, jnp.where(out, 2, 1))).astype(jnp.int32))


def check(model: Model, st: State, sol: Solution, dsol: Solution, d_star):
    """Phase CHECK: the new contact set solved at d*. Test it by hypothesis; if that changed
    it, update the slots and solve again at d*; else accept the row. An event that undid itself
    within event_tol of the row the last event made would repeat forever; so would a set that
    does not settle (``unsettled``). Either is first resolved again with event_tol / REFINE[0]
    (the row accepted and its event located anew, or the set checked again at d*), at most
    REFINE[1] times in a squeeze, then stops the squeeze with STALLED (a finger left without
    contacts ends it as LOST_CONTACT instead).
    Returns (state, accept)."""
    mode, finger, theta, changed, unsettled, logged, kinds = _hypothesis(model, st, sol, dsol)
    again = changed & ~unsettled & (st.fault == RUNNING)      # a faulted run stops at this row

    def retry():
        ns = st.nodes
        nodes = Nodes(mode, finger, theta, ns.armed & (mode == ns.mode))   # sol: a set just rejected
        added = jnp.where(mode > FREE, jnp.where(ns.mode == FREE, st.checks + 1, st.added), -1).astype(jnp.int32)
        events, n_ev, fault = _log(model, st, logged, kinds, finger, d_star)
        return _with(st, nodes=nodes, added=added, checks=st.checks + 1, events=events, n_ev=n_ev, fault=fault)

    # a finger left empty is no stall: the row is accepted and the squeeze ends, LOST_CONTACT
    held, _ = _per_finger(model, st.nodes.mode, st.nodes.finger)
    # (measured from the last event's row: a step predicted to the next event may stop short of
    # it by less than event_tol, and a cycle that follows is no event undone, docs/numerics.md §2, 25)
    undone = jnp.all(st.nodes.mode == st.before) & (d_star <= st.d_ev + model.ev_tol) & jnp.all(held > 0) & ~unsettled
    # (a bracket narrower than 100 eps, in d <= 1, is round-off)
    refine = (undone | unsettled) & (st.stats.refined < REFINE[1]) & (st.fault == RUNNING) \
        & (model.ev_tol >= REFINE[0] * 100 * jnp.finfo(d_star.dtype).eps) \
        if d_star.dtype == jnp.float64 and model.cfg.friction_model != "frictionless" else jnp.zeros((), bool)
    fault = jnp.where((undone | unsettled) & ~refine & (st.fault == RUNNING), Status.STALLED, st.fault).astype(jnp.int32)
    settle = unsettled & refine              # CHECK again at d*: the finer tolerance, SETTLE_ITERS more passes
    done = lambda: _with(st, fault=fault, stats=st.stats._replace(refined=st.stats.refined + refine.astype(jnp.int32)))  # noqa: E731
    return lax.cond(again, retry, done), ~again & ~settle


# ----------------------------------------------------------------------------- finish
def _per_finger(model: Model, mode, finger):
    """(contacts per finger (2,), sliding contacts per finger (2,))."""
    contact = mode > FREE
    per = jnp.stack([jnp.sum(contact & (finger == k)) for k in (0, 1)])
    slid = jnp.stack([jnp.sum((mode >= SLIP_POS) & (finger == k)) for k in (0, 1)])
    return per, slid


def _record(model: Model, st: State) -> State:
    """Write the accepted row into the history (row ``count``; with ``Config.history`` off, row 1
    holds the last row and row 0 the last squeeze-phase row) and add the push work of the
    increment since the last row (trapezoid rule, the formulas of :mod:`jaxsqueeze.plan.quality`)."""
    ns = st.nodes
    depth = jnp.where(model.phase == 0, st.d, model.rot_depth[0])
    push = jnp.where(model.phase == 0, 0.0, st.d)
    vals = (depth, ns.mode.astype(jnp.int8), ns.finger.astype(jnp.int8), st.angle, st.F, st.u,
            model.centres(st.d), model.angles(st.d), st.g, push)
    g_before = st.g_before
    if model.cfg.history:
        hist = tuple(h.at[st.count].set(v) for h, v in zip(st.hist, vals))
    else:
        g_before = st.hist[8][1]
        hist = tuple(h.at[1].set(v) for h, v in zip(st.hist, vals))
        hist = tuple(jnp.where(model.phase == 0, h.at[0].set(v), h) for h, v in zip(hist, vals))
    ff = _finger_totals(model, st.F, ns.mode, ns.finger)
    work = st.work
    if model.cfg.adversary:
        dx = model.centres(st.d)[2] - st.hist[6][jnp.maximum(st.count - 1, 0) if model.cfg.history else 1, 2]
        mid = 0.5 * (ff + st.ff)
        mid0 = 0.5 * (ff + st.ff) - st.ff0
        inc = jnp.stack([jnp.sum(mid[2] * dx), -jnp.sum(mid0[0] * dx), -jnp.sum(mid0[1] * dx)])
        work = work + jnp.where((model.phase == 1) & (st.count > 0), inc, 0.0)
    return _with(st, hist=hist, ff=ff, work=work, g_before=g_before)


def finish(model: Model, st: State, ok) -> State:
    """Record the row and decide the status (an overflow, which records nothing, ends in
    :func:`reconcile`).

    Precedence: a structural fault raised by a stage (invalid input, infeasible grip,
    overflow, event-log overflow, stall), then a finger without contact (the solve of such a
    set is singular, so its non-finite values are a consequence, not the cause), non-finite
    values, Newton failure, a finger whose contacts all slide, the target depth, the step bound.
    """
    st = _record(model, st)
    count = st.count + 1
    finite = jnp.all(jnp.isfinite(st.F)) & jnp.all(jnp.isfinite(st.u))
    per, slid = _per_finger(model, st.nodes.mode, st.nodes.finger)
    lost = jnp.any(per == 0)
    slip = jnp.any(slid == per) if model.cfg.slip_events else jnp.array(False)
    status = jnp.where(st.fault != RUNNING, st.fault,
             jnp.where(lost, Status.LOST_CONTACT,
             jnp.where(~finite, Status.NONFINITE,
             jnp.where(~ok, Status.NEWTON_FAILURE,
             jnp.where(slip, Status.SLIP_FAILURE,
             jnp.where(st.d >= model.D, Status.SUCCESS,
             jnp.where(count >= model.cfg.max_steps + 1, Status.MAX_STEPS, RUNNING)))))))
    return _with(st, count=count, status=status.astype(jnp.int32))


# ----------------------------------------------------------------------------- the loop
def _loop(model: Model, st: State) -> State:
    return lax.while_loop(lambda s: s.status == RUNNING, lambda s: step(model, s), _seeded(model, st))


def _seeded(model: Model, st: State) -> State:
    """``st`` unchanged. Under ``jvp`` every float field but the contact slots (whose kept
    factorization carries no tangent: :func:`contacts.solve` takes its rate by the implicit step)
    and the statistics enters the loop with a tangent, a zero where it had none. JAX derives a
    ``while_loop`` body again for as long as the last derivation gave more carries a tangent,
    and under ``vmap`` (``jacfwd``) batches it again for as long as more carries become batched.
    The squeeze starts with 3 such fields (the first touch) and its step gives 33: a placed
    squeeze's ``jacfwd`` derived the whole step three times and batched it up to 15 times,
    now once each (benchmarks/README.md, note of 2026-12-06 14:10)."""
    carried = {f.name: getattr(st, f.name) for f in dataclasses.fields(st) if f.name not in ("slots", "stats")}
    return _with(st, **_hint(carried, tuple(x for x in jax.tree.leaves(model) if floating(x))))


@jax.custom_jvp
def _hint(xs, inputs):
    """``xs`` (a pytree). Its derivative is that of ``xs`` with every float leaf whose tangent
    is a symbolic zero given a zero that depends on the first of ``inputs`` that moves (so that
    under ``vmap`` of the ``jvp`` it is batched as well; a non-finite tangent there gives 0)."""
    return xs


def _hint_jvp(primals, tangents):
    xs, _ = primals
    dxs, dinputs = tangents
    moving = [t for t in dinputs if not isinstance(t, SymbolicZero) and jnp.size(t)]
    if not moving:
        return xs, dxs
    t0 = jnp.ravel(moving[0])[0]
    zero = jnp.where(jnp.isfinite(t0), t0 * 0, 0)
    fill = lambda x, t: (jnp.broadcast_to(zero.astype(x.dtype), jnp.shape(x))  # noqa: E731
                         if isinstance(t, SymbolicZero) and floating(x) else t)
    return xs, jax.tree.map(fill, xs, dxs)


_hint.defjvp(_hint_jvp, symbolic_zeros=True)


def floating(x) -> bool:
    """Does ``x`` have a floating (differentiable) dtype?"""
    return jnp.issubdtype(jnp.result_type(x), jnp.inexact)


def run(model: Model, st: State) -> State:
    """``step`` in a ``lax.while_loop`` until ``finish`` sets a status; with ``Config.fused``
    the loop is compiled as one CPU kernel (:func:`jaxsqueeze.compiler.one_kernel`)."""
    return compiler.one_kernel(_loop, model, st) if model.cfg.fused else _loop(model, st)


def start_push(model: Model, st: State) -> State:
    """Hand a finished squeeze to the adversary phase: λ restarts at 0 from the squeezed state
    (contacts, anchors and forces carry over); only a squeeze that succeeded is pushed, and only
    by a pusher that can touch it (:func:`push_model`; else INFEASIBLE_GRIP). The first
    iteration (PRIME) evaluates the push phase's event functions at λ = 0."""
    go = jnp.where(model.margin < 0, Status.INFEASIBLE_GRIP, RUNNING)      # a pusher that cannot touch
    status = jnp.where(st.status == Status.SUCCESS, go, st.status).astype(jnp.int32)
    hist = list(st.hist)
    hist[6] = hist[6].at[:, 2].set(model.base[2])       # the pusher waits at its start in squeeze rows
    return _with(st, d=jnp.zeros_like(st.d), d_ev=jnp.zeros_like(st.d), status=status, squeeze_status=st.status,
                 hist=tuple(hist), phase=jnp.array(PRIME, jnp.int32), ff0=st.ff)


def let_go(model: Model, st: State) -> State:
    """A squeeze that ended with a finger left without contact (LOST_CONTACT) records that row
    from a singular solve when no contact is left to fix the object's rigid motion: its
    displacements are not finite. The object is let go: no forces, so no deformation, and the
    rigid motion of the row before (its boundary displacement is that rigid motion; none when
    it lets go at the touch, row 0). With ``Config.history`` off the row before is
    ``State.g_before``, and the let-go row is row 1 (and row 0 when the squeeze phase ended)."""
    depth, mode, finger, theta, F, u, C, alpha, g, push = st.hist
    k = st.count - 1
    lost = (st.status == Status.LOST_CONTACT) & (k >= 0)
    before = jnp.where(k >= 1, g[jnp.maximum(k - 1, 0)] if model.cfg.history else st.g_before, 0.0)
    last = k if model.cfg.history else 1
    for r in ((k,) if model.cfg.history else (0, 1)):
        bad = lost & ~(jnp.all(jnp.isfinite(u[r])) & jnp.all(jnp.isfinite(g[r])))
        g = g.at[r].set(jnp.where(bad, before, g[r]))
        u = u.at[r].set(jnp.where(bad, (model.op.N @ before).reshape(u[r].shape), u[r]))
        F = F.at[r].set(jnp.where(bad, jnp.zeros_like(F[r]), F[r]))
    hist = (depth, mode, finger, theta, F, u, C, alpha, g, push)
    return _with(st, hist=hist, F=F[last], u=u[last], g=g[last])       # (the state is its last recorded row)


def simulate(op: Compliance, grasp: Grasp, cfg: Config) -> State:
    """The jittable core of :func:`jaxsqueeze.squeeze`: ``init``, then ``step`` in a
    ``lax.while_loop`` until ``finish`` sets a status; with an adversary, a second loop of the
    same stages pushes the squeezed object (:func:`push_model`).

    Returns the final :class:`State` (scaled units; history and event log padded).
    """
    model = make_model(op, grasp, cfg)
    with jax.named_scope("init"):
        st = init(model)
    with jax.named_scope("squeeze"):
        st = run(model, st)
    st = _with(st, squeeze_status=st.status, squeeze_events=st.n_ev)
    if cfg.adversary:
        with jax.named_scope("push"):
            pm = push_model(model, grasp, st)
            st = run(pm, start_push(pm, st))
    return let_go(model, st)
