"""Hard cases (build issue 5): material, mesh, friction, geometry and event extremes, float32
against float64, and bad input at the API and the command line.

Every squeeze here must give a finite result, hold the per-state invariants of
``physics.check_states`` and report a meaningful status. Most scenes share one mesh
(``SQ``) and one static configuration, so they reuse one compiled squeeze; the numbers
measured here are recorded in docs/numerics.md.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap

import jax
import meshio
import numpy as np
import pytest

import jaxsqueeze as jsq
from jaxsqueeze.io import cli, scenefile
from jaxsqueeze.simulation import api as grasp_mod
from jaxsqueeze.simulation.laws import CONE_SLACK
import physics
from physics import Bounds, check_states, nearest, replay_events, sliding_against_friction, symmetric_square

HERE = os.path.dirname(os.path.abspath(physics.__file__))   # tests/: physics.py for the child
ROOT = physics.ROOT

MAT = jsq.Material(E=1e5, nu=0.3, thickness=0.0254)
SQ = symmetric_square(0.1, 0.008)          # m = 56 boundary nodes, spacing 0.1/14 = 7.1 mm
SPACING = SQ.edge_length()
RESULT_FIELDS = ("depth", "forces", "boundary_displacement", "centres", "theta", "g")


def base_scene(mesh=SQ, **kw):
    a = np.ptp(mesh.points[:, 1]) / 2
    grip = (nearest(mesh, (0.0, -a) + mesh.offset), nearest(mesh, (0.0, a) + mesh.offset))
    args = dict(mesh=mesh, material=MAT, fingers=jsq.Fingers(radius=0.015), grip=grip, friction=0.5, depth=0.012)
    args.update(kw)
    return jsq.Scene(**args)


def assert_sane(res, scene, statuses=(jsq.Status.SUCCESS,)):
    """Finite arrays, a status from ``statuses`` with advice, and the invariants of every state."""
    assert res.outcome in statuses, f"{res.outcome.name}: {res.outcome.advice}"
    assert res.outcome.advice
    for name in RESULT_FIELDS:
        assert np.all(np.isfinite(np.asarray(getattr(res, name)))), f"non-finite {name}"
    if res.displacement is not None:
        assert np.all(np.isfinite(np.asarray(res.displacement)))
    F = np.abs(np.asarray(res.forces)).max()
    unit = float(scene.material.E * scene.material.thickness * np.ptp(scene.mesh.points, axis=0).max())
    if F <= 1e-12 * unit:
        # the squeeze ended at the touch (d = 0 up to round-off): forces are round-off
        # (1e-32 N), whose relative balance check_states cannot judge
        assert res.final_depth <= 1e-12 * float(np.ptp(scene.mesh.points, axis=0).max())
        return
    mu = float(scene.friction) if scene.friction_model == "coulomb" else 0.0
    check_states(res, scene.mesh, mu, scene.friction_model)


def squeeze_ok(scene, statuses=(jsq.Status.SUCCESS,)):
    res = jsq.squeeze(scene)
    assert_sane(res, scene, statuses)
    return res


def f2(res, row=-1):
    """Total force of finger 2 on the object [N]."""
    return res.total_force[row][1]


def event_depths(res):
    return np.array([d for d, *_ in res.events.rows()])


def kinds(res):
    return "".join(k for _, _, k, _ in res.events.rows())


@pytest.fixture(scope="module")
def base():
    return squeeze_ok(base_scene())


# ============================================================================ material extremes
@pytest.mark.parametrize("nu", [0.4999, 0.5, -0.99])
def test_poisson_extremes(nu, base):
    """Nearly incompressible, exactly incompressible (plane stress allows ν = 0.5) and auxetic."""
    scene = base_scene(material=jsq.Material(E=1e5, nu=nu, thickness=0.0254))
    res = squeeze_ok(scene)
    assert res.final_depth == pytest.approx(0.012, rel=1e-12)
    F = f2(res)
    assert F[1] < 0 and abs(F[0]) < 1e-9 * abs(F[1])
    # docs/numerics.md: ν = 0.4999 and ν = 0.5 agree to 2e-5 (1.3e-5)
    if nu >= 0.4999:
        other = jsq.squeeze(base_scene(material=jsq.Material(E=1e5, nu=0.5 if nu < 0.5 else 0.4999, thickness=0.0254)))
        np.testing.assert_allclose(F, f2(other), rtol=2e-5, atol=1e-9)


def test_forces_scale_linearly_with_E(base):
    """Displacements are fixed by the fingertips, so forces = E x (forces at E = 1): exactly linear."""
    ref = base
    for E in (1e3, 1e8, 2e11):
        res = squeeze_ok(base_scene(material=jsq.Material(E=E, nu=0.3, thickness=0.0254)))
        assert kinds(res) == kinds(ref)
        np.testing.assert_allclose(event_depths(res), event_depths(ref), rtol=1e-12)
        np.testing.assert_array_equal(np.asarray(res.modes), np.asarray(ref.modes))
        np.testing.assert_allclose(np.asarray(res.forces) / E, np.asarray(ref.forces) / 1e5, rtol=1e-9,
                                   atol=1e-12 * np.abs(ref.forces).max() / 1e5)
        np.testing.assert_allclose(res.displacement, ref.displacement, rtol=1e-9, atol=1e-15)


def test_millimetres_and_metres_give_the_same_physics(base):
    """The same square with every length x k (mesh, radius, depth, step; thickness kept).

    Plane stress: strain ε = u/L is unchanged when u and L both grow by k, so the stress
    σ = E ε is unchanged and a force (σ x thickness x length along the contact) grows by k.
    Displacements and event depths grow by k; modes, events and angles are identical.
    """
    k = 1000.0
    big = jsq.Mesh.from_arrays(SQ.points * k, SQ.triangles)
    np.testing.assert_array_equal(big.boundary, SQ.boundary)
    scene = base_scene(big, fingers=jsq.Fingers(radius=0.015 * k), depth=0.012 * k,
                       settings=jsq.Settings(step=0.012 / 50 * k))
    assert scene.grip == base_scene().grip
    with pytest.warns(UserWarning, match="the object is 100 m across; every length is in metres"):
        res = squeeze_ok(scene)                      # scaled on purpose: it works, and it warns of mixed units
    assert kinds(res) == kinds(base)
    np.testing.assert_array_equal(np.asarray(res.modes), np.asarray(base.modes))
    np.testing.assert_allclose(event_depths(res), k * event_depths(base), rtol=1e-10)
    np.testing.assert_allclose(np.asarray(res.forces), k * np.asarray(base.forces), rtol=1e-9,
                               atol=1e-10 * k * np.abs(base.forces).max())
    np.testing.assert_allclose(res.displacement, k * np.asarray(base.displacement), rtol=1e-9,
                               atol=1e-10 * k * np.abs(base.displacement).max())
    np.testing.assert_allclose(np.asarray(res.theta), np.asarray(base.theta), atol=1e-10)


# ============================================================================ mesh extremes
def _grid(nx, ny, a=0.1):
    xs, ys = np.linspace(-a / 2, a / 2, nx + 1), np.linspace(-a / 2, a / 2, ny + 1)
    X, Y = np.meshgrid(xs, ys)
    P = np.c_[X.ravel(), Y.ravel()]
    idx = np.arange(P.shape[0]).reshape(ny + 1, nx + 1)
    a_, b_, c_, d_ = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    T = np.r_[np.c_[a_, b_, c_], np.c_[a_, c_, d_]]
    return P, T


def test_sliver_triangles_change_little():
    """Interior columns of a grid pushed 95 % of the way to their neighbours: cells 1/20 as wide
    as tall (min angle < 5°), boundary untouched. The squeeze holds its invariants and the force
    stays within 10 % of the regular grid's (measured 5.7 %: the moved columns leave cells
    1.95 h wide, a genuinely coarser discretization, so the two meshes need not agree closer)."""
    P, T = _grid(14, 14)
    h = 0.1 / 14
    Q = P.copy()
    inner = (np.abs(P[:, 0]) < 0.05 - 1e-9) & (np.abs(P[:, 1]) < 0.05 - 1e-9)
    col = np.round((P[:, 0] + 0.05) / h).astype(int)
    move = inner & (col % 3 == 1)
    Q[move, 0] += 0.95 * h
    regular, sliver = jsq.Mesh.from_arrays(P, T), jsq.Mesh.from_arrays(Q, T)
    assert sliver.min_angle() < 5.0 < regular.min_angle()
    r_reg = squeeze_ok(base_scene(regular))
    r_sl = squeeze_ok(base_scene(sliver))
    F_reg, F_sl = f2(r_reg)[1], f2(r_sl)[1]
    print(f"sliver mesh: min angle {sliver.min_angle():.2f} deg, force {F_sl:.4f} N vs regular {F_reg:.4f} N")
    assert abs(F_sl - F_reg) < 0.10 * abs(F_reg)


def test_strong_grading_near_the_contacts():
    """refine_edge = max_edge / 20 near both grip points."""
    g = [(0.0, -0.05), (0.0, 0.05)]
    mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=0.01, refine_near=g, refine_edge=0.0005)
    e = np.linalg.norm(mesh.points[np.roll(mesh.boundary, -1)] - mesh.points[mesh.boundary], axis=1)
    assert e.max() / e.min() > 15
    res = squeeze_ok(base_scene(mesh, depth=0.004, settings=jsq.Settings(capacity=96)))
    assert len(event_depths(res)) >= 4
    assert f2(res)[1] < 0


def test_twenty_thousand_nodes_sparse():
    """A 20,000+ node square with the sparse build: one deform and a short squeeze."""
    mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=0.00075)
    assert mesh.n > 20_000
    op = jsq.fem.compliance(mesh, MAT, "sparse")
    grip = (nearest(mesh, (0, -0.05)), nearest(mesh, (0, 0.05)))
    sol = jsq.deform(op, list(grip), [[0.0, 5e-4], [0.0, -5e-4]])
    assert np.all(np.isfinite(sol.forces)) and np.all(np.isfinite(sol.displacement))
    np.testing.assert_allclose(sol.forces.sum(0), 0.0, atol=1e-10 * np.abs(sol.forces).max())
    assert sol.forces[0, 1] > 0
    scene = jsq.Scene(mesh=mesh, material=MAT, fingers=jsq.Fingers(radius=0.015), grip=grip, friction=0.5,
                      depth=4e-4, settings=jsq.Settings(step=1e-4, capacity=16, max_steps=40, max_events=32))
    res = squeeze_ok(scene)
    assert "A" in kinds(res)


@pytest.mark.parametrize("factor", [20.0, 0.2])
def test_fingertip_much_larger_or_smaller_than_node_spacing(factor):
    r = factor * SPACING
    depth = 0.012 if factor > 1 else 0.004
    res = squeeze_ok(base_scene(fingers=jsq.Fingers(radius=r), depth=depth))
    n_contact = int(np.sum(np.asarray(res.modes[-1]) > 0))
    if factor > 1:
        assert n_contact > 10            # a flat-ish tip lays down on many nodes
    else:
        assert n_contact == 2            # a needle: neighbours 7 mm away never reach it


# ============================================================================ friction extremes
def test_frictionless_model_and_zero_coulomb_friction(base):
    fl = squeeze_ok(base_scene(friction_model="frictionless"))
    assert set(kinds(fl)) <= {"A", "B"}
    # docs/numerics.md: Coulomb with mu = 0 on the mirror-symmetric base scene: the grip
    # contacts' tangential forces are round-off, inside the cone slack, so they stick and every
    # new contact slides at once (AAAACCCC); the forces are the frictionless ones
    c0 = squeeze_ok(base_scene(friction=0.0))
    assert "".join(kinds(c0)) == "AAAACCCC"
    np.testing.assert_allclose(f2(c0), f2(fl), rtol=1e-6, atol=1e-9 * abs(f2(fl)[1]))


def test_tiny_and_huge_friction(base):
    small = squeeze_ok(base_scene(friction=1e-3), (jsq.Status.SUCCESS, jsq.Status.SLIP_FAILURE))
    huge = squeeze_ok(base_scene(friction=1e6))
    assert set(kinds(huge)) == {"A"}
    assert np.all(np.asarray(huge.modes) <= 1)
    # a huge mu is the all-stick squeeze of the base scene (mu = 0.5 never slips there)
    np.testing.assert_allclose(np.asarray(huge.forces), np.asarray(base.forces), atol=1e-12 * np.abs(base.forces).max())
    # with mu = 1e-3 the forces are nearly the frictionless ones (within 1 %)
    fl = jsq.squeeze(base_scene(friction_model="frictionless"))
    if small.outcome == jsq.Status.SUCCESS:
        assert abs(f2(small)[1] - f2(fl)[1]) < 0.01 * abs(f2(fl)[1])


def _edge_grip():
    i, j = nearest(SQ, (-0.01, -0.05)), nearest(SQ, (0.01, 0.05))
    pos = {int(v): k for k, v in enumerate(SQ.boundary)}
    seg = (SQ.points[j] - SQ.points[i]) / np.linalg.norm(SQ.points[j] - SQ.points[i])
    ang = np.arccos(np.clip([-SQ.normals[pos[i]] @ seg, SQ.normals[pos[j]] @ seg], -1, 1))
    return (i, j), float(ang.max())


def test_initial_force_exactly_on_the_cone_edge():
    """mu = tan(angle between segment and node normals): the two-contact force lies on the edge."""
    grip, ang = _edge_grip()
    edge = squeeze_ok(base_scene(grip=grip, friction=float(np.tan(ang))))      # docs/numerics.md: SUCCESS,
    inside = squeeze_ok(base_scene(grip=grip, friction=float(np.tan(ang)) * (1 + 1e-6)))   # the same events
    assert "".join(kinds(edge)) == "".join(kinds(inside)) == "AACCAACCDDCC"
    np.testing.assert_allclose(f2(edge), f2(inside), rtol=1e-7)
    # just outside the cone beyond the slack: refused before any tracing
    with pytest.raises(ValueError, match="friction cones"):
        jsq.squeeze(base_scene(grip=grip, friction=float(np.tan(ang - 2 * CONE_SLACK))))


def test_grip_within_cone_slack_counts_as_inside():
    grip, ang = _edge_grip()
    within = jsq.squeeze(base_scene(grip=grip, friction=float(np.tan(ang - 0.5 * CONE_SLACK))))
    inside = jsq.squeeze(base_scene(grip=grip, friction=float(np.tan(ang)) * (1 + 1e-6)))
    assert within.outcome == jsq.Status.SUCCESS, (within.outcome.name, within.final_depth)
    np.testing.assert_allclose(f2(within), f2(inside), rtol=1e-3)


def test_cone_check_agrees_between_api_and_scene_file():
    grip, ang = _edge_grip()
    scene = base_scene(grip=grip, friction=float(np.tan(ang - 0.5 * CONE_SLACK)))
    grasp_mod.check_grip(scene, scene.operator())       # the API accepts it
    scenefile._check_cones(scene, "grip.nodes")         # so should the scene file


def test_a_frictionless_grip_refusal_does_not_ask_for_friction():
    """Friction does not enter a frictionless grip's check (its fingertips sit on the segment):
    the message names the allowed turn instead of a friction cone, and no friction fixes it."""
    grip, ang = _edge_grip()
    scene = base_scene(grip=grip, friction=10.0, friction_model="frictionless")
    with pytest.raises(ValueError, match="frictionless fingertips sit on the segment") as err:
        grasp_mod.check_grip(scene, scene.operator())
    assert "friction cones" not in str(err.value) and "raise the friction" not in str(err.value)


# ============================================================================ geometry
def test_grip_at_corner_nodes():
    """Opposite corners: the node normal is the bisector (-1, -1)/√2 of the two edge normals
    (mesh._loop_normals), the diagonal segment lies on both cone axes, and the squeeze runs."""
    c1, c2 = nearest(SQ, (-0.05, -0.05)), nearest(SQ, (0.05, 0.05))
    pos = {int(v): k for k, v in enumerate(SQ.boundary)}
    np.testing.assert_allclose(SQ.normals[pos[c1]], [-np.sqrt(0.5), -np.sqrt(0.5)], atol=1e-15)
    res = squeeze_ok(base_scene(grip=(c1, c2), depth=0.006, friction=0.2))
    F = f2(res)
    assert F[0] == pytest.approx(F[1], rel=1e-9) and F[0] < 0     # along the diagonal


def test_contact_region_grows_around_a_corner():
    """A wide fingertip gripping next to the corners: the contact region takes in the corner node."""
    grip = (nearest(SQ, (0.045, -0.05)), nearest(SQ, (0.045, 0.05)))
    res = squeeze_ok(base_scene(grip=grip, fingers=jsq.Fingers(radius=0.04)))
    corners = {nearest(SQ, (0.05, -0.05)), nearest(SQ, (0.05, 0.05))}
    contact = set(np.asarray(res.nodes)[np.asarray(res.modes[-1]) > 0].tolist())
    assert corners <= contact
    assert res.total_force[-1][1][0] != 0      # off-centre grip: a sideways force component


L_SHAPE = np.array([[0, 0], [0.1, 0], [0.1, 0.04], [0.04, 0.04], [0.04, 0.1], [0, 0.1]])


def test_non_convex_l_shape_with_a_grazing_wall():
    """L-shape pressed on its inner ledge next to the re-entrant wall: the fingertip passes the
    wall at a gap of 2 % of its radius, so wall nodes approach it tangentially."""
    mesh = jsq.shapes.polygon(L_SHAPE, max_edge=0.006)
    r = 0.012
    top = nearest(mesh, (0.04 + 1.02 * r, 0.04))
    bottom = nearest(mesh, ((mesh.points[top] + mesh.offset)[0], 0.0))
    res = squeeze_ok(jsq.Scene(mesh=mesh, material=MAT, fingers=jsq.Fingers(radius=r), grip=(bottom, top),
                               friction=0.5, depth=0.008))
    assert f2(res)[1] < 0


def test_annulus_with_hole():
    mesh = jsq.shapes.annulus(0.05, 0.025, max_edge=0.006)
    assert len(mesh.loops) == 2
    res = squeeze_ok(base_scene(mesh, depth=0.01))
    hole = np.asarray(mesh.boundary[mesh.loops[0]:])
    assert not np.any(np.isin(np.asarray(res.events.node), hole)), "a hole node touched an outside finger"
    contact = np.asarray(res.nodes)[np.asarray(res.modes).max(0) > 0]
    assert not np.any(np.isin(contact, hole))
    assert f2(res)[1] < 0


# ============================================================================ events
def test_simultaneous_events_on_both_fingers(base):
    """symmetric_square: the four events (two nodes per finger, mirrored) are one event depth."""
    rows = base.events.rows()
    assert len(rows) == 4
    assert len({d for d, *_ in rows}) == 1, "mirror events located at different depths"
    assert sorted(f for *_, f in rows) == [0, 0, 1, 1]
    P = SQ.points
    nodes = [n for _, n, _, _ in rows]
    for mirror in ([1, -1], [-1, 1]):
        key = lambda p: tuple(np.round(p / 1e-12).astype(int))  # noqa: E731
        assert {key(P[n] * mirror) for n in nodes} == {key(P[n]) for n in nodes}


def test_several_events_inside_one_step(base):
    """One step over the whole depth: all four events are located inside it, at the same depths."""
    res = squeeze_ok(base_scene(settings=jsq.Settings(step=0.012, event_tol=1e-10)))
    assert kinds(res) == kinds(base)
    np.testing.assert_allclose(event_depths(res), event_depths(base), rtol=0, atol=1e-9 * 0.012)
    np.testing.assert_allclose(f2(res), f2(base), rtol=1e-9, atol=1e-12 * np.abs(f2(base)).max())


def test_event_exactly_at_the_target_depth(base):
    d_ev = event_depths(base)[0]
    res = squeeze_ok(base_scene(depth=d_ev))
    assert res.final_depth == d_ev
    assert len(event_depths(res)) in (0, 2, 4)                 # all of a mirror pair or none
    # the state at the target is the base run's there: a contact that just touches carries no
    # force, so with or without the new contacts the forces agree to the located depth's accuracy
    k = int(np.flatnonzero(np.asarray(base.depth) == d_ev)[0])
    np.testing.assert_allclose(f2(res), f2(base, k), rtol=1e-6, atol=1e-12 * np.abs(f2(base)).max())


def test_a_finger_peeling_off_releases_its_contacts_at_one_depth():
    """Full stick on a slender bar (auxetic, soft): at 9.57 mm finger 1's contact 22 lets go
    (event B) and the release pulls on its neighbour 23, which lets go at the same depth (a B
    event of the same row) instead of being recorded pulling with 30 % of the largest force, as
    it was. Every row holds the invariants until the one in which finger 1 is empty, and the
    squeeze ends there, LOST_CONTACT (that row is finger 0's contacts alone: a body held by one
    finger, whatever its sticking contacts carry, is no grasp)."""
    import dataclasses
    mesh = jsq.shapes.rectangle(0.03, 0.12, max_edge=0.007)
    sc = jsq.Scene(mesh=mesh, material=jsq.Material(E=5101.2, nu=-0.14547, thickness=0.012386),
                   fingers=jsq.Fingers(radius=0.014735), grip=(2, 22), friction=0.5489, depth=0.0124,
                   friction_model="stick")
    res = jsq.squeeze(sc)
    assert res.status == jsq.Status.LOST_CONTACT
    check_states(dataclasses.replace(res, count=res.count - 1), mesh, 0.5489, "stick")
    at_end = [(node, kind, finger) for depth, node, kind, finger in res.events.rows()
              if depth == pytest.approx(res.final_depth, abs=1e-12)]
    assert at_end == [(22, "B", 1), (23, "B", 1)]
    final = np.asarray(res.modes[-1]) > 0
    assert final.sum() == 2 and not np.any(final & (np.asarray(res.finger[-1]) == 1))
    assert res.depth[-2] < res.final_depth and np.all(np.isfinite(res.forces))     # one row for both releases


def test_a_release_that_lands_a_node_inside_a_fingertip_rejoins_until_it_comes_free():
    """Full stick with turning tips (found by the rotating oracle): tip 1 drags its grip node 134
    sideways until its normal force reaches zero while it still carries 1.1 N of shear. Event B
    drops that shear and the node lands 4.8e-4 L inside the tip: it joins again where it is (A
    at the same depth, as the next step's event location would find it; it went on with the
    node inside the tip, SUCCESS, and later stopped there, STALLED). At 12.164 mm it lets go
    again, lands inside and joins, and pulls again 2.7 µm and then 30 nm deeper: cycles that
    shrink until, released at 12.167192 mm, it no longer sinks. The engine judged a contact made
    at the event depth by its force 3 µm (step / 100) beyond it, past the next cycle's end: it
    pulled at once, and after SETTLE_ITERS passes of B/A at one depth the squeeze stopped with
    STALLED at 12.1645 mm. Judged at event_tol beyond it (3 nm), the squeeze follows the cycles
    to 15 mm, event for event with the oracle at any of its steps (docs/numerics.md §2, 21),
    and every row holds the invariants."""
    from jaxsqueeze.simulation.engine import SUNK_TOLS
    mesh = symmetric_square(0.1, 0.01)
    sc = jsq.Scene(mesh=mesh, material=jsq.Material(E=1e5, nu=0.3, thickness=0.0254),
                   fingers=jsq.Fingers(radius=0.03, rotation=[[-27.5, 0.0], [33.5, 0.0]]),
                   grip=(6, 134), friction=0.5, depth=0.015, friction_model="stick")
    res = jsq.squeeze(sc)
    assert res.outcome == jsq.Status.SUCCESS and res.final_depth == pytest.approx(0.015, rel=1e-12)
    rows = res.events.rows()
    cycles = [(round(d * 1e3, 6), k) for d, n, k, f in rows if (n, f) == (134, 1)]
    assert cycles == [(11.932844, "B"), (11.932844, "A"), (12.164466, "B"), (12.164466, "A"),
                      (12.167162, "B"), (12.167162, "A"), (12.167192, "B")]
    check_states(res, mesh, 0.5, "stick")
    k = list(np.asarray(res.nodes)).index(134)
    gap = lambda r: np.linalg.norm(mesh.points[mesh.boundary][k] + np.asarray(res.boundary_displacement[r][k])  # noqa: E731
                                   - np.asarray(res.centres[r][1])) - 0.03
    for d, kind in cycles:                  # rejoined on the tip's surface; free at last, outside it
        at = int(np.flatnonzero(np.abs(np.asarray(res.depth) - d * 1e-3) <= 1e-9)[-1])
        if kind == "A":
            assert res.modes[at][k] == 1 and abs(gap(at)) <= 1e-12
    assert res.modes[at][k] == 0 and gap(at) > -SUNK_TOLS[0] * 1e-9 * 0.1


def test_a_corner_pinched_between_both_tips_warns():
    """docs/numerics.md §2, 27 (a random full-stick scene against the oracle): a rectangle's
    corner node between two 240 mm tips touches both at 1.0776 mm; a node holds one contact,
    and the other tip passes through it, 1.5 mm deep at 3.2 mm. The squeeze warns from the
    first row where it is inside, and not before that depth; with point contacts it warns of
    the free nodes a tip passes through."""
    import warnings
    mesh = jsq.shapes.rectangle(0.08, 0.05, max_edge=0.005)
    corner = mesh.points[0]
    ring = list(mesh.boundary)
    at = ring.index(0)
    assert np.argmin(mesh.points.sum(axis=1)) == 0 and {ring[at - 1], ring[(at + 1) % len(ring)]} == {1, 51}
    sc = jsq.Scene(mesh=mesh, material=jsq.Material(E=1e5, nu=-0.9, thickness=0.0254), fingers=jsq.Fingers(radius=0.24),
                   grip=(51, 1), friction=0.5, depth=0.0032, friction_model="stick")
    with pytest.warns(UserWarning, match=r"node 0, a contact of finger 0, lies inside fingertip 1") as said:
        res = jsq.squeeze(sc)
    assert res.outcome == jsq.Status.SUCCESS
    k = list(np.asarray(res.nodes)).index(0)
    x = corner + np.asarray(res.boundary_displacement)[:, k]                # (rows, 2) node 0, deformed
    inside = 0.24 - np.linalg.norm(x - np.asarray(res.centres)[:, 1], axis=1)
    on_0 = (np.asarray(res.modes)[:, k] > 0) & (np.asarray(res.finger)[:, k] == 0)
    first = int(np.argmax(on_0 & (inside > 10 * 1e-9 * 0.08)))
    assert inside[-1] == pytest.approx(1.52e-3, rel=0.01) and on_0[-1]
    [message] = [str(w.message) for w in said if "fingertip 1" in str(w.message)]
    assert {w.filename for w in said} == {__file__}
    assert f"from depth = {res.depth[first]:g} m" in message and "corner" in message
    assert 1.0776e-3 < res.depth[first] < 1.2e-3
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        before = jsq.squeeze(sc.replace(depth=0.00107))                          # node 0 still free
    assert before.outcome == jsq.Status.SUCCESS
    # point contacts (one node per tip, no event A) on this solid: tip 0 passes through node 50
    with pytest.warns(UserWarning, match=r"node 50, free, lies inside fingertip 0 .*contact='segment'"):
        point = jsq.squeeze(sc.replace(contact="point"))
    k = list(np.asarray(point.nodes)).index(50)
    x = mesh.points[50] + np.asarray(point.boundary_displacement)[-1, k]
    assert point.modes[-1][k] == 0 and 0.24 - np.linalg.norm(x - np.asarray(point.centres)[-1, 0]) > 1e-3


def test_an_eager_squeeze_that_runs_out_of_steps_squeezes_again_with_more():
    """Settings.max_steps = None: 400 loop iterations, and an eager squeeze that needs more
    squeezes again with 1,600 (the same squeeze: its first 401 rows are those of max_steps =
    400 set, which stops MAX_STEPS after 401 rows, advice naming max_steps); a bound the
    settings set does not grow."""
    fine = base_scene(settings=jsq.Settings(step=0.012 / 450))
    res = squeeze_ok(fine)
    assert int(res.count) > 401 and res.final_depth == pytest.approx(0.012, abs=1e-12)
    cut = squeeze_ok(fine.replace(settings=jsq.Settings(step=0.012 / 450, max_steps=400)),
                     (jsq.Status.MAX_STEPS,))
    assert int(cut.count) == 401 and cut.final_depth < 0.012 and "max_steps" in cut.outcome.advice
    np.testing.assert_array_equal(cut.forces, res.forces[:401])
    np.testing.assert_array_equal(cut.modes, res.modes[:401])


def test_automatic_loop_bounds_grow_fourfold_up_to_sixteen_times(monkeypatch):
    """The rule behind the rerun (``api._longer``): both automatic bounds x4 when either runs
    out, up to 6,400 steps and 4,096 events, the loop bound enough for the target depth at
    the pace of the rows so far (none when not even 6,400 are: a step far too small); a
    bound the settings set neither grows nor lets the squeeze rerun when it is the one that
    ran out; nothing beyond the memory limit."""
    from jaxsqueeze.simulation import scene as scene_mod, validate

    def stop(status, reached=0.006):            # a squeeze to 12 mm stopped at 6 mm
        return status, reached

    S, E = stop(jsq.Status.MAX_STEPS), stop(jsq.Status.EVENT_OVERFLOW)
    sc = base_scene()
    cfg = grasp_mod.config_of(sc, eager=True)
    assert (cfg.max_steps, cfg.max_events) == (scene_mod.STEPS, scene_mod.EVENTS) == (400, 256)
    assert grasp_mod.config_of(sc).max_events == 256                   # traced: the same start, no rerun
    longer = grasp_mod._longer(sc, cfg, *S)
    longest = grasp_mod._longer(sc, longer, *E)
    assert [(c.max_steps, c.max_events) for c in (longer, longest)] == [(1600, 1024), (6400, 4096)]
    assert longest.capacity == cfg.capacity and grasp_mod._longer(sc, longest, *S) is None
    # 2,400 / 6,900 / endless rows to 12 mm
    for reached, bounds in ((0.002, (6400, 4096)), (0.0007, None), (0.0, None)):
        grown = grasp_mod._longer(sc, cfg, *stop(jsq.Status.MAX_STEPS, reached=reached))
        assert bounds == (grown and (grown.max_steps, grown.max_events))
    fixed = sc.replace(settings=jsq.Settings(max_steps=500))
    c = grasp_mod.config_of(fixed, eager=True)
    assert grasp_mod._longer(fixed, c, *S) is None
    events_out = grasp_mod._longer(fixed, c, *E)
    assert (events_out.max_steps, events_out.max_events) == (500, 1024)
    monkeypatch.setattr(validate, "MEMORY_LIMIT", 2 * validate.history_bytes(56, cfg.capacity, 400, 256))
    assert len(sc.boundary_nodes()) == 56 and validate.scene_cost_problems(sc) == []
    assert grasp_mod._longer(sc, cfg, *E) is None


def test_too_few_slots_gives_overflow_with_advice():
    res = jsq.squeeze(base_scene(settings=jsq.Settings(capacity=2)))
    assert res.outcome == jsq.Status.OVERFLOW, res.outcome.name
    assert "capacity" in res.outcome.advice


# ============================================================================ precision
F32_SCRIPT = textwrap.dedent("""
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", False)
    sys.path.insert(0, {here!r})
    import numpy as np
    import jaxsqueeze as jsq
    from physics import FLOAT32, check_states, hexagon_scene, nearest, peel_scene, symmetric_square
    mesh = symmetric_square(0.1, 0.008)
    grip = (nearest(mesh, (0, -0.05)), nearest(mesh, (0, 0.05)))
    out, held = {{}}, {{}}

    def bounded(name, res, mesh, mu, bounds=FLOAT32, model="coulomb"):     # check_states: "" or what broke
        try:
            check_states(res, mesh, mu, model, bounds=bounds)
            held[name] = ""
        except AssertionError as e:
            held[name] = str(e)

    for name, E, depth, mu in {cases!r} + [("low friction", 1e5, 0.012, 0.2)]:
        mat = jsq.Material(E=E, nu=0.3, thickness=0.0254)
        res = jsq.squeeze(jsq.Scene(mesh=mesh, material=mat, fingers=jsq.Fingers(radius=0.015), grip=grip,
                                    friction=mu, depth=depth))
        assert res.forces.dtype == np.float32
        out[name] = dict(status=res.outcome.name, F=res.total_force[-1][1].tolist(),
                         events=[[d, k] for d, _, k, _ in res.events.rows()],
                         modes=np.asarray(res.modes[-1]).tolist())
        bounded(name, res, mesh, mu)
    hexagon = hexagon_scene()
    res = jsq.squeeze(hexagon)
    out["hexagon"] = dict(status=res.outcome.name, depth=float(res.final_depth),
                          events=[[d, n, k] for d, n, k, _ in res.events.rows()])
    # fingertips of 3 L: a float32 polar angle moves a node by r eps |theta| ~ 1e-6 L along its
    # tip, which puts its slip force 2.3e-4 of the largest force off the cone's edge
    bounded("hexagon", res, hexagon.mesh, float(hexagon.friction), FLOAT32._replace(force=5e-4))
    peel = peel_scene()
    res = jsq.squeeze(peel)
    out["peel"] = dict(status=res.outcome.name, F=np.asarray(res.forces[-1]).tolist(),
                       modes=np.asarray(res.modes[-1]).tolist(), kinds=[k for _, _, k, _ in res.events.rows()])
    bounded("peel", res, peel.mesh, float(peel.friction), FLOAT32, "stick")
    out["bounds"] = held
    print(json.dumps(out))
""")
F32_CASES = [("foam", 1e5, 0.012, 0.5), ("steel", 2e11, 0.012, 0.5), ("deep", 1e5, 0.03, 0.5),
             ("tiny", 1e5, 1e-6, 0.5)]


@pytest.fixture(scope="module")
def float32_runs():
    code = F32_SCRIPT.format(here=HERE, cases=F32_CASES)
    env = dict(os.environ, JAX_ENABLE_X64="0")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_a_float32_contact_joining_outside_its_cone_slides_as_in_float64(float32_runs):
    """In float32 a new contact's force at the hypothesis probe is mostly the normal push of
    the gap_tol penetration it was found at, which read as inside the cone: node 30 stuck and
    the squeeze reached 6.4 mm with SUCCESS where float64 (and the oracle) fail by total slip
    at 0.98 mm. Its force rate decides in float32 now, as for the pull test."""
    r32 = float32_runs["hexagon"]
    r64 = jsq.squeeze(physics.hexagon_scene())
    assert r32["status"] == r64.outcome.name == "SLIP_FAILURE"
    assert abs(r32["depth"] - float(r64.final_depth)) < 1e-4 * 0.08
    assert [(n, k) for _, n, k in r32["events"]] == [(n, k) for _, n, k, _ in r64.events.rows()]
    assert ["A", "C"] == [k for _, n, k in r32["events"] if n == 30]


def test_float32_states_hold_the_float32_bounds(float32_runs):
    """docs/numerics.md §3: check float32 results against float32's bounds
    (``physics.FLOAT32``: balance 1e-5, contact nodes 2e-6 L off their circle, free nodes 2e-5 L
    inside a tip, cone and pull 1e-4 of the largest force; 5e-4 with the hexagon's fingertips of
    3 L, whose polar angles hold a node's place on the tip only to r eps |theta|), which every row
    of these squeezes holds (the low-friction case is the section's probe of a node that joins
    sticking and slides 75 µm deeper); float64's (``physics.FLOAT64``) are 100 to 10,000 times tighter."""
    assert float32_runs["bounds"] == {name: "" for name in float32_runs["bounds"]}
    assert set(float32_runs["bounds"]) == {c[0] for c in F32_CASES} | {"low friction", "hexagon", "peel"}


def test_float32_follows_a_node_that_peels_off_in_cycles_as_float64_does(float32_runs):
    """Full stick on an ellipse (nu = -0.9, r = 100 mm): a node touches and peels off again in
    cycles. A node that a release sank joins on a later CHECK pass and carries a force of its
    own at d*; float32 judged it by the sign of its force's rate, as it judges a contact just
    made (whose force there is round-off): a rate of round-off sign let it go, it sank, joined
    again, and the squeeze STALLED at 3.21 mm. It is judged by its force now, as in float64:
    SUCCESS, the same final modes, forces within 1e-3 of the largest (docs/numerics.md §3)."""
    r32 = float32_runs["peel"]
    r64 = squeeze_ok(physics.peel_scene())
    assert r32["status"] == r64.outcome.name == "SUCCESS"
    assert "B" in r32["kinds"] and "B" in [k for _, _, k, _ in r64.events.rows()]
    np.testing.assert_array_equal(r32["modes"], np.asarray(r64.modes[-1]))
    F64 = np.asarray(r64.forces[-1])
    assert np.abs(np.array(r32["F"]) - F64).max() < 1e-3 * np.abs(F64).max()


@pytest.mark.parametrize("name, E, depth, mu", F32_CASES)
def test_float32_agrees_with_float64(float32_runs, name, E, depth, mu):
    """Tolerances of docs/numerics.md: total force 1e-3 relative; event-A depths 1e-4 L (the
    float32 default gap_tol = 1e-5 L delays event A by gap_tol / (dgap/dd)); same final modes.
    float32 may locate a C event just after an A event where float64 lets the new contact slide
    at once, a C at the A's depth (its force is on the cone edge; the hypothesis probe is
    round-off limited in float32)."""
    r32 = float32_runs[name]
    r64 = squeeze_ok(base_scene(material=jsq.Material(E=E, nu=0.3, thickness=0.0254), depth=depth, friction=mu))
    F64 = f2(r64)
    rel = np.abs(np.array(r32["F"]) - F64).max() / np.abs(F64).max()
    ev32 = [k for _, k in r32["events"]]
    print(f"{name}: float32 {r32['status']} {''.join(ev32)} F {r32['F']}, float64 {kinds(r64)} "
          f"F {F64.tolist()}, rel {rel:.2e}")
    assert r32["status"] == "SUCCESS"
    # positions are O(1) in scaled units, so float32 round-off is ~eps·L in the prescribed
    # displacements: relative force error ~eps·L/d, which dominates below d ≈ 1e-4 L
    assert rel < max(1e-3, np.finfo(np.float32).eps * 0.1 / depth)
    np.testing.assert_array_equal(r32["modes"], np.asarray(r64.modes[-1]))
    a32 = np.array([d for d, k in r32["events"] if k == "A"])
    a64 = np.array([d for d, _, k, _ in r64.events.rows() if k == "A"])
    assert len(a32) == len(a64)
    if len(a64):
        d_err = np.abs(a32 - a64).max()
        print(f"   event-A depths: max difference {d_err:.2e} m ({d_err / 0.1:.2e} L)")
        assert d_err < 1e-4 * 0.1


FOAM32_SCRIPT = textwrap.dedent("""
    import json, os, sys
    import jax
    jax.config.update("jax_enable_x64", False)
    sys.path.insert(0, os.path.join({root!r}, "tests"))
    import jaxsqueeze as jsq
    from jaxsqueeze.io import scenefile
    from physics import check_states
    demo = scenefile.load(os.path.join({root!r}, "jaxsqueeze", "scenes", "foam_square.toml")).scene
    res = jsq.squeeze(demo)
    assert res.forces.dtype.name == "float32"
    check_states(res, demo.mesh, float(demo.friction))      # physics.FLOAT32, docs/numerics.md §3
    heart = scenefile.load(os.path.join({root!r}, "jaxsqueeze", "scenes", "heart_band.toml")).scene
    slid = jsq.squeeze(heart.replace(friction_model="frictionless"))
    print(json.dumps(dict(status=res.outcome.name, F=res.total_force[-1].tolist(), events=int(res.n_events),
                          heart=[slid.outcome.name, float(slid.final_depth)])))
""")


def test_float32_demo_squeeze_keeps_its_contact_forces_exact():
    """The demo foam square in float32 makes and breaks ~60 contacts. The bordered inverse kept
    by bordering updates drifts in float32 (3e-4 relative to a fresh inverse at the end, against
    4e-13 in float64), so the float32 solve takes one step of iterative refinement against the
    bordered matrix itself (``contacts._linear``): the final grip force then matches float64 to
    2e-6 (2e-3 without the refinement), and the two fingers' forces balance; every row holds the float32 bounds of
    ``physics.check_states``."""
    env = dict(os.environ, JAX_ENABLE_X64="0")
    r = subprocess.run([sys.executable, "-c", FOAM32_SCRIPT.format(root=ROOT)], capture_output=True, text=True,
                       timeout=300, env=env, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    r32 = json.loads(r.stdout.strip().splitlines()[-1])
    demo = scenefile.load(os.path.join(ROOT, "jaxsqueeze", "scenes", "foam_square.toml")).scene
    r64 = jsq.squeeze(demo)
    assert r32["status"] == r64.outcome.name == "SUCCESS" and r32["events"] >= 50
    # the README: the demo fits the capacities an eager squeeze starts with (30 contacts, 8 sliding)
    # (config_of, not eager_config: a Coulomb squeeze of this object elsewhere in the process,
    # test_frictionless's mu = 0.01, may have grown the capacities it remembers for it)
    cfg = grasp_mod.config_of(demo, eager=True)
    assert (cfg.capacity, cfg.sliding) == (32, 8)
    assert np.max(np.sum(r64.modes > 0, 1)) == 30 and np.max(np.sum(r64.modes >= 2, 1)) == 8
    assert (int(r64.stats.contacts), int(r64.stats.sliding)) == (30, 8)       # what the README reads them from
    replay_events(r64)          # its ~60 events are the whole history of its contact modes
    # docs/numerics.md §3: in float64 the demo's kept inverse never needs recomputing
    assert int(r64.stats.refreshes) == 0
    F32, F64 = np.array(r32["F"]), np.asarray(r64.total_force[-1])
    scale = np.abs(F64).max()
    assert np.abs(F32 - F64).max() < 1e-4 * scale
    assert np.abs(F32.sum(0)).max() < 1e-5 * scale          # the fingers' forces balance
    # the frictionless heart band: its grip segment is 2.2 degrees off the surface normal, 3.8 %
    # of each force tangential, so it stalls at the first step in both precisions (float32 ran
    # to SUCCESS at 49 times the force: its scaled forces lay below an absolute floor of the
    # drift test)
    heart = scenefile.load(os.path.join(ROOT, "jaxsqueeze", "scenes", "heart_band.toml")).scene
    h64 = jsq.squeeze(heart.replace(friction_model="frictionless"))
    assert r32["heart"][0] == h64.outcome.name == "STALLED"
    assert r32["heart"][1] == pytest.approx(float(h64.final_depth), rel=1e-6)


def test_demo_at_the_widest_event_tolerance_squeezes_like_the_default():
    """``event_tol`` at its limit, a tenth of the step: an event depth d* may then lie up to that
    far before the true touch, so a contact made there pulls at d* while its force rises. The
    peel rule let such a contact go at d*, and the same A event came back at the same depth
    until the squeeze STALLED at 0.3 mm (the accuracy benchmark's coarsest event_tol). A
    contact made at d* whose force rate is positive is joining, not peeling: the demo now
    squeezes to the end, with the default tolerance's final contact set and force to 1e-6,
    and no contact pulls by more than the location error allows (its stiffness times at most
    event_tol: below event_tol / depth of the largest force; 4.6e-4 measured, as before the
    peel rule)."""
    demo = scenefile.load(os.path.join(ROOT, "jaxsqueeze", "scenes", "foam_square.toml")).scene
    ref = squeeze_ok(demo)
    tol = 0.1 * float(demo.depth) / 50                  # a tenth of the default step
    wide = jsq.squeeze(demo.replace(settings=jsq.Settings(event_tol=tol)))
    assert wide.outcome == jsq.Status.SUCCESS, wide.outcome.name
    np.testing.assert_array_equal(np.asarray(wide.modes[-1]), np.asarray(ref.modes[-1]))
    F, F0 = np.asarray(wide.total_force[-1]), np.asarray(ref.total_force[-1])
    assert np.abs(F - F0).max() < 1e-6 * np.abs(F0).max()
    P0 = demo.mesh.points[demo.mesh.boundary]
    pulls = []
    for k in range(int(wide.count)):
        Fk, u, mode, fg, C = (np.asarray(a[k]) for a in (wide.forces, wide.boundary_displacement, wide.modes,
                                                          wide.finger, wide.centres))
        on = mode > 0
        rel = P0 + u - C[np.where(on, fg, 0)]
        pulls.append(-np.min(np.sum(Fk * rel, 1)[on] / np.linalg.norm(rel[on], axis=1)))
    assert 0 < max(pulls) < tol / float(demo.depth) * np.abs(np.asarray(wide.forces)).max()



def test_demo_at_an_event_tolerance_below_round_off_squeezes_like_the_default():
    """``event_tol`` far below what float64 resolves (1e-300 m): a grip contact at the touch was
    judged by its force at d = 0 + event_tol, i.e. by the round-off of a zero force, read as a
    pull, and both let go: LOST_CONTACT at 0 mm (from about 1e-18 m on a 0.1 m square). The
    probe past d* is now at least 1e3 eps (scaled units, as η's floor), and the bracket runs to
    its iteration bound instead of to the tolerance: the same 60 events and final force."""
    demo = scenefile.load(os.path.join(ROOT, "jaxsqueeze", "scenes", "foam_square.toml")).scene
    ref = squeeze_ok(demo)
    tiny = jsq.squeeze(demo.replace(settings=jsq.Settings(event_tol=1e-300)))
    assert tiny.outcome == jsq.Status.SUCCESS, tiny.outcome.name
    assert [(n, k) for d, n, k, f in tiny.events.rows()] == [(n, k) for d, n, k, f in ref.events.rows()]
    F, F0 = np.asarray(tiny.total_force[-1]), np.asarray(ref.total_force[-1])
    assert np.abs(F - F0).max() < 1e-9 * np.abs(F0).max()

def test_one_object_squeezed_in_both_precisions_gets_an_operator_of_each():
    """A process that squeezes an object in float64 and then inside ``jax.enable_x64(False)``
    (the accuracy benchmark's precision knob) gets a float32 operator there, not the cached
    float64 one (which crashed the float32 squeeze: float64 columns in a float32 switch), and
    the float64 one back afterwards (a mesh of its own: the cache keeps ``CACHE_PER_OBJECT``
    operators per object)."""
    scene = base_scene(mesh=symmetric_square(0.1, 0.01))
    op64 = scene.operator()
    assert op64.G.dtype == np.float64
    with jax.enable_x64(False):
        op32 = scene.operator()
        assert op32.G.dtype == np.float32 and op32.stiffness.dtype == np.float32
        np.testing.assert_allclose(np.asarray(op32.G), np.asarray(op64.G), rtol=1e-4, atol=1e-6 * np.abs(op64.G).max())
    again = scene.operator()
    assert again.G.dtype == np.float64 and again.G is op64.G


def test_the_operator_cache_is_weak_and_bounded():
    """README: ``scene.operator()`` caches per object, ν and method in a weak, bounded cache:
    at most CACHE_PER_OBJECT operators per object (the oldest goes first), an equal rebuilt
    mesh finds them, and dropping the object frees them (no operator holds its object)."""
    import gc
    import weakref

    from jaxsqueeze.simulation import scene as scene_mod
    mesh = jsq.shapes.rectangle(0.05, 0.03, max_edge=0.01)
    gc.collect()                          # objects of earlier tests that are garbage already go now
    held = len(scene_mod._operators)
    nus = (0.1, 0.2, 0.3, 0.4, 0.45)
    ops = [scene_mod.compliance_of(mesh, jsq.Material(1e5, nu, 0.01)) for nu in nus]
    assert [key[0] for key in scene_mod._operators[mesh]] == list(nus[-scene_mod.CACHE_PER_OBJECT:])
    twin = jsq.Mesh.from_arrays(np.asarray(mesh.points) + mesh.offset, mesh.triangles)   # rebuilt from the same data
    assert twin == mesh and twin is not mesh
    assert scene_mod.compliance_of(twin, jsq.Material(2e5, 0.45, 0.02)).G is ops[-1].G
    assert scene_mod.compliance_of(mesh, jsq.Material(1e5, 0.1, 0.01)).G is not ops[0].G   # evicted: rebuilt
    gone = weakref.ref(mesh)
    del mesh, twin, ops
    gc.collect()
    assert gone() is None and len(scene_mod._operators) == held


# ============================================================================ bad input: API
def _no_trace(fn, match):
    """``fn`` raises ValueError matching ``match`` without compiling a squeeze."""
    before = grasp_mod._run._cache_size()
    with pytest.raises(ValueError, match=match):
        fn()
    assert grasp_mod._run._cache_size() == before


@pytest.mark.parametrize("kw, match", [
    (dict(E=float("inf"), nu=0.3, thickness=0.01), r"Material\.E=inf"),
    (dict(E=1e5, nu=0.5000001, thickness=0.01), r"Material\.nu=.*-1 < nu <= 0.5"),
    (dict(E=1e5, nu=float("nan"), thickness=0.01), r"Material\.nu=nan"),
    (dict(E=1e5, nu=0.3, thickness=-1e-3), r"Material\.thickness=.*> 0"),
])
def test_material_gaps(kw, match):
    _no_trace(lambda: jsq.Material(**kw), match)


@pytest.mark.parametrize("change, match", [
    (lambda s: s.replace(fingers=jsq.Fingers(radius=0.0)), r"radius=0\.0 must be .* > 0"),
    (lambda s: s.replace(fingers=jsq.Fingers(radius=float("nan"))), r"radius=nan"),
    (lambda s: s.replace(fingers=jsq.Fingers(radius=0.01, rotation=[[0.1, 0.0], [0.0]])), r"leading zeros"),
    (lambda s: s.replace(depth=-0.01), r"depth=-0\.01 must be .* > 0"),
    (lambda s: s.replace(depth=float("inf")), r"depth=inf"),
    (lambda s: s.replace(friction=float("nan")), r"friction=nan .* mu >= 0"),
    (lambda s: s.replace(grip=(1.0, 5.0)), r"two integer boundary node indices"),
    (lambda s: s.replace(grip=(True, s.grip[1])), r"two integer boundary node indices"),   # not node 1
    (lambda s: s.replace(settings=jsq.Settings(capacity=1)), r"capacity"),
    (lambda s: s.replace(settings=jsq.Settings(step=-1e-3)), r"Settings\.step=-0\.001"),
    (lambda s: jsq.squeeze(s.replace(grip=(s.grip[0], nearest(SQ, (0.05, 0.0))))), r"friction cones"),
])
def test_scene_gaps(change, match):
    _no_trace(lambda: change(base_scene()), match)


def test_mesh_reader_gaps(tmp_path):
    """A file whose only triangle block is empty, and NaN coordinates in a file."""
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    empty = tmp_path / "empty.xdmf"
    meshio.write(empty, meshio.Mesh(pts, [("triangle", np.zeros((0, 3), int))]))
    with pytest.raises(ValueError, match="empty mesh"):
        jsq.read_mesh(empty)
    nan = tmp_path / "nan.vtu"
    meshio.write(nan, meshio.Mesh(pts + np.array([[0, 0, 0], [0, 0, 0], [np.nan, 0, 0], [0, 0, 0]]),
                                  [("triangle", np.array([[0, 1, 2], [0, 2, 3]]))]))
    with pytest.raises(ValueError, match=r"non-finite .* nodes 2"):
        jsq.read_mesh(nan)


@pytest.mark.parametrize("ext", ["vtu", "vtk"])
def test_empty_triangle_block_gets_a_clear_error(tmp_path, ext):
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    path = tmp_path / f"empty.{ext}"
    try:
        meshio.write(path, meshio.Mesh(pts, [("triangle", np.zeros((0, 3), int))]))
    except Exception as exc:   # meshio's own writer cannot store an empty block in this format
        pytest.skip(f"meshio cannot write an empty triangle block as .{ext}: {exc!r}")
    with pytest.raises(ValueError, match=rf"empty\.{ext}"):
        jsq.read_mesh(path)


# ============================================================================ bad input: CLI
CLI_SCENE = """\
[object]
mesh_file = "part.vtu"

[material]
E = 1.0e5
nu = 0.3
thickness = 0.0254

[fingers]
radius = 0.01

[grip]
nodes = [0, 2]

[squeeze]
depth = 0.01
friction = 0.5
"""
_SQUARE_PTS = np.array([[0, 0, 0], [0.1, 0, 0], [0.1, 0.1, 0], [0, 0.1, 0], [0.05, 0.05, 0]], float)
_SQUARE_TRI = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
MESH_FILES = {
    "nan coordinate": (_SQUARE_PTS + np.array([[0, 0, 0]] * 4 + [[np.inf, 0, 0]]), _SQUARE_TRI, r"non-finite"),
    "degenerate triangle": (np.r_[_SQUARE_PTS, [[0.2, 0.0, 0]]], np.r_[_SQUARE_TRI, [[0, 1, 5]]], r"degenerate"),
    "non-manifold edge": (np.r_[_SQUARE_PTS, [[0.05, -0.05, 0], [0.05, -0.08, 0]]],
                          np.r_[_SQUARE_TRI, [[1, 0, 5], [1, 0, 6]]], r"non-manifold|inverted"),
    "empty triangle block": (_SQUARE_PTS, np.zeros((0, 3), int), r"empty mesh"),
}
MESH_EXT = {"empty triangle block": "xdmf"}   # meshio cannot read an empty block back from .vtu


@pytest.mark.parametrize("case", sorted(MESH_FILES))
def test_cli_bad_mesh_file(case, tmp_path, capsys):
    pts, tri, match = MESH_FILES[case]
    ext = MESH_EXT.get(case, "vtu")
    meshio.write(tmp_path / f"part.{ext}", meshio.Mesh(pts, [("triangle", tri)]))
    (tmp_path / "s.toml").write_text(CLI_SCENE.replace("part.vtu", f"part.{ext}"))
    out = tmp_path / "out"
    assert cli.main(["run", str(tmp_path / "s.toml"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("error: object.mesh_file: "), err
    assert re.search(match, err), err
    assert not out.exists()


CLI_BAD = {
    "E zero": ("material.E", "E = 1.0e5", "E = 0.0", r"out of range; Young's modulus E must be > 0"),
    "E negative": ("material.E", "E = 1.0e5", "E = -1e5", r"E must be > 0"),
    "nu -1": ("material.nu", "nu = 0.3", "nu = -1.0", r"-1 < nu <= 0.5"),
    "nu inf": ("material.nu", "nu = 0.3", "nu = inf", r"finite"),
    "thickness zero": ("material.thickness", "thickness = 0.0254", "thickness = 0.0", r"> 0"),
    "radius zero": ("fingers.radius", "radius = 0.01", "radius = 0.0", r"> 0"),
    "depth negative": ("squeeze.depth", "depth = 0.01", "depth = -0.01", r"> 0"),
    "grip same node": ("grip.nodes", "nodes = [0, 2]", "nodes = [2, 2]", r"twice"),
    "grip interior": ("grip.nodes", "nodes = [0, 2]", "nodes = [0, 4]", r"not on the boundary"),
    "grip off the cone": ("grip.nodes", "nodes = [0, 2]", "nodes = [0, 1]", r"friction cones only allow"),
    "step negative": ("accuracy.step", "friction = 0.5", "friction = 0.5\n\n[accuracy]\nstep = -1e-3", r"> 0"),
    "capacity one": ("accuracy.capacity", "friction = 0.5", "friction = 0.5\n\n[accuracy]\ncapacity = 1",
                     r"at least 2"),
}


@pytest.mark.parametrize("case", sorted(CLI_BAD))
def test_cli_bad_values(case, tmp_path, capsys):
    key, old, new, match = CLI_BAD[case]
    meshio.write(tmp_path / "part.vtu", meshio.Mesh(_SQUARE_PTS, [("triangle", _SQUARE_TRI)]))
    text = CLI_SCENE.replace(old, new)
    assert text != CLI_SCENE
    (tmp_path / "s.toml").write_text(text)
    out = tmp_path / "out"
    assert cli.main(["run", str(tmp_path / "s.toml"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith(f"error: {key}: "), err
    assert re.search(match, err), err
    assert not out.exists()


def test_cli_good_mesh_file_scene_loads(tmp_path):
    """The mesh file and scene that the bad cases above break are themselves valid."""
    meshio.write(tmp_path / "part.vtu", meshio.Mesh(_SQUARE_PTS, [("triangle", _SQUARE_TRI)]))
    (tmp_path / "s.toml").write_text(CLI_SCENE)
    spec = scenefile.load(tmp_path / "s.toml")
    assert spec.scene.mesh.n == 5


def test_asymmetric_frictionless_grip_stops_with_stalled():
    """The foam square gripped frictionlessly near a corner (bottom/top nodes at x ≈ -38 mm). The
    object would slide out sideways: holding it takes a growing tangential force (measured 0.3 %
    of the largest force at 0.3 mm, 12 % at 3 mm if the drift rule were left to it, with pulling
    contacts). The squeeze stops with STALLED and advice as soon as that share passes
    ``engine.DRIFT_SHARE`` (1 %), and every row it did accept is a consistent frictionless state."""
    from jaxsqueeze.io import scenefile
    from jaxsqueeze.simulation.engine import DRIFT_SHARE

    scene = scenefile.load(os.path.join(ROOT, "jaxsqueeze", "scenes", "foam_square.toml")).scene
    b = np.asarray(scene.mesh.boundary)
    P = scene.mesh.points[b] + scene.mesh.offset
    bot, top = b[np.abs(P[:, 1] + 0.05) < 1e-9], b[np.abs(P[:, 1] - 0.05) < 1e-9]
    xb, xt = scene.mesh.points[bot, 0], scene.mesh.points[top, 0]
    gap = np.abs(xb[:, None] - xt[None]) + 1e-3 * np.abs(xb[:, None] + scene.mesh.offset[0])
    i, j = np.unravel_index(np.argmin(gap), gap.shape)
    res = jsq.squeeze(scene.replace(grip=(int(bot[i]), int(top[j])), friction_model="frictionless"))
    assert res.outcome == jsq.Status.STALLED, res.outcome.name
    assert 0 < res.final_depth < 0.5 * scene.depth and int(res.n_events) <= 5
    assert "slide out sideways" in res.outcome.advice
    th = np.asarray(res.theta)
    n = np.stack([np.cos(th), np.sin(th)], -1)
    F = np.asarray(res.forces)
    on = np.asarray(res.modes) > 0
    ft = np.abs(n[..., 0] * F[..., 1] - n[..., 1] * F[..., 0])
    row_max = np.abs(F).reshape(len(F), -1).max(1)[:, None]
    assert np.all(ft[:-1][on[:-1]] <= (DRIFT_SHARE * row_max[:-1] * np.ones_like(ft[:-1]))[on[:-1]])
    assert np.any(ft[-1][on[-1]] > DRIFT_SHARE * row_max[-1])       # the row that stopped it


def test_a_contact_that_joins_pulling_soon_goes_the_same_way_wherever_the_band_starts():
    """A segment-contact circle band under a wide fingertip: at 21.7775 mm a new contact on each
    tip (A) pushes, and would pull 0.38 µm deeper if it stuck. Under full stick it lets go there
    (B), lands inside its tip and joins again (A), and once more 37 µm deeper; then it holds to
    the target depth. (Judged by its force a step / 100 = 4.8 µm beyond the event, the contact
    pulled at once and was released at its own depth, again and again: STALLED at the first
    repeat, docs/numerics.md §2, 21. Before that, the stall test compared the depth of the
    repeat with the last row's exactly, and each repeat landed 1e-16 to 3e-12 m past it, so
    how many A/B rounds ran before STALLED, 2 to 7, depended on which point the band's list
    started at.) Under Coulomb (mu = 0.26) the pulling contacts slide instead (C at the depth
    they joined; Section IV-B.1), pushing from there on with their forces on the cone edge.
    Both reach the depth the same way from either start of the band's list."""
    from jaxsqueeze.geometry import curves
    from jaxsqueeze.mechanics.band import Band
    m, h = 64, 5e-3
    xy = curves.sample(curves.circle(0.04), m)
    seen = {"stick": [], "coulomb": []}
    for k in (0, 42):
        band = Band.from_curve(np.roll(xy, -k, axis=0), width=0.5e-3, height=h)
        grip = ((49 - k) % m, (15 - k) % m)                      # the same two points
        D0 = np.linalg.norm(band.points[grip[0]] - band.points[grip[1]])
        for model in seen:
            res = jsq.squeeze(jsq.Scene(mesh=band, material=jsq.Material(E=2e9, nu=0.3, thickness=h),
                                        fingers=jsq.Fingers(radius=0.03), grip=grip, depth=0.3 * D0,
                                        contact="segment", friction=0.26, friction_model=model))
            kinds = [e[2] for e in res.events.rows()]
            nodes = sorted((int(n) + k) % m for _, n, _, _ in res.events.rows())
            seen[model].append((int(res.count), kinds, nodes, float(res.final_depth), np.asarray(res.total_force[-1])))
            if model == "stick":
                # one node on each fingertip joins, lets go and joins again, twice, and holds
                assert res.outcome == jsq.Status.SUCCESS and kinds == ["A", "A"] + ["B", "B", "A", "A"] * 2, kinds
                # with two adjacent contacts per tip on this stiff thin wall the solve puts them
                # 1e-10 to 3.7e-10 L off their circles, under Coulomb as well: its conditioning
                check_states(res, band, 0.26, "stick", physics.FLOAT64._replace(circle=1e-9))
                continue
            assert res.outcome == jsq.Status.SUCCESS and kinds == ["A", "A", "C", "C"], kinds
            assert len({d for d, *_ in res.events.rows()}) == 1              # slides from the depth it joined
            assert sliding_against_friction(res).size == 0
            replay_events(res)
            mode = np.asarray(res.modes[-1])
            F, P = np.asarray(res.forces[-1]), band.points[band.boundary] + np.asarray(res.boundary_displacement[-1])
            on = mode > 0
            n = P[on] - np.asarray(res.centres[-1])[np.asarray(res.finger[-1])[on]]
            n /= np.linalg.norm(n, axis=1)[:, None]
            fn, ft = np.sum(F[on] * n, 1), n[:, 0] * F[on, 1] - n[:, 1] * F[on, 0]
            assert np.all(fn > 0.2 * fn.max())                                 # every contact pushes
            slide = mode[on] >= 2
            assert slide.sum() == 2
            np.testing.assert_allclose(np.abs(ft[slide]), 0.26 * fn[slide], rtol=1e-9)
    for model, (a, b) in seen.items():
        assert a[:3] == b[:3], model
        assert a[3] == pytest.approx(b[3], rel=1e-9)
        # the two node orders agree to the band's conditioning (adjacent contacts on a stiff
        # thin wall: ~1e-8 of the force)
        np.testing.assert_allclose(a[4], b[4], rtol=0, atol=1e-6 * np.abs(a[4]).max())


@pytest.mark.parametrize("gap_tol", [1e-6, 5e-4])
def test_a_large_gap_tol_leaves_no_stick_force_outside_its_cone(gap_tol):
    """A contact joins gap_tol inside its tip, so its push moves the other contacts' forces by
    a finite jump at the event. With gap_tol = 5e-4 m (0.5 % of the object, 1 % allowed) a
    neighbour's stick force jumped from |ft|/fn = 0.11 to 0.28 (μ = 0.2) and stayed outside the
    cone for 0.9 mm of squeeze (ADVANCE sees only sign changes within a step); at 1e-6 m a
    lightly loaded one sat at 0.2046. The check after an event now slides an older stick
    contact whose force lies outside its cone, a C event at that depth."""
    mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=0.01, refine_near=[[-0.005, -0.05], [0.005, 0.05]],
                                refine_edge=0.002)
    grip = (jsq.scene.nearest_boundary_node(mesh, (-0.005, -0.05)), jsq.scene.nearest_boundary_node(mesh, (0.005, 0.05)))
    sc = jsq.Scene(mesh=mesh, material=jsq.Material(E=1e5, nu=0.3, thickness=0.0254), fingers=jsq.Fingers(radius=0.01),
                   grip=grip, friction=0.2, depth=0.006, settings=jsq.Settings(gap_tol=gap_tol))
    res = jsq.squeeze(sc)
    assert res.outcome == jsq.Status.SUCCESS
    L = 0.1
    check_states(res, mesh, 0.2, bounds=Bounds(balance=1e-7, circle=1e-10, sink=11 * gap_tol / L, force=1e-6))
    kinds = np.asarray(res.events.kind)
    assert np.sum(kinds == 0) >= 4 and np.sum(kinds == 2) >= 2            # contacts joined and some slid

