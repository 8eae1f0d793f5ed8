"""The opt-in persistent compilation cache (jaxsqueeze.compile_cache): a second process loads
the squeeze program from disk instead of compiling it (DESIGN 2.10)."""
import json
import os
import subprocess
import sys

import pytest


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# A tiny full-stick squeeze (its program is the smallest one) in a fresh process; reports the
# persistent-cache events JAX records (jax.monitoring) while compiling it.
CHILD = r"""
import json, sys
import jax
jax.config.update("jax_enable_x64", True)
from jax import monitoring
events = {}
monitoring.register_event_listener(lambda name, **kw: events.__setitem__(name, events.get(name, 0) + 1))
import jaxsqueeze as jsq
from jaxsqueeze import compile_cache
path = compile_cache.enable(sys.argv[1])
assert compile_cache.enable(sys.argv[1]) == path          # idempotent
mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=0.025)
sc = jsq.Scene(mesh=mesh, material=jsq.Material(1e5, 0.3, 0.0254), fingers=jsq.Fingers(radius=0.015),
               grip=(jsq.scene.nearest_boundary_node(mesh, (0, -0.05)), jsq.scene.nearest_boundary_node(mesh, (0, 0.05))),
               friction=0.5, depth=0.005, friction_model="stick")
res = jsq.squeeze(sc)
print(json.dumps(dict(path=path, x64=bool(jax.config.jax_enable_x64), status=res.outcome.name,
                      hits=events.get("/jax/compilation_cache/cache_hits", 0),
                      misses=events.get("/jax/compilation_cache/cache_misses", 0))))
"""


def _fresh_env():
    """This environment for a fresh process, without the test run's shared compilation cache
    (conftest.py): the child starts with no cache, as a user's process does."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("JAX_COMPILATION_CACHE_DIR", "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS",
                        "JAX_COMPILATION_CACHE_MAX_SIZE")}
    return dict(env, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""), JAX_PLATFORMS="cpu")


def _child(cache):
    env = _fresh_env()
    out = subprocess.run([sys.executable, "-c", CHILD, str(cache)], capture_output=True, text=True, env=env,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_second_process_loads_the_squeeze_from_the_cache(tmp_path):
    cache = tmp_path / "jaxcache"
    first = _child(cache)
    assert first["path"] == str(cache) and first["status"] == "SUCCESS"
    assert first["x64"], "enable() must not touch other JAX options"
    assert first["misses"] >= 1
    assert any(cache.iterdir()), "nothing was written to the cache folder"
    second = _child(cache)
    assert second["status"] == "SUCCESS"
    # the squeeze program came from disk. (The first process may hit too: under load a small
    # program can take longer than the threshold, be written, and be compiled again later.)
    assert second["hits"] > first["hits"], (first, second)
    assert second["misses"] < first["misses"], (first, second)


IDEMPOTENCE = r"""
import json, os, sys
import jax
from jaxsqueeze import compile_cache
x64 = jax.config.jax_enable_x64
p = compile_cache.enable(sys.argv[1])
again = compile_cache.enable(sys.argv[1])
print(json.dumps(dict(p=p, again=again, enabled=compile_cache.enabled(), isdir=os.path.isdir(p),
                      x64_kept=jax.config.jax_enable_x64 == x64,
                      min_time=jax.config.jax_persistent_cache_min_compile_time_secs,
                      min_size=jax.config.jax_persistent_cache_min_entry_size_bytes)))
"""


def test_default_path_and_idempotence(tmp_path, monkeypatch):
    from jaxsqueeze import compile_cache
    monkeypatch.setenv(compile_cache.ENV, str(tmp_path / "c"))
    assert compile_cache.default_path() == str(tmp_path / "c")
    monkeypatch.delenv(compile_cache.ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert compile_cache.default_path() == str(tmp_path / "xdg" / "jaxsqueeze" / "jax")
    # enabling: only the cache options change, and a second call is a no-op. In a child process:
    # once JAX has used a persistent cache in a process, moving or turning it off again is not
    # reliable (JAX keeps the cache "used" with no folder, and XLA aborted writing a later
    # program: the suite's CI crash), so this test process keeps the run's cache (conftest.py).
    before = compile_cache.enabled()
    env = _fresh_env()
    out = subprocess.run([sys.executable, "-c", IDEMPOTENCE, str(tmp_path / "here")], capture_output=True,
                         text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert r["p"] == r["again"] == r["enabled"] == str(tmp_path / "here") and r["isdir"]
    assert r["x64_kept"]
    assert r["min_time"] == compile_cache.MIN_COMPILE_TIME_S and r["min_size"] == -1
    assert compile_cache.enabled() == before          # this process is untouched


@pytest.mark.parametrize("args,kw,error,match", [
    ((3,), {}, TypeError, "path=3 must be a folder name"),
    (("",), {}, TypeError, "path='' must be a folder name"),
    (("FILE",), {}, ValueError, "cannot use .* as the cache folder \\(File exists\\)"),
    (("DIR",), dict(min_compile_time_s=-1), ValueError, "min_compile_time_s=-1 must be a finite number"),
    (("DIR",), dict(min_compile_time_s=float("nan")), ValueError, "min_compile_time_s=nan"),
    (("DIR",), dict(min_compile_time_s="1"), ValueError, "min_compile_time_s='1'"),
])
def test_enable_refuses_what_is_not_a_folder_or_a_time(tmp_path, args, kw, error, match):
    """A file where the folder belongs, an int, '' (it used the working directory) or a negative,
    NaN or string minimum time: an error naming the argument, before any JAX option changes
    (so this test process keeps the run's cache, conftest.py)."""
    from jaxsqueeze import compile_cache
    before = compile_cache.enabled()
    (tmp_path / "FILE").write_text("")
    args = tuple(str(tmp_path / a) if a in ("FILE", "DIR") else a for a in args)
    with pytest.raises(error, match=match):
        compile_cache.enable(*args, **kw)
    assert compile_cache.enabled() == before


def test_the_test_run_shares_one_cache_folder():
    """README, Development: the run's processes share one persistent compilation cache, a
    folder made for the run: this process uses the folder its environment passes on to the
    processes it starts; with a size bound, so that JAX locks the folder around every read and
    write (no worker reads an entry another is still writing)."""
    import jax
    from jaxsqueeze import compile_cache
    path = os.environ["JAX_COMPILATION_CACHE_DIR"]
    assert compile_cache.enabled() == jax.config.jax_compilation_cache_dir == path and os.path.isdir(path)
    if os.path.basename(path).startswith("jaxsqueeze-test-cache-"):      # made by conftest.py (not the user's own)
        pytest.importorskip("filelock")
        assert jax.config.jax_compilation_cache_max_size == 8 << 30
