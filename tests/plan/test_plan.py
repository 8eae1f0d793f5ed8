"""Grasp planning (DESIGN 2.9): continuous placement, qualities, maps and search."""
import contextlib
import dataclasses
import io
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsqueeze as jsq
from jaxsqueeze import plan
from jaxsqueeze.plan import quality as Q
from physics import check_states, compiles, nearest, sliding_against_friction, symmetric_square

MAT = jsq.Material(E=1e5, nu=0.3, thickness=0.0254)


def _kernel_stream():
    """A stand-in for a Jupyter kernel's sys.stderr (no terminal; progress is shown there too)."""
    return type("OutStream", (io.StringIO,), {"__module__": "ipykernel.iostream"})()


@pytest.fixture(scope="module")
def ellipse():
    mesh = jsq.shapes.ellipse(0.06, 0.04, max_edge=0.006)
    return jsq.Scene(mesh=mesh, material=MAT, fingers=jsq.Fingers(radius=0.01),
                     placement=plan.Placement(s=(0.0, 0.1)), friction=0.5, depth=0.006)


@pytest.fixture(scope="module")
def square():
    mesh = symmetric_square(0.1, 0.01)
    grip = (nearest(mesh, (0, -0.05)), nearest(mesh, (0, 0.05)))
    return jsq.Scene(mesh=mesh, material=MAT, fingers=jsq.Fingers(radius=0.01), grip=grip, friction=0.5, depth=0.01)


def test_bad_map_spacing_and_placement_shapes_are_refused_before_compiling(ellipse):
    """A map's spacing must be a finite arc length > 0 and leave at most 10 positions per
    boundary node (a map squeezes every pair); an eager squeeze takes one placement (s of
    shape (2,), a scalar angle); a search needs counts, an optax optimizer and finite starting
    candidates. Each is an error that says so, and nothing compiles."""
    from jaxsqueeze.simulation import api
    before = api._run._cache_size()
    for spacing in (-1.0, 0.0, float("nan")):
        with pytest.raises(ValueError, match="finite arc length > 0"):
            jsq.grasp_map(ellipse, "squeeze_work", spacing=spacing)
    for spacing in ("0.1", True, 1j, [0.1, [0.2]]):
        with pytest.raises(ValueError, match="finite arc length > 0"):
            jsq.grasp_map(ellipse, "squeeze_work", spacing=spacing)
    for spacing in (1e-6, 1e-310, 5e-324):          # subnormal ones overflowed counting positions
        with pytest.raises(ValueError, match="more than 10 per boundary node"):
            jsq.grasp_map(ellipse, "squeeze_work", spacing=spacing)
    with pytest.raises(ValueError, match=r"spacing=100 m puts 0 position\(s\) .* at least 3"):   # was 3 quietly
        jsq.grasp_map(ellipse, "squeeze_work", spacing=100.0)
    with pytest.raises(ValueError, match="one placement"):
        jsq.squeeze(ellipse.replace(placement=plan.Placement(s=(0.0, 0.1), angle=(0.1, 0.0))))
    # a search's counts, optimizer and starting candidates (starts=0 said "no feasible placement
    # on the coarse map" after squeezing it; steps=-1 ran; a string optimizer failed in optax)
    for kw, match in [(dict(starts=0), "starts=0 must be an integer >= 1"), (dict(steps=-1), "steps=-1"),
                      (dict(steps=2.5), "steps=2.5"), (dict(budget=0), "budget=0"),
                      (dict(init=[[0.0, float("nan")]]), "init of shape"), (dict(init=[[0.0, 0.1, 0.0, 1.0]]), "init")]:
        with pytest.raises(ValueError, match=match):
            jsq.optimize_placement(ellipse, "squeeze_work", progress=False, **kw)
    with pytest.raises(TypeError, match="not an optax optimizer"):
        jsq.optimize_placement(ellipse, "squeeze_work", optimizer="adam", progress=False)
    with pytest.raises(TypeError, match="vary_angle='False' must be True or False"):     # (a true string)
        jsq.optimize_placement(ellipse, "squeeze_work", vary_angle="False", progress=False)
    for call in (lambda: jsq.optimize_placement(ellipse, "squeeze_work", progress="no"),
                 lambda: jsq.grasp_map(ellipse, "squeeze_work", spacing=0.02, progress="no")):
        with pytest.raises(TypeError, match="progress='no' must be True or False"):
            call()
    import optax        # a line search needs the value inside optax: it failed there, deep in optax's update
    with pytest.raises(ValueError, match=r"cannot take a step from a gradient alone .*optax.lbfgs, ...\) evaluate"):
        jsq.optimize_placement(ellipse, "squeeze_work", optimizer=optax.lbfgs(), progress=False)
    # a NaN or infinite learning rate made every step non-finite: each was undone and the search
    # returned its start as the best, silently
    for lr in (float("nan"), float("inf")):
        with pytest.raises(ValueError, match="not finite: check its learning rate"):
            jsq.optimize_placement(ellipse, "squeeze_work", optimizer=optax.sgd(lr), progress=False)
    # a negative learning rate, or a transform without optax's minus sign, walked downhill and
    # returned the start as the best, silently
    for opt in (optax.sgd(-0.002), optax.scale(0.002)):
        with pytest.raises(ValueError, match="along the gradient, so the search would walk downhill"):
            jsq.optimize_placement(ellipse, "squeeze_work", optimizer=opt, progress=False)
    # the documented function itself (a TypeError from inside: a missing positional argument);
    # a budget below the given starts blamed a coarse map that never ran
    with pytest.raises(ValueError, match='needs μ and the scene besides a result: pass quality="slip_margin"'):
        jsq.optimize_placement(ellipse, Q.slip_margin, progress=False)
    with pytest.raises(ValueError, match=r"budget=2 .*no coarse map: init given; each of the 3 starts"):
        jsq.optimize_placement(ellipse, "squeeze_work", init=[[0.0, 0.1], [0.02, 0.12], [0.04, 0.14]], budget=2,
                               progress=False)
    # a budget the coarse map alone would spend: said before the map (it squeezed it all first)
    with pytest.raises(ValueError, match=r"budget=1 .*the coarse map squeezes the \d+ pairs that pass the cone test"):
        jsq.optimize_placement(ellipse, "squeeze_work", budget=1, progress=False)
    # candidates of complex numbers, booleans or text were read as numbers (True as 1 m)
    for bad in ([[0.0, 0.1 + 1j]], [[True, 0.1]], [["0.0", "0.1"]]):
        with pytest.raises(ValueError, match=r"init=.*: init must be finite \(k, 3\) candidates"):
            jsq.optimize_placement(ellipse, "squeeze_work", init=bad, progress=False)
        with pytest.raises(ValueError, match=r"X=.*: X must be finite \(k, 3\) candidates"):
            plan.evaluate(ellipse, bad, progress=False)
    # a placement or an adversary of another type failed inside the checks (AttributeError)
    for part in (dict(placement=(0.0, 0.1)), dict(placement={"s": (0.0, 0.1)}), dict(adversary=(0.1, 0.002)),
                 dict(adversary=plan.Placement(s=(0.0, 0.1)))):
        with pytest.raises(TypeError, match=r"Scene.(placement|adversary) must be a jsq.(Placement|Adversary) or None"):
            jsq.squeeze(ellipse.replace(**part))
    # a map's chunk, keep, processes and angle (chunk=0 looped forever, keep=-1 dropped the
    # last best candidate, a NaN angle squeezed NaN placements); a zero coarse spacing of a
    # search silently became the default
    P = float(ellipse.curve().perimeter)
    for kw, match in [(dict(chunk=0), "chunk=0 must be an integer >= 1"), (dict(keep=-1), "keep=-1"),
                      (dict(processes=0), "processes=0"), (dict(angle=float("nan")), "angle=nan must be a finite"),
                      (dict(angle="x"), "angle='x'"), (dict(angle=[0.0, [1.0]]), r"angle=\[0.0, \[1.0\]\] must be")]:
        with pytest.raises(ValueError, match=match):
            jsq.grasp_map(ellipse, "squeeze_work", spacing=P / 6, progress=False, **kw)
    with pytest.raises(ValueError, match="spacing=0 must be a finite arc length"):
        jsq.optimize_placement(ellipse, "squeeze_work", coarse_spacing=0, progress=False)
    # a scene an eager squeeze refuses is refused by maps and searches too (a push longer
    # than the object was INVALID_INPUT in every cell, then "no feasible placement")
    far = ellipse.replace(adversary=plan.Adversary(s=0.05, push=5.0))
    for call in (lambda: plan.evaluate(far, [[0.0, P / 2]], progress=False),
                 lambda: jsq.grasp_map(far, spacing=P / 6, progress=False),
                 lambda: jsq.optimize_placement(far, init=[[0.0, P / 2]], progress=False),
                 lambda: plan.candidate_pairs(ellipse.replace(depth=-1.0), spacing=P / 6)):
        with pytest.raises(ValueError, match="adversary = .*push 5.0|depth=-1.0 must be"):
            call()
    assert api._run._cache_size() == before


@pytest.mark.parametrize("name", ["squeeze_work", "grip_force", "slip_margin", "adversary_work", "finger_work",
                                  "failure_push"])
def test_a_quality_given_a_scene_or_other_object_says_it_takes_a_result(square, name):
    """(a scene passed for its squeeze reached an IndexError, a string an AttributeError)"""
    fn = getattr(Q, name)
    args = (0.5,) if name == "slip_margin" else ()
    with pytest.raises(TypeError, match=rf"{name} takes a SqueezeResult .*got Scene: squeeze it first"):
        fn(square, *args)
    with pytest.raises(TypeError, match=rf"{name} takes a SqueezeResult .*got dict$"):
        fn({"depth": 0.01}, *args)


def test_a_quality_that_is_not_one_finite_number_is_named():
    """A quality function returning a vector or a string failed deep in a map (or broadcast
    the summary); one returning NaN at successful squeezes ended a search with "no start
    reached a successful squeeze". Each is now an error that says what the function returned."""
    from jaxsqueeze.plan import search
    res = jsq.SqueezeResult.__new__(jsq.SqueezeResult)
    with pytest.raises(ValueError, match=r"array of shape \(3,\) .* must return one real number"):
        search._quality(lambda r: jnp.ones(3), res)
    with pytest.raises(TypeError, match="returned 'x'; it must return a number"):
        search._quality(lambda r: "x", res)
    with pytest.raises(TypeError, match="returned None; it must return a number"):
        search._quality(lambda r: None, res)
    assert search._quality(lambda r: 2.0, res).shape == ()
    # numpy, float() or an if on a traced result raised JAX's tracer error from deep in a map
    for fn in (lambda r: float(r), lambda r: np.asarray(r), lambda r: 1.0 if r > 0 else 0.0, lambda r: int(r)):
        with pytest.raises(TypeError, match=r"maps and searches call it on traced results .* compute it with "
                                            r"jax.numpy"):
            jax.jit(lambda x: search._quality(fn, x))(1.0)
    ok, bad = int(jsq.Status.SUCCESS), int(jsq.Status.SLIP_FAILURE)
    summ = search.Summary(np.array([bad, ok, ok]), np.array([np.nan, 1.0, np.inf]), *np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"the quality is inf at 1 successful squeeze\(s\), e.g. the candidate "
                                         r"\(s_0, s_1, angle\) = \[2.0, 2.0, 2.0\]"):
        search._check_quality(summ, np.arange(3)[:, None] * np.ones(3))
    search._check_quality(summ._replace(quality=np.array([np.nan, 1.0, 0.0])), np.zeros((3, 3)))


def test_a_placed_squeeze_deeper_than_its_first_contacts_are_apart_is_invalid(ellipse, square):
    """A placement's first contacts are known only after the approach: a depth beyond their
    distance (0.2 m across a 0.12 m ellipse) squeezed the fingers through each other with
    SUCCESS. Across the ellipse's minor axis (0.08 m) a depth of 0.1 m, less than the object's
    size (0.12 m), is INVALID_INPUT in a map, and an eager squeeze raises with the distance;
    deeper than the object's size it is refused before the squeeze."""
    P = float(ellipse.curve().perimeter)
    across = [[P / 4, 3 * P / 4]]
    with pytest.warns(UserWarning, match="50%"):
        s = plan.evaluate(ellipse.replace(depth=0.1), across * 3, batch="vmap", chunk=3, progress=False)
    assert list(s.status) == [jsq.Status.INVALID_INPUT] * 3 and np.all(s.quality == 0)
    with pytest.raises(ValueError, match=r"depth = 0.1 m: expected a depth smaller than the distance between the "
                                         r"fingers' first contacts, 0.07998 m"), pytest.warns(UserWarning, match="50%"):
        jsq.squeeze(ellipse.replace(depth=0.1, placement=plan.Placement(s=across[0])))
    placed = square.replace(grip=None, placement=plan.Placement(s=square.arc_length(square.grip)))
    with pytest.raises(ValueError, match=r"depth = 0.2 \(object size 0.1 m\): .* crush"):
        jsq.squeeze(placed.replace(depth=0.2))
    assert jsq.squeeze(placed).outcome == jsq.Status.SUCCESS
    # both fingers at one point: infeasible, nothing squeezed, and no warning of a depth deeper
    # than half the (meaningless) distance between the first contacts
    import warnings
    one = ellipse.replace(placement=plan.Placement(s=(0.05, 0.05)))
    a, b = (one.mesh.points[n] for n in np.asarray(jsq.squeeze(one).grip))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = jsq.squeeze(one.replace(depth=0.75 * float(np.linalg.norm(a - b))))
    assert res.outcome == jsq.Status.INFEASIBLE_GRIP


def test_a_rebuilt_equal_scene_reuses_the_compiled_map(ellipse):
    """Meshes compare by content: the same mesh built again is equal (and hashes alike), so a
    map of the rebuilt scene reuses the compiled program (every new mesh object compiled the
    planner's programs again, ~3 s each); another mesh is not equal. The same for the quality
    "slip_margin", which is the margin of a direct squeeze."""
    from jaxsqueeze.plan import search
    again = jsq.shapes.ellipse(0.06, 0.04, max_edge=0.006)
    assert again is not ellipse.mesh and again == ellipse.mesh and hash(again) == hash(ellipse.mesh)
    assert jsq.shapes.ellipse(0.06, 0.041, max_edge=0.006) != ellipse.mesh
    P = float(ellipse.curve().perimeter)
    first = plan.evaluate(ellipse, [[0.0, P / 2]], batch="loop", progress=False)
    n = search._one._cache_size()
    with jax.transfer_guard("disallow"):         # README, "Your JAX settings": maps run under a guard
        other = plan.evaluate(ellipse.replace(mesh=again), [[0.0, P / 2]], batch="loop", progress=False)
        gmap = jsq.grasp_map(ellipse, spacing=P / 4, progress=False)
    assert gmap.evaluations == 6 and gmap.feasible().any()
    assert search._one._cache_size() == n and other.quality[0] == first.quality[0]
    # the quality "slip_margin" too: it was a closure made anew on every call, and every map and
    # search with it compiled again (~5 s each)
    margin = plan.evaluate(ellipse, [[0.0, P / 2]], "slip_margin", batch="loop", progress=False)
    n = search._one._cache_size()
    again = plan.evaluate(ellipse.replace(mesh=again), [[0.0, P / 2]], "slip_margin", batch="loop", progress=False)
    assert search._one._cache_size() == n and again.quality[0] == margin.quality[0]
    placed = ellipse.replace(placement=plan.Placement(s=(0.0, P / 2)))
    assert margin.quality[0] == pytest.approx(float(Q.slip_margin(jsq.squeeze(placed), 0.5, scene=placed)), rel=1e-12)


def test_named_qualities_squeeze_with_two_rows_and_functions_with_the_history(ellipse):
    """A map or search of a named quality squeezes with two rows kept (history=False: it reads
    only the end of the squeeze and the last row), a quality function with the whole history
    (it may read any row): the traced programs hold (2, m) or (rows, m) arrays. Both give the
    quality of a direct squeeze."""
    from jaxsqueeze.plan import search
    op, m = ellipse.operator(), ellipse.mesh.m
    P = float(ellipse.curve().perimeter)
    x = jnp.array([0.0, P / 2, 0.0])

    def shapes(qfn):
        seen = set()

        def walk(jaxpr):
            for eqn in jaxpr.eqns:
                seen.update(tuple(v.aval.shape) for v in eqn.outvars if hasattr(v.aval, "shape"))
                for value in eqn.params.values():
                    for sub in value if isinstance(value, (list, tuple)) else [value]:
                        inner = getattr(sub, "jaxpr", sub)
                        if hasattr(inner, "eqns"):
                            walk(inner)
        walk(jax.make_jaxpr(lambda x: search._summary(ellipse, qfn, op, x))(x).jaxpr)
        return {sh[0] for sh in seen if len(sh) == 2 and sh[1] == m}

    rows = jsq.Settings().max_steps or 400
    named = search.quality_of(ellipse, "slip_margin")
    assert search.two_rows(named) and search.two_rows(Q.squeeze_work)
    assert not search.two_rows(lambda r: Q.squeeze_work(r))
    assert 2 in shapes(named) and rows + 1 not in shapes(named)
    assert rows + 1 in shapes(lambda r: Q.squeeze_work(r))
    placed = ellipse.replace(placement=plan.Placement(s=(0.0, P / 2)))
    direct = float(Q.squeeze_work(jsq.squeeze(placed)))
    mapped = plan.evaluate(ellipse, [[0.0, P / 2]], batch="loop", progress=False).quality[0]
    assert mapped == pytest.approx(direct, rel=1e-12)


def test_a_slip_margin_map_at_a_new_friction_compiles_nothing(ellipse):
    """The map's programs took the "slip_margin" quality with its μ as a static argument: a μ
    sweep of slip-margin maps compiled every map again (~4 s each), where a squeeze_work sweep
    compiled nothing. The programs now take μ from the scene, traced."""
    P = float(ellipse.curve().perimeter)
    plan.evaluate(ellipse, [[0.0, P / 2]], "slip_margin", batch="loop", progress=False)
    other = ellipse.replace(friction=0.6)
    with compiles() as seen:
        got = plan.evaluate(other, [[0.0, P / 2]], "slip_margin", batch="loop", progress=False)
    assert seen == []
    placed = other.replace(placement=plan.Placement(s=(0.0, P / 2)))
    assert float(got.quality[0]) == pytest.approx(float(Q.slip_margin(jsq.squeeze(placed), 0.6)), rel=1e-9)


def test_placement_at_grip_nodes_reproduces_the_integer_grip(square):
    """Fingers placed by arc length at the grip nodes touch those nodes first, and the squeeze
    is the integer-grip squeeze."""
    a = jsq.squeeze(square)
    pl = plan.Placement(s=square.arc_length(square.grip))
    b = jsq.squeeze(square.replace(grip=None, placement=pl))
    assert b.outcome == jsq.Status.SUCCESS
    np.testing.assert_array_equal(b.grip, square.grip)
    np.testing.assert_allclose(b.total_force[-1], a.total_force[-1], rtol=1e-9, atol=1e-12)
    from jaxsqueeze.post import views          # the summary says where the fingers were placed
    placed = views.summary(b, square.replace(grip=None, placement=pl))["scene"]
    assert placed["placement"] == dict(s=[float(v) for v in pl.s], angle=0.0)
    assert "placement" not in views.summary(a, square)["scene"]


def test_frictionless_fingertips_are_reseated_on_the_line_of_their_contacts(square):
    """docs/planning.md: placed frictionless fingertips are re-seated on the line through the
    two nodes they touch (forces along it), and their cone test takes the node normals with
    laws.FRICTIONLESS_TILT. Placed 20 mm along the edge from the mid-edge nodes and squeezed
    along a line tilted by 0.2 rad, both touch nodes at x = 20 mm: the squeeze is the integer
    grip of those nodes. Placed with only finger 0 moved, the nodes' segment leans 11.3° and
    the margin is FRICTIONLESS_TILT (+ the round-off slack) − atan(0.2) < 0: INFEASIBLE_GRIP."""
    from jaxsqueeze.simulation.laws import CONE_SLACK, FRICTIONLESS_TILT
    sc = square.replace(friction_model="frictionless")
    s = np.asarray(square.arc_length(square.grip))
    P = np.asarray(square.mesh.points)
    r = float(square.fingers.radius)
    for ds, ok in ((np.array([0.02, -0.02]), True), (np.array([0.02, 0.0]), False)):
        res = jsq.squeeze(sc.replace(grip=None, placement=plan.Placement(s=s + ds, angle=0.2)))
        g = [int(v) for v in res.grip]
        np.testing.assert_allclose(P[g[0]][0], 0.02, atol=1e-12)
        e = (P[g[0]] - P[g[1]]) / np.linalg.norm(P[g[0]] - P[g[1]])
        C = np.asarray(res.centres[0])                   # fingertip centres before the squeeze
        np.testing.assert_allclose(C, P[g] + r * np.stack([e, -e]), atol=1e-12)
        lean = np.arctan2(abs(e[0]), abs(e[1]))
        assert float(res.margin) == pytest.approx(FRICTIONLESS_TILT + CONE_SLACK - lean, abs=1e-12)
        if ok:
            assert res.outcome == jsq.Status.SUCCESS
            same = jsq.squeeze(sc.replace(grip=tuple(g)))
            assert int(same.count) == int(res.count)
            np.testing.assert_allclose(res.forces, same.forces, rtol=0, atol=1e-12 * np.abs(same.forces).max())
        else:
            assert res.outcome == jsq.Status.INFEASIBLE_GRIP and float(res.margin) < 0


def test_a_broad_frictionless_fingertip_tilted_against_a_flat_face_is_refused(square):
    """A frictionless fingertip sits on the line through both grip nodes, tilted from the normals
    by up to laws.FRICTIONLESS_TILT (2.56°). With the top face's nodes moved 1.5 mm along it the
    mid-edge nodes' line leans 0.86°, and a 5 m pad on it reaches past the flat face's other
    nodes (the dip s·α − s²/2r, 0.5 mm 50 mm away). It is refused: the integer grip with
    grip.overlap (the measure matches r − |x − c| with the centre placed as the squeeze places
    it), the placement with INFEASIBLE_GRIP. Until 2026-12-08 the overlap was measured from a
    fingertip along the normals, within 1e-3 · radius (5 mm for this pad): the squeeze joined
    the face's nodes at d = 0 and stalled at its first step. Now the limit is 1e-3 ·
    min(radius, size); within it, past gap_tol, the squeeze warns that the node joins at d = 0
    with a force (a 0.5 m pad reaches 5e-5 m past its neighbours: half the limit). Along the
    normals (Coulomb), the same pad touches only its grip nodes."""
    from jaxsqueeze.simulation import api, validate as V
    P = np.array(square.mesh.points, float)
    top = np.isclose(P[:, 1], 0.05) & (np.abs(P[:, 0]) < 0.049)
    P[top, 0] += 0.0015                                        # (same node count: the same programs)
    mesh = jsq.Mesh.from_arrays(P, square.mesh.triangles)
    g = (nearest(mesh, (0, -0.05)), nearest(mesh, (0.0015, 0.05)))
    sc = square.replace(mesh=mesh, grip=g, fingers=jsq.Fingers(radius=5.0), friction_model="frictionless")
    r, X = 5.0, np.asarray(mesh.points)                       # (the mesh's own, centred, frame)
    e = (X[g[0]] - X[g[1]]) / np.linalg.norm(X[g[0]] - X[g[1]])
    c, Pb = X[g[0]] + r * e, X[mesh.boundary]                  # fingertip 0's centre, on the grip line
    direct = r - np.linalg.norm(Pb - c, axis=1)
    direct[np.flatnonzero(mesh.boundary == g[0])] = -np.inf
    ov = V.values_of(sc)["grip.overlap"]
    assert ov[0] == pytest.approx(direct.max(), rel=1e-9) and 4e-4 < ov[0] < 6e-4
    with pytest.raises(ValueError, match=r"grip.overlap = .*frictionless fingertip sits on the line through both"):
        V.check_scene(sc)
    V.check_scene(sc.replace(friction_model="coulomb"))       # along the normals it touches one node
    assert np.max(V.values_of(sc.replace(friction_model="coulomb"))["grip.overlap"]) < 0
    half = sc.replace(fingers=jsq.Fingers(radius=0.5))
    assert np.max(V.values_of(half)["grip.overlap"]) == pytest.approx(5e-5, rel=1e-3)
    V.check_scene(half)
    with pytest.warns(UserWarning, match=r"reaches 5e-05 m past another boundary node .* joins at d = 0 with a "
                                         r"force .* about 0.005 of the squeeze's forces"):
        api.check_scene(half)
    res = jsq.squeeze(sc.replace(grip=None, placement=plan.Placement(s=sc.arc_length(np.array(g)))))
    assert res.outcome == jsq.Status.INFEASIBLE_GRIP and float(res.margin) == -np.pi
    assert [int(v) for v in res.grip] == list(g) and int(res.count) == 1 and not res.events.rows()


def _pushed(ellipse, x):
    """The ellipse placed at x = (s_0, s_1, angle, s_push) and pushed 2 mm by an adversary at
    arc length s_push after its squeeze: one signature, so that the derivative tests share
    one compiled forward-mode program (squeeze and push phase)."""
    return jsq.squeeze(ellipse.replace(placement=plan.Placement(s=x[:2], angle=x[2]),
                                       adversary=plan.Adversary(s=x[3], push=0.002)))


def test_jacfwd_in_placement_matches_central_differences(ellipse):
    """d(grip force, adversary work, its work up to 1 mm of push)/d(s_0, s_1, angle, s_push) by
    jax.jacfwd against central differences (step 1e-6 m or rad; agree to rtol 1e-6 away from
    event switches): through the squeeze and through the push phase, whose pushed point and
    normal move continuously with s_push (docs/planning.md, "The adversary push").

    The eager ``jacfwd`` compiles ~30 programs when it runs first in a process (the squeeze's
    derivative, the scene's conversions and validation, each quality, the operator's element
    kernel; the slicing and stacking of x and JAX's basis): not each small operation of the
    library's code on its own, which were ~100 more (~5 s on 2 cores)."""
    P = float(ellipse.curve().perimeter)
    x0 = np.array([0.01, P / 2 + 0.004, 0.05, P / 4])

    def f(x):
        res = _pushed(ellipse, x)
        return jnp.stack([Q.grip_force(res), Q.adversary_work(res), Q.adversary_work(res, push=0.001)]), res.status

    with compiles() as compiled:
        J, status = jax.jacfwd(f, has_aux=True)(jnp.asarray(x0))
    assert len(compiled) <= 40, len(compiled)
    assert int(status) == jsq.Status.SUCCESS
    for k in range(4):
        h = np.eye(4)[k] * 1e-6
        fd = (np.asarray(f(x0 + h)[0]) - np.asarray(f(x0 - h)[0])) / 2e-6
        on = [0, 1, 2] if k < 3 else [1, 2]        # the push comes after the grip force's row
        assert np.all(np.abs(fd[on]) > 1e-6)
        np.testing.assert_allclose(J[on, k], fd[on], rtol=1e-6)
    assert float(J[0, 3]) == 0.0
    # at a kink, both fingers on nodes (s_0 = 0 is node 0, P/2 a node of this symmetric mesh):
    # the grip force's one-sided differences disagree in sign, and jacfwd is one of them
    # (docs/planning.md, "piecewise smooth"); the same compiled program
    x1 = np.array([0.0, P / 2, 0.0, P / 4])
    with compiles() as compiled:
        J1, status = jax.jacfwd(f, has_aux=True)(jnp.asarray(x1))
    assert compiled == []
    assert int(status) == jsq.Status.SUCCESS
    f1 = float(f(x1)[0][0])
    for k in (0, 1):
        h = np.eye(4)[k] * 1e-7
        sides = np.array([float(f(x1 + h)[0][0]) - f1, f1 - float(f(x1 - h)[0][0])]) / 1e-7
        assert sides[0] * sides[1] < 0
        assert np.min(np.abs(sides - float(J1[0, k]))) <= 1e-4 * abs(float(J1[0, k]))


def test_derivatives_stay_finite_where_the_grip_never_started(ellipse):
    """An infeasible placement records zero forces: the qualities that take a norm of them
    (grip force, slip margin) have derivative 0 there, not NaN, so one infeasible member cannot
    poison a gradient step; the margin's derivative is the one that says where to go (checked
    against central differences: the fingertip normals swing fast between neighbouring
    placements). No push happens, and the adversary's work is 0 with derivative 0."""
    x0 = jnp.array([0.0, 0.02, 0.0, 0.05])

    def f(x):
        res = _pushed(ellipse, x)
        return jnp.stack([Q.grip_force(res), res.grip_force, Q.squeeze_work(res), Q.adversary_work(res),
                          Q.slip_margin(res, 0.5), res.margin])

    out, J = f(x0), jax.jacfwd(f)(x0)
    assert float(out[-1]) < 0 and np.all(np.isfinite(J))
    np.testing.assert_array_equal(out[:4], 0.0)
    np.testing.assert_array_equal(J[:4], 0.0)
    for k in range(2):       # steep (-138 rad/m): a step of 1e-6 m leaves a truncation error of 1.5e-6
        h = np.eye(4)[k] * 1e-8
        np.testing.assert_allclose(J[-1, k], (float(f(x0 + h)[-1]) - float(f(x0 - h)[-1])) / 2e-8, rtol=1e-6, atol=1e-6)
    assert abs(float(J[-1, 0])) > 100
    # both fingers placed at one point (a map's diagonal): no squeeze line, still finite (the
    # squeeze direction once divided by their zero distance: NaN centres and derivatives)
    x1 = jnp.array([0.03, 0.03, 0.0, 0.05])
    out, J = f(x1), jax.jacfwd(f)(x1)
    res = _pushed(ellipse, x1)
    assert res.outcome == jsq.Status.INFEASIBLE_GRIP and float(out[-1]) == -np.pi
    assert np.all(np.isfinite(np.asarray(res.centres))) and np.all(np.isfinite(J))


def test_cone_angles_of_exactly_opposite_contacts_have_a_finite_derivative():
    """Two contacts exactly on each other's normal (a symmetric grip): the angle is 0, where
    arccos of the cosine had an infinite derivative and made jacfwd of the margin NaN."""
    from jaxsqueeze.simulation import laws

    def margin(y):
        p = jnp.array([[0.0, -0.05], [0.0, y]])
        return laws.grip_margin(p, jnp.array([[0.0, 1.0], [0.0, -1.0]]), 0.3, "coulomb")

    assert float(jax.jacfwd(margin)(0.05)) == 0.0
    tilt = lambda x: laws.grip_cone_angles(jnp.array([[0.0, 0.0], [x, 1.0]]), jnp.array([[0.0, 1.0], [0.0, -1.0]]))  # noqa: E731
    np.testing.assert_allclose(tilt(1e-9), [1e-9, 1e-9], rtol=1e-12)          # exact near 0, as arccos was not
    np.testing.assert_allclose(jax.jacfwd(tilt)(0.3), [1 / 1.09] * 2, rtol=1e-12)


def test_an_accelerator_vmaps_up_to_1024_candidates_per_program():
    """evaluate/grasp_map without chunk=: a vmap on an accelerator takes the whole batch in one
    program up to ACCELERATOR_CHUNK (on an H200 a vmap of foam-square squeezes took 1.0 ms per
    grasp at 256 members, 0.41 at 4,096); a CPU's vmap chunks and the workers' shares stay CHUNK."""
    from jaxsqueeze.plan import search
    assert (search.CHUNK, search.ACCELERATOR_CHUNK) == (64, 1024)
    assert search._default_chunk("vmap", 3, "gpu") == 3
    assert search._default_chunk("vmap", 5000, "tpu") == 1024
    for batch in ("vmap", "loop", "processes"):
        assert search._default_chunk(batch, 5000, "cpu") == 64
        assert search._default_chunk(batch, 3, "cpu") == 64
    assert search._default_chunk("processes", 5000, "gpu") == 64


def test_a_short_vmap_chunk_is_padded_to_a_power_of_two_only(ellipse, monkeypatch):
    """A vmap chunk shorter than ``chunk`` was padded to the full chunk, and on a CPU the
    padding members are squeezed one after another (2 candidates cost 64 squeezes; chunk=10**6
    with one candidate, a million). Now a batch of one short chunk is padded to the next power
    of two; the last of several chunks to a whole one, whose program exists (a second program
    would compile for seconds). batch="auto" loops on a CPU, however many the candidates."""
    from jaxsqueeze.plan import search
    sizes = []

    def fake(scene, qfn, op, X):
        sizes.append(len(X))
        return search.Summary(*(jnp.zeros(len(X)),) * 5)
    monkeypatch.setattr(search, "_batch", fake)
    op = ellipse.operator()
    for n, chunk in ((2, None), (70, 64), (1, 10 ** 6), (5, 4)):
        summ = search._evaluate(ellipse, np.zeros((n, 3)), "squeeze_work", op, "vmap", chunk, False, None, True)
        assert len(summ.status) == n
    assert sizes == [2, 64, 64, 1, 4, 4]
    # progress: after each chunk (each 16 squeezes of a loop), in a notebook as on a terminal
    monkeypatch.setattr(search, "_one", lambda scene, qfn, op, x: search.Summary(*(jnp.zeros(()),) * 5))
    assert jax.default_backend() == "cpu"
    sizes.clear()
    summ = search._evaluate(ellipse, np.zeros((1030, 3)), "squeeze_work", op, "auto", None, False, None, True)
    assert len(summ.status) == 1030 and sizes == []
    for batch, n, shown in (("vmap", 5, ["4/5", "5/5"]), ("loop", 20, ["16/20", "20/20"])):
        notebook = _kernel_stream()
        with contextlib.redirect_stderr(notebook):
            search._evaluate(ellipse, np.zeros((n, 3)), "squeeze_work", op, batch, 4, True, None, True)
        assert [line.split(" (")[0] for line in notebook.getvalue().split("\r")[1:]] == \
            [f"grasp map: {k}" for k in shown]


def test_infeasible_placements_are_a_status_inside_a_vmapped_batch(ellipse):
    """A batch with one placement whose contacts leave the cones and one whose finger cannot
    touch returns their statuses (never NaN, never an exception) beside a good one."""
    P = float(ellipse.curve().perimeter)
    X = np.array([[0.0, P / 2, 0.0],             # across the major axis: feasible
                  [0.0, 0.02, 0.0],              # neighbouring points: outside the cones
                  [0.0, P / 2, np.pi / 2]])      # squeezing along the tangent: the fingers miss
    s = plan.evaluate(ellipse, X, batch="vmap", chunk=3, progress=False)
    assert list(s.status) == [jsq.Status.SUCCESS, jsq.Status.INFEASIBLE_GRIP, jsq.Status.INFEASIBLE_GRIP]
    assert s.margin[0] > 0 and s.margin[1] < 0 and s.margin[2] < 0
    assert np.all(np.isfinite(s.quality)) and s.quality[1] == 0 and s.quality[2] == 0
    loop = plan.evaluate(ellipse, X, batch="loop", progress=False)
    np.testing.assert_array_equal(loop.status, s.status)
    np.testing.assert_allclose(loop.quality, s.quality, rtol=1e-9)
    # (B, 2) candidates have angle 0 (they used to take s_1 as the angle) and Placements are
    # candidates; any other width is refused
    two = plan.evaluate(ellipse, X[:2, :2], batch="loop", progress=False)
    np.testing.assert_array_equal(two.quality, loop.quality[:2])
    placed = plan.evaluate(ellipse, plan.Placement(s=X[0, :2]), batch="loop", progress=False)
    assert placed.quality[0] == loop.quality[0]
    for bad in (X[:, :1], np.ones((2, 4)), [["a", "b"]], np.zeros((0, 3))):
        with pytest.raises(ValueError, match=r"must be finite \(k, 3\) candidates"):
            plan.evaluate(ellipse, bad, progress=False)
    cands = plan.candidate_pairs(ellipse, spacing=P / 12)
    assert len(cands) > 0
    assert np.all(plan.evaluate(ellipse, cands[:2], progress=False).margin >= 0)
    # the cone test's program is compiled once per scene shape and grid, not once per call
    with compiles() as compiled:
        fewer = plan.candidate_pairs(ellipse.replace(friction=0.4), spacing=P / 12)
    assert compiled == [] and 0 < len(fewer) < len(cands)
    # Settings(fused=True): the planner's own programs run each squeeze loop as one kernel
    fused = ellipse.replace(settings=dataclasses.replace(ellipse.settings, fused=True))
    f = plan.evaluate(fused, X, batch="vmap", chunk=3, progress=False)
    np.testing.assert_array_equal(f.status, s.status)
    np.testing.assert_allclose(f.quality, s.quality, rtol=1e-9)


def test_a_placed_fingertip_is_judged_by_its_own_cone():
    """A placed fingertip closes in along the squeeze line and may touch a node off its axis:
    the first forces (along the segment between the contacts) meet the fingertip's normal there,
    from its centre to the node, and that is the cone the margin tests, as the squeeze does.
    Here finger 0 closes in onto a corner of a long bar: the corner's bisector normal would call
    the grip feasible, the fingertip's normal does not (it used to end SLIP_FAILURE at d = 0)."""
    from jaxsqueeze.simulation import laws
    mesh = jsq.shapes.rectangle(0.2, 0.05, max_edge=0.012)
    sc = jsq.Scene(mesh=mesh, material=MAT, fingers=jsq.Fingers(radius=0.03), friction=0.94, depth=0.014,
                   placement=plan.Placement(s=(0.03335, 0.25849), angle=0.05869))
    res = jsq.squeeze(sc)
    g = np.asarray(res.grip)
    p, C = mesh.points[g], np.asarray(res.centres[0])
    tip = (p - C) / np.linalg.norm(p - C, axis=1, keepdims=True)
    pos = [int(np.flatnonzero(mesh.boundary == k)[0]) for k in g]
    node = -mesh.normals[pos]
    assert laws.grip_margin(p, node, 0.94, "coulomb", xp=np) > 0.1          # the object's normals: fine
    assert float(res.margin) == pytest.approx(laws.grip_margin(p, tip, 0.94, "coulomb", xp=np), abs=1e-12)
    assert float(res.margin) < -0.5 and res.status == jsq.Status.INFEASIBLE_GRIP


def test_a_fingertip_between_coarse_nodes_touches_one_tilted_and_refining_there_mends_it():
    """A placed fingertip centred between two boundary nodes first touches one of them off its
    axis and is judged by its own normal there: on an ellipse (50 x 35 mm) meshed at 12 mm for
    a 10 mm fingertip, the opposite placement (0, P/2) has its squeezing fingertip touch a node
    5.8 mm off its axis: its normal there makes 39 degrees with the segment between the
    contacts, past the 16.7 degree cone of mu = 0.3: infeasible, and INFEASIBLE_GRIP's advice
    says what to do. Refined to 2 mm near the fingers (refine_near), the same placement
    touches nodes on its axis: margin atan(0.3).

    A map or a search over placements on edges that long warns before it squeezes
    (PlacementResolutionWarning: up to asin(h / 2r) = 35.4 degrees off the normal against the
    cone's 16.7, and the edge length that would do, 2 r sin(atan mu) = 5.75 mm); on the refined
    mesh a map of placements near the fingers says nothing, while a search, which may go
    anywhere on the boundary, still warns of the 12 mm edges elsewhere."""
    import warnings

    from jaxsqueeze.plan import search
    from jaxsqueeze.simulation import api, engine, validate
    margins, said = [], []
    for kw in ({}, dict(refine_near=[[0.05, 0.0], [-0.05, 0.0]], refine_edge=0.002)):
        mesh = jsq.shapes.ellipse(0.05, 0.035, max_edge=0.012, **kw)
        sc = jsq.Scene(mesh=mesh, material=MAT, fingers=jsq.Fingers(radius=0.01), friction=0.3, depth=0.006,
                       placement=plan.Placement(s=(0.0, 0.1)))
        sc = sc.replace(placement=plan.Placement(s=(0.0, float(sc.curve().perimeter) / 2)))
        margin = jax.jit(lambda o, sc=sc: engine.make_model(o, api.grasp_of(sc, o), api.config_of(sc)).margin)
        margins.append(float(margin(sc.operator())))
        X = np.array([[*np.asarray(sc.placement.s), 0.0]])
        for everywhere in (False, True):
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                search._check(sc, X, None, everywhere=everywhere)
            said.append([str(w.message) for w in caught if w.category is plan.PlacementResolutionWarning])
    assert margins[0] < np.arctan(0.3) - np.radians(35)
    assert margins[1] == pytest.approx(np.arctan(0.3), abs=1e-5)
    assert "refine_near" in jsq.Status.INFEASIBLE_GRIP.advice
    assert [len(w) for w in said] == [1, 1, 0, 1], said
    assert said[0][0].startswith("boundary edges 0.0116 m long under fingertips of radius 0.01 m: a placed fingertip "
                                 "that lands between two nodes first touches one of them up to 35.4 deg off its "
                                 "normal, beyond the friction cone's 16.7 deg (mu=0.3)")
    assert said[0][0].endswith("edges of at most 2 r sin(atan mu) = 0.00575 m (max_edge, or refine_near)")
    with warnings.catch_warnings(record=True) as caught:         # docs/planning.md: how to silence it
        warnings.simplefilter("always")
        warnings.simplefilter("ignore", plan.PlacementResolutionWarning)
        search._check(sc, X, None, everywhere=True)
    assert not caught
    edge = 2 * 0.01 * np.sin(np.arctan(0.3))           # the tilt reaches the cone's edge: no warning yet
    assert validate.placement_warning(edge, 0.01, 0.3) is None and validate.placement_warning(1.001 * edge, 0.01, 0.3)


@pytest.mark.parametrize("s, angle, what", [((0.2047, 0.4498), -0.2135, "slips between nodes, through the object"),
                                            ((0.0632, 0.2451), -0.00135, "both fingers onto one node")])
def test_a_fingertip_narrower_than_the_mesh_never_squeezes_through_the_object(s, angle, what):
    """A 1 mm fingertip on a 7 mm mesh can pass between two boundary nodes and first touch a
    node from inside the object (it used to report SUCCESS with the finger inside), or both
    fingers can reach the same node (the result was NaN): both are infeasible placements,
    margin −π, one unloaded row, every number finite. A wider fingertip squeezes."""
    mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=0.007)
    sc = jsq.Scene(mesh=mesh, material=MAT, fingers=jsq.Fingers(radius=0.001), friction=0.9, depth=0.01,
                   placement=plan.Placement(s=s, angle=angle))
    res = jsq.squeeze(sc)
    assert res.status == jsq.Status.INFEASIBLE_GRIP and float(res.margin) == pytest.approx(-np.pi), what
    assert int(res.count) == 1 and len(set(np.asarray(res.grip).tolist())) == 2
    for name in ("forces", "boundary_displacement", "rigid"):
        a = np.asarray(getattr(res, name))
        assert np.all(np.isfinite(a)) and np.all(a == 0), name
    assert float(Q.squeeze_work(res)) == 0.0 and float(Q.grip_force(res)) == 0.0
    if what.startswith("slips"):
        from matplotlib.path import Path
        wide = jsq.squeeze(sc.replace(fingers=jsq.Fingers(radius=0.01)))
        assert not Path(mesh.points[mesh.boundary]).contains_points(np.asarray(wide.centres[0])).any()
        assert wide.status == jsq.Status.SUCCESS


def test_a_placement_without_a_squeeze_line_still_plots(ellipse, tmp_path):
    """An eager squeeze of both fingers placed at one point has no squeeze line: INFEASIBLE_GRIP,
    its grip the node finger 0 touches along its normal and the next one, and both fingertips
    where they were placed (finite: until 2026-12-08 they were NaN, and so were the derivatives);
    the plots still draw the object and say the status instead of failing inside matplotlib or
    warning."""
    import warnings

    missed = ellipse.replace(placement=plan.Placement(s=(0.1, 0.1)))
    res = jsq.squeeze(missed)
    assert res.outcome == jsq.Status.INFEASIBLE_GRIP and np.all(np.isfinite(res.centres))
    s = missed.arc_length(np.asarray(res.grip))               # two neighbours at the placement
    assert abs(s[0] - 0.1) < 0.006 and 0 < s[1] - s[0] < 0.006
    with warnings.catch_warnings():
        warnings.simplefilter("error")         # nor warn about the all-NaN row
        paths = jsq.plots.save_all(res, missed, str(tmp_path))
    assert all(os.path.getsize(p) > 0 for p in paths.values())


def test_squeeze_work_is_the_work_of_the_squeezing_finger(square):
    """Full stick dissipates nothing: the strain energy equals ∫ F_1 · e dd (trapezoid over the
    recorded rows; the force is linear between events, so the rule is exact up to round-off
    where rows straddle no event)."""
    res = jsq.squeeze(square.replace(friction_model="stick"))
    e = np.array([0.0, -1.0])
    f1 = np.asarray(res.total_force)[:, 1] @ e
    d = np.asarray(res.depth)
    work = np.sum(0.5 * (f1[1:] + f1[:-1]) * np.diff(d))
    np.testing.assert_allclose(float(Q.squeeze_work(res)), work, rtol=2e-3)
    np.testing.assert_allclose(float(Q.grip_force(res)), float(res.grip_force), rtol=1e-12)


def test_slip_margin_shrinks_as_the_grip_slants(square):
    """Forces along the contact normals give a margin near sin(atan μ); a slanted grip less."""
    mu = 0.5
    res = jsq.squeeze(square)
    m0 = float(Q.slip_margin(res, mu))
    mesh = square.mesh
    slanted = square.replace(grip=(nearest(mesh, (-0.01, -0.05)), nearest(mesh, (0.01, 0.05))))
    m1 = float(Q.slip_margin(jsq.squeeze(slanted), mu))
    assert 0.8 * np.sin(np.arctan(mu)) < m0 <= np.sin(np.arctan(mu))
    assert m1 < m0
    # the oracle: per finger the force-weighted mean of sin(φ − ψ) over its contacts, then the
    # smaller of the two; the smooth minimum lies below it by at most τ log 2, so with every
    # contact of finger 0 on its cone edge (exact margin 0: the grasp fails) it is not positive
    # (an unweighted soft maximum read +τ log k there: a failed disk squeeze read +0.009)
    fg, phi = np.asarray(res.finger[-1]), np.arctan(mu)
    ang = np.asarray(res.theta[-1]) + np.asarray(res.alpha[-1])[fg]
    axis, tangent = np.stack([np.cos(ang), np.sin(ang)], -1), np.stack([-np.sin(ang), np.cos(ang)], -1)
    F = np.asarray(res.forces[-1])
    size, psi = np.linalg.norm(F, axis=-1), np.arctan2(np.abs(np.sum(F * tangent, -1)), np.sum(F * axis, -1))
    contact = np.asarray(res.modes[-1]) > 0
    exact = min(np.sum((size * np.sin(phi - psi))[contact & (fg == f)]) / np.sum(size[contact & (fg == f)])
                for f in (0, 1))
    got = float(Q.slip_margin(res, mu, tau=1e-12))                  # below exact by ≤ τ log 2 = 6.9e-13
    assert exact - 1e-12 * np.log(2) - 1e-15 <= got <= exact + 1e-15, (got, exact)
    assert exact - 0.01 * np.log(2) - 1e-12 <= m0 <= exact       # attained: the two fingers' margins tie here
    on = contact & (fg == 0)
    edge = (np.cos(phi) * axis + np.sin(phi) * tangent) * size[:, None]
    forces = np.array(res.forces)
    forces[-1][on] = edge[on]
    failed = dataclasses.replace(res, forces=forces)
    assert abs(float(Q.slip_margin(failed, mu, tau=1e-12))) < 1e-12
    assert float(Q.slip_margin(failed, mu)) <= 1e-12
    # a sliding contact is on its cone's edge by the model: a force a round-off inside it read
    # +1.9e-15 for a SLIP_FAILURE (a failed grasp is never positive); here 1e-9 of φ inside
    near = (np.cos(phi * (1 - 1e-9)) * axis + np.sin(phi * (1 - 1e-9)) * tangent) * size[:, None]
    forces[-1][on], modes = near[on], np.array(res.modes)
    modes[-1][on] = 2
    assert float(Q.slip_margin(dataclasses.replace(res, forces=forces), mu, tau=1e-12)) > 0       # sticking: inside
    assert float(Q.slip_margin(dataclasses.replace(res, forces=forces, modes=modes), mu)) <= 0.0


def test_slip_margin_is_continuous_where_a_contact_joins(square):
    """A contact joins with zero force, so the forces and the margin do not jump there. A
    maximum over the contacts (even a smooth one) took the new contact's margin, the direction
    of a vanishing force, at once: on this slanted grip it read 0.087 just before the first
    new contact and 0.270 two nanometres deeper; weighted by force it changes by 1e-7."""
    mesh, mu = square.mesh, 0.3
    slanted = square.replace(grip=(nearest(mesh, (-0.01, -0.05)), nearest(mesh, (0.01, 0.05))),
                             fingers=jsq.Fingers(radius=0.03), friction=mu)
    joins = sorted({d for d, _, kind, _ in jsq.squeeze(slanted).events.rows() if kind == "A" and d > 0})
    assert len(joins) >= 2
    for d in joins[:2]:
        below, above = (float(Q.slip_margin(jsq.squeeze(slanted.replace(depth=d + h)), mu)) for h in (-1e-9, 1e-9))
        assert 0.05 < below and abs(above - below) < 1e-6, (d, below, above)


def test_slip_margin_takes_the_cones_of_the_scene_friction_model(square):
    """Given the scene (as the planner passes it), full stick measures against cones of half
    angle π/2 and frictionless against μ = 0, as the squeeze does; μ = scene.friction gave a
    full-stick map negative margins (down to −0.77) and a frictionless one +0.44."""
    from jaxsqueeze.plan.search import quality_of
    for model, mu in (("stick", np.inf), ("frictionless", 0.0)):
        sc = square.replace(friction_model=model)
        res = jsq.squeeze(sc)
        got = float(quality_of(sc, "slip_margin")(res))
        assert got == float(Q.slip_margin(res, sc.friction, scene=sc)) == float(Q.slip_margin(res, mu))
        if model == "stick":      # forces along the normals of the mirror-symmetric grip: reserve ≈ 1
            assert 0.95 < got <= 1.0
        else:                     # all slide, forces on the radius: 0 less τ log 2
            assert got == pytest.approx(-0.01 * np.log(2), abs=1e-9)
    # a temperature or a μ it cannot mean: tau = 0 gave NaN, tau = -1 a margin above 1, μ < 0 a
    # failing margin for a grasp that holds, μ = "0.5" was read, None failed inside JAX; a push
    # position asked of a result without a push read 0
    for kw, match in [(dict(tau=0.0), "tau .* must be a positive"), (dict(tau=-1.0), "tau .* must be a positive"),
                      (dict(friction=-0.5), r"friction must be ≥ 0 \(μ = ∞ for full stick\); got -0.5"),
                      (dict(friction=float("nan")), "friction must be ≥ 0"),
                      (dict(friction="0.5"), "friction .* must be real numbers"),
                      (dict(friction=None), "friction .* must be real numbers")]:
        with pytest.raises(ValueError, match=match):
            Q.slip_margin(res, **{"friction": 0.5, **kw})
    # the point-contact scene of another object failed inside JAX ("add got incompatible shapes")
    from types import SimpleNamespace
    other = SimpleNamespace(contact="point", friction_model="coulomb", mesh=jsq.shapes.rectangle(0.1, 0.1, max_edge=0.05))
    with pytest.raises(ValueError, match=r"slip_margin's scene has \d+ boundary nodes, the result \d+: pass the scene"):
        Q.slip_margin(res, 0.5, scene=other)
    with pytest.raises(ValueError, match="no adversary phase"):
        Q.failure_push(res)


def test_push_work_up_to_a_push_displacement(square):
    """``adversary_work(res, push=p)`` and ``finger_work(res, push=p)``: the work up to the push
    displacement p. At a recorded row's push it is the plain trapezoid sum over the rows up to
    it; its slope in p (``jax.jacfwd``) is the pusher's force along its motion, and central
    differences agree; it never falls (the pusher pushes); the shares add up to it; from the
    last row's push on it is the whole work. A result that kept two rows cannot say it (an
    error eagerly, NaN when traced); a bad push is an error that names it."""
    k = nearest(square.mesh, (0.05, 0.0))
    sc = square.replace(adversary=plan.Adversary(s=float(square.arc_length([k])[0]) + 0.004, push=0.003))
    res = jsq.squeeze(sc)
    p, x = np.asarray(res.push), np.asarray(res.centres)[:, 2]
    F = np.asarray(res.finger_forces)
    W = float(Q.adversary_work(res))
    first = int(np.argmax(p > 0))                       # the first push row; the one before starts the push
    inc = np.einsum("ki,ki->k", 0.5 * (F[first:, 2] + F[first - 1:-1, 2]), x[first:] - x[first - 1:-1])
    for row in (first + 3, (first + len(p)) // 2, len(p) - 2):
        np.testing.assert_allclose(float(Q.adversary_work(res, push=p[row])), inc[:row - first + 1].sum(), rtol=1e-10)
    sweep = [float(Q.adversary_work(res, push=q)) for q in np.linspace(0, p[-1], 23)]
    assert sweep[0] == 0 and np.all(np.diff(sweep) >= 0) and sweep[-1] == W > 0
    np.testing.assert_allclose(float(Q.adversary_work(res, push=p[-1] * (1 - 1e-9))), W, rtol=1e-7)
    assert float(Q.adversary_work(res, push=1.0)) == W
    q = 0.5 * (p[first + 5] + p[first + 6])            # mid-increment: forces linear in the push
    slope = float(jax.jacfwd(lambda z: Q.adversary_work(res, push=z))(q))
    j = first + 6
    along = 0.5 * (F[j - 1, 2] + F[j, 2]) @ (x[j] - x[j - 1]) / (p[j] - p[j - 1])
    h = 1e-3 * (p[j] - p[j - 1])
    fd = (float(Q.adversary_work(res, push=q + h)) - float(Q.adversary_work(res, push=q - h))) / (2 * h)
    np.testing.assert_allclose(slope, along, rtol=1e-10)
    np.testing.assert_allclose(fd, slope, rtol=1e-6)
    w = np.asarray(Q.finger_work(res, push=q))
    np.testing.assert_allclose(w.sum(), float(Q.adversary_work(res, push=q)), rtol=1e-9)
    short = jsq.squeeze(sc, history=False)
    with pytest.raises(ValueError, match="kept two rows"):
        Q.finger_work(short, push=q)
    assert np.isnan(float(jax.jit(lambda r: Q.adversary_work(r, push=q))(short)))
    assert float(Q.adversary_work(short, push=p[-1])) == float(Q.adversary_work(short))
    for bad in (-1e-3, float("nan"), "0.001", [q, q], True):
        with pytest.raises(ValueError, match="adversary_work's push"):
            Q.adversary_work(res, push=bad)


def test_symmetric_push_is_resisted_equally_by_both_fingers(square, tmp_path):
    """An adversary pushing the mirror-symmetric squeezed square at mid-height of a free side
    (on the node there), toward its centre: both grasping fingers resist equally, and their
    shares add up to the pusher's work. The push is continuous across that node: 1e-9 m to
    either side the shares agree with it (the pushed normal turns by the outline's rotation
    interpolated between nodes; it once turned as the span holding s turned, and the shares
    jumped by 3e-3 of the work at every node, ±1.6e-3 here)."""
    k = nearest(square.mesh, (0.05, 0.0))
    s3 = float(square.arc_length([k])[0])
    sc = square.replace(adversary=plan.Adversary(s=s3, push=0.003))
    res = jsq.squeeze(sc)
    assert res.outcome == jsq.Status.SUCCESS and int(res.squeeze_status) == jsq.Status.SUCCESS
    W = float(Q.adversary_work(res))
    w = np.asarray(Q.finger_work(res))
    assert W > 0
    np.testing.assert_allclose(w.sum(), W, rtol=1e-9)
    np.testing.assert_allclose(w[0], w[1], rtol=1e-9)
    for ds in (-1e-9, 1e-9):
        near = np.asarray(Q.finger_work(jsq.squeeze(square.replace(adversary=plan.Adversary(s=s3 + ds, push=0.003)))))
        np.testing.assert_allclose(near, w, rtol=1e-6)
    # the same works from a result that keeps two rows (history=False: a sum over the rows it
    # kept saw one push increment, exact only while the forces are linear in the push); 4 mm
    # off the node a second pusher contact joins halfway
    off = square.replace(adversary=plan.Adversary(s=s3 + 0.004, push=0.003))
    full, short = jsq.squeeze(off), jsq.squeeze(off, history=False)
    assert int(short.count) == 2 and [e[2] for e in full.events.rows()].count("A") >= 2
    np.testing.assert_allclose(float(Q.adversary_work(short)), float(Q.adversary_work(full)), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(Q.finger_work(short)), np.asarray(Q.finger_work(full)), rtol=1e-12)
    # the push in the pictures and the export: the event plot said "0 in all" beside the push's
    # events, the sliding profile drew the push rows (all at the final depth) as vertical lines,
    # and the export had no push field
    import matplotlib
    matplotlib.use("Agg")
    import meshio
    from jaxsqueeze.post import export, plots, views
    assert plots.plot_deformed(res, sc.mesh).axes[0].get_title().startswith(      # the push in the title
        f"Deformed object at d = 10.00 mm (10.0 %), push {float(res.push[-1]) * 1e3:.2f} mm")
    pushed = sum(e["phase"] == "push" for e in views.event_table(res))
    assert pushed >= 1 and f"and {pushed} in the adversary's push" in plots.plot_events(res)._suptitle.get_text()
    sq = np.asarray(res.push) == 0
    fig = plots.plot_sliding_profile(res)
    drawn = sum(len(c.get_segments()) for ax in fig.axes for c in ax.collections)
    on = [np.isfinite(views.sliding_profile(res, f).theta[sq]) for f in (0, 1)]
    assert drawn == sum(int(np.sum(o[1:] & o[:-1])) for o in on) > 0      # the squeeze rows' segments only
    vtu = meshio.read(export.write_final_vtu(tmp_path / "push.vtu", res, sc))
    np.testing.assert_allclose(vtu.point_data["push"], 0.003, rtol=1e-12)
    F = np.asarray(res.finger_forces)[-1]
    np.testing.assert_allclose(F.sum(0), 0, atol=1e-7 * np.abs(F).max())     # three-finger balance
    assert float(Q.failure_push(res)) == pytest.approx(0.003)
    # the pusher is finger 2 in the views too: its contact region, total force and events
    from jaxsqueeze.post import views
    s = views.summary(res, sc)
    np.testing.assert_allclose(s["total_force"]["finger2"], F[2], rtol=1e-12)
    assert s["contact_regions"]["finger2"]["n_stick"] + s["contact_regions"]["finger2"]["n_slip"] > 0
    table = views.event_table(res)
    assert [e["finger"] for e in table] == list(np.asarray(res.events.finger)[:len(table)]) and table[0]["finger"] == 2
    # the push's events are marked as such (their depth is the push displacement, no relative depth)
    assert int(res.squeeze_events) == 0 and {e["phase"] for e in table} == {"push"}
    assert all(e["relative_depth"] is None and 0 < e["depth"] <= 0.003 for e in table)
    assert s["squeeze_status"] == "SUCCESS" and s["push"] == pytest.approx(0.003)
    from matplotlib.patches import Circle
    from jaxsqueeze.post import plots
    ax = plots.plot_deformed(res, sc.mesh, details=False).axes[0]
    radii = sorted(p.radius for p in ax.patches if isinstance(p, Circle))
    np.testing.assert_allclose(radii, [10.0] * 3, rtol=1e-6)         # [mm]: both fingertips and the pusher


@pytest.mark.filterwarnings("ignore:boundary nodes .* are equally near")     # the grip points sit midway on purpose
def test_a_push_that_reverses_a_slip_sticks_the_node_where_the_push_starts(square, monkeypatch):
    """Slanted grip, mu = 0.25: two contacts slide at the end of the squeeze. The push (from
    the squeezed state, fingers still) reverses one's slip rate at once, so it sticks at the
    push's first instant (event D where the pusher touches: ADVANCE only sees a rate that
    changes sign within a step, not one already inconsistent). The engine once let it slide on against its friction for three push
    rows."""
    grip = (nearest(square.mesh, (-0.005, -0.05)), nearest(square.mesh, (0.005, 0.05)))
    sc = square.replace(grip=grip, friction=0.25, fingers=jsq.Fingers(radius=0.02),
                        adversary=plan.Adversary(s=0.05, push=0.003))
    res = jsq.squeeze(sc)
    assert int(res.squeeze_status) == jsq.Status.SUCCESS and res.outcome == jsq.Status.SUCCESS
    k = int(res.squeeze_events)
    pushed = [(kind, d) for d, _, kind, _ in res.events.rows()[k:]]
    assert pushed[0][0] == "A" and pushed[1] == ("D", pushed[0][1]) and pushed[0][1] < 1e-9   # the pusher touches
    assert sliding_against_friction(res).size == 0
    check_states(res, sc.mesh, 0.25)
    # the squeeze rows are those of the scene without the adversary (the grip stays a grip)
    plain = jsq.squeeze(sc.replace(adversary=None))
    n = int(plain.count)
    assert np.all(np.asarray(res.push)[:n] == 0) and np.asarray(res.push)[n] > 0
    np.testing.assert_allclose(np.asarray(res.forces)[:n], plain.forces, rtol=0, atol=1e-12 * np.abs(plain.forces).max())
    # a map's grip force is the squeeze's, at its last row (it read the final row, after the push)
    from jaxsqueeze.plan import search
    monkeypatch.setattr(search, "squeeze", lambda *a, **kw: res)
    monkeypatch.setattr(search, "_placed", lambda scene, x: scene)
    summ = search._summary(sc, Q.adversary_work, None, None)
    assert float(summ.grip_force) == pytest.approx(float(plain.grip_force), rel=1e-12)
    assert abs(float(res.grip_force) - float(plain.grip_force)) > 1e-3 * float(plain.grip_force)


def test_a_pusher_that_cannot_touch_from_outside_pushes_nothing(square):
    """An adversary turned past a right angle from the inward normal would reach the object
    through it (it pushed the far side), and one placed on a grasping fingertip's contact
    would overlap that fingertip: the push phase ends at once with INFEASIBLE_GRIP, the squeeze
    keeps its SUCCESS, and the push does no work. Turned 0.6 rad the pusher pushes (work > 0),
    as it does turned 0.6 + 2π (the same direction), and a push as long as the object is
    refused before running."""
    k = nearest(square.mesh, (0.05, 0.0))
    s3 = float(square.arc_length([k])[0])
    s_grip = float(square.arc_length([square.grip[0]])[0])
    s_corner = float(square.arc_length([nearest(square.mesh, (0.05, 0.05))])[0])
    work = {}
    # (at a corner, turned 2 rad, the pusher met the next edge from outside and pushed: SUCCESS,
    # against the documented rule that cos(angle) <= 0 pushes nothing)
    for s, angle, pushes in ((s3, 0.6, True), (s3, 1.7, False), (s3, np.pi, False), (s_grip, 0.0, False),
                             (s3, 0.6 + 2 * np.pi, True), (s3, 1.7 - 2 * np.pi, False),   # angles are directions
                             (s_corner, 2.0, False), (s_corner, -2.0, False)):
        res = jsq.squeeze(square.replace(adversary=plan.Adversary(s=s, push=0.003, angle=angle)))
        assert int(res.squeeze_status) == jsq.Status.SUCCESS
        assert (res.outcome == jsq.Status.SUCCESS) == pushes, (s, angle, res.outcome)
        assert pushes or (res.outcome == jsq.Status.INFEASIBLE_GRIP and float(Q.adversary_work(res)) == 0.0)
        assert not pushes or float(Q.adversary_work(res)) > 0
        work[angle] = float(Q.adversary_work(res))
    assert work[0.6 + 2 * np.pi] == pytest.approx(work[0.6], rel=1e-9)
    # a pusher narrower than push / 50 steps by its radius (the default step was refused as too long for it)
    fine = jsq.squeeze(square.replace(adversary=plan.Adversary(s=s3, push=0.003, angle=0.6, radius=6e-5)))
    push = np.asarray(fine.push)
    assert fine.outcome == jsq.Status.SUCCESS and push[-1] == pytest.approx(0.003)
    assert np.max(np.diff(push)) <= 6e-5 * (1 + 1e-9) and np.sum(np.diff(push) > 0) >= 50
    with pytest.raises(ValueError, match="push 0.2, radius 0.01, step 0.004, object size 0.1"):
        jsq.squeeze(square.replace(adversary=plan.Adversary(s=s3, push=0.2)))


def test_a_map_squeezes_both_finger_orders_when_the_fingers_differ(ellipse):
    """Fingers that rotate differently make the roles matter: the map mirrored each pair anyway
    and showed one order's quality for both (13 % off on a disk), and the better order could
    never be its best. A quality given as a function may read one finger, so it is not
    mirrored either."""
    turning = ellipse.replace(fingers=jsq.Fingers(radius=0.01, rotation=[[0.0, 0.0], [60.0, 0.0]]))
    alike = ellipse.replace(fingers=jsq.Fingers(radius=0.01, rotation=[[60.0, 0.0], [60.0, 0.0]]))
    assert plan.roles_symmetric(ellipse) and plan.roles_symmetric(alike)
    assert not plan.roles_symmetric(turning) and not plan.roles_symmetric(ellipse, Q.squeeze_work)
    P = float(ellipse.curve().perimeter)
    gm = jsq.grasp_map(turning, spacing=P / 6, progress=False)
    n = len(gm.s)
    assert gm.evaluations == n * (n - 1)
    i, j = np.nonzero((gm.status == jsq.Status.SUCCESS) & (gm.status.T == jsq.Status.SUCCESS))
    assert len(i) >= 2
    direct = plan.evaluate(turning, np.stack([gm.s[i], gm.s[j], np.zeros(len(i))], 1), progress=False)
    np.testing.assert_allclose(gm.quality[i, j], direct.quality, rtol=1e-12)
    assert np.max(np.abs(gm.quality[i, j] - gm.quality[j, i]) / np.abs(gm.quality[i, j])) > 0.01
    assert len(plan.candidate_pairs(turning, P / 6, ordered=True)) == 2 * len(plan.candidate_pairs(turning, P / 6))
    with pytest.raises(TypeError, match="ordered='yes' must be True or False"):
        plan.candidate_pairs(turning, P / 6, ordered="yes")


def test_map_chunks_across_processes_equal_the_loop(ellipse, tmp_path):
    """evaluate(batch="processes"): chunks of candidates looped in two worker processes give
    the loop's statuses and qualities, in input order (an infeasible pair included)."""
    P = float(ellipse.curve().perimeter)
    X = np.concatenate([plan.candidate_pairs(ellipse, spacing=P / 8)[:3], [[0.0, 0.004, 0.0]]])
    loop = plan.evaluate(ellipse, X, batch="loop", progress=False)
    pooled = plan.evaluate(ellipse, X, batch="processes", processes=2, chunk=2, progress=False,
                           cache=tmp_path / "cache")
    assert int(loop.status[-1]) == jsq.Status.INFEASIBLE_GRIP and np.any(loop.status == jsq.Status.SUCCESS)
    np.testing.assert_array_equal(pooled.status, loop.status)
    np.testing.assert_allclose(pooled.quality, loop.quality, rtol=1e-12, atol=0)
    np.testing.assert_allclose(pooled.grip_force, loop.grip_force, rtol=1e-12, atol=0)


def test_maps_squeeze_with_quick_capacities_and_redo_what_overflows(ellipse, monkeypatch):
    """evaluate squeezes every candidate with plan.search.quick(scene) (the automatic capacities
    fixed where an eager squeeze starts them) and again with the scene's own where that
    overflows: the same statuses and qualities as squeezing with the scene's own throughout."""
    from jaxsqueeze.plan import search
    from jaxsqueeze.simulation import scene as scene_mod
    s = search.quick(ellipse).settings
    assert (s.capacity, s.sliding_capacity) == (32, 8)
    P = float(ellipse.curve().perimeter)
    X = plan.candidate_pairs(ellipse, spacing=P / 8)[[0, 1, 5]]
    op = ellipse.operator()
    own = search._evaluate(ellipse, X, "squeeze_work", op, "loop", 64, False, None, True)
    fast = plan.evaluate(ellipse, X, op=op, batch="loop", progress=False)
    assert np.sum(own.status == jsq.Status.SUCCESS) == 2              # and one SLIP_FAILURE
    np.testing.assert_array_equal(fast.status, own.status)
    np.testing.assert_allclose(fast.quality, own.quality, rtol=1e-10, atol=0)
    monkeypatch.setattr(scene_mod, "EAGER_SLOTS", 2)          # every candidate overflows 2 slots
    assert search._evaluate(search.quick(ellipse), X, "squeeze_work", op, "loop", 64, False, None,
                            True).status.tolist() == [jsq.Status.OVERFLOW] * 3
    from jaxsqueeze import compiler
    started, ahead = [], compiler.TopLevelJit.compile_ahead
    monkeypatch.setattr(compiler.TopLevelJit, "compile_ahead",
                        lambda self, *a, **kw: started.append(a[0].settings.capacity) or ahead(self, *a, **kw))
    redone = plan.evaluate(ellipse, X, op=op, batch="loop", progress=False)
    np.testing.assert_array_equal(redone.status, own.status)
    np.testing.assert_array_equal(redone.quality, own.quality)
    # the first overflow started compiling the scene's own program; the loop went on meanwhile
    assert started == [ellipse.settings.capacity]


def test_maps_and_searches_redo_what_runs_out_of_steps_with_longer_bounds(ellipse, monkeypatch):
    """A candidate that runs out of the automatic loop bound (400) or event log (256) is
    squeezed again with both 4 times longer, then 16 times, by the eager rule (``_again``,
    ``api._longer``: sized by the pace so far; a bound set by hand stays), one at a time
    ("loop") in any batch mode; one that overflows the quick capacities again with the
    scene's own. Maps and search steps climb that ladder (here on stand-ins for their
    compiled squeezes, which report what they ran with)."""
    from jaxsqueeze.plan import search
    S, M, E, O = jsq.Status.SUCCESS, jsq.Status.MAX_STEPS, jsq.Status.EVENT_OVERFLOW, jsq.Status.OVERFLOW
    fine = ellipse.replace(settings=jsq.Settings(step=ellipse.depth / 450))      # 6 mm in 450 steps
    fast = search.quick(fine)
    bounds = lambda sc: (sc.settings.capacity, sc.settings.max_steps, sc.settings.max_events)  # noqa: E731
    longer = search._again(fine, fast, M, 0.0053)                  # stopped at 5.3 mm: 460 rows needed
    assert bounds(longer) == (32, 1600, 1024)
    assert bounds(search._again(fine, fast, M, 0.001)) == (32, 6400, 4096)     # 2,400 rows needed
    assert search._again(fine, fast, M, 0.0003) is None                        # 8,000: a step far too small
    longest = search._again(fine, longer, E, 0.003)
    assert bounds(longest) == (32, 6400, 4096) and search._again(fine, longest, E, 0.003) is None
    assert bounds(search._again(fine, longer, O, 0.003)) == (None, 1600, 1024)  # the scene's own capacities
    assert search._again(fine, fast, jsq.Status.SLIP_FAILURE, 0.003) is None
    by_hand = fine.replace(settings=jsq.Settings(step=ellipse.depth / 450, max_steps=400))
    assert search._again(by_hand, search.quick(by_hand), M, 0.0053) is None

    # evaluate: candidate k (s_0 = k mm) ends as the stand-in says for what it runs with
    def outcome(k, capacity, steps, events):
        if k == 1:
            return M if steps is None else S             # needs 1,600 steps
        if k == 2:
            return O if capacity == 32 else (M if steps is None else S)
        if k == 3:
            return E                                     # never enough events
        return S

    calls = []

    def fake(scene, X, quality, op, batch, chunk, progress, processes, cache, grown=None):
        ks = np.rint(X[:, 0] * 1e3).astype(int)
        calls.append((bounds(scene), batch, ks.tolist()))
        st = np.array([outcome(k, *bounds(scene)) for k in ks])
        one = np.ones(len(ks))
        return search.Summary(st, np.where(st == S, (scene.settings.max_steps or 400) * one, 0.0), one, 0.003 * one, one)

    monkeypatch.setattr(search, "_evaluate", fake)
    X = np.array([[k * 1e-3, 0.1, 0.0] for k in range(4)])
    summ = plan.evaluate(fine, X, op=ellipse.operator(), batch="vmap", progress=False)
    assert summ.status.tolist() == [S, S, S, E] and summ.quality.tolist() == [400, 1600, 1600, 0]
    assert calls == [((32, None, None), "vmap", [0, 1, 2, 3]),
                     ((32, 1600, 1024), "loop", [1, 3]),          # longer: one at a time
                     ((None, None, None), "vmap", [2]),           # the scene's own capacities
                     ((None, 1600, 1024), "loop", [2]),
                     ((32, 6400, 4096), "loop", [3])]

    # a search step: quick capacities, longer bounds, then the scene's own where those overflow
    ran = []

    def step(scene, qfn, op, u, scale, vary_angle):
        ran.append(bounds(scene)[:2])
        st = {(32, None): M, (32, 1600): O}.get(ran[-1], S)
        summary = search.Summary(jnp.array(st), jnp.array(1.0), jnp.array(1.0), jnp.array(0.003), jnp.array(0.1))
        return summary, jnp.zeros(3)

    monkeypatch.setattr(search, "_value_and_grad", step)
    best = jsq.optimize_placement(fine, "squeeze_work", init=X[:1], steps=0, progress=False)
    assert ran == [(32, None), (32, 1600), (None, 1600)] and best.history[0][0].status == S
    # a start keeps what it grew to: its next steps squeeze with that at once
    ran.clear()
    jsq.optimize_placement(fine, "squeeze_work", init=X[:1], steps=2, progress=False)
    assert ran == [(32, None), (32, 1600), (None, 1600), (None, 1600), (None, 1600)]

    # a search from its coarse map starts where the start's cell ended (here the scene's own
    # capacities), that program compiled ahead like the quick one
    summ, runs = search._evaluate_with_runs(fine, X, "squeeze_work", fine.operator(), "vmap", None, False, None, True)
    assert [bounds(r) for r in runs] == [(32, None, None), (32, 1600, 1024), (None, 1600, 1024), (32, 6400, 4096)]
    ahead = []

    class Stand:                         # the stand-in program, with compile_ahead
        __call__ = staticmethod(step)

        def compile_ahead(self, scene, *args):
            ahead.append(bounds(scene)[:2])

    def coarse(scene, X, *args):         # every cell feasible, the last one best, after growing
        n = len(X)
        cells = search.Summary(np.full(n, S), np.arange(n, dtype=float), np.ones(n), np.full(n, 0.003), np.ones(n))
        return cells, [fast] * (n - 1) + [search._again(fine, fast, O, 0.0)]

    monkeypatch.setattr(search, "_value_and_grad", Stand())
    monkeypatch.setattr(search, "_evaluate_with_runs", coarse)
    ran.clear()
    jsq.optimize_placement(fine, "squeeze_work", starts=1, steps=0, progress=False)
    assert ahead == [(32, None), (None, None)] and ran == [(None, None)]


PLANNING_OBJECTS = {     # coarse meshes: a fine exhaustive map at node spacing stays affordable in a test
    "square": lambda: jsq.shapes.rectangle(0.1, 0.1, max_edge=0.01),
    "ellipse": lambda: jsq.shapes.ellipse(0.06, 0.04, max_edge=0.01),
    "L-shape": lambda: jsq.shapes.polygon([(0, 0), (0.1, 0), (0.1, 0.05), (0.05, 0.05), (0.05, 0.1), (0, 0.1)],
                                          max_edge=0.01),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(PLANNING_OBJECTS))
def test_search_reaches_the_best_of_the_exhaustive_map(name):
    """Issue 10: five starts from a screened coarse map reach within 2 % of the best quality of an
    exhaustive map at node spacing (or pass it: placements between nodes are allowed), with at
    most a tenth of its squeezes, on a square, an ellipse and a non-convex L-shape."""
    import optax

    mesh = PLANNING_OBJECTS[name]()
    sc = jsq.Scene(mesh=mesh, material=MAT, fingers=jsq.Fingers(radius=0.01), placement=plan.Placement(s=(0.0, 0.1)),
                   friction=0.5, depth=0.008)
    op = sc.operator()
    P = float(sc.curve().perimeter)
    fine = plan.grasp_map(sc, "squeeze_work", op=op, progress=False)          # node spacing
    assert fine.evaluations == mesh.m * (mesh.m - 1) // 2
    best = float(fine.quality[fine.feasible()].max())
    with compiles(where=True) as compiled:
        found = plan.optimize_placement(sc, "squeeze_work", starts=5, steps=12, coarse_spacing=P / 12, op=op,
                                        optimizer=optax.adam(0.03), progress=False, budget=fine.evaluations // 10)
    # the search's gradient program compiled in the background while the coarse map ran, once
    gradient = [thread for name, thread in compiled if name == "jit(_value_and_grad)"]
    assert gradient[:1] == ["compile _value_and_grad"], compiled
    assert found.quality >= 0.98 * best, (found.quality, best)
    assert found.squeezes <= fine.evaluations / 10, (found.squeezes, fine.evaluations)
    assert found.screened == 66 and len(found.history) == 5
    res = jsq.squeeze(sc.replace(placement=found.best), op=op)
    assert res.outcome == jsq.Status.SUCCESS
    np.testing.assert_allclose(float(Q.squeeze_work(res)), found.quality, rtol=1e-9)


def test_placements_are_periodic_in_the_perimeter(square):
    """docs/planning.md: s is an arc length modulo the perimeter P (both directions). (The
    placed square of the depth test above: the same compiled squeeze.)"""
    P = float(square.curve().perimeter)
    s0 = np.asarray(square.arc_length(square.grip), float)
    runs = [jsq.squeeze(square.replace(grip=None, placement=plan.Placement(s=s0 + shift)))
            for shift in ((0.0, 0.0), (P, P), (-2 * P, P))]
    assert all(r.outcome == jsq.Status.SUCCESS and tuple(r.grip) == tuple(runs[0].grip) for r in runs)
    for r in runs[1:]:
        np.testing.assert_allclose(np.asarray(r.forces[-1]), np.asarray(runs[0].forces[-1]), rtol=0,
                                   atol=1e-9 * np.abs(np.asarray(runs[0].forces[-1])).max())


def test_a_search_history_records_undone_steps_once(ellipse):
    """A step onto an infeasible placement is undone: the history records it once, with its
    status and ``undone`` (the placement it started from was listed twice before, as if the
    search had stood still), and the map's plot draws it apart from the path."""
    import matplotlib
    import optax
    matplotlib.use("Agg")
    from jaxsqueeze.post.maps import plot_grasp_map
    P = float(ellipse.curve().perimeter)
    found = jsq.optimize_placement(ellipse, "grip_force", init=[[0.0, P / 2 + 0.01]], optimizer=optax.sgd(2.0),
                                   steps=5, progress=False)
    hist = found.history[0]
    assert len(hist) == 6 and found.squeezes == 6
    undone = [h for h in hist if h.undone]
    assert undone and all(h.status != jsq.Status.SUCCESS for h in undone)
    path = [h for h in hist if not h.undone]
    assert all(h.status == jsq.Status.SUCCESS for h in path)
    assert all(np.any(a.x != b.x) for a, b in zip(path, path[1:]))       # it moved at every accepted step
    assert found.quality == max(h.quality for h in path)
    # starts that never squeeze with SUCCESS: the error says how they ended and what to do
    with pytest.raises(ValueError, match=r"no start reached a successful squeeze \(the 1 start\(s\) ended with "
                                         r"INFEASIBLE_GRIP\); start from feasible placements"):
        jsq.optimize_placement(ellipse, "grip_force", init=[[0.0, 0.05]], steps=1, progress=False)
    # docs/planning.md: the compiled gradient is shared by every search on scenes of the same
    # shapes (other numbers, another start and optimizer: nothing compiles)
    from jaxsqueeze.plan import search
    compiled = search._value_and_grad._cache_size()
    notebook = _kernel_stream()                  # and a notebook shows where the search is
    with contextlib.redirect_stderr(notebook), jax.transfer_guard("disallow"):     # (README: under a guard)
        other = jsq.optimize_placement(ellipse.replace(friction=0.6, depth=0.005, fingers=jsq.Fingers(radius=0.012)),
                                       "grip_force", init=[[0.01, P / 2]], optimizer=optax.adam(0.05), steps=2)
    assert other.squeezes == 3 and search._value_and_grad._cache_size() == compiled
    assert notebook.getvalue() == f"start 1/1: best {other.quality:.6g}\n"
    from jaxsqueeze.plan.search import GraspMap
    grid = np.linspace(0.0, P, 4)[:3]
    status = np.where(np.eye(3, dtype=bool), jsq.Status.INFEASIBLE_GRIP, jsq.Status.SUCCESS)
    gmap = GraspMap(grid, np.ones((3, 3)), status, np.ones((3, 3)), np.zeros((3, 3)), 0.0, np.zeros((0, 3)), 6)
    # both print in one line (a map printed its four n × n arrays, a search every step)
    assert repr(gmap) == (f"GraspMap(3 positions {P / 3:.4g} m apart, 6 squeezes, 6 of 6 ordered pairs feasible, "
                          "best 1)")
    s0, s1 = found.best.s
    assert repr(found) == (f"Search(best quality {found.quality:.4g} at s = ({s0:.4g}, {s1:.4g}) m, angle 0 rad; "
                           "1 start, 6 squeezes, 0 screened)")
    fig = plot_grasp_map(gmap, found)
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert "undone steps" in labels and "search" in labels


def test_a_search_keeps_its_angle_and_stops_at_a_step_that_is_not_finite(ellipse):
    """vary_angle=False masked the gradient but not the optimizer's step: weight decay (adamw)
    or noise moved the angle all the same. A step that is not finite at a successful placement
    was undone and retried at half scale with the same NaN, every step, and the search returned
    its start quietly; it is now an error that says where."""
    import optax
    P = float(ellipse.curve().perimeter)
    found = jsq.optimize_placement(ellipse, "grip_force", init=[[0.0, P / 2 + 0.01, 0.1]],
                                   optimizer=optax.adamw(0.02, weight_decay=5.0), steps=2, progress=False)
    assert [h.x[2] for h in found.history[0]] == [0.1] * 3 and found.best.angle == 0.1
    assert len({h.x[1] for h in found.history[0]}) == 3                          # while s moved
    nan_later = optax.GradientTransformation(lambda u: jnp.zeros((), jnp.int32),
                                             lambda g, n, u=None: (jnp.where(n > 0, jnp.nan, g), n + 1))
    with pytest.raises(ValueError, match=r"at the placement .* which squeezes with SUCCESS, .* not finite"):
        jsq.optimize_placement(ellipse, "grip_force", init=[[0.0, P / 2 + 0.01]], steps=3, progress=False,
                               optimizer=optax.chain(optax.sgd(0.02), nan_later))


def test_vary_angle_moves_the_angle_along_the_qualitys_derivative(ellipse):
    """optimize_placement(vary_angle=True) also moves the squeeze-direction offset: one plain
    gradient step (optax.sgd, the angle unscaled in u) moves it by the learning rate times
    d quality / d angle, which central differences of the quality give too. Without it the
    search differentiates in the arc lengths only (one tangent fewer) and steps them alike."""
    import optax
    P, lr, a0, d = float(ellipse.curve().perimeter), 0.02, 0.1, 1e-4
    found = jsq.optimize_placement(ellipse, "grip_force", init=[[0.0, P / 2 + 0.01, a0]], optimizer=optax.sgd(lr),
                                   steps=1, vary_angle=True, progress=False)
    start, moved = found.history[0]
    assert start.status == moved.status == jsq.Status.SUCCESS and not moved.undone
    q = [jsq.optimize_placement(ellipse, "grip_force", init=[[0.0, P / 2 + 0.01, a]], steps=0, vary_angle=True,
                                progress=False).quality for a in (a0 + d, a0 - d)]     # (the same program)
    fd = (q[0] - q[1]) / (2 * d)
    assert abs(fd) > 0.1                              # the angle matters here
    np.testing.assert_allclose((moved.x[2] - a0) / lr, fd, rtol=1e-6)
    kept = jsq.optimize_placement(ellipse, "grip_force", init=[[0.0, P / 2 + 0.01, a0]], optimizer=optax.sgd(lr),
                                  steps=1, progress=False).history[0][1]
    assert kept.x[2] == a0 and kept.status == jsq.Status.SUCCESS
    np.testing.assert_allclose(kept.x[:2], moved.x[:2], rtol=1e-12, atol=0)


def test_plot_grasp_map_names_what_it_draws():
    """plot_grasp_map(a squeeze result) failed with "'SqueezeResult' object has no attribute 's'"."""
    import matplotlib
    matplotlib.use("Agg")
    from jaxsqueeze.plan.search import GraspMap
    from jaxsqueeze.post.maps import plot_grasp_map
    with pytest.raises(TypeError, match=r"draws a GraspMap \(jaxsqueeze.grasp_map\(scene, ...\)\), got dict"):
        plot_grasp_map({"s": [0.0]})
    s = np.array([0.0, 0.01, 0.02])
    status = np.where(np.eye(3, dtype=bool), jsq.Status.INFEASIBLE_GRIP, jsq.Status.SUCCESS)
    gmap = GraspMap(s, np.ones((3, 3)), status, np.ones((3, 3)), np.zeros((3, 3)), 0.0, np.array([[0.0, 0.01, 0.0]]), 6)
    with pytest.raises(TypeError, match="search= takes a Search"):
        plot_grasp_map(gmap, search="x")
    ax = plot_grasp_map(gmap).axes[0]
    assert len(ax.collections) == 2          # the grey infeasible cells and the quality
