"""The engine's stages, each alone on a state (init, step with its phases advance /
locate_event / check, apply_event, finish), and the status precedence decided in finish."""
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsqueeze as jsq
from jaxsqueeze.simulation import api, engine
from jaxsqueeze.simulation.laws import FREE, SLIP_POS, STICK
from jaxsqueeze.simulation.status import Status
from physics import nearest, symmetric_square

MAT = jsq.Material(E=1e5, nu=0.3, thickness=0.0254)


@pytest.fixture(scope="module")
def model():
    mesh = symmetric_square(0.1, 0.01)
    grip = (nearest(mesh, (0, -0.05)), nearest(mesh, (0, 0.05)))
    scene = jsq.Scene(mesh=mesh, material=MAT, fingers=jsq.Fingers(radius=0.02), grip=grip, friction=0.5,
                      depth=0.02)
    op = dataclasses.replace(scene.operator(), field=None)
    return engine.make_model(op, api.grasp_of(scene, op), api.config_of(scene))


_step = jax.jit(engine.step)


@jax.jit
def _solved(model, st):
    """(solution, its derivative in d) of the state's contact set at its depth (one program)."""
    return jax.jvp(lambda d: engine.contacts.solve(model, st.slots, st.nodes, d), (st.d,), (jnp.ones_like(st.d),))


@pytest.fixture(scope="module")
def first(model):
    return jax.jit(engine.init)(model)


@pytest.fixture(scope="module")
def touched(model, first):
    """The state after the first step: the touch recorded (row 0), phase ADVANCE."""
    return _step(model, first)


def test_init_touches_the_grip_nodes_and_the_first_step_records_the_touch(model, first):
    """init: the grip nodes in contact (stick first), phase CHECK at d = 0, nothing recorded;
    the first step solves the touch there and records row 0 with no force."""
    assert int(first.status) == engine.RUNNING and int(first.count) == 0
    assert int(first.phase) == engine.CHECK and float(first.d_star) == 0.0
    mode = np.asarray(first.nodes.mode)
    on = np.flatnonzero(mode > FREE)
    assert sorted(on.tolist()) == sorted(np.asarray(model.grip).tolist())
    added = np.asarray(first.added)            # the CHECK pass each contact joined at, -1 none
    assert np.all(mode[on] == STICK) and np.all(added[on] == 0) and np.all(np.delete(added, on) == -1)
    np.testing.assert_array_equal(np.asarray(first.nodes.finger)[np.asarray(model.grip)], [0, 1])
    assert int(np.sum(np.asarray(first.slots.active))) == 2
    st = _step(model, first)
    assert int(st.status) == engine.RUNNING and int(st.count) == 1 and int(st.phase) == engine.ADVANCE
    assert float(st.d) == 0.0 and np.abs(np.asarray(st.F)).max() < 1e-12   # no force at touch


def test_step_advances_by_one_step_when_nothing_happens(model, touched):
    st = _step(model, touched)
    np.testing.assert_allclose(float(st.d), float(model.h), rtol=1e-12)
    assert int(st.count) == 2 and int(st.stats.steps) == 1 and int(st.stats.events) == 0
    assert int(st.stats.solves) == int(touched.stats.solves) + 1        # one solve per step
    F = np.asarray(st.F)
    assert np.abs(F.sum(0)).max() < 1e-12 * np.abs(F).max()      # equal and opposite


def test_locate_event_brackets_a_new_contact_and_apply_event_adds_it(model, touched):
    """One step over the whole depth crosses the first event of the square, a new contact (A):
    ADVANCE opens a bracket, LOCATE shrinks it to the tolerance with the crossing inside,
    apply_event logs it at one depth inside the bracket and hands CHECK the new contact.
    (``missed``: the step is a plain one, not the predicted crossing of ``engine.ahead``.)"""
    wide = dataclasses.replace(model, h=model.D)
    st = _step(wide, dataclasses.replace(touched, missed=jnp.asarray(engine.PREDICTIONS, jnp.int32)))
    assert int(st.phase) == engine.LOCATE and int(st.count) == 1            # nothing accepted
    b = st.bracket
    assert float(b.lo) == 0.0 and float(b.hi) == float(model.D) and np.any(np.asarray(b.e_hi) < 0)
    while int(st.phase) == engine.LOCATE:
        st = _step(wide, st)
        assert int(st.stats.bracket_iters) <= int(model.cfg.bisect_iters)
    b = st.bracket                                    # the final bracket (apply_event keeps it)
    # closed by its width, or by Newton from the crossed end: every crossed function's Newton
    # crossing lies within the tolerance below hi (its rate there falling)
    e_hi, de_hi, tol = np.asarray(b.e_hi), np.asarray(b.de_hi), float(model.ev_tol)
    crossed = e_hi < 0
    newton = float(b.hi) - e_hi[crossed] / de_hi[crossed]
    by_newton = np.all(de_hi[crossed] < 0) and np.all(newton >= max(float(b.hi) - tol, float(b.lo)))
    assert float(b.hi - b.lo) <= tol or by_newton or int(b.iters) >= model.cfg.bisect_iters
    assert np.all(np.asarray(b.e_lo) >= 0) and np.any(np.asarray(b.e_hi) < 0)
    assert int(st.phase) == engine.CHECK and int(st.n_ev) >= 1
    assert np.all(np.asarray(st.events[2])[: int(st.n_ev)] == 0)           # kind A
    assert float(b.lo) <= float(st.d_star) <= float(b.hi)
    added = np.asarray(st.added) == 0                 # joined by the event (pass 0)
    assert added.sum() == int(st.n_ev) and np.all(np.asarray(st.nodes.mode)[added] == STICK)
    assert int(np.sum(np.asarray(st.slots.active))) == 2 + int(st.n_ev)     # reconcile bordered them in
    node, slot, S = np.asarray(st.slots.node), np.asarray(st.slots.slot), int(model.cfg.capacity)
    on = np.flatnonzero(node >= 0)                   # the node -> slot map inverts slot -> node
    np.testing.assert_array_equal(slot[node[on]], on)
    assert np.sum(slot < S) == on.size and np.all(np.asarray(st.nodes.mode)[slot < S] > FREE)
    # apply_event alone on the last bracket gives the same state
    again = jax.jit(engine.apply_event)(wide, dataclasses.replace(st, bracket=b, phase=jnp.asarray(engine.LOCATE),
                                                                  nodes=touched.nodes, n_ev=touched.n_ev,
                                                                  events=touched.events))
    np.testing.assert_array_equal(np.asarray(again.nodes.mode), np.asarray(st.nodes.mode))
    assert float(again.d_star) == float(st.d_star)


def _drive(model, st, plain):
    """Step a state to its end in Python; ``plain``: every ADVANCE a plain step (``missed``)."""
    while int(st.status) == engine.RUNNING:
        st = _step(model, dataclasses.replace(st, missed=jnp.asarray(engine.PREDICTIONS, jnp.int32)) if plain else st)
    return st


def test_predicted_crossings_give_the_located_events_with_fewer_solves(model):
    """engine.ahead: steps that go a quarter tolerance past the crossing the accepted row's
    event functions predict close most brackets in the iteration that opens them (no LOCATE
    solve), and the squeeze is the one of plain steps: the same events at the same depths (to
    the event tolerance), the same final contact set and forces, fewer solves. (The square
    gripped slanted, so that events come one at a time: a new contact and a slip.)"""
    mesh = symmetric_square(0.1, 0.01)
    grip = (nearest(mesh, (0.01, -0.05)), nearest(mesh, (-0.01, 0.05)))
    scene = jsq.Scene(mesh=mesh, material=MAT, fingers=jsq.Fingers(radius=0.02), grip=grip, friction=0.3,
                      depth=0.02)
    op = dataclasses.replace(scene.operator(), field=None)
    slanted = engine.make_model(op, api.grasp_of(scene, op), api.config_of(scene))
    touched = _step(slanted, jax.jit(engine.init)(slanted))
    fast, slow = _drive(slanted, touched, False), _drive(slanted, touched, True)
    assert int(fast.status) == int(slow.status) == Status.SUCCESS
    n = int(fast.n_ev)
    assert n == int(slow.n_ev) >= 2 and set(np.asarray(slow.events[2])[:n].tolist()) == {0, 2}   # A and C
    for k in (1, 2, 3):
        np.testing.assert_array_equal(np.asarray(fast.events[k])[:n], np.asarray(slow.events[k])[:n])
    np.testing.assert_allclose(np.asarray(fast.events[0])[:n], np.asarray(slow.events[0])[:n],
                               rtol=0, atol=float(slanted.ev_tol))
    np.testing.assert_array_equal(np.asarray(fast.nodes.mode), np.asarray(slow.nodes.mode))
    F = np.asarray(slow.F)
    np.testing.assert_allclose(np.asarray(fast.F), F, rtol=0, atol=1e-9 * np.abs(F).max())
    fs, ss = fast.stats, slow.stats
    assert int(fs.events) == int(ss.events) and int(ss.bracket_iters) >= int(ss.events)
    assert int(fs.bracket_iters) < int(fs.events)             # some events cost no LOCATE solve
    assert int(fs.solves) < int(ss.solves)


def test_predictions_that_fall_short_are_rows_and_then_a_step_is_plain(model, touched):
    """engine.ahead: event functions that predict a crossing the solve does not find (here one
    free node's function and rate set to predict a crossing at half a step, then at a tenth,
    while its real gap stays open) give rows at the predicted depths, counted in ``missed``;
    after ``PREDICTIONS`` of them the step is d + h, so that a function bending away from zero
    cannot shrink the steps again and again."""
    mode = np.asarray(touched.nodes.mode)
    k = int(np.flatnonzero(mode == FREE)[0])
    h, q = float(model.h), 0.25 * float(model.ev_tol)
    fake = lambda st, ahead: dataclasses.replace(st, e=st.e.at[k].set(ahead), de=st.de.at[k].set(-1.0))  # noqa: E731
    st = touched
    for n in range(1, engine.PREDICTIONS + 1):
        before = st
        st = _step(model, fake(st, 0.5 * h / n))
        assert int(st.phase) == engine.ADVANCE and int(st.count) == int(before.count) + 1
        np.testing.assert_allclose(float(st.d), float(before.d) + 0.5 * h / n + q, rtol=1e-12)
        assert int(st.missed) == n
    nxt = _step(model, fake(st, 0.1 * h))
    np.testing.assert_allclose(float(nxt.d), float(st.d) + h, rtol=1e-12)
    assert int(nxt.missed) == 0


def test_the_bracket_estimate_finds_the_root_of_a_cubic_from_its_ends():
    """engine._hermite_root: the cubic Hermite interpolant of an event function from its values
    and rates at the bracket's ends is the function itself when that is a cubic, so Newton on it
    finds the root to round-off; data that are no fall through zero give NaN (the estimate then
    falls back to Newton from an end or the secant)."""
    lo, hi = 0.2, 0.7
    roots = np.array([0.25, 0.46, 0.69])
    e = lambda d: -(d - roots) * (1.0 + 3.0 * (d - 0.4) ** 2)            # noqa: E731  falling cubics
    de = lambda d: -(1.0 + 3.0 * (d - 0.4) ** 2) - 6.0 * (d - roots) * (d - 0.4)  # noqa: E731
    z = jnp.zeros(3)
    b = engine.Bracket(z, jnp.asarray(lo), jnp.asarray(hi), jnp.asarray(e(lo)), jnp.asarray(de(lo)),
                       jnp.asarray(e(hi)), jnp.asarray(de(hi)), jnp.zeros(3, jnp.int32), z, z, z, z, z, jnp.zeros(()),
                       jnp.asarray(0, jnp.int32))
    np.testing.assert_allclose(np.asarray(engine._hermite_root(b)), roots, rtol=0, atol=1e-12)
    # a function already below zero at lo, or still above it at hi, has no crossing to estimate
    b2 = b._replace(e_lo=b.e_lo.at[0].set(-1.0), e_hi=b.e_hi.at[1].set(0.5))
    r = np.asarray(engine._hermite_root(b2))
    assert np.isnan(r[0]) and np.isnan(r[1]) and abs(r[2] - roots[2]) < 1e-12


def test_a_dip_below_zero_inside_a_step_is_found_from_its_ends():
    """engine._dip: an event function above zero at both ends of a step, falling at lo and
    rising at hi, whose cubic Hermite interpolant falls below zero inside (here quadratics,
    which the interpolant reproduces): flagged, with the depth of its minimum; one that stays
    above zero, that does not turn within the step, or whose minimum lies within the tolerance
    of an end, is not."""
    lo, hi, c = 0.2, 0.7, 0.45
    lift = np.array([-0.01, 0.01, -0.01])
    e = lambda d: (d - c) ** 2 + lift                                    # noqa: E731
    de = lambda d: np.array([2 * (d - c), 2 * (d - c), -1.0])            # noqa: E731  the third falls at hi
    z = jnp.zeros(3)
    b = engine.Bracket(z, jnp.asarray(lo), jnp.asarray(hi), jnp.asarray(e(lo)), jnp.asarray(de(lo)),
                       jnp.asarray(e(hi)), jnp.asarray(de(hi)), jnp.zeros(3, jnp.int32), z, z, z, z, z, jnp.zeros(()),
                       jnp.asarray(0, jnp.int32))
    dip, deepest = engine._dip(b, 1e-3)
    assert np.asarray(dip).tolist() == [True, False, False]
    np.testing.assert_allclose(np.asarray(deepest)[:2], [c, c], rtol=0, atol=1e-12)
    # a dip within the tolerance of an end is a crossing and its return within it: not chased
    lo2, f = c - 2e-5, lambda d: (d - c) ** 2 - 1e-10                   # noqa: E731
    near = b._replace(lo=jnp.asarray(lo2), e_lo=jnp.full(3, f(lo2)), de_lo=jnp.full(3, 2 * (lo2 - c)),
                      e_hi=jnp.full(3, f(hi)), de_hi=jnp.full(3, 2 * (hi - c)))
    assert float(near.e_lo[0]) > 0 and not np.any(np.asarray(engine._dip(near, 1e-3)[0]))
    assert np.all(np.asarray(engine._dip(near, 1e-6)[0]))


def test_the_event_log_appends_flagged_nodes_in_order_and_drops_past_its_end():
    """``_log`` appends the flagged nodes' events in node order after the ``n_ev`` logged ones
    (a gather since 2026-12-04; it was a scatter), leaves every other entry alone, and past
    ``max_events`` drops the rest and raises EVENT_OVERFLOW: against a plain loop, for random
    flags at offsets 0, mid-log, at the end and past it."""
    import types
    m, E = 9, 12
    nodes = np.arange(100, 100 + m)
    model = types.SimpleNamespace(cfg=types.SimpleNamespace(max_events=E), op=types.SimpleNamespace(nodes=jnp.asarray(nodes)))
    rng = np.random.default_rng(3)
    state = lambda events, n_ev: types.SimpleNamespace(events=events, n_ev=n_ev, fault=jnp.int32(engine.RUNNING))  # noqa: E731
    log = jax.jit(lambda events, n_ev, *flags: engine._log(model, state(events, n_ev), *flags, 0.5))
    for n_ev in (0, 5, 10, 12, 14):
        for _ in range(3):
            flag, kinds, finger = rng.random(m) < 0.4, rng.integers(0, 4, m), rng.integers(0, 2, m)
            old = (rng.random(E), rng.integers(0, 99, E), rng.integers(0, 9, E), rng.integers(0, 9, E))
            events, count, fault = log(tuple(jnp.asarray(a) for a in old), jnp.int32(n_ev), jnp.asarray(flag),
                                       jnp.asarray(kinds), jnp.asarray(finger))
            want = [np.array(a) for a in old]
            pos = n_ev
            for i in np.flatnonzero(flag):
                if pos < E:
                    for a, v in zip(want, (0.5, nodes[i], kinds[i], finger[i])):
                        a[pos] = v
                pos += 1
            for got, w in zip(events, want):
                np.testing.assert_array_equal(np.asarray(got), w)
            assert int(count) == n_ev + flag.sum()
            assert int(fault) == (Status.EVENT_OVERFLOW if n_ev + flag.sum() > E else engine.RUNNING)


def test_finish_decides_the_status_in_one_order(model, touched):
    fin = jax.jit(engine.finish)
    ns = touched.nodes
    mode = np.asarray(ns.mode)
    i, j = (int(v) for v in np.asarray(model.grip))
    with_mode = lambda st, mo: dataclasses.replace(st, nodes=ns._replace(mode=jnp.asarray(mo)))  # noqa: E731
    # a finger without contact: LOST_CONTACT (before SLIP_FAILURE)
    lost = with_mode(touched, np.where(np.arange(len(mode)) == j, FREE, mode))
    assert int(fin(model, lost, True).status) == Status.LOST_CONTACT
    # every contact of one finger sliding: SLIP_FAILURE
    slid = with_mode(touched, np.where(np.arange(len(mode)) == i, SLIP_POS, mode))
    assert int(fin(model, slid, True).status) == Status.SLIP_FAILURE
    # Newton failure comes before the contact checks, a stage's fault before everything
    assert int(fin(model, slid, False).status) == Status.NEWTON_FAILURE
    faulted = dataclasses.replace(slid, fault=jnp.asarray(Status.OVERFLOW, jnp.int32))
    assert int(fin(model, faulted, False).status) == Status.OVERFLOW
    nan = dataclasses.replace(touched, F=touched.F.at[0, 0].set(jnp.nan))
    assert int(fin(model, nan, True).status) == Status.NONFINITE
    done = dataclasses.replace(touched, d=model.D)
    assert int(fin(model, done, True).status) == Status.SUCCESS
    assert int(fin(model, touched, True).status) == engine.RUNNING
    assert int(fin(model, touched, True).count) == int(touched.count) + 1   # finish records the row


def test_stats_and_records_of_a_full_squeeze(model):
    st = jax.jit(lambda m: engine.run(m, engine.init(m)))(model)
    assert int(st.status) == Status.SUCCESS
    s = st.stats
    assert int(st.count) == 1 + int(s.steps) + int(s.events)
    # a solve per row, per event its crossing solve and LOCATE solves (none when the predicted
    # step closed it), and CHECK retries
    assert int(s.events) >= 1 and int(s.solves) >= int(st.count) + int(s.events) + int(s.bracket_iters)
    rigid = np.asarray(st.hist[8])[int(st.count) - 1]
    np.testing.assert_allclose(rigid, np.asarray(st.g), rtol=0, atol=0)   # the rigid part is recorded
    # after every contact made and broken, the node -> slot map still inverts the slots and
    # holds exactly the contact set
    node, slot, mode = np.asarray(st.slots.node), np.asarray(st.slots.slot), np.asarray(st.nodes.mode)
    on = np.flatnonzero(node >= 0)
    np.testing.assert_array_equal(slot[node[on]], on)
    np.testing.assert_array_equal(slot < model.cfg.capacity, mode > FREE)


def test_the_loop_state_enters_a_jvp_with_a_finite_zero_tangent_in_every_float_field(model, first):
    """engine._seeded: the identity on the state; under jvp in the model every float field but
    the slots and the statistics gets a tangent (zero where the state had none, also when an
    input's tangent is not finite), so JAX derives the loop body once (benchmarks/README.md)."""
    floats = lambda m, v: jax.tree.map(  # noqa: E731
        lambda x: np.full(np.shape(x), v) if engine.floating(x) else np.zeros(np.shape(x), jax.dtypes.float0), m)
    for v in (1.0, np.nan):
        out, dout = jax.jvp(lambda m: engine._seeded(m, first), (model,), (floats(model, v),))
        assert jax.tree.all(jax.tree.map(lambda a, b: bool(np.array_equal(a, b, equal_nan=True)), out, first))
        for field in dataclasses.fields(first):
            for t in jax.tree.leaves(getattr(dout, field.name)):
                if t.dtype != jax.dtypes.float0:
                    np.testing.assert_array_equal(np.asarray(t), 0.0, err_msg=field.name)
    # the zeros depend on the input's tangent: under jacfwd's vmap they are batched from the start
    tangents = jax.tree.map(lambda x: jnp.stack([x, x]) if x.dtype != jax.dtypes.float0 else np.zeros((2,) + x.shape, x.dtype),
                            floats(model, 1.0))
    with pytest.raises(ValueError, match="out_axes"):
        jax.vmap(lambda t: jax.jvp(lambda m: engine._seeded(m, first), (model,), (t,))[1].F, out_axes=None)(tangents)
    # the tangents a field already has pass through
    x, dx = jax.jvp(lambda a: engine._hint({"x": 2 * a, "k": jnp.int32(1)}, (a,)), (jnp.float64(1.0),), (jnp.float64(3.0),))
    assert float(x["x"]) == 2.0 and float(dx["x"]) == 6.0 and dx["k"].dtype == jax.dtypes.float0


def test_update_makes_and_breaks_contacts_keeping_the_inverse_and_the_node_map(model):
    """contacts.update from the grip pair to four contacts, then two leave and one joins: the
    node -> slot map inverts the slots, and the bordered inverse kept by bordering updates equals
    the inverse of the bordered matrix of eq. (4) built afresh for the slots."""
    op, S = model.op, model.cfg.capacity
    i, j = (int(v) for v in np.asarray(model.grip))
    a, b, c = (i + 1) % op.m, (i - 1) % op.m, (j + 1) % op.m
    on = lambda *ps: jnp.zeros(op.m, bool).at[jnp.array(ps)].set(True)  # noqa: E731
    upd = jax.jit(lambda sl, old, new: engine.contacts.update(op, sl, old, new)[:2])
    sl, over = upd(engine.contacts.pair(op, S, i, j), on(i, j), on(i, j, a, b))
    sl, over2 = upd(sl, on(i, j, a, b), on(j, a, c))
    assert not bool(over) and not bool(over2)
    node, slot = np.asarray(sl.node), np.asarray(sl.slot)
    act = np.flatnonzero(node >= 0)
    assert sorted(node[act].tolist()) == sorted([j, a, c])
    np.testing.assert_array_equal(slot[node[act]], act)
    assert np.sum(slot < S) == 3
    G, N = np.asarray(op.G), np.asarray(op.N)
    M = np.zeros((2 * S + 3, 2 * S + 3))
    M[: 2 * S, : 2 * S] = np.eye(2 * S)
    for k in act:
        dk = [2 * node[k], 2 * node[k] + 1]
        for q in act:
            M[2 * k: 2 * k + 2, 2 * q: 2 * q + 2] = G[np.ix_(dk, [2 * node[q], 2 * node[q] + 1])]
        M[2 * k: 2 * k + 2, 2 * S:] = N[dk]
        M[2 * S:, 2 * k: 2 * k + 2] = N[dk].T
    np.testing.assert_allclose(np.asarray(sl.Minv), np.linalg.inv(M), rtol=0, atol=1e-8 * np.abs(np.linalg.inv(M)).max())


def test_update_recomputes_a_drifted_inverse_and_keeps_a_sound_one(model):
    """contacts.update checks the kept inverse after a contact change (its backward error on a
    probe, contacts.drift): one that has drifted beyond DRIFT_TOL (here perturbed by 1e-8) is
    recomputed from the bordered matrix; one within it is the bordering update's own, bit for
    bit (no LU on the way)."""
    contacts = engine.contacts
    op, S = model.op, model.cfg.capacity
    i, j = (int(v) for v in np.asarray(model.grip))
    a, b = (i + 1) % op.m, (i - 1) % op.m
    on = lambda *ps: jnp.zeros(op.m, bool).at[jnp.array(ps)].set(True)  # noqa: E731
    upd = jax.jit(lambda sl, old, new: contacts.update(op, sl, old, new))
    sl, _, fresh = upd(contacts.pair(op, S, i, j), on(i, j), on(i, j, a))
    assert not bool(fresh)
    inverse = lambda s: np.linalg.inv(np.asarray(contacts.bordered_matrix_of(op, s)))  # noqa: E731
    assert float(contacts.drift(op, sl)) < 1e-14
    bump = 1 + 1e-8 * np.cos(np.arange(sl.Minv.size)).reshape(sl.Minv.shape)
    bad = sl._replace(Minv=sl.Minv * bump)
    assert float(contacts.drift(op, bad)) > contacts.DRIFT_TOL[0]
    healed, _, fresh = upd(bad, on(i, j, a), on(i, j, a, b))
    assert bool(fresh)
    assert float(contacts.drift(op, healed)) < 1e-14
    ref = inverse(healed)
    np.testing.assert_allclose(np.asarray(healed.Minv), ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    # a sound inverse: the bordering update alone, no recomputation
    kept, _, fresh = upd(sl, on(i, j, a), on(i, j, a, b))
    assert not bool(fresh)
    k = int(np.argmax(np.asarray(sl.node) < 0))
    alone = jax.jit(lambda s: contacts.activate(op, s, k, b))(sl)
    np.testing.assert_array_equal(np.asarray(kept.Minv), np.asarray(alone.Minv))


def test_kept_inverse_stays_exact_over_many_contact_changes():
    """150 random contacts made and broken among the boundary nodes near the grip of a square
    with 0.5 mm contact zones: the inverse kept by bordering updates alone drifts by orders of
    magnitude (its backward error grows exponentially, to ~1e-4 here),
    while contacts.update keeps it within DRIFT_TOL by recomputing it now and then."""
    contacts = engine.contacts
    mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=0.006, refine_near=[(0, -0.05), (0, 0.05)], refine_edge=0.0005)
    op = dataclasses.replace(jsq.fem.compliance(mesh, MAT), field=None)
    P = np.asarray(op.points)
    edge = lambda y: np.argsort(np.where(np.abs(P[:, 1] - y) < 1e-9, np.abs(P[:, 0]), np.inf))[:15]  # noqa: E731
    bot, top = edge(P[:, 1].min()), edge(P[:, 1].max())
    on = lambda ps: jnp.zeros(op.m, bool).at[jnp.array(ps)].set(True)  # noqa: E731
    upd = jax.jit(lambda sl, a, c: contacts.update(op, sl, a, c))
    act = jax.jit(lambda sl, k, p: contacts.activate(op, sl, k, p))
    dea = jax.jit(contacts.deactivate)
    drift = jax.jit(lambda sl: contacts.drift(op, sl))
    cur = [int(bot[0]), int(top[0])]
    checked = raw = contacts.pair(op, 32, *cur)
    rng = np.random.default_rng(0)
    pool = [int(q) for q in np.r_[bot[1:], top[1:]]]
    refreshes, worst = 0, 0.0
    for _ in range(150):
        p = int(rng.choice(pool))
        new = [q for q in cur if q != p] if p in cur else cur + [p]
        checked, over, fresh = upd(checked, on(cur), on(new))
        assert not bool(over)
        refreshes += int(fresh)
        worst = max(worst, float(drift(checked)))
        raw = dea(raw, int(np.asarray(raw.slot)[p])) if p in cur else act(raw, int(np.argmax(np.asarray(raw.node) < 0)), p)
        cur = new
    assert float(drift(raw)) > 1e2 * contacts.DRIFT_TOL[0]
    assert worst <= contacts.DRIFT_TOL[0] and refreshes >= 1
    ref = np.linalg.inv(np.asarray(contacts.bordered_matrix_of(op, checked)))
    np.testing.assert_allclose(np.asarray(checked.Minv), ref, rtol=0, atol=1e-9 * np.abs(ref).max())


def test_check_refines_then_stops_with_stalled_when_an_event_undoes_itself(model, touched):
    """check: after an event at the depth where the last event left the squeeze, a contact set
    that came back to the modes from before the event would repeat forever. It is accepted as a
    row with ``stats.refined`` raised (the loop divides event_tol by REFINE[0] per refinement,
    and the next step locates the event anew), at most REFINE[1] times; then STALLED (a fault
    that finish reports first), never a loop. The same pass with the depth moved on is accepted
    as a row, no refinement; so is one whose row before was a step that stopped just short of
    the event, the last event's row a step behind (a cycle, not an event undone)."""
    st = _step(model, touched)                                        # a row at d = h, phase ADVANCE
    sol, dsol = _solved(model, st)
    undone = dataclasses.replace(st, phase=jnp.asarray(engine.CHECK, jnp.int32), d_star=st.d, before=st.nodes.mode,
                                 added=jnp.full_like(st.added, -1), checks=jnp.asarray(0, jnp.int32), d_ev=st.d)
    chk = jax.jit(engine.check)
    out, accept = chk(model, undone, sol, dsol, st.d)
    assert bool(accept) and int(out.fault) == engine.RUNNING and int(out.stats.refined) == 1
    spent = dataclasses.replace(undone, stats=undone.stats._replace(refined=jnp.asarray(engine.REFINE[1], jnp.int32)))
    out, accept = chk(model, spent, sol, dsol, st.d)
    assert bool(accept) and int(out.fault) == Status.STALLED and int(out.stats.refined) == engine.REFINE[1]
    assert int(jax.jit(engine.finish)(model, out, True).status) == Status.STALLED
    moved = dataclasses.replace(undone, d_star=st.d + model.h)
    out, accept = chk(model, moved, sol, dsol, st.d + model.h)
    assert bool(accept) and int(out.fault) == engine.RUNNING and int(out.stats.refined) == 0
    short = dataclasses.replace(undone, d_ev=st.d - model.h)
    out, accept = chk(model, short, sol, dsol, st.d)
    assert bool(accept) and int(out.fault) == engine.RUNNING and int(out.stats.refined) == 0


def test_check_resolves_an_unsettled_set_again_with_a_finer_tolerance(model, touched):
    """check: a set left ``unsettled`` after SETTLE_ITERS passes (a node still inside a tip) is
    not accepted: the row stays in CHECK at d* with ``stats.refined`` raised, which gives the
    hypothesis SETTLE_ITERS more passes at the finer tolerance; once REFINE[1] refinements are
    spent, STALLED."""
    st = _step(model, touched)
    sol, dsol = _solved(model, st)
    free = int(np.flatnonzero(np.asarray(st.nodes.mode) == FREE)[0])
    sunk = sol._replace(gap=sol.gap.at[free].set(-2 * engine.SUNK_TOLS[0] * model.gap_tol))
    at = dataclasses.replace(st, phase=jnp.asarray(engine.CHECK, jnp.int32), d_star=st.d, before=st.nodes.mode,
                             added=jnp.full_like(st.added, -1), checks=jnp.asarray(engine.SETTLE_ITERS, jnp.int32))
    chk = jax.jit(engine.check)
    out, accept = chk(model, at, sunk, dsol, st.d)
    assert not bool(accept) and int(out.fault) == engine.RUNNING and int(out.stats.refined) == 1
    assert int(out.phase) == engine.CHECK and np.array_equal(out.nodes.mode, st.nodes.mode)
    new_mode, *_ = jax.jit(engine._hypothesis)(model, out, sunk, dsol)      # more passes: it joins
    assert int(new_mode[free]) == STICK
    spent = dataclasses.replace(at, stats=at.stats._replace(refined=jnp.asarray(engine.REFINE[1], jnp.int32)),
                                checks=jnp.asarray(engine.SETTLE_ITERS * (1 + engine.REFINE[1]), jnp.int32))
    out, accept = chk(model, spent, sunk, dsol, st.d)
    assert bool(accept) and int(out.fault) == Status.STALLED


def test_a_check_pass_past_the_settle_limit_leaves_the_set_unsettled(model, touched):
    """_hypothesis at an event depth: a free node found inside a fingertip joins there (A), and
    a contact that pulls peels off (B), while CHECK passes remain; on pass ``SETTLE_ITERS``
    neither happens and the set is ``unsettled`` (check then stops with STALLED rather than
    accept a row with a node inside a tip or a contact pulling)."""
    st = _step(model, touched)                                        # the grip nodes in contact
    sol, dsol = _solved(model, st)
    mode = np.asarray(st.nodes.mode)
    free, held = int(np.flatnonzero(mode == FREE)[0]), int(np.flatnonzero(mode > FREE)[0])
    sunk = sol._replace(gap=sol.gap.at[free].set(-2 * engine.SUNK_TOLS[0] * model.gap_tol))
    pulls = sol._replace(fn=sol.fn.at[held].set(-float(engine.largest(sol.F))))
    hyp = jax.jit(engine._hypothesis)
    for checks in (0, engine.SETTLE_ITERS - 1, engine.SETTLE_ITERS):
        at = dataclasses.replace(st, phase=jnp.asarray(engine.CHECK, jnp.int32), d_star=st.d, before=st.nodes.mode,
                                 added=jnp.full_like(st.added, -1), checks=jnp.asarray(checks, jnp.int32))
        settle = checks < engine.SETTLE_ITERS
        new_mode, _, _, changed, unsettled, logged, kinds = hyp(model, at, sunk, dsol)
        assert (int(new_mode[free]) == STICK) == settle and bool(logged[free]) == settle
        assert bool(unsettled) != settle and bool(changed) == settle
        if settle:
            assert int(kinds[free]) == 0                                # logged as A
        new_mode, _, _, changed, unsettled, logged, kinds = hyp(model, at, pulls, dsol)
        assert (int(new_mode[held]) == FREE) == settle and bool(unsettled) != settle
        if settle:
            assert int(kinds[held]) == 1                                # logged as B
