"""The squeeze grasp (Section IV): invariants, symmetry, friction limits, convergence, JAX properties."""
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsqueeze as jsq
from jaxsqueeze import compiler
from jaxsqueeze.simulation import api as grasp_mod
from jaxsqueeze.simulation import engine
from physics import check_states, compiles, nearest, symmetric_square

MAT = jsq.Material(E=1e5, nu=0.3, thickness=0.0254)


@pytest.fixture(scope="module")
def mesh():
    return symmetric_square(0.1, 0.006)


@pytest.fixture(scope="module")
def centred(mesh):
    """Square squeezed at the midpoints of two opposite edges."""
    grip = (nearest(mesh, (0, -0.05)), nearest(mesh, (0, 0.05)))
    return jsq.Scene(mesh=mesh, material=MAT, fingers=jsq.Fingers(radius=0.015), grip=grip, friction=0.5,
                     depth=0.012)


@pytest.fixture(scope="module")
def slanted(mesh):
    """Grip 12.5° off the normals: the initial contacts slip once the friction margin is used up."""
    grip = (nearest(mesh, (-0.01, -0.05)), nearest(mesh, (0.01, 0.05)))
    return jsq.Scene(mesh=mesh, material=MAT, fingers=jsq.Fingers(radius=0.015), grip=grip, friction=0.23,
                     depth=0.012)


def finger_force(res, finger, row=-1):
    on = (res.modes[row] > 0) & (res.finger[row] == finger)
    return jnp.sum(jnp.where(on[:, None], res.forces[row], 0.0), axis=0)


def test_centred_squeeze_is_mirror_symmetric(mesh, centred):
    res = jsq.squeeze(centred)
    assert res.outcome == jsq.Status.SUCCESS
    assert abs(res.final_depth - 0.012) < 1e-12
    check_states(res, mesh, 0.5)
    P = mesh.points[mesh.boundary]
    for row in range(int(res.count)):
        mode, fg = np.asarray(res.modes[row]), np.asarray(res.finger[row])
        for f in (0, 1):
            pts = P[(mode > 0) & (fg == f)]
            # left-right mirror inside each contact region
            assert np.allclose(np.sort(pts[:, 0]), np.sort(-pts[:, 0]), atol=1e-12)
        a = np.sort(P[(mode > 0) & (fg == 0)][:, 0])
        b = np.sort(P[(mode > 0) & (fg == 1)][:, 0])
        assert np.allclose(a, b, atol=1e-12), "contact regions differ between the two fingers"
    f1, f2 = finger_force(res, 0), finger_force(res, 1)
    np.testing.assert_allclose(f1, -f2, atol=1e-10 * np.abs(f1).max())
    assert abs(f1[0]) < 1e-8 * abs(f1[1]) and f1[1] > 0
    # simultaneous events on both fingers are located at the same depth
    ev = res.events.rows()
    assert ev and all(k == "A" for _, _, k, _ in ev)
    depths = np.array([d for d, *_ in ev])
    assert np.ptp(depths[:4]) < 1e-9


def test_slanted_squeeze_slips_and_holds_invariants(mesh, slanted):
    res = jsq.squeeze(slanted)
    assert res.outcome == jsq.Status.SUCCESS
    kinds = [k for _, _, k, _ in res.events.rows()]
    assert "C" in kinds, kinds
    check_states(res, mesh, 0.23)


@pytest.mark.parametrize("turn, mirror", [(0.65, False), (2.0, True)])
def test_a_rigid_motion_of_the_whole_scene_changes_nothing(mesh, slanted, turn, mirror):
    """Turned (and mirrored) by a non-right angle and moved 1 km away, the same squeeze: same
    events at the same depths, same force magnitudes. Node numbers stay (the boundary may start
    elsewhere), so event rows compare directly."""
    c, s = np.cos(turn), np.sin(turn)
    R = np.array([[c, -s], [s, c]]) @ np.diag([-1.0 if mirror else 1.0, 1.0])
    moved = jsq.Mesh.from_arrays((mesh.points + mesh.offset) @ R.T + [1e3, -2e3], mesh.triangles)
    base, res = jsq.squeeze(slanted), jsq.squeeze(slanted.replace(mesh=moved))
    assert res.outcome == base.outcome == jsq.Status.SUCCESS
    a, b = (sorted(r.events.rows(), key=lambda row: (row[1:], row[0])) for r in (base, res))   # ties may swap
    assert [r[1:] for r in a] == [r[1:] for r in b]
    np.testing.assert_allclose([r[0] for r in b], [r[0] for r in a], rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.grip_force, base.grip_force, rtol=1e-8)
    by_node = [np.linalg.norm(r.final_forces, axis=-1)[np.argsort(m.boundary)] for r, m in ((base, mesh), (res, moved))]
    np.testing.assert_allclose(by_node[1], by_node[0], rtol=0, atol=1e-8 * float(base.grip_force))
    check_states(res, moved, 0.23)


def test_large_friction_equals_all_stick(mesh, slanted):
    big = jsq.squeeze(slanted.replace(friction=1e3))
    stick = jsq.squeeze(slanted.replace(friction_model="stick"))
    assert {k for _, _, k, _ in big.events.rows()} == {"A"}
    assert int(big.count) == int(stick.count)
    np.testing.assert_allclose(big.forces, stick.forces, atol=1e-10 * np.abs(stick.forces).max())
    np.testing.assert_allclose(big.displacement, stick.displacement, atol=1e-12)
    assert np.all(np.asarray(stick.modes) <= 1)


def test_small_friction_ends_in_slip_failure():
    """A disk gripped 10° off its diameter: friction just above tan 10° fails, more friction holds."""
    disk = jsq.shapes.disk(0.05, 0.005)
    b = np.radians(10.0)
    grip = (nearest(disk, 0.05 * np.array([np.sin(b), -np.cos(b)])), nearest(disk, 0.05 * np.array([np.sin(b), np.cos(b)])))
    scene = jsq.Scene(mesh=disk, material=MAT, fingers=jsq.Fingers(radius=0.015), grip=grip, friction=0.178,
                      depth=0.01)
    res = jsq.squeeze(scene)
    assert res.outcome == jsq.Status.SLIP_FAILURE
    assert res.final_depth < 0.01
    # README: throw=True raises RuntimeError with advice unless the squeeze reached its depth
    with pytest.raises(RuntimeError, match=rf"squeeze ended with SLIP_FAILURE at depth {float(res.final_depth):.6g} m: "):
        jsq.squeeze(scene, throw=True)
    last, fg = np.asarray(res.modes[-1]), np.asarray(res.finger[-1])
    assert any(np.all(last[(last > 0) & (fg == f)] >= 2) for f in (0, 1))
    check_states(res, disk, 0.178)
    assert jsq.squeeze(scene.replace(friction=0.2)).outcome == jsq.Status.SUCCESS


def test_rotating_fingertip_carries_its_sticking_nodes(mesh, centred):
    """With α2(d) = 40 rad/m · d, a node sticking to finger 2 keeps its finger-frame angle."""
    twist = jsq.Fingers(radius=0.015, rotation=[[0.0, 0.0], [40.0, 0.0]])
    res = jsq.squeeze(centred.replace(fingers=twist, friction=0.2))
    assert res.outcome == jsq.Status.SUCCESS
    check_states(res, mesh, 0.2)
    np.testing.assert_allclose(res.alpha[:, 1], 40.0 * res.depth, rtol=1e-12)
    np.testing.assert_allclose(res.alpha[:, 0], 0.0)
    x = mesh.points[mesh.boundary] + np.asarray(res.boundary_displacement)
    rel = x - np.asarray(res.centres)[:, 1][:, None, :]
    local = np.arctan2(rel[..., 1], rel[..., 0]) - np.asarray(res.alpha)[:, 1][:, None]
    stuck = (np.asarray(res.modes) == 1) & (np.asarray(res.finger) == 1)
    np.testing.assert_allclose(np.angle(np.exp(1j * (local - np.asarray(res.theta))))[stuck], 0.0, atol=1e-9)
    kinds = {k for _, _, k, _ in res.events.rows()}
    assert {"C", "D"} <= kinds


def test_frictionless_never_sticks_and_keeps_neutral_modes_still(mesh, centred):
    res = jsq.squeeze(centred.replace(friction_model="frictionless"))
    assert res.outcome == jsq.Status.SUCCESS
    check_states(res, mesh, 0.0, friction_model="frictionless")
    # the neutral sideways/rotational mode stays unexcited: the result is mirror symmetric
    u = np.asarray(res.displacement)
    P = mesh.points
    mirror = np.array([np.argmin(np.linalg.norm(P - p * [-1, 1], axis=1)) for p in P])
    np.testing.assert_allclose(u[mirror] * [-1, 1] - u, 0.0, atol=1e-9 * np.abs(u).max())


def test_bad_scene_values_raise(mesh, centred):
    with pytest.raises(ValueError, match="friction"):
        centred.replace(friction=-0.1)
    with pytest.raises(ValueError, match="depth"):
        centred.replace(depth=0.0)
    with pytest.raises(ValueError, match="radius"):
        jsq.Fingers(radius=-1.0)
    interior = int(np.setdiff1d(np.arange(mesh.n), mesh.boundary)[0])
    with pytest.raises(ValueError, match="not on the boundary"):
        centred.replace(grip=(interior, centred.grip[1]))
    with pytest.raises(ValueError, match="twice"):
        centred.replace(grip=(centred.grip[0], centred.grip[0]))
    side = nearest(mesh, (0.05, 0.0))
    with pytest.raises(ValueError, match="friction cones"):
        jsq.squeeze(centred.replace(grip=(centred.grip[0], side)))


def test_step_and_event_tolerance_converge(slanted):
    """Halving step and event tolerance converges event depths and final forces."""
    runs = []
    for k in range(3):
        step = 0.012 / (25 * 2**k)
        res = jsq.squeeze(slanted.replace(settings=jsq.Settings(step=step, event_tol=step * 1e-3)))
        assert res.outcome == jsq.Status.SUCCESS
        runs.append(res)
    ev = [np.array([d for d, *_ in r.events.rows()]) for r in runs]
    assert all(len(e) == len(ev[0]) for e in ev)
    d_err = [np.abs(ev[k] - ev[-1]).max() for k in range(2)]
    f_err = [np.abs(np.asarray(finger_force(runs[k], 1) - finger_force(runs[-1], 1))).max() for k in range(2)]
    ref = np.abs(np.asarray(finger_force(runs[-1], 1))).max()
    print(f"event-depth differences {d_err}, force differences {f_err} (ref {ref:.3g} N)")
    # the located depths carry the implicit-function refinement: already at round-off
    assert d_err[0] < 1e-9 * 0.012
    assert max(f_err) < 1e-8 * ref


def test_vmap_over_friction_equals_loop(slanted):
    mus = jnp.array([0.23, 0.3, 1.0])

    def total(mu):
        return finger_force(jsq.squeeze(slanted.replace(friction=mu)), 1)

    batched = jax.vmap(total)(mus)
    for k, mu in enumerate(mus):
        single = total(float(mu))
        np.testing.assert_allclose(batched[k], single, rtol=1e-10, atol=1e-12 * np.abs(single).max())


def test_a_squeeze_pinned_to_the_cpu_on_a_gpu_machine_runs_as_on_a_cpu(slanted, monkeypatch):
    """README: on a GPU machine ``with jax.default_device(jax.devices("cpu")[0]): res =
    jsq.squeeze(scene)`` runs one squeeze on the CPU. ``jax.default_backend()`` stays "gpu"
    there, and the library's choices followed it: no CPU compile options, and batches of small
    solves through jaxlib's batched LAPACK, which deadlocks inside a loop on the CPU. They now
    follow compiler.platform(), the platform of the device. (The GPU backend is simulated.)"""
    from jaxsqueeze import compiler
    from jaxsqueeze.mechanics import linalg
    ref = jsq.squeeze(slanted)
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    A = jnp.eye(3)[None] * jnp.arange(1.0, 5.0)[:, None, None]
    one_at_a_time = lambda: "scan" in str(jax.make_jaxpr(jax.vmap(linalg.solve))(A, jnp.ones((4, 3))))  # noqa: E731
    assert compiler.platform() == "gpu" and compiler.options() == () and not one_at_a_time()
    with jax.default_device(jax.devices("cpu")[0]):
        assert compiler.platform() == "cpu" and compiler.options() == compiler._options("cpu") != ()
        assert one_at_a_time()
        res = jsq.squeeze(slanted)
    np.testing.assert_array_equal(res.forces, ref.forces)       # the same program as without the context
    with jax.default_device("cpu"):
        assert compiler.platform() == "cpu"


def test_invalid_lanes_of_a_batch_are_statuses_and_record_nothing(slanted):
    """Inside vmap a bad number cannot raise: its lane reports INVALID_INPUT with the index of
    the field (depth), records one unloaded row at depth 0 (not the invalid depth echoed back),
    and the good lane equals the eager squeeze."""
    from jaxsqueeze.simulation import validate
    d0, E0 = float(slanted.depth), float(slanted.material.E)
    mat = slanted.material
    run = jax.vmap(lambda d, E: jsq.squeeze(slanted.replace(depth=d, material=jsq.Material(E, mat.nu, mat.thickness))))
    out4 = run(jnp.array([d0, 0.0, -0.004, d0]), jnp.array([E0, E0, E0, np.nan]))
    assert [jsq.Status(int(v)) for v in out4.status] == [jsq.Status.SUCCESS] + [jsq.Status.INVALID_INPUT] * 3
    assert list(np.asarray(out4.invalid)[1:]) == [validate.FIELDS.index("depth")] * 2 + [validate.FIELDS.index("material.E")]
    np.testing.assert_array_equal(np.asarray(out4.final_depth)[1:], 0.0)
    np.testing.assert_array_equal(np.asarray(out4.count)[1:], 1)
    # zero forces, also where the refused number is in the force scale E h L (they were NaN)
    assert np.all(np.asarray(out4.forces)[1:] == 0) and np.all(np.asarray(out4.push_work)[1:] == 0)
    out = jax.tree.map(lambda a: a[:3], out4)
    eager = jsq.squeeze(slanted)
    np.testing.assert_allclose(np.asarray(out.final_forces)[0], eager.final_forces, rtol=1e-10,
                               atol=1e-12 * np.abs(eager.final_forces).max())
    # a quality of a batched result is one value per member (it was a raw TypeError)
    from jaxsqueeze.plan import quality
    work, force = quality.squeeze_work(out), quality.grip_force(out)
    assert work.shape == force.shape == (3,) and np.all(np.asarray(work)[1:] == 0)
    np.testing.assert_allclose(work[0], quality.squeeze_work(eager), rtol=1e-10)
    np.testing.assert_allclose(force[0], eager.grip_force, rtol=1e-10)
    assert quality.slip_margin(out, slanted.friction).shape == (3,)
    mus = jnp.array([0.5, 0.4, 0.3])                   # one μ per member (a shape error before)
    one = [float(quality.slip_margin(jax.tree.map(lambda a: a[k], out), mus[k])) for k in range(3)]
    np.testing.assert_allclose(quality.slip_margin(out, mus), one, rtol=1e-12)
    programs = quality._slip_margin._cache_size()       # one compiled program per shape, not op by op
    quality.slip_margin(jax.tree.map(lambda a: a[1], out), 0.2), quality.slip_margin(out, mus[::-1])
    assert quality._slip_margin._cache_size() == programs
    with pytest.raises(ValueError, match=r"friction of shape \(2,\): expected one μ, or one per member"):
        quality.slip_margin(out, mus[:2])
    # the one-squeeze methods say so (they were "only scalar arrays can be converted")
    for call in (lambda: out.outcome, out.trim, out.raise_for_status):
        with pytest.raises(ValueError, match=r"takes one squeeze, but this result is batched .*pick one lane"):
            call()
    # the event log of a padded lane lists its events only (its padding read as A events at
    # depth 0 on node 0), and a batch's log says to take one squeeze (it was numpy's TypeError)
    lane = jax.tree.map(lambda a: a[0], out)
    rows, want = lane.events.rows(), eager.events.rows()
    assert len(lane.events) > int(lane.n_events) == len(rows) == len(want)
    assert [r[1:] for r in rows] == [r[1:] for r in want]
    np.testing.assert_allclose([r[0] for r in rows], [r[0] for r in want], rtol=1e-12)
    assert np.all(np.asarray(lane.events.kind)[int(lane.n_events):] == -1)
    with pytest.raises(ValueError, match=r"this event log holds a batch .* take one squeeze first"):
        out.events.rows()
    with pytest.raises(RuntimeError, match=r"INVALID_INPUT .* Here it is depth \(result.invalid = 5\): expected a finite "
                                           r"depth > 0 m"):                  # the field in words, not just its index
        jax.tree.map(lambda a: a[1], out).raise_for_status()
    # and under tracing they, and throw=True, say what to do instead of a ConcretizationTypeError
    with pytest.raises(ValueError, match="throw=True raises on the status, which is traced under jax.jit"):
        jax.jit(lambda d: jsq.squeeze(slanted.replace(depth=d), throw=True).grip_force)(d0)
    with pytest.raises(ValueError, match="result.outcome needs a concrete result"):
        jax.jit(lambda d: int(jsq.squeeze(slanted.replace(depth=d)).outcome))(d0)


def test_vmap_over_grips_equals_loop(mesh, centred):
    grips = jnp.array([centred.grip, (nearest(mesh, (0.006, -0.05)), nearest(mesh, (0.006, 0.05)))])

    def total(g):
        return finger_force(jsq.squeeze(centred.replace(grip=g)), 1)

    batched = jax.vmap(total)(grips)
    for k in range(2):
        single = total(tuple(int(v) for v in grips[k]))
        np.testing.assert_allclose(batched[k], single, rtol=1e-10, atol=1e-12 * np.abs(single).max())


def test_jvp_matches_finite_differences(slanted):
    """Forward-mode derivatives of the final force w.r.t. friction and depth (away from events).
    The derivative leaves no tracer behind (a user's ``jax.checking_leaks()`` passes: the
    squeeze's jvp rule and the displacement field's callback kept theirs alive)."""
    def fy(mu, depth):
        return finger_force(jsq.squeeze(slanted.replace(friction=mu, depth=depth)), 1)[1]

    mu, d = 0.23, 0.012
    for args, tangent in (((mu, d), (1.0, 0.0)), ((mu, d), (0.0, 1.0))):
        with jax.checking_leaks():
            _, jvp = jax.jvp(fy, args, tangent)
        h = 1e-6 * np.array(args) * np.array(tangent)
        fd = (fy(*(np.array(args) + h)) - fy(*(np.array(args) - h))) / (2 * np.linalg.norm(h))
        assert abs(fd) > 0
        np.testing.assert_allclose(jvp, fd, rtol=1e-5)


def test_event_depth_carries_its_derivative(slanted):
    """dd_C/dμ of the located stick→slip depth of a grip node matches finite differences. (The
    new contacts that join sliding log their C at their A's depth, which μ does not move.)"""
    def first_c(mu):
        res = jsq.squeeze(slanted.replace(friction=mu))
        k = jnp.argmax((res.events.kind == 2) & (res.events.node == slanted.grip[0]))
        return res.events.depth[k]

    _, dd = jax.jvp(first_c, (0.23,), (1.0,))
    h = 1e-6
    fd = (first_c(0.23 + h) - first_c(0.23 - h)) / (2 * h)
    assert fd > 0          # more friction: slip starts later
    np.testing.assert_allclose(dd, fd, rtol=1e-4)


def test_second_call_does_not_recompile(mesh, slanted):
    """README: every number of a scene is a leaf, so a changed number never recompiles: the
    grip, friction, depth, radius, material and the tolerances of Settings."""
    jsq.squeeze(slanted)
    before = grasp_mod._run._cache_size()
    other = (nearest(mesh, (0.004, -0.05)), nearest(mesh, (-0.004, 0.05)))
    for changed in (slanted.replace(friction=0.4, depth=0.01, fingers=jsq.Fingers(radius=0.02)),
                    slanted.replace(grip=other),
                    slanted.replace(material=jsq.Material(E=3e5, nu=0.3, thickness=0.01)),
                    slanted.replace(settings=jsq.Settings(step=0.0004, event_tol=1e-8, newton_tol=1e-11,
                                                          gap_tol=1e-9))):
        assert jsq.squeeze(changed).outcome in (jsq.Status.SUCCESS, jsq.Status.SLIP_FAILURE)
        assert grasp_mod._run._cache_size() == before


def test_a_second_eager_squeeze_compiles_nothing(slanted):
    """Nothing on the eager path (validation, the compiled core, the full displacement field,
    trimming) compiles again for new numbers: no per-call host callback or tiny programs."""
    jsq.squeeze(slanted)
    with compiles() as compiled:
        res = jsq.squeeze(slanted.replace(friction=0.25, depth=0.011))
    assert res.displacement is not None and res.displacement.shape == slanted.mesh.points.shape
    assert compiled == []


def test_a_squeeze_compiled_ahead_compiles_nothing_when_it_runs(mesh, slanted):
    """``api.compile_ahead`` (the CLI's ``plan`` starts it for the best grasp while its search
    runs) compiles an eager squeeze's program in a background thread: a squeeze of the same
    object with another grip and other numbers then finds it compiled. A scene that the squeeze
    refuses starts nothing."""
    sc = slanted.replace(settings=jsq.Settings(max_steps=397))    # a loop bound no other test compiles
    with compiles(where=True) as compiled:
        grasp_mod.compile_ahead(sc)
        other = (nearest(mesh, (0.004, -0.05)), nearest(mesh, (-0.004, 0.05)))
        res = jsq.squeeze(sc.replace(grip=other, friction=0.3))
    assert res.outcome == jsq.Status.SUCCESS
    assert [thread for name, thread in compiled if name == "jit(_run)"] == ["compile _run"], compiled
    with compiles(where=True) as compiled:
        softer = sc.replace(material=jsq.Material(E=1e5, nu=0.45, thickness=0.0254),
                            settings=jsq.Settings(max_steps=398))
        grasp_mod.compile_ahead(softer, op=sc.operator())           # an operator of nu = 0.3
        compiler.wait_ahead()
    assert compiled == []


def test_fused_squeeze_is_the_same_squeeze_in_one_kernel(slanted):
    """Settings(fused=True): an eager squeeze compiles its loop as one CPU kernel
    (compiler.one_kernel, with Gauss-Jordan in place of LAPACK) and gives the squeeze of the
    usual program: the same rows, modes, events and status, forces to round-off. A traced
    squeeze keeps the usual program (the caller's compile has no one-kernel options)."""
    from jaxsqueeze import compiler
    from jaxsqueeze.simulation import engine
    fused = slanted.replace(settings=dataclasses.replace(slanted.settings, fused=True))
    assert not grasp_mod.config_of(fused).fused
    assert grasp_mod.config_of(fused, eager=True).fused == compiler.can_fuse()
    if not compiler.can_fuse():
        pytest.skip("one-kernel loops need the CPU backend and its options")
    calls = []
    run = engine.run
    try:        # the fused program is traced once here (a new static config): count its kernels
        engine.run = lambda model, st: calls.append(model.cfg.fused) or run(model, st)
        a, b = jsq.squeeze(slanted), jsq.squeeze(fused)
    finally:
        engine.run = run
    assert True in calls
    assert (a.count, a.status) == (b.count, b.status) and a.outcome == jsq.Status.SUCCESS
    np.testing.assert_array_equal(a.modes, b.modes)
    assert [e[1:] for e in a.events.rows()] == [e[1:] for e in b.events.rows()]
    np.testing.assert_allclose([e[0] for e in b.events.rows()], [e[0] for e in a.events.rows()], rtol=1e-9)
    np.testing.assert_allclose(b.forces, a.forces, rtol=0, atol=1e-9 * np.abs(a.forces).max())
    np.testing.assert_allclose(b.displacement, a.displacement, rtol=0, atol=1e-9 * np.abs(a.displacement).max())


def test_fused_batch_inside_the_librarys_top_level_program(slanted):
    """Inside a program the library compiles at the top level (compiler.jit: split_vmap, the
    planner) a traced squeeze honours Settings.fused: a vmap over frictions runs one kernel
    per member and equals the eager squeezes; forward-mode derivatives through it match central
    differences (the kernel's jvp is the region as ordinary operations)."""
    from jaxsqueeze import compiler
    if not compiler.can_fuse():
        pytest.skip("one-kernel loops need the CPU backend and its options")
    small = dataclasses.replace(slanted.settings, capacity=32, sliding_capacity=8)
    plain, fused = (slanted.replace(settings=dataclasses.replace(small, fused=f)) for f in (False, True))
    op = slanted.operator()
    mus = jnp.array([0.23, 0.3])
    force = lambda sc, mu: jsq.squeeze(sc.replace(friction=mu), op=op, trim=False).grip_force  # noqa: E731
    batch = compiler.jit(jax.vmap(lambda mu: force(fused, mu)))
    assert 'inlineable="false"' in batch.lower(mus).compile().as_text()
    want = [float(jsq.squeeze(plain.replace(friction=float(mu)), op=op).grip_force) for mu in mus]
    np.testing.assert_allclose(batch(mus), want, rtol=1e-9)
    slope = compiler.jit(jax.jacfwd(lambda mu: force(fused, mu)))(0.23)
    h = 1e-6       # central difference of eager squeezes (the usual program, compiled above)
    fd = [float(jsq.squeeze(plain.replace(friction=0.23 + k * h), op=op).grip_force) for k in (1, -1)]
    np.testing.assert_allclose(slope, (fd[0] - fd[1]) / (2 * h), rtol=1e-6)


def test_batch_lanes_report_an_infeasible_grip_and_an_overflow(slanted):
    """README: under vmap a grip outside the friction cones is INFEASIBLE_GRIP (eagerly a
    ValueError before tracing), and with fixed capacities a member that outgrows them reports
    OVERFLOW while the others run; each lane is its eager squeeze. The grip is 11.3° off the
    normals (μ = 0.1 allows 5.7°); 4 slots hold the first 4.4 mm, then 6 contacts join."""
    small = slanted.replace(settings=jsq.Settings(capacity=4))
    mus, depths = jnp.array([0.23, 0.1, 0.23]), jnp.array([0.002, 0.002, 0.012])
    with jax.transfer_guard("disallow"):         # README, "Your JAX settings": an eager vmap too
        out = jax.vmap(lambda mu, d: jsq.squeeze(small.replace(friction=mu, depth=d)))(mus, depths)
        assert np.shape(out.final_depth) == np.shape(out.grip_force) == (3,)
    S = jsq.Status
    assert [S(int(v)) for v in out.status] == [S.SUCCESS, S.INFEASIBLE_GRIP, S.OVERFLOW]
    assert float(out.margin[1]) < 0 and float(out.final_depth[1]) == 0
    assert np.all(np.asarray(out.forces)[1] == 0)
    with pytest.raises(ValueError, match="but the friction cones only allow 5.711°"):
        jsq.squeeze(small.replace(friction=0.1, depth=0.002))
    for k in (0, 2):
        eager = jsq.squeeze(small.replace(friction=float(mus[k]), depth=float(depths[k])))
        lane = jax.tree.map(lambda a: a[k], out).trim()
        assert eager.outcome == S(int(out.status[k])) and int(eager.count) == int(lane.count)
        np.testing.assert_allclose(lane.forces, eager.forces, rtol=0, atol=1e-10 * np.abs(eager.forces).max())
    assert int(out.stats.contacts[2]) > 4 and float(out.final_depth[2]) < 0.005
    assert repr(out) == (f"SqueezeResult(batch of 3: SUCCESS 1, INFEASIBLE_GRIP 1, OVERFLOW 1; final depth 0 to "
                         f"{float(np.max(out.final_depth)):.4g} m)")
    assert repr(jax.tree.map(lambda a: a[1], out)) == "SqueezeResult(INFEASIBLE_GRIP at depth 0 m, 1 row, 0 events, grip force 0 N)"
    assert repr(out.events) == f"EventLog(batch of 3 logs × {out.events.depth.shape[1]} slots)"
    assert repr(jax.tree.map(lambda a: a[1], out).events) == "EventLog(0 events)"     # padding is not an event


def test_eager_functions_run_under_a_transfer_guard(slanted, tmp_path):
    """README, "Your JAX settings": under jax.transfer_guard("disallow") a squeeze, operator
    builds, deform, stresses, qualities, plots and ParaView files take host numbers in and give host arrays
    back (a squeeze stopped at its first compiled call: the scene's floats are host values)."""
    import matplotlib
    matplotlib.use("Agg")
    from jaxsqueeze.plan import quality
    base = jsq.squeeze(slanted)
    with jax.transfer_guard("disallow"):
        res = jsq.squeeze(slanted)
        built = jsq.fem.compliance(slanted.mesh, jsq.Material(2e5, 0.25, 0.01))
        assert jsq.fem.stiffness(slanted.mesh, slanted.material).shape == (2 * slanted.mesh.n,) * 2
        u = np.zeros((2, 2))
        u[1, 1] = -0.001
        forces = jsq.deform(slanted.operator(), list(slanted.grip), u).forces
        stress = jsq.fem.von_mises(jsq.fem.element_stress(slanted.mesh, slanted.material, res.displacement))
        qualities = [float(q(res)) for q in (quality.squeeze_work, quality.grip_force)]
        margin = float(quality.slip_margin(res, slanted.friction))
        jsq.plots.plot_deformed(res, slanted)
        jsq.export.write_final_vtu(str(tmp_path / "final.vtu"), res, slanted)
        with pytest.raises(jax.errors.JaxRuntimeError, match="Disallowed host-to-device transfer"):     # the guard still watches
            jnp.asarray(1.0) + np.ones(2)
    np.testing.assert_array_equal(res.forces, base.forces)
    assert np.all(np.isfinite(np.asarray(forces))) and np.all(np.asarray(stress) >= 0)
    assert qualities == [float(quality.squeeze_work(base)), float(base.grip_force)] and margin > 0
    assert (tmp_path / "final.vtu").stat().st_size > 0 and built.m == slanted.mesh.m


def test_a_result_a_scene_and_an_operator_print_in_one_line(slanted):
    """A notebook cell ending in a result or a scene printed every array (31,000 characters for
    a 16-node square, the meshes' nodes in a scene): now one line each, with what a reader
    looks for first; traced, the sizes."""
    res = jsq.squeeze(slanted)
    kinds = sorted({k for _, _, k, _ in res.events.rows()})
    count = {k: sum(row[2] == k for row in res.events.rows()) for k in kinds}
    assert len(kinds) >= 2 and repr(res) == (
        f"SqueezeResult(SUCCESS at depth {float(slanted.depth):.4g} m, {int(res.count)} rows, {len(res.events)} events "
        f"({', '.join(f'{k} {count[k]}' for k in kinds)}), grip force {float(res.grip_force):.4g} N)")
    depths = [d for d, *_ in res.events.rows()]
    assert repr(res.events) == (f"EventLog({len(res.events)} events ({', '.join(f'{k} {count[k]}' for k in kinds)}) at "
                                f"depths {min(depths):.4g} to {max(depths):.4g} m; .rows() lists them)")
    mesh = slanted.mesh
    assert repr(mesh) == f"Mesh({mesh.n} nodes, {len(mesh.triangles)} triangles, {mesh.m} boundary nodes in 1 loop, 0.1 × 0.1 m)"
    assert repr(slanted).startswith(f"Scene(mesh={mesh!r}, material=Material(E=100000.0") and len(repr(slanted)) < 600
    assert repr(slanted.operator()) == f"Compliance(sparse build, {mesh.m} boundary nodes, L = 0.1 m, float64, field map)"
    seen = []

    def traced(d):
        out = jsq.squeeze(slanted.replace(depth=d))
        seen.extend([repr(out), repr(out.events)])
        return out
    shapes = jax.eval_shape(traced, float(slanted.depth))
    assert seen == [f"SqueezeResult(traced, {shapes.forces.shape[0]} rows × {mesh.m} boundary nodes)",
                    f"EventLog(traced, {shapes.events.depth.shape[0]} slots)"]


def test_automatic_capacities_grow_on_overflow_to_the_same_result(slanted, monkeypatch):
    """Settings.capacity and sliding_capacity = None: an eager squeeze starts with EAGER_SLOTS
    contact slots and EAGER_SLIDING Newton slots and, when its contact set outgrows them,
    squeezes again with more; the result is the one of those capacities fixed, the grown
    capacities are remembered (the next squeeze compiles nothing), and a traced squeeze keeps
    TRACED_SLOTS with both Newton systems (sliding = 0). This squeeze reaches 6 contacts, 4 of
    them sliding: 4 slots and 1 Newton slot overflow."""
    from jaxsqueeze.simulation import scene as scene_mod
    assert slanted.settings.capacity is None and slanted.settings.sliding_capacity is None
    cfg = grasp_mod.config_of(slanted, eager=True)
    assert (cfg.capacity, cfg.sliding) == (scene_mod.EAGER_SLOTS, scene_mod.EAGER_SLIDING) == (32, 8)
    traced = grasp_mod.config_of(slanted)
    assert (traced.capacity, traced.sliding) == (scene_mod.TRACED_SLOTS, 0) and len(slanted.boundary_nodes()) > 64
    # no more slots than boundary nodes, traced or eager (a 20-node outline: 20 slots)
    small = slanted.replace(mesh=jsq.shapes.rectangle(0.1, 0.1, max_edge=0.02), grip=(4, 14))
    assert len(small.boundary_nodes()) == 20
    assert grasp_mod.config_of(small).capacity == grasp_mod.config_of(small, eager=True).capacity == 20
    monkeypatch.setattr(scene_mod, "EAGER_SLOTS", 4)
    monkeypatch.setattr(scene_mod, "EAGER_SLIDING", 1)
    monkeypatch.setattr(grasp_mod, "_GROWN", {})
    res = jsq.squeeze(slanted)
    assert res.outcome == jsq.Status.SUCCESS
    assert np.max(np.sum(res.modes > 0, axis=1)) > 4 and np.max(np.sum(res.modes >= 2, axis=1)) > 1
    ((capacity, sliding),) = grasp_mod._GROWN.values()
    assert capacity == 8 and sliding >= 4
    fixed = jsq.squeeze(slanted.replace(settings=jsq.Settings(capacity=8, sliding_capacity=sliding)))
    np.testing.assert_array_equal(res.modes, fixed.modes)
    np.testing.assert_array_equal(res.forces, fixed.forces)
    # stats count the largest contact and sliding sets: the smallest capacities that run it
    need = (int(res.stats.contacts), int(res.stats.sliding))
    assert need == (np.max(np.sum(res.modes > 0, axis=1)), np.max(np.sum(res.modes >= 2, axis=1)))
    tight = jsq.squeeze(slanted.replace(settings=jsq.Settings(capacity=need[0], sliding_capacity=need[1])))
    assert tight.outcome == jsq.Status.SUCCESS
    np.testing.assert_allclose(tight.forces, res.forces, rtol=0, atol=1e-12 * float(np.abs(res.forces).max()))
    for small in (jsq.Settings(capacity=4), jsq.Settings(sliding_capacity=1)):
        over = jsq.squeeze(slanted.replace(settings=small))
        assert over.outcome == jsq.Status.OVERFLOW and "sliding_capacity" in over.outcome.advice
        # its stats name the set that overflowed (docs/errors.md: raise the capacity to them)
        assert int(over.stats.contacts) > 4 if small.capacity else int(over.stats.sliding) > 1
        # it ends at its last row solved with every contact in a slot (the rows of the full
        # squeeze up to there), and logs the event that overflowed after it; the solve of
        # the overflowing set was once recorded as a last row with pulling forces
        n = int(over.count)
        np.testing.assert_allclose(over.forces, res.forces[:n], rtol=0, atol=1e-12 * float(np.abs(res.forces).max()))
        check_states(over, slanted.mesh, slanted.friction)
        assert over.events.rows()[-1][0] > float(over.final_depth)
    with compiles() as compiled:
        again = jsq.squeeze(slanted.replace(friction=0.25))
    assert again.outcome == jsq.Status.SUCCESS and compiled == []


def _primitives(scene):
    """Counter of the primitives in the compiled squeeze's program (all nested jaxprs)."""
    import collections
    import dataclasses

    op = dataclasses.replace(scene.operator(), field=None)
    closed = jax.make_jaxpr(lambda g: grasp_mod.simulate(op, g, grasp_mod.config_of(scene)))(
        grasp_mod.grasp_of(scene, op))
    count = collections.Counter()

    def walk(jaxpr):
        for eqn in jaxpr.eqns:
            count[eqn.primitive.name] += 1
            for value in eqn.params.values():
                for sub in value if isinstance(value, (list, tuple)) else [value]:
                    inner = getattr(sub, "jaxpr", sub)
                    if hasattr(inner, "eqns"):
                        walk(inner)

    walk(closed.jaxpr)
    return count


def test_effects_compile_only_what_the_scene_needs(centred):
    """DESIGN 2.7: full stick has no Newton solve (custom_root) and no slip events; without a
    rotation schedule there is no rotation code."""
    coulomb = _primitives(centred)
    stick = _primitives(centred.replace(friction_model="stick"))
    rotating = _primitives(centred.replace(fingers=jsq.Fingers(radius=0.015, rotation=[[0.0, 0.0], [1.0, 0.0]])))
    # Newton's while loops (slip angles, inside every configuration solve) are absent: only the
    # squeeze loop and the event location loop remain
    assert stick["while"] == 2 and coulomb["while"] > 2
    assert sum(stick.values()) < 0.5 * sum(coulomb.values())
    assert sum(rotating.values()) > sum(coulomb.values())


def test_jacfwd_in_every_number_matches_central_differences(slanted):
    """jax.jacfwd of the final grip force w.r.t. E, ν, thickness, μ, radius, depth and a
    fingertip-rotation coefficient, against central differences (relative step 1e-6; agree to
    rtol 1e-5 away from event switches). ν is traced, so the operator is built in the trace
    (dense build); the differences use the default sparse build: the two agree to ~1e-14."""
    names = ("E", "nu", "thickness", "mu", "radius", "depth", "rotation")
    p0 = np.array([1e5, 0.3, 0.0254, 0.23, 0.015, 0.012, 0.5])

    def force(p):
        E, nu, h, mu, r, depth, c = (p[k] for k in range(7))
        rot = jnp.stack([jnp.zeros(2, p.dtype), jnp.stack([c, 0.0 * c])])     # α2(d) = c·d
        sc = slanted.replace(material=jsq.Material(E, nu, h), friction=mu, depth=depth,
                             fingers=jsq.Fingers(radius=r, rotation=rot))
        return jsq.squeeze(sc).grip_force

    J = jax.jacfwd(force)(jnp.asarray(p0))
    assert J.shape == (7,)
    f0 = float(force(p0))
    np.testing.assert_allclose(J[0], f0 / p0[0], rtol=1e-9)       # force is linear in E
    for k, name in enumerate(names):
        h = 1e-6 * p0[k]
        up, down = p0.copy(), p0.copy()
        up[k] += h
        down[k] -= h
        fd = (float(force(up)) - float(force(down))) / (2 * h)
        assert abs(fd) > 0, name
        np.testing.assert_allclose(J[k], fd, rtol=1e-5, err_msg=name)
    # README: at an input refused under tracing (a depth beyond the grip distance:
    # Status.INVALID_INPUT) the derivatives are those of the returned result, zero forces
    bad = p0.copy()
    bad[5] = 1.0
    np.testing.assert_array_equal(jax.jacfwd(force)(jnp.asarray(bad)), np.zeros(7))
    # also where the refused number is the force scale's own (E h L): a NaN modulus or
    # thickness gave NaN forces and derivatives
    for k in (0, 2):
        bad = p0.copy()
        bad[k] = np.nan
        np.testing.assert_array_equal(jax.jacfwd(force)(jnp.asarray(bad)), np.zeros(7), err_msg=names[k])


def test_a_traced_nu_other_than_a_given_operators_is_refused(slanted):
    """A given op fixes ν. Eagerly a scene of another ν is a ValueError; traced, a lane of
    another ν was the op's squeeze under the scene's name (vmap over ν gave one grip force
    twice), and its derivative was zero: now that lane is INVALID_INPUT (material.nu), and
    differentiating ν with op= given is a TypeError that says to omit op=."""
    from jaxsqueeze.simulation import validate
    op = slanted.operator()
    mat = slanted.material
    f = lambda nu: jsq.squeeze(slanted.replace(material=jsq.Material(mat.E, nu, mat.thickness)), op=op)  # noqa: E731
    out = jax.vmap(f)(jnp.array([mat.nu, 0.4]))
    assert [jsq.Status(int(v)) for v in out.status] == [jsq.Status.SUCCESS, jsq.Status.INVALID_INPUT]
    assert int(out.invalid[1]) == validate.FIELDS.index("material.nu")
    np.testing.assert_allclose(float(out.grip_force[0]), float(jsq.squeeze(slanted, op=op).grip_force), rtol=1e-12)
    with pytest.raises(TypeError, match=r"nu is differentiated .* the given op fixes nu .* Omit op="):
        jax.jvp(lambda nu: f(nu).grip_force, (mat.nu,), (1.0,))


def test_reverse_mode_is_refused_with_the_way_to_a_gradient(slanted):
    """README: jax.grad / vjp / jacrev through a squeeze raise a TypeError that names jax.jacfwd
    (JAX's own error was "Linearization failed to produce known values"), also under vmap;
    nothing is compiled on the way."""
    force = lambda mu: jsq.squeeze(slanted.replace(friction=mu)).grip_force  # noqa: E731
    attempts = [lambda: jax.grad(force)(0.3), lambda: jax.vjp(force, 0.3), lambda: jax.jacrev(force)(0.3),
                lambda: jax.vmap(jax.grad(force))(jnp.array([0.3, 0.4])),
                lambda: jax.grad(lambda r: jsq.squeeze(slanted.replace(fingers=jsq.Fingers(radius=r))).grip_force)(0.015)]
    for attempt in attempts:
        with pytest.raises(TypeError, match=r"forward mode only.*jax\.jacfwd"):
            attempt()
    # README: through the user's own jit or checkpoint, JAX's own words (nothing compiles)
    for wrap in (jax.jit, jax.checkpoint):
        with pytest.raises(ValueError, match=r"Linearization failed to produce known values"):
            jax.grad(wrap(force))(0.3)


def test_jacfwd_holds_where_an_anchor_that_moves_with_mu_sticks_beside_sliding_contacts():
    """A contact that sticks at an anchor which μ moves (it stuck by event D at a depth that μ
    moves) beside contacts that slide. The slip angles' implicit step took the Jacobian's
    columns of every slot, though a sticking slot's angle is its anchor, not an unknown, and so
    counted the anchor's tangent twice: dF/dμ 7 % off central differences on this 10 mm
    rectangle (numerics §2, 19). Found by random scenes with turning tips, μ = 2, ν = 0.49."""
    mesh = jsq.shapes.rectangle(0.08, 0.05, max_edge=0.01)
    grip = (nearest(mesh, (-0.03, -0.025)), nearest(mesh, (0.02, 0.025)))
    sc = jsq.Scene(mesh=mesh, material=jsq.Material(E=1e5, nu=0.49, thickness=0.0254), friction=2.0, depth=0.0032,
                   fingers=jsq.Fingers(radius=0.24, rotation=[[0.0, 0.0], [-14.65, 0.03]]), grip=grip,
                   settings=jsq.Settings(capacity=8, sliding_capacity=8))     # one 8 x 8 slip-angle system
    res = jsq.squeeze(sc)
    assert res.outcome == jsq.Status.SUCCESS
    assert [k for _, _, k, _ in res.events.rows()][-1] == "D"
    check_states(res, mesh, 2.0, "coulomb")
    force = lambda mu: jsq.squeeze(sc.replace(friction=mu)).grip_force  # noqa: E731
    h = 2e-6
    fd = (float(force(2.0 + h)) - float(force(2.0 - h))) / (2 * h)
    # a vmap of jacfwd (on the CPU its members run one at a time, each its own squeeze)
    slopes = jax.vmap(jax.jacfwd(force))(jnp.array([2.0, 2.0 + h]))
    np.testing.assert_allclose(np.asarray(slopes), [fd, fd], rtol=1e-6)


def test_a_second_derivative_is_refused_with_the_way_to_it(slanted):
    """README: derivatives are exact to first order. Nested forward mode (jax.jacfwd of
    jax.jacfwd, a jvp inside a jvp, also through the user's own jit) raises a TypeError that
    says so and names central differences of jax.jacfwd, instead of returning a second
    derivative that the implicit-function steps get wrong (0.5 % on a sliding square,
    docs/numerics.md §2): at the front door, or (through a jit) while the jvp is traced."""
    force = lambda mu, d: jsq.squeeze(slanted.replace(friction=mu, depth=d)).grip_force  # noqa: E731
    attempts = [lambda: jax.jacfwd(jax.jacfwd(force, argnums=1), argnums=1)(0.23, 0.012),
                lambda: jax.jvp(lambda d: jax.jvp(lambda mu: force(mu, d), (0.23,), (1.0,))[1], (0.012,), (1.0,)),
                lambda: jax.jacfwd(jax.jacfwd(jax.jit(force)))(0.23, 0.012)]
    for attempt in attempts:
        with pytest.raises(TypeError, match=r"exact first derivatives.*central differences of jax\.jacfwd"):
            attempt()


def test_eager_and_jitted_squeezes_agree(slanted):
    """An eager squeeze is a top-level program compiled with ``compiler.options()``; inside
    ``jax.jit`` the same squeeze is the plain program. Both give the same history. The scene
    is a constant of the jitted function: every number concrete, yet inside a trace (the
    squeeze took the eager path there and failed reading a traced force scale as a float)."""
    from jaxsqueeze import compiler
    eager = jsq.squeeze(slanted, trim=False)
    jitted = jax.jit(lambda: jsq.squeeze(slanted, trim=False))()
    if compiler.options():
        assert grasp_mod._run._tuned is not grasp_mod._run.plain
    assert int(eager.count) == int(jitted.count) and int(eager.n_events) == int(jitted.n_events)
    np.testing.assert_array_equal(eager.modes, jitted.modes)
    scale = float(np.abs(eager.forces).max())
    np.testing.assert_allclose(jitted.forces, eager.forces, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(jitted.events.depth, eager.events.depth, rtol=0, atol=1e-15)


@pytest.mark.parametrize("transform", ["jit", "jacfwd", "vmap"])
def test_the_first_squeeze_of_an_object_may_be_a_traced_one(transform, monkeypatch):
    """The compliance operator of a new object is built (host-side, sparse) and cached on the
    first squeeze, also when that squeeze is being traced by jit, jacfwd or vmap; it used to
    fail converting a tracer to numpy unless an eager squeeze had built it first. (Traced only,
    not compiled: the build is what is being tested.) The engine is traced once: the
    derivative and batching rules reuse its trace (they traced it again, once each, in a
    context that JAX's cache told apart: a jacfwd traced it three times)."""
    mesh = jsq.shapes.disk(0.05, 0.02)       # a new object: nothing is cached for it
    grip = (nearest(mesh, (0.0, -0.05)), nearest(mesh, (0.0, 0.05)))
    new_loop_bound = jsq.Settings(max_steps=401 + ["jit", "jacfwd", "vmap"].index(transform))  # no trace to reuse
    sc = jsq.Scene(mesh=mesh, material=jsq.Material(E=1e5, nu=0.3, thickness=0.0254),
                   fingers=jsq.Fingers(radius=0.012), grip=grip, friction=0.3, depth=0.008,
                   settings=new_loop_bound)
    traces = []
    monkeypatch.setattr(grasp_mod, "simulate", lambda *a: traces.append(a) or engine.simulate(*a))
    f = lambda mu: jsq.squeeze(sc.replace(friction=mu)).grip_force  # noqa: E731
    g = {"jit": jax.jit(f), "jacfwd": jax.jacfwd(f), "vmap": jax.vmap(f)}[transform]
    jax.make_jaxpr(g)(np.array([0.3, 0.4]) if transform == "vmap" else 0.3)
    assert sc.operator().G.shape == (2 * len(mesh.boundary),) * 2
    assert len(traces) == 1


def test_a_full_event_log_ends_the_squeeze_with_event_overflow(slanted):
    """Settings.max_events=2 on a squeeze with more events: EVENT_OVERFLOW at the row that
    overfilled the log, which holds the first two events of the full squeeze, and n_events
    counts the events held (it counted the dropped ones too)."""
    full = jsq.squeeze(slanted)
    assert len(full.events) > 2
    res = jsq.squeeze(slanted.replace(settings=dataclasses.replace(slanted.settings, max_events=2)))
    assert res.outcome == jsq.Status.EVENT_OVERFLOW and "max_events" in res.outcome.advice
    assert int(res.n_events) == len(res.events) == 2
    for a, b in zip(res.events, full.events):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b)[:2])
    assert float(res.final_depth) <= float(full.events.depth[2]) + 1e-12


def test_newton_failure_records_where_newton_stopped(slanted):
    """docs/errors.md: under NEWTON_FAILURE the last row holds the iterate where Newton stopped
    (not a solution), and ``stats.residual`` includes its last update; the rows before it are
    the converged squeeze. One Newton iteration cannot converge the first sliding row."""
    full = jsq.squeeze(slanted)
    res = jsq.squeeze(slanted.replace(settings=dataclasses.replace(slanted.settings, newton_iters=1)))
    assert res.outcome == jsq.Status.NEWTON_FAILURE and "newton_iters" in res.outcome.advice
    tol = 1e-11                                          # the float64 default of Settings.newton_tol
    assert float(res.stats.residual) > tol >= float(full.stats.residual)
    k = int(res.count) - 1                               # the failed row; those before it converged
    assert k > 0 and np.any(np.asarray(res.modes[k]) >= 2)
    np.testing.assert_allclose(res.forces[:k], full.forces[:k], rtol=0, atol=1e-12 * np.abs(full.forces).max())
