"""jaxsqueeze.batch.map_scenes: results in input order, inline equal to the process pool,
a squeeze in worker processes equal to the same squeeze here; split_vmap equal to vmap on one
and on two host devices; progress on a terminal or in a notebook only."""
import io
import os
import sys

import numpy as np
import pytest

import jaxsqueeze as jsq
from jaxsqueeze.batch import ItemError, interactive, map_scenes


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


class _Terminal(io.StringIO):
    def isatty(self):
        return True


#: what ipykernel gives a notebook as sys.stderr: no terminal, but it redraws a line on "\r"
_KernelStream = type("OutStream", (io.StringIO,), {"__module__": "ipykernel.iostream"})


class _NoIsatty:
    def write(self, text):
        return len(text)


def test_progress_goes_to_a_terminal_or_a_notebook_and_nowhere_else(monkeypatch):
    closed = io.StringIO()
    closed.close()
    assert interactive(_Terminal()) and interactive(_KernelStream())
    assert not interactive(io.StringIO()) and not interactive(closed) and not interactive(_NoIsatty())
    for stream, shown in ((_Terminal(), True), (_KernelStream(), True), (io.StringIO(), False)):
        monkeypatch.setattr(sys, "stderr", stream)
        assert map_scenes(_fail_on_three, [0, 1, 2], processes=1) == [0, 1, 2]
        assert ("] 3/3 " in stream.getvalue()) is shown, stream.getvalue()
        stream.truncate(0)
        map_scenes(_fail_on_three, [0, 1, 2], processes=1, progress=False)
        assert stream.getvalue() == ""


def test_an_item_error_names_the_item():
    with pytest.raises(ItemError, match="item 3"):
        map_scenes(_fail_on_three, range(6), processes=1, progress=False)
    with pytest.raises(ItemError, match="item 3"):
        map_scenes(_fail_on_three, range(6), processes=2, chunk=2, progress=False, cache=False)


@pytest.mark.parametrize("kw", [dict(processes=1.5), dict(processes="2"), dict(processes=0), dict(chunk=0),
                                dict(chunk=True)], ids=str)
def test_counts_that_are_not_positive_integers_are_refused(kw):
    """processes=1.5 ran one worker, "2" two and chunk=0 one item per task: all refused."""
    with pytest.raises(ValueError, match=r"must be an integer >= 1 \(or None\), got"):
        map_scenes(_square_and_env, range(4), progress=False, **kw)


def test_a_progress_switch_given_as_text_is_refused():
    """progress="False" is true to Python and drew the bar."""
    with pytest.raises(TypeError, match="progress='False' must be True or False"):
        map_scenes(_square_and_env, range(4), progress="False", processes=1)


def test_a_function_workers_cannot_receive_is_named_before_any_worker_starts():
    """A lambda failed with pickle's bare "Can't pickle local object" from the pool."""
    with pytest.raises(TypeError, match=r"sends fn to worker processes by name, .* top level of a module"):
        map_scenes(lambda x: x, range(4), processes=2, progress=False, cache=False)
    assert map_scenes(lambda x: 2 * x, range(3), processes=1, progress=False) == [0, 2, 4]    # inline needs no pickle


def test_squeezes_in_two_processes_equal_inline(tmp_path):
    xs = [0.0, 0.01]
    pooled = map_scenes(_stick_squeeze, xs, processes=2, chunk=1, progress=False, cache=tmp_path / "cache")
    inline = map_scenes(_stick_squeeze, xs, processes=1, progress=False)
    for (s1, f1, x64), (s2, f2, _) in zip(pooled, inline):
        assert s1 == s2 == "SUCCESS"
        assert x64, "workers take this process's precision"
        np.testing.assert_allclose(f1, f2, rtol=1e-12, atol=1e-15)
    assert any((tmp_path / "cache").iterdir())


SPLIT_CHILD = r"""
import os, sys, json
from jaxsqueeze.batch import host_devices_flag, split_vmap
os.environ["XLA_FLAGS"] = host_devices_flag(2)
import jax, jax.numpy as jnp, numpy as np
sys.path.insert(0, {tests!r})
import test_batch
assert jax.device_count() == 2
f = split_vmap(test_batch._split_member, in_axes=(None, 0))
for size in (1, 5, 8):          # odd sizes are padded, and the padding dropped
    x = jnp.arange(size * 3.0).reshape(size, 3)
    y, s = f(jnp.float32(2.0), {{"x": x}})
    np.testing.assert_allclose(np.asarray(y), 2.0 * np.asarray(x) + 1.0)
    np.testing.assert_allclose(np.asarray(s), np.asarray(x).sum(1))
    devs = {{d.id for d in y.sharding.device_set}}
    print(json.dumps(dict(size=size, shape=list(y.shape), devices=sorted(devs))))
for args, msg in (((jnp.float32(2.0), {{"x": jnp.float32(1.0)}}), "scalar leaf"), ((jnp.float32(2.0),), "2 entries for 1")):
    try:
        f(*args)
        raise AssertionError(msg)
    except ValueError as e:
        assert msg in str(e), e
"""


def _split_member(a, tree):
    """One member of a split_vmap batch: a shared scalar and a pytree with a (3,) leaf."""
    return a * tree["x"] + 1.0, tree["x"].sum()


def test_split_vmap_equals_vmap_on_one_and_two_devices():
    """split_vmap: with this process's one CPU device it is jit(vmap); in a child with two host
    devices (host_devices_flag) the batch is split over both, padded for odd sizes, and equal."""
    import json
    import subprocess
    import sys

    import jax
    import jax.numpy as jnp

    from jaxsqueeze.batch import split_vmap
    x = jnp.arange(12.0).reshape(4, 3)
    y, s = split_vmap(_split_member, in_axes=(None, 0))(jnp.float32(2.0), {"x": x})
    ry, rs = jax.vmap(_split_member, in_axes=(None, 0))(jnp.float32(2.0), {"x": x})
    np.testing.assert_array_equal(np.asarray(y), np.asarray(ry))
    np.testing.assert_array_equal(np.asarray(s), np.asarray(rs))
    with pytest.raises(ValueError, match="in_axes"):
        split_vmap(_split_member, in_axes=(None, 1))
    # bad devices, a non-function, a scalar batch, in_axes that do not match the arguments, and
    # a device count of 0: errors that say so (they failed deep in jax, or divided by zero)
    dev = jax.local_devices()[0]
    for kw, match in [(dict(devices=[]), "non-empty list of distinct"), (dict(devices=[dev, dev]), "distinct"),
                      (dict(devices="cpu"), "devices='cpu'; pass a list")]:
        with pytest.raises((ValueError, TypeError), match=match):
            split_vmap(_split_member, **kw)
    with pytest.raises(TypeError, match="fn must be a function"):
        split_vmap(3)
    from jaxsqueeze.batch import host_devices_flag
    with pytest.raises(ValueError, match="n must be an integer >= 1"):
        host_devices_flag(0)
    assert host_devices_flag(3) == "--xla_force_host_platform_device_count=3"
    here = os.path.dirname(os.path.abspath(__file__))
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    out = subprocess.run([sys.executable, "-c", SPLIT_CHILD.format(tests=here)], capture_output=True, text=True,
                         timeout=300, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    rows = [json.loads(ln) for ln in out.stdout.splitlines() if ln.startswith("{")]
    assert [r["size"] for r in rows] == [1, 5, 8] and all(r["devices"] == [0, 1] for r in rows)
    assert [r["shape"] for r in rows] == [[1, 3], [5, 3], [8, 3]]
