"""The validation layer (issue 12): every rule eagerly and under jit / vmap / jvp, the same answer."""
from __future__ import annotations

import dataclasses
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsqueeze as jsq
from jaxsqueeze.simulation import validate as V

GOOD = {
    "material.E": 1e5, "material.nu": 0.3, "material.thickness": 0.0254, "fingers.radius": 0.01,
    "friction": 0.5, "depth": 0.01, "grip_distance": 0.1, "settings.step": 2e-4, "settings.event_tol": 2e-8,
    "settings.newton_tol": 1e-11, "settings.gap_tol": 1e-10, "grip_slots": np.array([3, 20]), "n_boundary": 40,
    "fingers.rotation": np.zeros((2, 1)), "grip.overlap": np.array([-1e-3, -1e-3]),
    "placement.s": np.array([0.0, 0.2]), "placement.angle": 0.0, "size": 0.1,
    "adversary.s": 0.05, "adversary.angle": 0.0, "adversary.push": 0.003, "adversary.radius": 0.01,
    "adversary.step": 6e-5,
}
NAN, INF = float("nan"), float("inf")
POS = [NAN, INF, -INF, 0.0, -1.0]
BAD = {
    "material.E": POS + [1e160],                 # E h L = 2.5e155 N: forces overflow when squared (traced: inf, SUCCESS)
    "material.nu": [NAN, INF, -1.0, -2.0, 0.5000001],
    "material.thickness": POS,
    "fingers.radius": POS + [2e5],               # 2e6 object sizes (0.1 m); 1e200 overflowed the overlap test
    "friction": [NAN, INF, -0.1],
    "depth": POS + [0.1, 0.2],                   # 0.1 / 0.2 >= the grip distance: fingertips pass through
    "settings.step": POS + [1e-300, 1e-17, 0.02],  # below the depth's round-off; above the depth
    "settings.event_tol": POS + [1e-4],          # wider than a tenth of the step (2e-4): events anywhere in it
    "settings.newton_tol": POS + [1e-300, 0.5],  # below round-off: never met; half a radian: no tolerance
    "settings.gap_tol": POS + [2e-3],            # beyond 1 % of the object (0.1 m) nodes sink in unseen
    "grip_slots": [np.array([3, 3]), np.array([-1, 20]), np.array([3, 40]), np.array([1000000, 2])],
    "fingers.rotation": [np.array([[NAN], [0.0]]), np.array([[0.0], [INF]]), np.array([[0.0], [-63.0]])],
    "grip.overlap": [np.array([1.4e-3, -1.0]), np.array([NAN, 0.0])],
    "placement.s": [np.array([NAN, 0.2]), np.array([0.0, INF]),
                    np.array([1e15, 0.2]), np.array([0.0, -100.5])],   # beyond 1,000 sizes: wrapping is round-off
    "adversary.push": POS + [0.1, 0.5],           # as long as the object (0.1 m) or longer: it would crush it
}
KEY = {f: f for f in V.FIELDS}
KEY["grip"] = "grip_slots"
KEY["placement"] = "placement.s"
KEY["adversary"] = "adversary.push"
CASES = [(k, f, v) for k, f in enumerate(V.FIELDS) for v in BAD[KEY[f]]]


@pytest.mark.parametrize("change", [{"settings.step": 3e-4, "settings.event_tol": 3e-5},
                                    {"settings.gap_tol": 1e-3}, {"size": 0.7, "settings.gap_tol": 7e-3}], ids=str)
def test_a_tolerance_at_exactly_its_limit_is_valid(change):
    """event_tol a tenth of the step and gap_tol 1 % of the size are inside their limits, also
    where the limit rounds below the number a user typed (0.1 * 3e-4 < 3e-5 and 0.01 * 0.7 <
    7e-3 in binary)."""
    vals = dict(GOOD, **change)
    assert V.problems(vals) == [] and int(V.invalid_index(vals)) == -1
    assert int(jax.jit(V.invalid_index)(vals)) == -1


def test_every_field_has_bad_cases_and_rules_line_up():
    assert tuple(r.field for r in V.RULES) == V.FIELDS
    assert all(BAD[KEY[f]] for f in V.FIELDS)
    assert V.problems(GOOD) == []
    assert int(V.invalid_index(GOOD)) == -1
    V.raise_if_invalid(GOOD)


@pytest.mark.parametrize("k,field,bad", CASES, ids=[f"{f}={np.asarray(v).tolist()}" for _, f, v in CASES])
def test_rule_eager_jit_vmap_agree(k, field, bad):
    vals = dict(GOOD, **{KEY[field]: bad})
    # eager: exactly one line, naming the field
    p = V.problems(vals)
    assert len(p) == 1 and p[0].startswith(field + " = "), p
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        V.raise_if_invalid(vals)
    # traced twin, eager call, jit and vmap (good lane, bad lane)
    assert int(V.invalid_index(vals)) == k
    assert int(jax.jit(V.invalid_index)(vals)) == k
    batch = jnp.stack([jnp.asarray(GOOD[KEY[field]], jnp.result_type(float) if not
                                   np.issubdtype(np.asarray(bad).dtype, np.integer) else jnp.int64),
                       jnp.asarray(bad)])
    rest = {kk: vv for kk, vv in GOOD.items() if kk != KEY[field]}
    out = jax.jit(jax.vmap(lambda x: V.invalid_index(dict(rest, **{KEY[field]: x}))))(batch)
    assert out.tolist() == [-1, k]


@pytest.mark.parametrize("change", [{"adversary.step": 0.011}, {"adversary.step": 0.004}, {"adversary.step": 1e-300},
                                    {"adversary.step": NAN}, {"adversary.radius": 0.0}, {"adversary.s": NAN},
                                    {"adversary.angle": INF}, {"adversary.s": 1e15}, {"adversary.angle": -1001.0}],
                         ids=str)
def test_adversary_step_beyond_its_radius_or_push_is_refused(change):
    """The pusher's step must be at most its radius (a longer step could carry it across a
    boundary node between two gap checks: it passed through the object, SUCCESS with no work)
    and at most the push; its position, angle and radius finite."""
    vals = dict(GOOD, **change)
    p = V.problems(vals)
    assert len(p) == 1 and p[0].startswith("adversary = ") and "push 0.003, radius" in p[0], p
    assert int(jax.jit(V.invalid_index)(vals)) == V.FIELDS.index("adversary")


def test_a_placement_too_far_out_to_wrap_is_refused_with_the_modulo_to_take(square):
    """Placement.s wraps round the perimeter and the angle round the circle, but wrapping a
    value X keeps it only to X * eps: s = 1e15 m gave INFEASIBLE_GRIP at a node pair of
    round-off (a squeeze of noise), 1e308 the same. Up to 1,000 object sizes and 1,000 rad
    they wrap; beyond, an error says to take the modulo (traced: INVALID_INPUT)."""
    assert V.problems(dict(GOOD, **{"placement.s": np.array([99.9, -99.9]), "placement.angle": -999.0})) == []
    far = V.problems(dict(GOOD, **{"placement.angle": 1001.0}))
    assert len(far) == 1 and far[0].startswith("placement = s [0. , 0.2], angle 1001.0 (object size 0.1 m)"), far
    placed = _scene(square).replace(grip=None, placement=jsq.Placement(s=(1e15, 0.25)))
    with pytest.raises(ValueError, match=r"placement = s \[1\.0e\+15, 2\.5e-01\].*modulo the perimeter"):
        jsq.squeeze(placed)
    lanes = {"placement.s": jnp.array([[0.0, 0.2], [1e308, 0.2]]), "placement.angle": jnp.array([0.0, 0.0])}
    rest = {k: v for k, v in GOOD.items() if k not in lanes}
    out = jax.vmap(lambda s, a: V.invalid_index(dict(rest, **{"placement.s": s, "placement.angle": a})))(
        lanes["placement.s"], lanes["placement.angle"])
    assert out.tolist() == [-1, V.FIELDS.index("placement")]


def test_a_fingertip_turning_more_than_ten_turns_over_the_squeeze_is_refused():
    """rotation = [[1e10, 0], ...] rad/m (a unit slip: 1e7 rad per mm) turned the tips 25 rad in
    the first step and ended LOST_CONTACT or STALLED with NaN fields; the bound is on
    sum |c_k| depth^k, the most a polynomial can turn over [0, depth]."""
    lin = lambda c: dict(GOOD, **{"fingers.rotation": np.array([[c, 0.0], [0.0, 0.0]])})  # noqa: E731
    assert V.problems(lin(6000.0)) == []                        # 60 rad over depth 0.01 m
    assert V.problems(lin(-6400.0))[0].startswith("fingers.rotation = ")
    assert int(jax.jit(V.invalid_index)(lin(1e10))) == V.FIELDS.index("fingers.rotation")
    quad = dict(GOOD, **{"fingers.rotation": np.array([[6.4e5, 0.0, 0.0], [0.0, 0.0, 0.0]])})
    assert V.problems(quad)[0].startswith("fingers.rotation")   # 64 rad at the full depth
    assert V.problems(dict(quad, depth=0.009)) == []            # 51.8 rad


def test_first_invalid_wins_and_all_problems_listed():
    vals = dict(GOOD, **{"material.E": -1.0, "settings.gap_tol": NAN, "depth": 0.2})
    assert int(V.invalid_index(vals)) == V.FIELDS.index("material.E")
    p = V.problems(vals)
    assert [line.split(" = ")[0] for line in p] == ["material.E", "depth", "settings.gap_tol"]
    with pytest.raises(ValueError) as e:
        V.raise_if_invalid(vals)
    assert all(f in str(e.value) for f in ("material.E", "depth", "settings.gap_tol"))


def test_a_problem_is_one_line():
    """A value shown in a problem is on one line (a (2, 1) rotation spread over two 'error:'
    lines of the CLI)."""
    rot = np.array([[1e9], [0.0]])
    p = V.problems({"fingers.rotation": rot, "depth": 0.01})
    assert len(p) == 1 and "\n" not in p[0] and "[[1.e+09], [0.e+00]]" in p[0]


def test_missing_values_are_skipped():
    assert int(V.invalid_index({"material.E": 1.0})) == -1
    # no depth: only > 0 is checked, by both paths (the suite runs with x64 on: 1e-300 is > 0)
    assert int(V.invalid_index({"settings.step": 1e-300})) == -1 and V.problems({"settings.step": 1e-300}) == []
    assert int(V.invalid_index({"settings.step": -1.0})) == V.FIELDS.index("settings.step")
    assert V.problems({"settings.step": None, "depth": 0.01}) == []


def test_step_resolution_follows_the_precision():
    vals = {"depth": 0.01, "settings.step": 1e-8}
    assert int(V.invalid_index(vals)) == -1                                     # float64: fine
    assert int(V.invalid_index(dict(vals, eps=float(np.finfo(np.float32).eps)))) == V.FIELDS.index("settings.step")
    f32 = {"depth": jnp.float32(0.01), "settings.step": jnp.float32(1e-8)}
    assert int(V.invalid_index(f32)) == V.FIELDS.index("settings.step")


def test_jvp_through_a_depth_beyond_the_grip_distance_is_flagged():
    def f(d):
        bad = V.invalid_index(dict(GOOD, depth=d)) >= 0
        return jnp.where(bad, jnp.nan, d ** 2)

    for d, flagged in ((0.01, False), (0.2, True)):
        y, t = jax.jvp(f, (jnp.asarray(d),), (jnp.asarray(1.0),))
        assert bool(jnp.isnan(y)) == flagged
        if not flagged:
            assert math.isclose(float(t), 2 * d)


@pytest.fixture(scope="module")
def square():
    return jsq.shapes.rectangle(0.1, 0.1, max_edge=0.02)


def _scene(mesh, **kw):
    b = np.asarray(mesh.boundary)
    P = mesh.points + mesh.offset
    i = int(b[np.argmin(np.linalg.norm(P[b] - [0.0, -0.05], axis=1))])
    j = int(b[np.argmin(np.linalg.norm(P[b] - [0.0, 0.05], axis=1))])
    base = dict(mesh=mesh, material=jsq.Material(E=1e5, nu=0.3, thickness=0.0254),
                fingers=jsq.Fingers(radius=0.01), grip=(i, j), friction=0.5, depth=0.01)
    base.update(kw)
    return jsq.Scene(**base)


def test_scene_values_eager_and_batched(square):
    sc = _scene(square)
    V.check_scene(sc)                                      # a good scene passes
    with pytest.raises(ValueError, match="depth = 0.2 .*grip distance"):
        V.check_scene(sc.replace(depth=0.2))               # the API row: fingertips pass through
    f = jax.jit(jax.vmap(lambda d, E: V.invalid_index(V.values_of(sc.replace(
        depth=d, material=jsq.Material(E=E, nu=0.3, thickness=0.0254))))))
    out = f(jnp.array([0.01, 0.2, 0.01, 0.01, 0.01]), jnp.array([1e5, 1e5, NAN, -1.0, 0.0]))
    assert out.tolist() == [-1, V.FIELDS.index("depth")] + [V.FIELDS.index("material.E")] * 3
    # grip node 1000000 under jit: reported, never another node
    g = jax.jit(lambda grip: V.invalid_index(V.values_of(sc.replace(grip=grip))))
    assert int(g(jnp.array([1000000, sc.grip[1]]))) == V.FIELDS.index("grip")
    interior = int(np.setdiff1d(np.arange(square.n), square.boundary)[0])
    assert int(g(jnp.array([interior, sc.grip[1]]))) == V.FIELDS.index("grip")
    assert int(g(jnp.array(sc.grip))) == -1
    # the same node twice is a bad grip (not a depth beyond a grip distance of 0)
    assert int(g(jnp.array([sc.grip[0]] * 2))) == V.FIELDS.index("grip")


def test_numbers_of_mixed_types_trace_under_strict_dtype_promotion(square):
    """README, "Your JAX settings": a scene given as float32, int16 and int64 numbers in a
    float64 session traces under ``jax.numpy_dtype_promotion("strict")`` (the traced
    validation and the grip lookup take the caller's numbers as given; the assembly casts ν to
    the mesh's precision), and its stiffness is the float64 scene's to float32 round-off of ν.
    Promotion is decided while tracing, so lowering the jitted squeeze checks every operation."""
    f32 = np.float32
    sc = _scene(square)
    mixed = sc.replace(material=jsq.Material(E=f32(1e5), nu=jnp.float32(0.3), thickness=0.0254),
                       fingers=jsq.Fingers(radius=f32(0.01)), grip=(np.int16(sc.grip[0]), np.int64(sc.grip[1])),
                       friction=jnp.float32(0.5), depth=f32(0.01))
    with jax.numpy_dtype_promotion("strict"):
        jax.jit(lambda s: jsq.squeeze(s).total_force).lower(mixed)
        K = jsq.fem.stiffness(square, mixed.material).todense()
    assert K.dtype == jnp.float64
    np.testing.assert_allclose(K, jsq.fem.stiffness(square, sc.material).todense(), rtol=0, atol=1e-6 * np.abs(K).max())


def test_nearest_boundary_node_warns_when_two_nodes_are_equally_near(square):
    """(0, -0.05) lies midway between two nodes of the 20 mm square: which one round-off picks
    decides whether a 'centred' grip is slanted (11 degrees here, a fifth of the grip force
    sideways), so it says so; a point on a node says nothing."""
    import warnings
    with pytest.warns(UserWarning, match=r"boundary nodes \d+ and \d+ are equally near \[0.0, -0.05\]") as said:
        node = jsq.scene.nearest_boundary_node(square, (0.0, -0.05))
    assert said[0].filename == __file__                    # the warning names the caller's line
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert jsq.scene.nearest_boundary_node(square, (square.points + square.offset)[node]) == node


def test_an_equally_near_pair_is_settled_by_boundary_order_not_round_off(square):
    """The tie at (0, -0.05) is settled the same way however the nodes are numbered: the first
    of the two in boundary order (the mesh's offset, whose rounding depends on the numbering,
    used to pick by the last bit: 20 of 30 numberings picked another node at one of four
    such points)."""
    from jaxsqueeze.geometry.mesh import Mesh
    P, T = np.asarray(square.points) + square.offset, np.asarray(square.triangles)
    xy = (0.0, -0.05)
    picked = []
    for seed in range(10):
        p = np.random.default_rng(seed).permutation(len(P))
        m = Mesh.from_arrays(P[p], np.argsort(p)[T])
        s = jsq.scene.snap(m, xy)
        assert s.tie is not None
        order = list(m.boundary)
        assert order.index(s.node) < order.index(s.tie)
        picked.append((m.points + m.offset)[s.node])
    np.testing.assert_allclose(picked, np.repeat(picked[:1], len(picked), axis=0), atol=1e-12)


@pytest.mark.parametrize("xy", [(0.0, 50.0), (0.0, 0.0)])
def test_nearest_boundary_node_warns_of_a_point_off_the_outline(square, xy):
    """A point in millimetres among metres, or the object's centre, snapped silently to some
    boundary node; the scene files refuse it, the function says so (one warning, not also a tie)."""
    with pytest.warns(UserWarning, match=r"is .* m from the nearest boundary node \d+ at .*, more than twice the "
                                         r"boundary edges there .* a grip point belongs on the object's outline") as said:
        jsq.scene.nearest_boundary_node(square, xy)
    assert len(said) == 1 and said[0].filename == __file__


@pytest.mark.parametrize("xy", [(np.nan, 0.0), (np.inf, 0.0), 0.0, (0.0, -0.05, 0.0), "0,0", (1j, 0.0)])
def test_nearest_boundary_node_refuses_a_point_that_is_not_one_finite_pair(square, xy):
    """A NaN point returned some node without a word, a scalar was read as (0, 0), a 3-D point
    and a string failed in numpy's words."""
    with pytest.raises(ValueError, match=r"the point xy must be (one finite \(x, y\) pair in metres|real numbers)"):
        jsq.scene.nearest_boundary_node(square, xy)


def test_a_depth_as_large_as_the_object_is_refused_also_across_a_diagonal(square):
    """A grip across the square's diagonal is 0.14 m apart, so a 0.105 m squeeze passes the
    grip-distance rule; it is deeper than the object is across (0.1 m) and was SUCCESS with
    no word (a deeper squeeze than the 50 % that warns). Refused eagerly, in scene values and
    under jit, naming the object size."""
    sw = jsq.scene.nearest_boundary_node(square, (-0.05, -0.05))
    ne = jsq.scene.nearest_boundary_node(square, (0.05, 0.05))
    sc = _scene(square).replace(grip=(sw, ne), depth=0.105)
    with pytest.raises(ValueError, match=r"depth = 0\.105 \(grip distance 0\.14.* m, object size 0\.1 m\).*crush"):
        jsq.squeeze(sc)
    f = jax.jit(lambda d: V.invalid_index(V.values_of(sc.replace(depth=d))))
    assert int(f(0.105)) == V.FIELDS.index("depth") and int(f(0.099)) == -1


@pytest.mark.parametrize("change,field", [
    (dict(friction=[0.2, 0.3]), "friction has shape \\(2,\\)"),
    (dict(depth=[0.01]), "depth has shape \\(1,\\)"),
    (dict(depth="deep"), "depth = 'deep': expected a number"),
    (dict(material=jsq.Material(E=np.array([1e5, 2e5]), nu=0.3, thickness=0.0254)), "material.E has shape"),
    (dict(fingers=jsq.Fingers(radius=[0.01])), "fingers.radius has shape"),
    (dict(settings=jsq.Settings(step=[1e-3])), "settings.step has shape"),
    (dict(adversary=jsq.Adversary(s=[0.1, 0.2], push=1e-3)), "adversary.s has shape"),
])
def test_an_eager_squeeze_refuses_an_array_where_a_number_belongs(square, change, field):
    """One squeeze takes one number per field (a batch is for vmap): the error names the field
    (an array friction reached float() in the cone test, an array depth a lax.switch type error)."""
    with pytest.raises(ValueError, match=field):
        jsq.squeeze(_scene(square, **change))


def test_fingertip_overlapping_a_reentrant_vertex_is_refused():
    # a five-pointed star gripped at a re-entrant vertex: the fingertip overlaps the two
    # neighbouring arms at first touch
    k = np.arange(10)
    r = np.where(k % 2 == 0, 0.05, 0.02)
    star = np.stack([r * np.cos(np.pi * k / 5 + np.pi / 2), r * np.sin(np.pi * k / 5 + np.pi / 2)], 1)
    mesh = jsq.shapes.polygon(star, max_edge=0.005)
    P = mesh.points + mesh.offset
    b = np.asarray(mesh.boundary)
    near = lambda xy: int(b[np.argmin(np.linalg.norm(P[b] - xy, axis=1))])  # noqa: E731
    inner, outer = near(star[1]), near(star[6])
    sc = _scene(mesh, grip=(inner, outer), fingers=jsq.Fingers(radius=0.01), depth=0.005)
    v = V.values_of(sc)
    assert np.max(v["grip.overlap"]) > 1e-3
    with pytest.raises(ValueError, match=r"grip.overlap = \[.*\] \(how far \[m\] fingertip 0 and fingertip 1 reach past"):
        V.check_scene(sc)
    idx = jax.jit(lambda rr: V.invalid_index(V.values_of(sc.replace(fingers=jsq.Fingers(radius=rr)))))
    assert int(idx(0.01)) == V.FIELDS.index("grip.overlap")
    # two tips of the star: convex, no overlap
    V.check_scene(_scene(mesh, grip=(near(star[0]), near(star[4])), depth=0.005))


def test_a_flat_pad_on_a_turned_face_overlaps_nothing_in_float32():
    """The overlap test of a 3000 m pad (tolerance 1e-3 of a 0.1 m object) is computed without
    cancellation: r − |x − c| in float32 rounds at ulp(3000) = 2.4e-4 m and refused a face
    turned by 30° (0.00024 m past its neighbours); the cancellation-free form gives the dip
    −s²/2r (−4.2e-9 m at 5 mm) to 1e-8 m."""
    x = np.linspace(-0.05, 0.05, 21)
    P = np.concatenate([np.c_[x, -0.05 + 0 * x], np.c_[x[::-1], 0.05 + 0 * x]])
    a = np.deg2rad(30)
    turn = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    P, n = (P @ turn.T).astype(np.float32), (np.array([[0.0, -1.0], [0.0, 1.0]]) @ turn.T).astype(np.float32)
    slots, r = np.array([10, 31]), np.float32(3000.0)
    ov = np.asarray(V.fingertip_overlap(jnp.asarray(P), slots, jnp.asarray(n), r))
    assert ov.dtype == np.float32
    np.testing.assert_allclose(ov, -0.005 ** 2 / (2 * 3000.0), atol=1e-8)
    C = P[slots] + r * n                                     # the direct form, for the record
    direct = r - np.hypot(*(P[None] - C[:, None]).transpose(2, 0, 1))
    direct[[0, 1], slots] = -np.inf
    assert direct.max() > 1e-4


ENV_GUARDS = r"""
import numpy as np, pytest
import jaxsqueeze as jsq
from jaxsqueeze.geometry import curves, shapes
from jaxsqueeze.mechanics import band
from jaxsqueeze.simulation import validate as V
assert (shapes.MAX_ELEMENTS, band.MAX_NODES, V.MEMORY_LIMIT) == (500, 16, 1_000_000)
with pytest.raises(ValueError, match=r"triangles.*JAXSQUEEZE_MAX_ELEMENTS"):
    shapes.rectangle(0.1, 0.1, max_edge=0.004)
with pytest.raises(ValueError, match=r"a band of 32 nodes .* limit of 16 nodes .*JAXSQUEEZE_MAX_BAND_NODES"):
    band.Band.from_curve(curves.sample(curves.circle(0.04), 32))
lines = V.check_costs(m=100, n=800, method="sparse", capacity=64, max_steps=400, max_events=256)
assert lines and all("env JAXSQUEEZE_MEMORY_LIMIT" in line for line in lines), lines
print("ok")
"""


def test_cost_guards_take_their_limits_from_the_environment():
    """docs/errors.md: JAXSQUEEZE_MAX_ELEMENTS, JAXSQUEEZE_MAX_BAND_NODES and
    JAXSQUEEZE_MEMORY_LIMIT set the cost guards of a new process (read at import), and a request
    beyond them is refused naming the variable; the defaults here accept the same requests."""
    import os
    import subprocess
    import sys
    env = dict(os.environ, JAXSQUEEZE_MAX_ELEMENTS="500", JAXSQUEEZE_MAX_BAND_NODES="16", JAXSQUEEZE_MEMORY_LIMIT="1e6")
    r = subprocess.run([sys.executable, "-c", ENV_GUARDS], capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0 and r.stdout.strip().endswith("ok"), r.stderr[-3000:]
    from jaxsqueeze.geometry import curves, shapes
    from jaxsqueeze.mechanics import band
    assert shapes.rectangle(0.1, 0.1, max_edge=0.004).triangles.shape[0] > 500
    assert band.Band.from_curve(curves.sample(curves.circle(0.04), 32)).m == 32
    assert V.check_costs(m=100, n=800, method="sparse", capacity=64, max_steps=400, max_events=256) == []


def test_cost_guards():
    lim = V.MEMORY_LIMIT
    assert V.history_bytes(100, 64, 400, 256) < 50e6            # the defaults are cheap
    for kw in (dict(max_events=9223372036854775807), dict(max_steps=1_000_000_000)):
        args = dict(m=100, n=800, method="sparse", capacity=64, max_steps=400, max_events=256)
        args.update(kw)
        p = V.check_costs(**args)
        assert len(p) == 1 and "GiB" in p[0] and p[0].startswith(f"settings.{next(iter(kw))} = ") \
            and "MEMORY_LIMIT" in p[0]
    p = V.check_costs(m=100, n=800, method="sparse", capacity=10**9, max_steps=400, max_events=256)
    assert len(p) == 1 and p[0].startswith("settings.capacity = 1000000000") and "GiB" in p[0]
    p = V.check_costs(m=10**6, n=10**6, method="band", capacity=64, max_steps=400, max_events=256)
    assert any("compliance build" in line for line in p)
    assert V.compliance_bytes(100, 10**5, "dense") > lim > V.compliance_bytes(100, 10**5, "sparse")
    assert V.check_costs(m=100, n=800, method="dense", capacity=64, max_steps=400, max_events=256) == []


def test_mixed_units():
    err, warn = V.unit_problems(size=100.0, radius=0.01, depth=0.015)
    assert not err and any("metres" in w and "millimetres" in w for w in warn)
    err, warn = V.unit_problems(size=0.1, radius=0.01, depth=0.2)
    assert err and "depth" in err[0]
    err, warn = V.unit_problems(size=0.1, radius=0.01, depth=0.01, E=1.0)
    assert not err and any("pascals" in w for w in warn)
    assert V.unit_problems(size=0.1, radius=0.01, depth=0.01, E=1e5) == ([], [])
    err, warn = V.unit_problems(size=0.1, radius=0.01, depth=0.0999, E=1e5)      # 99.9 %: triangles invert
    assert not err and any("more than 50% of the object" in w for w in warn)
    # a 10 mm fingertip and a 25.4 mm plate written in mm on a 0.1 m object: were silent
    assert V.unit_problems(size=0.1, radius=10.0)[1][0].startswith("the fingertip radius (10 m) and the object")
    assert "near-flat pad" in V.unit_problems(size=0.1, radius=10.0)[1][0]          # (docs/numerics.md §2, 31)
    assert "near-flat pad" not in V.unit_problems(size=100.0, radius=0.01)[1][0]    # a tip in mm: no pad
    assert "plane stress describes a thin plate" in V.unit_problems(size=0.1, thickness=25.4)[1][0]
    assert V.unit_problems(size=0.1, radius=0.5, thickness=0.1) == ([], [])


# ----------------------------------------------------------------------------- the front door, as a hostile user
@pytest.mark.parametrize("change,error,message", [
    (dict(material=jsq.Material(E="1e5", nu=0.3, thickness=0.0254)), ValueError, "material.E = '1e5': expected a number"),
    (dict(material=jsq.Material(E=None, nu=0.3, thickness=0.0254)), ValueError, "material.E = None: expected a number"),
    (dict(friction=None), ValueError, "friction = None: expected a number"),
    (dict(material=jsq.Material(E=True, nu=0.3, thickness=0.0254)), ValueError, "material.E = True: expected a number"),
    (dict(friction=np.array(True)), ValueError, "friction = array.True.: expected a number"),
    (dict(grip=None, placement=jsq.Placement(s=(0.0, "0.1"))), ValueError, r"placement.s = \(0.0, '0.1'\): expected two"),
    (dict(grip=None, placement=jsq.Placement(s=(0.0, 0.1), angle=1j)), ValueError, "placement.angle = 1j: expected a"),
    (dict(fingers=jsq.Fingers(radius="0.01")), ValueError, "fingers.radius = '0.01': expected a number"),
    (dict(grip=("3", "13")), ValueError, "grip = .*expected two integer node indices"),
    (dict(grip=np.array([[3, 13], [1, 11]])), ValueError, r"grip has shape \(2, 2\): one squeeze takes one grip"),
    (dict(material=None), TypeError, "Scene.material must be a jsq.Material, got NoneType"),
    (dict(fingers=0.01), TypeError, "Scene.fingers must be a jsq.Fingers, got float"),
    (dict(settings=None), TypeError, "Scene.settings must be a jsq.Settings"),
    (dict(settings=jsq.Settings(gap_tol=1.0)), ValueError, "settings.gap_tol = 1.0: expected .* at most 1% of the object's size"),
    (dict(method="Sparse"), ValueError, "method='Sparse'; choose one of"),
    (dict(contact="point", adversary=jsq.Adversary(s=0.05, push=1e-3)), ValueError, "an Adversary needs contact='segment'"),
    (dict(method=["sparse"]), ValueError, r"method=\['sparse'\]; choose one of"),
    (dict(settings=jsq.Settings(fused="no")), ValueError, "Settings.fused='no' must be True or False"),
    (dict(settings=jsq.Settings(max_steps=True)), ValueError, "Settings.max_steps=True must be a positive integer"),
    # the loops count in int32: 2**31 wrapped to a negative bound (NEWTON_FAILURE advising more
    # iterations; a bisection that never ran gave SUCCESS with spurious events), 2**63 overflowed
    (dict(settings=jsq.Settings(newton_iters=2**31)), ValueError, "Settings.newton_iters=2147483648 is more than 10,000"),
    (dict(settings=jsq.Settings(bisect_iters=np.uint64(2**63))), ValueError, "Settings.bisect_iters=.* is more than 10,000"),
    # lists of unequal lengths, which NumPy cannot make an array of (its own "inhomogeneous
    # shape" ValueError came out of the checks, naming no field)
    (dict(friction=[0.1, [0.2, 0.3]]), ValueError, r"friction = \[0.1, \[0.2, 0.3\]\]: expected a number"),
    (dict(grip=(3, [13, 14])), ValueError, r"grip = \(3, \[13, 14\]\): expected two integer node indices"),
    (dict(grip=None, placement=jsq.Placement(s=(0.0, [0.1, 0.2]))), ValueError, r"placement.s = .*: expected two arc"),
    (dict(grip=None, placement=jsq.Placement(s=(0.0, 0.1), angle=[0.0, [1.0]])), ValueError, "placement.angle = "),
    (dict(settings=jsq.Settings(step=[1e-3, [2e-3]])), ValueError, r"settings.step = \[0.001, \[0.002\]\]: expected a"),
])
def test_wrong_types_and_sizes_are_named(square, change, error, message):
    """Each fails before any tracing, with the field and what it should be (they reached
    string arithmetic, a numpy ufunc or an attribute error deep inside before)."""
    with pytest.raises(error, match=message):
        jsq.squeeze(_scene(square, **change))


@pytest.mark.parametrize("rotation", [[[0.1j, 0.0], [0.0, 0.0]], np.array([["0.1"], ["0"]]),
                                      [[True, False], [False, True]], [[0.1, True], [0.0, 0.0]],
                                      [[0.1, [0.2]], [0.0, 0.0]], {"a": 1.0}])
def test_a_rotation_of_complex_text_or_boolean_coefficients_is_named(rotation):
    """(complex reached a bare float() TypeError inside grasp_of; numpy would drop its imaginary
    part; booleans squeezed as 1 rad/m and 1 rad, refused everywhere else; a ragged row reached
    NumPy's own error, a dict was accepted)"""
    with pytest.raises(ValueError, match=r"Fingers.rotation = .*: expected real polynomial coefficients"):
        jsq.Fingers(radius=0.01, rotation=rotation)


@pytest.mark.parametrize("rotation", [[[np.nan, 0.0], [0.0, 0.0]], [[0.0], [np.inf]]])
def test_a_rotation_with_nan_or_infinite_coefficients_says_so(rotation):
    """(it said "must be ... of shape (2, k) ...; got shape (2, 2)", pointing at a right shape)"""
    with pytest.raises(ValueError, match=r"Fingers.rotation = \[\[.*\]\] holds NaN or infinite coefficients"):
        jsq.Fingers(radius=0.01, rotation=rotation)


def test_a_grip_of_integers_of_mixed_numpy_kinds_is_taken(square):
    """numpy promotes int64 with uint64 to float64: the grip was refused as "must be two integer
    boundary node indices" though both are integers."""
    sc = _scene(square)
    i, j = sc.grip
    for grip in ((np.int64(i), np.uint64(j)), (i, np.uint64(j)), (np.uint8(i), np.int64(j))):
        assert [int(v) for v in sc.replace(grip=grip).grip] == [i, j]
    with pytest.raises(ValueError, match="must be two integer boundary node indices"):
        sc.replace(grip=(np.int64(i), True))


def test_a_squeeze_across_a_narrow_part_warns_and_counts_the_triangles_it_turns_inside_out():
    """A 100 mm x 20 mm strip squeezed across its width to 88 %: SUCCESS with no word (the deep
    squeeze warning compared the depth with the object's 0.1 m only) and two triangles turned
    inside out. Now one warning compares the depth with the grip distance, in the squeeze and in
    a scene file, and another counts the inverted triangles (the oracle: signed areas in numpy)."""
    from jaxsqueeze.io import scenefile
    strip = jsq.shapes.rectangle(0.1, 0.02, max_edge=0.005)
    b, P = np.asarray(strip.boundary), strip.points + strip.offset
    grip = tuple(int(b[np.argmin(np.linalg.norm(P[b] - q, axis=1))]) for q in ([0.0, -0.01], [0.0, 0.01]))
    sc = jsq.Scene(mesh=strip, material=jsq.Material(E=1e5, nu=0.3, thickness=0.0254),
                   fingers=jsq.Fingers(radius=0.005), grip=grip, friction=0.5, depth=0.018)
    with pytest.warns(UserWarning) as said:
        res = jsq.squeeze(sc)
    texts = [str(w.message) for w in said]
    assert res.outcome == jsq.Status.SUCCESS
    assert any("more than 50% of the distance between the fingers' first contacts (0.02 m)" in t for t in texts), texts
    x0, x1, tri = strip.points, strip.points + np.asarray(res.displacement), np.asarray(strip.triangles)
    def area(x):
        (ax, ay), (bx, by) = (x[tri[:, 1]] - x[tri[:, 0]]).T, (x[tri[:, 2]] - x[tri[:, 0]]).T
        return ax * by - ay * bx
    flipped = int(np.sum(area(x1) / area(x0) <= 0))
    assert flipped >= 1
    assert any(t.startswith(f"at depth = 0.018 m {flipped} of {len(tri)} triangles are turned inside out") for t in texts)
    assert {w.filename for w in said} == {__file__}        # each names the user's line, not the library's
    with warnings.catch_warnings(record=True) as quiet:
        warnings.simplefilter("always")          # a squeeze of 15 % says neither (only that 5 mm edges are coarse)
        jsq.squeeze(sc.replace(depth=0.003))
    assert all("the contact stayed one node wide" in str(w.message) for w in quiet), [str(w.message) for w in quiet]
    text = ("[object]\nshape = \"rectangle\"\nwidth = 0.1\nheight = 0.02\nmax_edge = 0.005\n[material]\nE = 1e5\n"
            "nu = 0.3\nthickness = 0.0254\n[fingers]\nradius = 0.005\n[grip]\npoints = [[0.0, -0.01], [0.0, 0.01]]\n"
            "[squeeze]\nrelative_depth = 0.6\n")
    assert any("of the distance between the fingers' first contacts" in w
               for w in scenefile.load_text(text).warnings)


def test_a_scene_without_an_object_or_with_two_grips_is_named(square):
    """Scene(mesh=None) raised AttributeError: 'NoneType' object has no attribute 'm'; a grip
    given to a placed scene was silently ignored (the placement won)."""
    with pytest.raises(TypeError, match=r"Scene.mesh must be a jsq.Mesh .* got NoneType"):
        jsq.Scene(mesh=None, material=jsq.Material(E=1e5, nu=0.3, thickness=0.01), fingers=jsq.Fingers(radius=0.01),
                  grip=(0, 5))
    placed = _scene(square).replace(grip=None, placement=jsq.Placement(s=(0.0, 0.2)))
    with pytest.raises(ValueError, match=r"a Scene takes grip=\(1, 3\) or placement=.*, not both"):
        placed.replace(grip=(1, 3))


def test_a_capacity_beyond_the_boundary_nodes_is_clipped_to_them(square):
    """Settings(capacity=100000) on a 20-node boundary was refused for 1.5e3 GiB of slots that
    can never hold a contact (and capacity=3000 allocated them); no more contacts than boundary
    nodes exist, so the slots stop at m."""
    from jaxsqueeze.simulation import api
    sc = _scene(square, settings=jsq.Settings(capacity=100_000))
    m = len(sc.boundary_nodes())
    assert api.config_of(sc).capacity == m and not V.scene_cost_problems(sc)
    assert api.config_of(_scene(square, settings=jsq.Settings(capacity=8))).capacity == 8 < m


def test_a_squeeze_deeper_than_half_the_object_warns(square, tmp_path):
    """depth 95 % of the object returned SUCCESS with inverted triangles and no word; now the
    eager squeeze warns, and so does the CLI for a relative_depth (it only checked a depth).
    A thickness in mm (25.4 for 0.0254 m) warns too: it gave 1000 times the force silently."""
    from jaxsqueeze.io import scenefile
    with pytest.warns(UserWarning, match="more than 50% of the object"):
        jsq.squeeze(_scene(square, depth=0.06))
    with pytest.warns(UserWarning, match=r"thickness = 25.4 m is 254 times the object's size") as said:
        jsq.squeeze(_scene(square, material=jsq.Material(E=1e5, nu=0.3, thickness=25.4)))   # mm for m
    assert said[0].filename == __file__
    text = (b"[object]\nshape = \"rectangle\"\nwidth = 0.1\nheight = 0.1\nmax_edge = 0.02\n[material]\nE = 1e5\n"
            b"nu = 0.3\nthickness = 0.01\n[fingers]\nradius = 0.01\n[grip]\npoints = [[0.0, -0.05], [0.0, 0.05]]\n"
            b"[squeeze]\nrelative_depth = 0.9\n")
    (tmp_path / "s.toml").write_bytes(text)
    assert any("more than 50% of the object" in w for w in scenefile.load(tmp_path / "s.toml").warnings)


def test_a_contact_that_stays_one_node_wide_warns(square):
    """Fingertips smaller than the boundary edges at the grip touched one node through the
    whole squeeze and said nothing: the forces were a point load's, the same for every radius (the node sticks),
    and 32 % off a converged mesh for a 2 mm tip on 10 mm edges (docs/numerics.md §2, 29). The
    eager squeeze now warns with the contact's Hertz width and the edges that resolve it; a
    corner grip and a contact that grew past one node say nothing."""
    small = _scene(square, fingers=jsq.Fingers(radius=0.002))
    with pytest.warns(UserWarning, match=r"the contact stayed one node wide on finger 0 \(node \d+, edges 0.02 m, at most "
                      r"8.29 N: about 0.0058 m wide\) and finger 1 .*edges of at most 0.0014 m") as said:
        res = jsq.squeeze(small)
    assert said[0].filename == __file__
    on = np.asarray(res.modes) > 0
    assert on.sum(axis=1).max() == 2 and res.outcome == jsq.Status.SUCCESS       # one node per tip
    F = float(res.grip_force)
    assert 2 * math.sqrt(4 * F * 0.002 / (math.pi * 1e5 * 0.0254)) == pytest.approx(0.0058, abs=5e-5)   # 2D Hertz 2a
    with pytest.warns(UserWarning, match=r"one node wide .* about 0.022 m wide"):
        wider = jsq.squeeze(small.replace(fingers=jsq.Fingers(radius=0.03)))
    assert float(wider.grip_force) == pytest.approx(F, rel=1e-12)               # a point load: no radius in it
    b, P = np.asarray(square.boundary), square.points + square.offset
    corners = tuple(int(b[np.argmin(np.linalg.norm(P[b] - q, axis=1))]) for q in ([-0.05, -0.05], [0.05, 0.05]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        big = jsq.squeeze(small.replace(fingers=jsq.Fingers(radius=0.1)))          # several nodes per tip
        assert (np.asarray(big.modes)[-1] > 0).sum() > 2
        jsq.squeeze(small.replace(grip=corners))                                   # a corner is a point


def test_a_free_node_inside_a_tip_of_a_stalled_squeeze_is_the_stall_not_a_bug():
    """A squeeze deeper than the object's half stopped STALLED (a node joining and leaving at
    one depth) and the warning of the free node left inside a tip asked to report the scene as
    a bug. Now it says that is the stall; a squeeze that did not stop still asks. (A synthetic
    one-row result: nodes 0 and 1 hold the two tips, node 2 is free 0.5 mm inside tip 0.)"""
    from types import SimpleNamespace
    pts = np.array([[0.0, -0.01], [0.0, 0.01], [0.002, -0.011]])
    res = SimpleNamespace(count=1, modes=np.array([[1, 1, 0]]), finger=np.array([[0, 1, 0]]),
                          boundary_displacement=np.zeros((1, 3, 2)), radius=0.005, nodes=np.arange(3),
                          centres=np.array([[[0.0, -0.015], [0.0, 0.015]]]), depth=np.array([0.002]),
                          status=int(jsq.Status.STALLED))
    said = V.inside_tip_warning(res, pts, 1e-9)
    assert said.startswith("from depth = 0.002 m node 2, free, lies inside fingertip 0") and "STALLED" in said
    assert "please report" not in said
    assert "please report" in V.inside_tip_warning(SimpleNamespace(**{**vars(res), "status": 0}), pts, 1e-9)


def test_squeeze_takes_a_scene_and_an_operator(square):
    with pytest.raises(TypeError, match="squeeze takes a jsq.Scene, got Mesh"):
        jsq.squeeze(square)
    with pytest.raises(TypeError, match=r"op must be the scene's compliance operator \(op = scene.operator\(\)\)"):
        jsq.squeeze(_scene(square), op="sparse")
    with pytest.raises(TypeError, match="Scene.grip must be integer node indices"):     # traced floats
        jax.jit(lambda g: jsq.squeeze(_scene(square, grip=g)))(jnp.array([3.0, 13.0]))
    # a switch given as text was read by its truthiness: history="False" recorded every row
    for kw in (dict(history="False"), dict(trim="no"), dict(throw=1)):
        name, value = next(iter(kw.items()))
        with pytest.raises(TypeError, match=f"{name}={value!r} must be True or False"):
            jsq.squeeze(_scene(square), **kw)
    with pytest.raises(TypeError, match="history='False' must be True or False"):
        jsq.simulation.api.compile_ahead(_scene(square), history="False")
    with pytest.raises(TypeError, match=r"arrived traced .* static_argnames=\"history\""):    # (a bool argument of jit)
        jax.jit(jsq.squeeze)(_scene(square), history=False)


def test_a_given_operator_takes_E_and_thickness_from_the_scene_and_must_match_it(square):
    """An operator fixes the object and ν (its scaled G depends on nothing else); E and the
    thickness only scale it and are the scene's, derivatives included (a given op kept the E
    and thickness it was built with: half the force at twice E, and dF/dE = 0)."""
    sc = _scene(square)
    op = sc.operator()
    for mat in (jsq.Material(E=2e5, nu=0.3, thickness=0.0254), jsq.Material(E=1e5, nu=0.3, thickness=0.0508)):
        other = sc.replace(material=mat)
        np.testing.assert_allclose(jsq.squeeze(other, op=op).total_force, jsq.squeeze(other).total_force, rtol=1e-12)
        np.testing.assert_allclose(jsq.squeeze(other, op=op).total_force[-1, 1, 1],
                                   2 * jsq.squeeze(sc).total_force[-1, 1, 1], rtol=1e-12)
    f = lambda E: jsq.squeeze(sc.replace(material=jsq.Material(E=E, nu=0.3, thickness=0.0254)), op=op).grip_force  # noqa: E731
    y, dy = jax.jvp(f, (1e5,), (1.0,))
    np.testing.assert_allclose(dy, y / 1e5, rtol=1e-9)                  # the force is linear in E
    with pytest.raises(ValueError, match="op was built for nu = 0.3, but the scene's material has nu = 0.45"):
        jsq.squeeze(sc.replace(material=jsq.Material(E=1e5, nu=0.45, thickness=0.0254)), op=op)
    finer = _scene(jsq.shapes.rectangle(0.1, 0.1, max_edge=0.01))
    with pytest.raises(ValueError, match="op was built for another object"):
        jsq.squeeze(sc, op=finer.operator())


def test_a_force_scale_beyond_the_precision_is_refused(square):
    """E h L whose forces would overflow when squared (E = 1e30 Pa in float32 gave inf grip
    forces with SUCCESS)."""
    from jaxsqueeze.simulation import api
    op = _scene(square).operator()
    api.check_force_scale(op)
    f32 = lambda a: jnp.asarray(a, jnp.float32)  # noqa: E731
    op32 = dataclasses.replace(op, G=f32(op.G), length=f32(op.length), stiffness=f32(1e30 * 0.0254))
    with pytest.raises(ValueError, match="force scale E \\* thickness \\* size = 2.5.e\\+27 N is too large for float32"):
        api.check_force_scale(op32)
    api.check_force_scale(dataclasses.replace(op32, stiffness=f32(1e5 * 0.0254)))
    # the same bound under tracing (a traced E of 1e160 gave SUCCESS with an infinite grip force)
    for eps, Es in ((float(jnp.finfo(jnp.float32).eps), (1e5, 1e20)), (2.2e-16, (1e20, 1e150, 1e160))):
        rule = jax.jit(lambda E: V.invalid_index(dict(GOOD, eps=eps, **{"material.E": E, "settings.newton_tol": 1e-5})))  # noqa: B023
        assert [int(rule(E)) for E in Es] == [-1] * (len(Es) - 1) + [V.FIELDS.index("material.E")]


def test_a_placement_turned_past_a_right_angle_does_not_grip_through_the_object(square):
    """Placement angle π: each tip would close in away from the other and 'touch' the far
    side through the object (it reported SUCCESS on swapped nodes). A touch more than a radius
    behind a tip's placed position is no touch: INFEASIBLE_GRIP. At π/2 the tips slide off and
    both contacts break at once: LOST_CONTACT, not the NaNs of the empty contact set."""
    sc = _scene(square)
    P = float(sc.curve().perimeter)
    sc = sc.replace(grip=None, placement=jsq.Placement(s=(0.0, P / 2)))
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        res = {a: jsq.squeeze(sc.replace(placement=jsq.Placement(s=(0.0, P / 2), angle=a))) for a in (0.3, np.pi / 2, np.pi)}
    # (the let-go row is not a fingertip passing through the object: validate.inside_tip_warning)
    assert not [w for w in said if "lies inside fingertip" in str(w.message)]
    assert res[0.3].status == jsq.Status.SUCCESS
    lost = res[np.pi / 2]
    assert lost.status == jsq.Status.LOST_CONTACT
    # its last row has no contact to fix the rigid motion (a singular solve: NaN displacements,
    # a NaN squeeze_work and NaN derivatives): the object is let go, with no forces and so no
    # deformation, moved rigidly as in the row before
    for name in ("forces", "boundary_displacement", "rigid", "g", "displacement"):
        assert np.all(np.isfinite(np.asarray(getattr(lost, name)))), name
    from jaxsqueeze.mechanics.operator import rigid_modes
    P, g = np.asarray(sc.mesh.points), np.asarray(lost.rigid[-2])
    np.testing.assert_allclose(lost.rigid[-1], g, rtol=0, atol=0)
    np.testing.assert_allclose(lost.displacement, (rigid_modes(P, xp=np) @ g).reshape(-1, 2), rtol=0, atol=1e-15)
    assert not np.any(np.asarray(lost.forces[-1])) and float(jsq.quality.squeeze_work(lost)) == 0.0
    # the same with two rows kept (history=False: the row before is gone, its g
    # is kept aside): the let-go rows were NaN there, and so were squeeze_work and its derivative
    short = jsq.squeeze(sc.replace(placement=jsq.Placement(s=sc.placement.s, angle=np.pi / 2)), history=False)
    assert short.status == jsq.Status.LOST_CONTACT and int(short.count) == 2
    for name in ("forces", "boundary_displacement", "rigid"):
        np.testing.assert_array_equal(np.asarray(getattr(short, name))[-1], np.asarray(getattr(lost, name))[-1], name)
    np.testing.assert_array_equal(short.displacement, lost.displacement)
    assert float(jsq.quality.squeeze_work(short)) == 0.0
    assert res[np.pi].status == jsq.Status.INFEASIBLE_GRIP and float(res[np.pi].margin) == -np.pi
