"""compiler.jit: top-level calls compile with the accepted CPU options, traced calls stay plain."""
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

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
    assert (f._tuned is not f.plain) == bool(compiler.options())
    # inside jit (compiler options there are an error), vmap and jvp: the plain program
    np.testing.assert_allclose(jax.jit(lambda y: f(y, 2.0))(x), _f(x, 2.0), rtol=1e-15)
    np.testing.assert_allclose(jax.vmap(lambda y: f(y, 2.0))(x), _f(x, 2.0), rtol=1e-15)
    _, t = jax.jvp(lambda y: f(y, 2.0), (x,), (jnp.ones_like(x),))
    np.testing.assert_allclose(t, 2.0 * jnp.cos(x), rtol=1e-15)
    assert f.lower(x, 2.0).compile() is not None
    assert f._cache_size() >= 1


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
    assert f._tuned is f.plain
