"""jaxsqueeze.batch.map_scenes: results in input order, inline equal to the process pool,
a squeeze in worker processes equal to the same squeeze here."""
import os

import numpy as np
import pytest

import jaxsqueeze as jsq
from jaxsqueeze.batch import ItemError, map_scenes


def _square_and_env(x):
    """Module level, so spawned workers import it by name. Also reports the worker's XLA flags."""
    return x * x, os.getpid(), os.environ.get("XLA_FLAGS", "")


def _fail_on_three(x):
    if x == 3:
        raise ValueError("three")
    return x


def _stick_squeeze(grip_x):
    """A tiny full-stick squeeze of a coarse square, gripped at x = grip_x on both edges."""
    import jax
    mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=0.025)
    near = jsq.scene.nearest_boundary_node
    sc = jsq.Scene(mesh=mesh, material=jsq.Material(1e5, 0.3, 0.0254), fingers=jsq.Fingers(radius=0.015),
                   grip=(near(mesh, (grip_x, -0.05)), near(mesh, (grip_x, 0.05))), friction=0.5, depth=0.005,
                   friction_model="stick")
    res = jsq.squeeze(sc)
    return res.outcome.name, np.asarray(res.total_force[-1]), bool(jax.config.jax_enable_x64)


def test_order_and_inline_equals_pool():
    items = list(range(23))
    inline = map_scenes(_square_and_env, items, processes=1, progress=False)
    pooled = map_scenes(_square_and_env, items, processes=2, chunk=3, progress=False, cache=False)
    assert [r[0] for r in inline] == [x * x for x in items]
    assert [r[0] for r in pooled] == [r[0] for r in inline]
    assert all(r[1] == os.getpid() for r in inline)          # inline: no pool
    assert all(r[1] != os.getpid() for r in pooled)
    assert all("xla_cpu_multi_thread_eigen=false" in r[2] for r in pooled)
    assert "xla_cpu_multi_thread_eigen=false" not in os.environ.get("XLA_FLAGS", "")   # restored here
    assert map_scenes(_square_and_env, [], processes=2) == []


def test_an_item_error_names_the_item():
    with pytest.raises(ItemError, match="item 3"):
        map_scenes(_fail_on_three, range(6), processes=1, progress=False)
    with pytest.raises(ItemError, match="item 3"):
        map_scenes(_fail_on_three, range(6), processes=2, chunk=2, progress=False, cache=False)


def test_squeezes_in_two_processes_equal_inline(tmp_path):
    xs = [0.0, 0.01]
    pooled = map_scenes(_stick_squeeze, xs, processes=2, chunk=1, progress=False, cache=tmp_path / "cache")
    inline = map_scenes(_stick_squeeze, xs, processes=1, progress=False)
    for (s1, f1, x64), (s2, f2, _) in zip(pooled, inline):
        assert s1 == s2 == "SUCCESS"
        assert x64, "workers take this process's precision"
        np.testing.assert_allclose(f1, f2, rtol=1e-12, atol=1e-15)
    assert any((tmp_path / "cache").iterdir())
