"""Many squeezes on a multi-core CPU: one single-threaded worker process per core (DESIGN 2.10).

On a CPU a ``jax.vmap`` over grasps does not use more cores (the loop's small solves run one
system at a time), and a squeeze is a chain of small XLA operations that a shared thread pool
only slows down. :func:`map_scenes` runs a plain function of one item in a pool of worker
processes instead, each with XLA single-threaded, so ``processes`` workers keep that many
cores busy::

    from jaxsqueeze.batch import map_scenes

    def evaluate(grip):                       # module level: workers import it by name
        res = jsq.squeeze(SCENE.replace(grip=grip))
        return int(res.outcome), float(res.grip_force)

    out = map_scenes(evaluate, grips)         # results in the order of ``grips``

Workers are started with the ``spawn`` method (JAX is not fork-safe), so ``fn`` and the items
must be picklable and the calling script must guard its entry point with
``if __name__ == "__main__":``. Each worker turns on the persistent compilation cache
(:mod:`jaxsqueeze.compile_cache`), so only the first worker to reach a program compiles it;
the others, and the next run, load it from disk. Each worker pays its imports and its first
compile or cache load once (seconds): a pool pays off for batches that take longer than that.
Return small results (numbers, small numpy arrays), not whole :class:`SqueezeResult` objects
with their padded history, to keep the transfer back cheap.

Inside one process, :func:`split_vmap` splits a ``vmap`` batch over the process's devices
(one chunk per device, the chunks run at once): on a CPU start the process with
``XLA_FLAGS=--xla_force_host_platform_device_count=<cores>`` (:func:`host_devices_flag`; it
must be set before JAX starts) and every core runs its share of the batch, without a pool's
start-up.
"""
from __future__ import annotations

import math
import numbers
import os
import pickle
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import contextmanager
from typing import Any, Callable, Iterable

from .numbers import flag

#: environment of a worker process: XLA and BLAS on one thread each
WORKER_ENV = {
    "XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1",
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}


def cpu_count() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:      # not on Linux
        return os.cpu_count() or 1


def host_devices_flag(n: int | None = None) -> str:
    """The ``XLA_FLAGS`` entry that gives a CPU process ``n`` devices (default: one per core),
    for :func:`split_vmap`. Set it in the environment before JAX is imported, e.g.
    ``os.environ["XLA_FLAGS"] = host_devices_flag()`` at the top of a script."""
    if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
        raise ValueError(f"host_devices_flag(n={n!r}): n must be an integer >= 1 (or None: one per core)")
    return f"--xla_force_host_platform_device_count={n or cpu_count()}"


def split_vmap(fn: Callable, in_axes=0, devices=None) -> Callable:
    """``jax.vmap(fn, in_axes)`` with the batch split evenly over ``devices`` (default: all
    local devices), each device vmapping its own chunk at the same time (``jax.shard_map``
    over a one-axis mesh). ``in_axes``: 0 or None per positional argument (None: shared by
    every member, e.g. the compliance operator). The batch is padded to a multiple of the
    device count with copies of its last member, and the padding is dropped from the result.

    With one device it is ``jax.jit(jax.vmap(fn))``. The returned function is jitted once
    (:func:`jaxsqueeze.compiler.jit`: a top-level call compiles with the CPU options);
    keep it and call it again to reuse the compiled program. Results equal ``jax.vmap``'s
    (each member is the same computation on its own device).
    """
    import jax
    import jax.numpy as jnp
    import numpy as np
    from jax.sharding import Mesh, PartitionSpec

    from .compiler import jit

    if not callable(fn):
        raise TypeError(f"split_vmap: fn must be a function of the batch members, got {fn!r}")
    if isinstance(devices, (str, bytes)):
        raise TypeError(f"split_vmap: devices={devices!r}; pass a list of jax devices (e.g. jax.devices('cpu'))")
    devs = list(devices) if devices is not None else jax.local_devices()
    if not devs or not all(isinstance(d, jax.Device) for d in devs) or len(set(devs)) != len(devs):
        raise ValueError(f"split_vmap: devices must be a non-empty list of distinct jax devices, got {devs!r}")
    for a in jax.tree.leaves(in_axes):
        if a not in (0, None):
            raise ValueError(f"split_vmap: in_axes must be 0 or None per argument, got {in_axes!r}")
    n = len(devs)
    inner = jax.vmap(fn, in_axes=in_axes)
    if n == 1:
        return jit(inner)

    @jit
    def call(*args):
        axes = in_axes if isinstance(in_axes, (tuple, list)) else (in_axes,) * len(args)
        if len(axes) != len(args):
            raise ValueError(f"split_vmap: in_axes={in_axes!r} has {len(axes)} entries for {len(args)} arguments")
        if any(a == 0 and jnp.ndim(x) == 0 for a, arg in zip(axes, args) for x in jax.tree.leaves(arg)):
            raise ValueError("split_vmap: a batched argument (in_axes 0) has a scalar leaf; batch members are "
                             "stacked along a leading axis (shape (B, ...))")
        sizes = {x.shape[0] for a, arg in zip(axes, args) if a == 0 for x in jax.tree.leaves(arg)}
        if len(sizes) != 1:
            raise ValueError(f"split_vmap: the batched arguments need one common leading size, got {sorted(sizes)}")
        size = sizes.pop()
        pad = -size % n

        def padded(x):
            return jnp.concatenate([x, jnp.repeat(x[-1:], pad, axis=0)]) if pad else x

        args = [jax.tree.map(padded, arg) if a == 0 else arg for a, arg in zip(axes, args)]
        spec = PartitionSpec("batch")
        mapped = jax.shard_map(inner, mesh=Mesh(np.array(devs), ("batch",)),
                               in_specs=tuple(spec if a == 0 else PartitionSpec() for a in axes),
                               out_specs=spec, check_vma=False)
        return jax.tree.map(lambda y: y[:size], mapped(*args))

    return call


def map_scenes(fn: Callable[[Any], Any], items: Iterable, processes: int | None = None,
               chunk: int | None = None, progress: bool = True, cache: bool | str = True) -> list:
    """``[fn(item) for item in items]``, spread over worker processes.

    Args:
        fn: a module-level function of one item (picklable by name) returning a small,
            picklable result (numbers, numpy arrays, a small pytree of them).
        items: the inputs; each must pickle.
        processes: number of workers; ``None``: one per available core. ``1`` runs inline in
            this process (no pool, no change to this process's configuration).
        chunk: items per task sent to a worker; ``None``: about four tasks per worker.
        progress: a one-line progress bar on stderr when stderr is a terminal or a Jupyter
            notebook's (:func:`interactive`).
        cache: the workers' persistent compilation cache: ``True`` for the default folder
            (:func:`jaxsqueeze.compile_cache.default_path`), a folder, or ``False`` for none.
    Returns:
        the results in the order of ``items``. An exception in ``fn`` is raised here, with
        the index of the item that caused it.

    The workers use this process's floating-point precision (``jax_enable_x64``) if JAX is
    imported here, else JAX's default.
    """
    items = list(items)
    n = len(items)
    for name, v in (("processes", processes), ("chunk", chunk)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < 1):
            raise ValueError(f"{name} must be an integer >= 1 (or None), got {v!r}")
    progress = flag(progress, "progress")
    processes = cpu_count() if processes is None else int(processes)
    if processes > 1 and n > 1:          # a worker receives fn by name: say so before any worker starts
        try:
            pickle.dumps(fn)
        except Exception as e:  # noqa: BLE001  (lambdas, closures, local functions: PicklingError, AttributeError)
            raise TypeError(f"map_scenes sends fn to worker processes by name, and {fn!r} cannot be sent ({e}): "
                            "define it at the top level of a module (not a lambda or a nested function), or "
                            "use processes=1") from None
    bar = _Progress(n, progress and interactive())
    if processes == 1 or n <= 1:
        out = []
        for i, item in enumerate(items):
            out.append(_call(fn, i, item))
            bar.update(1)
        bar.close()
        return out

    processes = min(processes, n)
    chunk = max(1, math.ceil(n / (4 * processes))) if chunk is None else int(chunk)
    tasks = [(k, items[k:k + chunk]) for k in range(0, n, chunk)]
    env = dict(WORKER_ENV)
    if "jax" in sys.modules:                # the workers read the caller's precision at their jax import
        env["JAX_ENABLE_X64"] = "1" if sys.modules["jax"].config.jax_enable_x64 else "0"
    cache_path = None
    if cache:
        from . import compile_cache
        cache_path = compile_cache.default_path() if cache is True else os.fspath(cache)

    import multiprocessing as mp
    out: list = [None] * n
    with _environment(env):                 # spawned workers inherit it before they import jax
        pool = ProcessPoolExecutor(processes, mp_context=mp.get_context("spawn"), initializer=_init_worker,
                                   initargs=(cache_path,))
        try:
            pending = {pool.submit(_run_chunk, fn, k, part): (k, len(part)) for k, part in tasks}
        except BaseException:
            pool.shutdown(wait=False, cancel_futures=True)
            raise
    try:
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                k, size = pending.pop(fut)
                out[k:k + size] = fut.result()
                bar.update(size)
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    else:
        pool.shutdown()
    finally:
        bar.close()
    return out


class ItemError(RuntimeError):
    """``fn`` failed on one item (the original exception is the ``__cause__``)."""


def _call(fn, i, item):
    try:
        return fn(item)
    except Exception as exc:
        raise ItemError(f"{getattr(fn, '__name__', fn)} failed on item {i}: {type(exc).__name__}: {exc}") from exc


def _run_chunk(fn, start, part):
    return [_call(fn, start + j, item) for j, item in enumerate(part)]


def _init_worker(cache_path):
    if cache_path:
        from . import compile_cache
        compile_cache.enable(cache_path)


@contextmanager
def _environment(env: dict):
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def interactive(stream=None) -> bool:
    """Whether progress belongs on ``stream`` (default ``sys.stderr``): a terminal, or the
    output stream of a Jupyter kernel (a notebook redraws a line on ``\\r`` as a terminal
    does); not a file, a pipe or a test's capture."""
    stream = sys.stderr if stream is None else stream
    try:
        if stream.isatty():
            return True
    except (AttributeError, ValueError):         # no isatty, or a closed stream
        return False
    return type(stream).__module__.startswith("ipykernel.")


class _Progress:
    """``[#####.....] 12/100  3.1 s  eta 10 s`` on one stderr line, redrawn at most 10× a second."""

    def __init__(self, total, on):
        self.total, self.on, self.done, self.t0, self.last = total, on and total > 0, 0, time.perf_counter(), 0.0

    def update(self, k):
        self.done += k
        now = time.perf_counter()
        if self.on and (now - self.last > 0.1 or self.done == self.total):
            self.last = now
            el = now - self.t0
            w = 30
            fill = int(w * self.done / self.total)
            eta = el / self.done * (self.total - self.done) if self.done else float("nan")
            sys.stderr.write(f"\r[{'#' * fill}{'.' * (w - fill)}] {self.done}/{self.total}  {el:.1f} s  eta {eta:.0f} s ")
            sys.stderr.flush()

    def close(self):
        if self.on:
            sys.stderr.write("\n")
            sys.stderr.flush()
            self.on = False


__all__ = ["ItemError", "WORKER_ENV", "cpu_count", "host_devices_flag", "interactive", "map_scenes", "split_vmap"]
