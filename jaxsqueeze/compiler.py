"""How the library's own top-level programs are compiled (issue 11, "Compilation").

On the CPU the squeeze is dozens of small operations per loop iteration; XLA:CPU's fusion
emitters spend compile time on them that buys no run time. Without them the XLA compile of
the foam-square squeeze takes 1.9 s instead of 3.4 s, and the program runs as fast and gives
the same numbers; LLVM's optimisation level 1 instead of 2 takes another ~0.2 s off, again
at the same run time and numbers (level 0 would save 1 s but runs 2.3x slower)
(``benchmarks/compile_options.py``; ``benchmarks/README.md``, "Compilation and host work").
Without XLA's tree-reduction rewriter (which splits every reduction over more than 32
elements into two operations) the squeeze runs ~6 % faster and compiles ~0.2 s faster
(the loop as one kernel: ~1 s), with the same numbers. With copy insertion's region analysis a
loop iteration copies 50 instead of 79 buffers between control-flow regions, ~5 % of the
squeeze's time (the event log is written by a gather, not a scatter, which that analysis
would split into one operation per node). Float32 programs leave it out
(:data:`NOT_FLOAT32`): there it let XLA:CPU run the loop body's operations on two threads,
whose hops made the squeeze ~1.6x slower.
JAX accepts compiler options only on a
top-level ``jax.jit`` (not inside a user's ``jit``), and an option this jaxlib does not know is
an error, so :func:`jit` gives a function that

* called where no program is being staged — eagerly, or with the tracers of an eager
  ``jax.vmap``, ``jax.jvp`` or ``jax.jacfwd``, whose transformed program JAX compiles at the
  top level with the options of the jit it transforms — compiles with :func:`options`: the
  options of :data:`CPU_OPTIONS` this jaxlib accepts, probed once (the derivative of a placed
  foam-square squeeze by ``jax.jacfwd`` compiled in 18 instead of 26 s, benchmarks/README.md);
* called while a user's ``jit`` (or a ``lax`` loop body) is traced, is the plain ``jax.jit``
  of the same function.

**One kernel** (:func:`one_kernel`). XLA:CPU runs a program as a sequence of kernels and
pays a dispatch for each, a few tenths of a microsecond; a squeeze loop iteration runs ~300
of them for a few microseconds of arithmetic. A ``call`` that carries the frontend attribute
``xla_cpu_small_call`` (and ``inlineable="false"``, so that it survives XLA's call inliner)
is compiled through XLA:CPU's whole-computation emitter into a single kernel, loops and
conditionals included: the foam-square squeeze runs ~40 % faster, and its program takes
~2.4 s longer to compile (``benchmarks/README.md``). That emitter cannot contain custom
calls (LAPACK: :func:`in_kernel` lets :mod:`jaxsqueeze.mechanics.linalg` pick plain JAX
operations there), XNNPACK/YNNPACK custom fusions (the top-level options turn those off,
:func:`can_fuse`), nor a parameter that the optimised program leaves unused (XLA aborts the
process), which is why its read-only inputs reach the kernel packed into one vector, behind
an optimization barrier (XLA would sink constant inputs into the kernel), and why derivatives
are taken of the region as ordinary operations (the jvp of a kernel call can leave a tangent
unused). :func:`top_level_trace` tells code traced for a library-compiled program (where
the options hold) from code traced in a user's ``jit``.

**Full-precision products** (:func:`precise`). Every program the library traces computes
its matrix products at ``jax.lax.Precision.HIGHEST``: JAX's default lets an NVIDIA GPU since
Ampere round float32 operands to TF32 (10-bit mantissas, relative errors ~5e-4), and a
user's ``jax.default_matmul_precision`` would otherwise reach the library's products too.
On the CPU and in float64 nothing changes.

**Compiling ahead** (:meth:`TopLevelJit.compile_ahead`). XLA compiles a program on one core,
and a map or a search runs its squeezes on one core too: the planner starts the compile of
the program it needs next in a background thread before it runs the one it has (the CLI's
``plan`` of the foam square, cold: 20 → 15.5 s on 2 cores; ``benchmarks/README.md``).

Every choice here and in the batch rules follows :func:`platform`, the platform a computation
runs on, so that a squeeze pinned to the CPU on a GPU machine (``with
jax.default_device(jax.devices("cpu")[0])``) is compiled and batched as on a CPU.

Nothing global is changed (DESIGN 4): no ``XLA_FLAGS``, no JAX config.
"""
from __future__ import annotations

import contextlib
import functools
import threading

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .tracing import is_concrete, own_transfers

#: keep XNNPACK/YNNPACK custom fusions out of the program (a one-kernel region cannot hold
#: them; the other programs run as fast without them)
NO_CUSTOM_FUSIONS = {"xla_cpu_experimental_ynn_fusion_type": "", "xla_cpu_experimental_xnn_fusion_type": ""}
#: options for the library's top-level programs on the CPU (applied only where accepted)
#: (XLA's tree-reduction rewriter splits every reduction over more than 32 elements into a
#: reduce-window and a reduce: 22 more operations per squeeze-loop iteration for sums over the
#: m ≈ 100 boundary nodes, which need no pairwise summation for accuracy; copy insertion's
#: region analysis proves more loop-carried buffers free of copies)
CPU_OPTIONS = {"xla_cpu_use_fusion_emitters": False, "xla_backend_optimization_level": 1,
               "xla_disable_hlo_passes": "tree_reduction_rewriter",
               "xla_cpu_copy_insertion_use_region_analysis": True, **NO_CUSTOM_FUSIONS}
#: options left out of float32 programs (x64 off): with fewer copies, the float32 squeeze
#: loop's body holds operations that XLA:CPU's thunk executor finds independent, so it runs
#: them on both threads of its pool, and every hop between threads costs microseconds (the
#: foam square's squeeze 13.5-14.5 against 8.2-9.0 ms without region analysis; float64 stays
#: on one thread with it and gains 5 %; benchmarks/README.md, 2026-12-05)
NOT_FLOAT32 = ("xla_cpu_copy_insertion_use_region_analysis",)


def platform() -> str:
    """The platform ("cpu", "gpu", "tpu") that a computation started now runs on: that of the
    device ``jax.default_device`` names, if a context or the config sets one, else JAX's
    default backend. (On a GPU machine ``jax.default_backend()`` stays "gpu" inside
    ``jax.default_device(cpu)``.)"""
    d = jax.config.jax_default_device
    if d is None:
        return jax.default_backend()
    return jax.devices(d)[0].platform if isinstance(d, str) else d.platform


def options() -> tuple:
    """The (name, value) pairs of :data:`CPU_OPTIONS` that this jaxlib accepts on the
    :func:`platform` a program is compiled for, probed by compiling a one-op program with all
    of them (and with each alone when that fails), less :data:`NOT_FLOAT32` where x64 is off
    (the precision of the library's programs); ``()`` off the CPU."""
    opts = _options(platform())
    if jax.dtypes.canonicalize_dtype(np.float64) != np.float64:        # x64 off: float32 programs
        opts = tuple(item for item in opts if item[0] not in NOT_FLOAT32)
    return opts


@functools.lru_cache(maxsize=None)
def _options(plat: str) -> tuple:
    if plat != "cpu":
        return ()
    items = tuple(sorted(CPU_OPTIONS.items()))
    if _accepted(dict(items)):      # one probe when all are known (the usual case)
        return items
    return tuple(item for item in items if _accepted(dict([item])))


options.cache_clear = _options.cache_clear      # (tests probe again with other CPU_OPTIONS)


def _accepted(opts: dict) -> bool:
    try:
        jax.jit(lambda x: x + 1, compiler_options=opts).lower(jnp.zeros(())).compile()
    except Exception:   # noqa: BLE001  (a jaxlib without this option: compile without it)
        return False
    return True


#: the precision of every matrix product in the library's programs (see :func:`precise`)
MATMUL_PRECISION = "highest"


def precise(fun):
    """``fun`` traced with its matrix products (``@``, ``jnp.dot``, ``einsum``, and those of
    JAX's own rules, derivatives included) at :data:`MATMUL_PRECISION`, whatever the
    caller's ``jax.default_matmul_precision`` and the device's default (TF32 for float32 on
    recent NVIDIA GPUs). Put it under a ``jax.jit``: the products are fixed when traced.

    It also names the abstract mesh in force (the empty one, unless the caller set one):
    JAX keys its cache of traced ``jit`` functions on the context, and evaluates the
    equations of a traced program (its derivative and batching rules) with the mesh named,
    where a first trace had none. Under the same name, the squeeze's derivative and batching
    rules reuse the squeeze's trace instead of tracing it again (the search's value and
    gradient on the foam square: 3.3–3.7 → 2.3 s before XLA)."""
    @functools.wraps(fun)
    def traced(*args, **kwargs):
        with jax.default_matmul_precision(MATMUL_PRECISION), \
                jax.sharding.use_abstract_mesh(jax.sharding.get_abstract_mesh()):
            return fun(*args, **kwargs)
    return traced


@own_transfers                     # (the probe's constant, under a caller's jax.transfer_guard)
def _top_level() -> bool:
    """No program is being staged around the call (inside ``jit`` even a new constant is a
    tracer; under an eager ``vmap`` or ``jvp`` it is not)."""
    return is_concrete(jnp.zeros(()))


class TopLevelJit:
    """``jax.jit(fun, **jit_kwargs)`` of :func:`precise` ``fun``, compiled with :func:`options`
    when called at the top level."""

    def __init__(self, fun, **jit_kwargs):
        fun = precise(fun)
        self.plain = jax.jit(fun, **jit_kwargs)
        self._fun, self._kwargs, self._tuned = fun, jit_kwargs, {}
        functools.update_wrapper(self, fun)

    def _top(self):
        """The jitted function with the options of the platform it runs on (one per platform:
        CPU options would be an error for another compiler)."""
        opts = options()
        if opts not in self._tuned:
            self._tuned[opts] = jax.jit(self._fun, compiler_options=dict(opts), **self._kwargs) if opts else self.plain
        return self._tuned[opts]

    def __call__(self, *args, **kwargs):
        if not _top_level():
            return self.plain(*args, **kwargs)
        if _AHEAD:                 # a compile started ahead (most likely of this program): wait for it
            wait_ahead(self)
        with _depth(_TOP):
            return self._top()(*args, **kwargs)

    def lower(self, *args, **kwargs):
        """Lower for a top-level compile (what an eager call compiles)."""
        with _depth(_TOP):
            return self._top().lower(*args, **kwargs)

    def compile_ahead(self, *args, **kwargs) -> None:
        """Start the top-level compile of these arguments (what an eager call with them would
        compile) in a background thread, and return: the caller's next work, a loop of small
        programs that keeps one core busy, runs meanwhile. The next top-level call of this
        function waits for it first (instead of compiling the same program a second time), as
        does :func:`wait_ahead`. A failure is left to that call to raise; a thread whose JAX
        context differs from the caller's (``jax.default_device``,
        ``jax.default_matmul_precision`` ...), whose program that call would not find,
        compiles nothing. The thread is not a
        daemon: a process that ends meanwhile waits for it (XLA cannot be stopped midway)."""
        t = threading.Thread(target=self._compile_quietly, args=(_context(), args, kwargs),
                             name=f"compile {getattr(self, '__name__', 'program')}")
        with _AHEAD_LOCK:
            _AHEAD.append((self, t))
        t.start()

    @own_transfers                 # (the library's own work, under a global jax_transfer_guard)
    def _compile_quietly(self, context, args, kwargs) -> None:
        if _context() != context:
            return
        try:
            self.lower(*args, **kwargs).compile()
        except Exception:   # noqa: BLE001  (the call raises it, with its own message)
            pass

    def _cache_size(self) -> int:
        """Compiled programs held, both variants (tests check that a call did not recompile)."""
        return self.plain._cache_size() + sum(f._cache_size() for f in self._tuned.values() if f is not self.plain)


#: (function, thread) of the compiles started ahead and not yet waited for
_AHEAD: list = []
_AHEAD_LOCK = threading.Lock()


def wait_ahead(fun: TopLevelJit | None = None) -> None:
    """Wait for the compiles started ahead (:meth:`TopLevelJit.compile_ahead`) of ``fun``, or
    of every function."""
    with _AHEAD_LOCK:
        mine = [item for item in _AHEAD if fun is None or item[0] is fun]
        for item in mine:
            _AHEAD.remove(item)
    for _, t in mine:
        t.join()


def _context():
    """JAX's thread-local context, the part of a traced program's cache key that a new thread
    does not inherit (None where this JAX does not say)."""
    try:
        from jax._src.config import trace_context
    except ImportError:
        return None
    return trace_context()


def can_fuse() -> bool:
    """True where a top-level program may hold :func:`one_kernel` regions: on the CPU, with a
    jaxlib that accepted the options keeping custom fusions out (:data:`NO_CUSTOM_FUSIONS`).
    Only programs compiled by :func:`jit` at the top level get those options."""
    return platform() == "cpu" and set(NO_CUSTOM_FUSIONS.items()) <= set(options())


_KERNEL, _TOP = threading.local(), threading.local()


@contextlib.contextmanager
def _depth(flag):
    flag.depth = getattr(flag, "depth", 0) + 1
    try:
        yield
    finally:
        flag.depth -= 1


def in_kernel() -> bool:
    """True while :func:`one_kernel` traces its region (code there must not emit custom calls)."""
    return getattr(_KERNEL, "depth", 0) > 0


def top_level_trace() -> bool:
    """True while a :func:`jit` function is traced for a top-level compile, i.e. with
    :func:`options` (an eager squeeze, the planner's programs, :func:`~jaxsqueeze.batch.split_vmap`,
    the core of an eager ``jax.vmap``/``jax.jacfwd`` of a squeeze): where :func:`one_kernel`
    regions may go when :func:`can_fuse` (a squeeze decides before its core is traced,
    :func:`jaxsqueeze.simulation.api.config_of`)."""
    return getattr(_TOP, "depth", 0) > 0


#: constants of :func:`one_kernel` with more elements than this are passed on unpacked
PACK_LIMIT = 4096


def _pack(leaves) -> jax.Array:
    """The leaves raveled into one vector of their float type, by value (differentiable; an
    integer is exact below 2**24 in float32 and 2**53 in float64)."""
    floats = [x.dtype for x in leaves if jnp.issubdtype(x.dtype, jnp.floating)]
    dtype = jnp.result_type(*floats) if floats else jnp.zeros(()).dtype
    return jnp.concatenate([x.astype(dtype).reshape(-1) for x in leaves] + [jnp.zeros(1, dtype)])


def _unpack(v, like) -> jax.Array:
    v = v.reshape(like.shape)
    return v != 0 if like.dtype == jnp.bool_ else v.astype(like.dtype)


def one_kernel(fn, consts, state):
    """``fn(consts, state)``, a new state of the same structure and types, compiled by XLA:CPU
    as one kernel (see the module docstring): for a region whose operations are many and
    small, such as a ``lax.while_loop`` of small solves.

    ``consts`` reach the kernel packed by value into one vector of their float type (a
    parameter the optimised program leaves unused would abort XLA; integer constants must be
    exact in it: below 2**24 in float32, 2**53 in float64), except those of more than
    :data:`PACK_LIMIT` elements, which ``fn`` must read (copying the foam square's 476 kB
    boundary compliance into the vector cost 0.3 ms of a 5 ms squeeze); the state leaves go as
    they are (each is an output, so each is used). Every input must be an argument: a
    closed-over array would be a parameter of its own. Weakly typed constants arrive strongly
    typed (same dtype: the library's models hold one precision, so promotion inside ``fn``
    does not change). Forward-mode derivatives pass through constants and state alike; they
    are computed by the region as ordinary operations, not in the kernel.
    ``fn`` is traced with :func:`in_kernel` set. Off the CPU this is ``fn(consts, state)``.
    The caller's program must be compiled with :data:`NO_CUSTOM_FUSIONS` (:func:`can_fuse`):
    inside a user's ``jit`` XLA may form a custom fusion in the region, which then fails to
    compile (``UNIMPLEMENTED: Fusion kind not implemented on CPU``).
    """
    if platform() != "cpu":
        return fn(consts, state)
    leaves, tree = jax.tree.flatten(consts)
    leaves = [jnp.asarray(x) for x in leaves]
    packed = _pack([x for x in leaves if x.size <= PACK_LIMIT])
    large = [x for x in leaves if x.size > PACK_LIMIT]

    likes = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in leaves]

    def region(buf, large, state):
        parts, at, big = [], 0, iter(large)
        for x in likes:
            if x.size > PACK_LIMIT:
                parts.append(next(big))
                continue
            parts.append(_unpack(lax.slice_in_dim(buf, at, at + x.size), x))
            at += x.size
        new = fn(jax.tree.unflatten(tree, parts), state)
        if jax.tree.structure(new) != jax.tree.structure(state) or any(
                (a.shape, a.dtype) != (b.shape, b.dtype) for a, b in zip(jax.tree.leaves(new), jax.tree.leaves(state))):
            raise TypeError("one_kernel: fn must return a state of the structure, shapes and dtypes it was given")
        return new

    @jax.custom_jvp
    def kernel(buf, large, state):
        from jax.experimental.xla_metadata import set_xla_metadata
        with _depth(_KERNEL):
            out = jax.jit(region)(buf, large, state)
        return set_xla_metadata(out, inlineable="false", xla_cpu_small_call="true")

    @kernel.defjvp
    def _(primals, tangents):     # derivatives: the region as ordinary operations (the jvp of a
        with _depth(_KERNEL):     # kernel call can leave a tangent parameter unused)
            return jax.jvp(region, primals, tangents)

    # the barrier hides which inputs are constants: XLA would sink them into the kernel and
    # leave its parameters unused (under vmap, a squeeze's whole initial state can be constant)
    return kernel(*lax.optimization_barrier((packed, large, state)))


def jit(fun=None, **jit_kwargs):
    """:class:`TopLevelJit` of ``fun``; usable as ``@jit`` or ``@jit(static_argnames=...)``."""
    if fun is None:
        return functools.partial(jit, **jit_kwargs)
    return TopLevelJit(fun, **jit_kwargs)


__all__ = ["CPU_OPTIONS", "MATMUL_PRECISION", "NO_CUSTOM_FUSIONS", "PACK_LIMIT", "TopLevelJit", "can_fuse", "in_kernel",
           "jit", "one_kernel", "options", "precise", "top_level_trace", "wait_ahead"]
