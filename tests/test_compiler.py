"""compiler.jit: top-level calls compile with the accepted CPU options, traced calls stay plain."""
import os
import threading

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import lax

from jaxsqueeze import compiler


@pytest.fixture
def fresh_options(monkeypatch):
    compiler.options.cache_clear()
    yield monkeypatch
    compiler.options.cache_clear()


def _f(x, k):
    return jnp.sin(x) * k


def test_top_level_calls_use_the_options_and_traced_calls_the_plain_jit(fresh_options):
    full = tuple(sorted(compiler.CPU_OPTIONS.items()))
    assert set(compiler.options()) <= set(full)
    if jax.default_backend() == "cpu" and "--xla_cpu_use_fusion_emitters=false" in os.environ.get("XLA_FLAGS", ""):
        # conftest's probe found that this jaxlib knows the option
        assert ("xla_cpu_use_fusion_emitters", False) in compiler.options()
    f = compiler.jit(_f, static_argnums=(1,))
    x = jnp.linspace(0.0, 1.0, 5)
    np.testing.assert_array_equal(f(x, 2.0), _f(x, 2.0))
    assert (f._top() is not f.plain) == bool(compiler.options())
    # inside jit (compiler options there are an error) the plain program; eager vmap and
    # jvp transform the tuned one
    np.testing.assert_allclose(jax.jit(lambda y: f(y, 2.0))(x), _f(x, 2.0), rtol=1e-15)
    np.testing.assert_allclose(jax.vmap(lambda y: f(y, 2.0))(x), _f(x, 2.0), rtol=1e-15)
    _, t = jax.jvp(lambda y: f(y, 2.0), (x,), (jnp.ones_like(x),))
    np.testing.assert_allclose(t, 2.0 * jnp.cos(x), rtol=1e-15)
    assert f.lower(x, 2.0).compile() is not None
    assert f._cache_size() >= 1


def test_eager_vmap_jvp_and_jacfwd_compile_with_the_options_and_a_users_jit_without():
    """JAX compiles the program of an eager ``vmap``/``jvp``/``jacfwd`` of a library function
    at the top level with that function's compiler options (how a user differentiates a
    squeeze: its derivative program compiles as fast as its value's); inside a user's ``jit``
    the plain program is staged. Seen in the round-off of a sum of 122 numbers of mixed
    magnitudes, which the options sum in one reduce and plain XLA in chunks of 32."""
    if ("xla_disable_hlo_passes", "tree_reduction_rewriter") not in compiler.options():
        pytest.skip("this jaxlib does not take xla_disable_hlo_passes as a compile option")
    f = compiler.jit(jnp.sum)
    rng = np.random.default_rng(0)
    for _ in range(20):     # numbers whose two sums differ in round-off (the 2nd draw on JAX 0.10.2)
        t = jnp.asarray(rng.standard_normal(122) * 10 ** rng.uniform(-8, 8, 122))
        tuned, plain = float(f(t)), float(jax.jit(jnp.sum)(t))
        if tuned != plain:
            break
    assert tuned != plain
    assert float(jax.jvp(f, (t,), (t,))[1]) == tuned
    np.testing.assert_array_equal(jax.vmap(f)(jnp.stack([t, t])), [tuned, tuned])
    assert float(jax.jacfwd(lambda s: f(s * t))(1.0)) == tuned
    assert float(jax.jit(lambda y: jax.jvp(f, (y,), (y,))[1])(t)) == plain


def test_library_programs_reduce_without_splitting_into_reduce_windows():
    """``CPU_OPTIONS`` turn XLA's tree-reduction rewriter off: a sum over 122 numbers (the
    boundary nodes of the foam square) is one reduce in a library program, where plain
    ``jax.jit`` splits it into a reduce-window and a reduce (two operations, the squeeze loop
    had 22 such pairs per iteration). The sum is the same."""
    if ("xla_disable_hlo_passes", "tree_reduction_rewriter") not in compiler.options():
        pytest.skip("this jaxlib does not take xla_disable_hlo_passes as a compile option")
    f = compiler.jit(lambda x: jnp.sum(x * x))
    x = jnp.linspace(0.0, 1.0, 122)
    tuned = f.lower(x).compile().as_text()
    plain = jax.jit(lambda x: jnp.sum(x * x)).lower(x).compile().as_text()
    assert "reduce-window(" in plain and "reduce-window(" not in tuned
    np.testing.assert_allclose(f(x), np.sum(np.asarray(x) ** 2), rtol=1e-14)


def test_library_programs_copy_fewer_buffers_around_conditionals_in_loops():
    """``CPU_OPTIONS`` turn on copy insertion's region analysis: a loop whose body switches
    among three branches that update or pass on three arrays (the squeeze loop's shape: the
    phase switch) compiles with fewer copies (7 against 14 on JAX 0.10.2), and computes the
    same."""
    key = ("xla_cpu_copy_insertion_use_region_analysis", True)
    if key not in compiler.options():
        pytest.skip("this jaxlib does not take xla_cpu_copy_insertion_use_region_analysis")

    def run(x):
        def body(s):
            i, ev, x, y = s
            branches = [lambda ev, x, y: (ev.at[i % 256].set(x[0]), x * 1.01, y),
                        lambda ev, x, y: (ev, x + 1.0, y), lambda ev, x, y: (ev, x, y + 1.0)]
            ev, x, y = lax.switch(i % 3, branches, ev, x, y)
            return i + 1, ev, lax.cond(x[1] > 3.0, lambda: x * 2.0, lambda: x), y
        return lax.while_loop(lambda s: s[0] < 100, body, (jnp.int32(0), jnp.zeros(256), x, jnp.zeros(122)))

    x = jnp.linspace(0.0, 1.0, 122)
    without = dict(opt for opt in compiler.options() if opt != key)
    copies = lambda c: c.as_text().count(" copy(")   # noqa: E731
    tuned, plain = compiler.jit(run).lower(x).compile(), jax.jit(run, compiler_options=without).lower(x).compile()
    assert copies(tuned) < 0.75 * copies(plain)
    for a, b in zip(tuned(x), plain(x)):
        np.testing.assert_array_equal(a, b)


def test_float32_programs_compile_without_region_analysis():
    """Region analysis lets XLA:CPU run the float32 squeeze loop's operations on two threads,
    whose hops cost more than the copies it saves (``compiler.NOT_FLOAT32``): a top-level
    program compiled with x64 off leaves it out, one with x64 on keeps it, and each precision
    gets its own compiled program with the same values."""
    key = ("xla_cpu_copy_insertion_use_region_analysis", True)
    if key not in compiler._options(compiler.platform()):
        pytest.skip("this jaxlib does not take xla_cpu_copy_insertion_use_region_analysis")
    f = compiler.jit(lambda x: jnp.cumsum(x * x))
    with jax.enable_x64(True):
        assert key in compiler.options()
        wide = f(jnp.linspace(0.0, 1.0, 7))
        top64 = f._top()
    with jax.enable_x64(False):
        opts = compiler.options()
        assert key not in opts and set(opts) == set(compiler._options(compiler.platform())) - {key}
        narrow = f(jnp.linspace(0.0, 1.0, 7))
        assert f._top() is not top64
    assert wide.dtype == jnp.float64 and narrow.dtype == jnp.float32
    np.testing.assert_allclose(narrow, wide, rtol=1e-6)


def test_every_matrix_product_is_full_precision_whatever_the_callers_setting():
    """``compiler.precise``: under a caller's ``jax.default_matmul_precision("bfloat16")``
    (DEFAULT precision, which on NVIDIA GPUs since Ampere rounds float32 operands to TF32),
    every ``dot_general`` in the library's programs is HIGHEST: a squeeze, its ``jax.jacfwd``
    and ``jax.vmap`` (whose custom rules JAX traces later, outside the squeeze's own trace), a
    placed squeeze with an adversary and its quality, ``deform`` under ``jax.jvp`` and the
    element stresses. (Lowered only: on the CPU both precisions compute the same.)"""
    import re

    import jaxsqueeze as jsq
    from jaxsqueeze.plan import quality
    mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=0.02, refine_near=[[-0.005, -0.05], [0.005, 0.05]],
                                refine_edge=0.005)
    grip = (jsq.scene.nearest_boundary_node(mesh, (-0.005, -0.05)), jsq.scene.nearest_boundary_node(mesh, (0.005, 0.05)))
    mat = jsq.Material(E=1e5, nu=0.3, thickness=0.0254)
    scene = jsq.Scene(mesh=mesh, material=mat, fingers=jsq.Fingers(radius=0.01), grip=grip, friction=0.2, depth=0.015)
    P = float(scene.curve().perimeter)
    placed = scene.replace(grip=None, placement=jsq.Placement(s=(0.0, P / 2)), adversary=jsq.Adversary(s=P / 4, push=0.003))
    op = scene.operator()
    programs = {
        "squeeze, jacfwd in mu": (jax.jacfwd(lambda mu: jsq.squeeze(scene.replace(friction=mu)).total_force), 0.2),
        "squeeze, vmap over mu": (jax.vmap(lambda mu: jsq.squeeze(scene.replace(friction=mu)).total_force),
                                  jnp.array([0.2, 0.3])),
        "placed and pushed": (lambda s: quality.adversary_work(jsq.squeeze(placed.replace(placement=jsq.Placement(s=s)))),
                              jnp.array([0.0, P / 2])),
        "deform, jvp": (lambda d: jax.jvp(lambda d: jsq.deform(op, np.array(grip), d).displacement, (d,), (d,)),
                        jnp.full((2, 2), 1e-3)),
        "element stress": (lambda u: jsq.fem.element_stress(mesh, mat, u), jnp.zeros((mesh.n, 2))),
    }
    with jax.default_matmul_precision("bfloat16"):
        for name, (fn, x) in programs.items():
            dots = re.findall(r"stablehlo\.dot_general[^\n]*", jax.jit(fn).lower(x).as_text())
            assert dots, name
            assert all("precision = [HIGHEST, HIGHEST]" in d for d in dots), (name, [d for d in dots if "HIGHEST" not in d][:1])


def test_an_option_this_jaxlib_rejects_is_left_out(fresh_options):
    if jax.default_backend() == "cpu":   # the others are kept
        fresh_options.setattr(compiler, "CPU_OPTIONS", {"xla_cpu_no_such_option_in_any_jaxlib": True,
                                                        "xla_backend_optimization_level": 1})
        assert compiler.options() == (("xla_backend_optimization_level", 1),)
        compiler.options.cache_clear()
    fresh_options.setattr(compiler, "CPU_OPTIONS", {"xla_cpu_no_such_option_in_any_jaxlib": True})
    assert compiler.options() == ()
    f = compiler.jit(_f, static_argnums=(1,))
    np.testing.assert_array_equal(f(jnp.ones(3), 3.0), _f(jnp.ones(3), 3.0))
    assert f._top() is f.plain


def _loop(consts, state):
    """A while loop of many small operations (what one_kernel is for); reads every kind of
    constant, one of them only in a branch XLA can see is never taken."""
    A, k, on, unused = consts

    def body(c):
        x, i = c
        y = jnp.where(on, jnp.tanh(A @ x) + k[i % k.shape[0]], x)
        return jnp.where(i < -1, unused, y), i + 1
    return lax.while_loop(lambda c: c[1] < 50, body, state)


def test_one_kernel_compiles_a_region_as_one_call_with_the_same_result():
    if not compiler.can_fuse():
        pytest.skip("one-kernel regions need the CPU backend and its options")
    rng = np.random.default_rng(0)
    consts = (jnp.asarray(rng.normal(size=(6, 6)) / 3), jnp.asarray(rng.normal(size=4)),
              jnp.asarray(rng.random(6) > 0.3), jnp.ones(6))
    state = (jnp.asarray(rng.normal(size=6)), jnp.array(0, jnp.int32))
    seen = []

    def fn(c, s):
        seen.append(compiler.in_kernel())
        return _loop(c, s)

    f = compiler.jit(lambda c, s: compiler.one_kernel(fn, c, s))
    x, i = f(consts, state)
    want_x, want_i = jax.jit(_loop)(consts, state)
    np.testing.assert_allclose(x, want_x, rtol=1e-14, atol=1e-15)
    assert int(i) == int(want_i) == 50 and seen == [True] and not compiler.in_kernel()
    text = f.lower(consts, state).compile().as_text()
    calls = [ln for ln in text.splitlines() if " call(" in ln and 'xla_cpu_small_call="true"' in ln]
    assert calls, "the region was inlined instead of kept as one kernel"
    with pytest.raises(TypeError, match="structure"):
        compiler.jit(lambda c, s: compiler.one_kernel(lambda c, s: s[0], c, s))(consts, state)


def test_gauss_jordan_solves_like_lapack_and_differentiates_alike():
    from jaxsqueeze.mechanics.linalg import gauss_jordan
    rng = np.random.default_rng(1)
    for n in (1, 2, 5, 12):
        A = rng.normal(size=(n, n)) + n * np.eye(n)[rng.permutation(n)]   # pivots off the diagonal
        for B in (rng.normal(size=n), rng.normal(size=(n, 3))):
            np.testing.assert_allclose(gauss_jordan(jnp.asarray(A), jnp.asarray(B)), np.linalg.solve(A, B),
                                       rtol=1e-12, atol=1e-13)
    dA, dB = rng.normal(size=(n, n)), rng.normal(size=n)
    _, t = jax.jvp(gauss_jordan, (jnp.asarray(A), jnp.asarray(B[:, 0])), (dA, dB))
    _, want = jax.jvp(jnp.linalg.solve, (jnp.asarray(A), jnp.asarray(B[:, 0])), (dA, dB))
    np.testing.assert_allclose(t, want, rtol=1e-11, atol=1e-12)
    assert not np.all(np.isfinite(gauss_jordan(jnp.ones((3, 3)), jnp.ones(3))))


def test_one_kernel_differentiates_through_constants_and_state():
    """Constants are packed by value, so forward-mode derivatives pass through them (and
    through the state) as through the plain function; integers and booleans come back exact."""
    def f(k, x0):
        def fn(c, s):
            scale, n, on = c
            return jnp.where(on, s[0] * scale, s[0]) + n, s[1] + 1
        return compiler.one_kernel(fn, (k, jnp.int32(-7), jnp.array([True, False, True])), (x0, jnp.array(0)))[0]
    x = 2.0 * jnp.ones(3)
    np.testing.assert_allclose(f(3.0 * jnp.ones(3), x), [-1.0, -5.0, -1.0])
    _, t = jax.jvp(lambda k: f(k, x), (3.0 * jnp.ones(3),), (jnp.ones(3),))
    np.testing.assert_allclose(t, [2.0, 0.0, 2.0])
    _, t = jax.jvp(lambda y: f(3.0 * jnp.ones(3), y), (x,), (jnp.ones(3),))
    np.testing.assert_allclose(t, [3.0, 1.0, 3.0])


def test_the_installed_jax_is_the_range_pyproject_asks_for():
    """README, Development: the compile options and batching rules follow JAX 0.10, so
    ``pyproject.toml`` asks for ``jax>=0.10.2,<0.11``; the suite must run on a JAX in that
    range (and on its own jaxlib), or what it passes says nothing about what users install."""
    import importlib.metadata as md
    try:
        import tomllib
    except ImportError:         # Python 3.10
        import tomli as tomllib

    from packaging.requirements import Requirement
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    with open(os.path.join(root, "pyproject.toml"), "rb") as f:
        deps = [Requirement(d) for d in tomllib.load(f)["project"]["dependencies"]]
    (jax_req,) = [r for r in deps if r.name == "jax"]
    assert set(str(jax_req.specifier).split(",")) == {">=0.10.2", "<0.11"}      # what the README says
    assert jax_req.specifier.contains(md.version("jax")) and jax.__version__ == md.version("jax")
    assert md.version("jaxlib").split(".")[:2] == md.version("jax").split(".")[:2]


def test_a_compile_started_ahead_is_the_one_the_next_call_runs():
    """``compile_ahead`` compiles the program of a later top-level call in a background thread:
    the call then compiles nothing itself. A compile ahead that fails leaves its error to the
    call, and one started under a thread-local JAX context (which its thread would not share)
    compiles nothing."""
    from physics import compiles
    me = threading.current_thread().name
    f = compiler.jit(lambda x, k: jnp.cos(x) * k + 0.25, static_argnums=(1,))     # no other test's program
    x = jnp.linspace(0.0, 1.0, 7)
    with compiles(where=True) as compiled:
        f.compile_ahead(x, 3.0)
        y = f(x, 3.0)
    np.testing.assert_allclose(y, jnp.cos(x) * 3.0 + 0.25, rtol=1e-15)
    assert compiled and all(thread == "compile <lambda>" for _, thread in compiled), compiled
    f.compile_ahead(x, "three")                  # fails in its thread, quietly
    with pytest.raises(TypeError):
        f(x, "three")
    with compiles(where=True) as compiled, jax.default_matmul_precision("float32"):
        f.compile_ahead(x, 4.0)
        compiler.wait_ahead()
        assert compiled == []
        f(x, 4.0)
    assert compiled and all(thread == me for _, thread in compiled), compiled
