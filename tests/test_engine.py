"""The engine's stages, each alone on a hand-built state (init, step, locate_event,
apply_event, finish), and the status precedence decided in finish."""
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


@pytest.fixture(scope="module")
def first(model):
    return jax.jit(engine.init)(model)


def test_init_touches_the_grip_nodes_and_records_one_row(model, first):
    assert int(first.status) == engine.RUNNING and int(first.count) == 1
    on = np.flatnonzero(np.asarray(first.mode) > FREE)
    assert sorted(on.tolist()) == sorted(np.asarray(model.grip).tolist())
    assert np.all(np.asarray(first.mode)[on] == STICK)
    np.testing.assert_array_equal(np.asarray(first.finger)[np.asarray(model.grip)], [0, 1])
    assert float(first.d) == 0.0 and np.abs(np.asarray(first.F)).max() < 1e-12   # no force at touch


def test_step_advances_by_one_step_when_nothing_happens(model, first):
    st = jax.jit(engine.step)(model, first)
    np.testing.assert_allclose(float(st.d), float(model.h), rtol=1e-12)
    assert int(st.count) == 2 and int(st.stats.steps) == 1 and int(st.stats.events) == 0
    F = np.asarray(st.F)
    assert np.abs(F.sum(0)).max() < 1e-12 * np.abs(F).max()      # equal and opposite


def test_locate_event_brackets_a_new_contact_and_apply_event_adds_it(model, first):
    """From the touch, the first event of the square is a new contact (A): located to the bracket
    tolerance, applied at one depth with the event logged."""
    c = engine.pack(model, first.mode, first.finger, first.theta, first.armed)
    D = model.D
    e_end = jnp.min(engine.solve_at(model, c, first.mode, D).e)
    assert float(e_end) < 0, "some node must touch before the target depth"
    lo, hi, iters = jax.jit(engine.locate_event)(model, c, first.mode, first.d, D, e_end)
    assert float(hi - lo) <= float(model.ev_tol) and int(iters) > 0
    assert float(jnp.min(engine.solve_at(model, c, first.mode, lo).e)) >= 0
    assert float(jnp.min(engine.solve_at(model, c, first.mode, hi).e)) < 0
    st = jax.jit(engine.apply_event)(model, first, c, lo, hi)
    assert int(st.n_ev) >= 1 and np.all(np.asarray(st.events[2])[: int(st.n_ev)] == 0)   # kind A
    assert float(lo) <= float(st.d) <= float(hi)
    assert np.sum(np.asarray(st.mode) > FREE) == 2 + int(st.n_ev)


def test_finish_decides_the_status_in_one_order(model, first):
    fin = jax.jit(engine.finish)
    mode, finger = np.asarray(first.mode), np.asarray(first.finger)
    i, j = (int(v) for v in np.asarray(model.grip))
    # a finger without contact: LOST_CONTACT (before SLIP_FAILURE)
    lost = dataclasses.replace(first, mode=jnp.asarray(np.where(np.arange(len(mode)) == j, FREE, mode)))
    assert int(fin(model, lost, True).status) == Status.LOST_CONTACT
    # every contact of one finger sliding: SLIP_FAILURE
    slid = dataclasses.replace(first, mode=jnp.asarray(np.where(np.arange(len(mode)) == i, SLIP_POS, mode)))
    assert int(fin(model, slid, True).status) == Status.SLIP_FAILURE
    # Newton failure comes before the contact checks, a stage's fault before everything
    assert int(fin(model, slid, False).status) == Status.NEWTON_FAILURE
    faulted = dataclasses.replace(slid, fault=jnp.asarray(Status.OVERFLOW, jnp.int32))
    assert int(fin(model, faulted, False).status) == Status.OVERFLOW
    nan = dataclasses.replace(first, F=first.F.at[0, 0].set(jnp.nan))
    assert int(fin(model, nan, True).status) == Status.NONFINITE
    done = dataclasses.replace(first, d=model.D)
    assert int(fin(model, done, True).status) == Status.SUCCESS
    assert int(fin(model, first, True).status) == engine.RUNNING


def test_stats_and_records_of_a_full_squeeze(model):
    st = jax.jit(lambda m: engine.run(m, engine.init(m)))(model)
    assert int(st.status) == Status.SUCCESS
    s = st.stats
    assert int(st.count) == 1 + int(s.steps) + int(s.events)
    assert int(s.events) >= 1 and int(s.bracket_iters) >= int(s.events)
    rigid = np.asarray(st.hist[8])[int(st.count) - 1]
    np.testing.assert_allclose(rigid, np.asarray(st.g), rtol=0, atol=0)   # the rigid part is recorded
