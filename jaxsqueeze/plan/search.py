"""Grasp maps and gradient-based placement search (DESIGN 2.9).

A *candidate* is a placement x = (s_0, s_1, angle): the two fingers' arc lengths [m] along the
outer boundary and the squeeze-direction offset [rad] (:class:`~jaxsqueeze.Placement`). A
batch of candidates is evaluated in one compiled ``vmap`` that keeps only a few scalars per
candidate (:class:`Summary`), never the squeeze history. The search climbs a quality with
forward-mode gradients (``jax.jacfwd``) and an optax optimizer, from the best cells of a
coarse map.
"""
from __future__ import annotations

import contextlib
import dataclasses
import math
import sys
import time
import warnings
from functools import partial
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .. import compiler
from ..batch import interactive
from ..geometry.mesh import Mesh
from ..numbers import flag, kind, real_array
from ..simulation import validate
from ..simulation.api import squeeze
from ..simulation.scene import Placement, Scene
from ..simulation.status import Status
from ..tracing import caller_level, numeric, own_transfers
from .quality import adversary_work, grip_force, slip_margin, squeeze_work


class Summary(NamedTuple):
    """What a map keeps of each candidate (arrays, batched like the candidates)."""

    status: jax.Array      # Status value
    quality: jax.Array     # the quality (NaN-free: 0 where the squeeze failed)
    grip_force: jax.Array  # [N] at the last squeeze row
    depth: jax.Array       # [m] depth reached
    margin: jax.Array      # [rad] feasibility margin of the first contacts


QUALITIES = ("squeeze_work", "grip_force", "slip_margin", "adversary_work")
CHUNK = 64            # candidates per chunk by default: a CPU's vmap chunk or a worker's share
ACCELERATOR_CHUNK = 1024   # per vmap chunk on an accelerator: on an H200 a vmap of foam-square squeezes
#                            took 1.0 ms per member at 256, 0.55 at 1,024, 0.41 at 4,096 (benchmarks)


class SceneSlipMargin(NamedTuple):
    """The quality "slip_margin" of a scene: :func:`~jaxsqueeze.plan.quality.slip_margin` with
    the scene's μ, object and contact and friction models (what it reads of a scene). A value,
    not a closure: maps and searches take their quality as a static argument of their compiled
    programs, so equal scenes share them (a closure made anew for every call compiled every
    map and search again, ~5 s each)."""

    friction: float | None     # None as the programs' static key: they take the scene's μ
    mesh: object
    contact: str
    friction_model: str

    def __call__(self, res):
        return slip_margin(res, self.friction, scene=self)


def _keyed(qfn):
    """``qfn`` as a static argument of the map and search programs: a :class:`SceneSlipMargin`
    without its μ, which :func:`_summary` takes from the (traced) scene, so that a map at a new
    μ compiles nothing (a μ sweep of slip-margin maps compiled every map again, ~4 s each)."""
    return qfn._replace(friction=None) if isinstance(qfn, SceneSlipMargin) else qfn


def quality_of(scene: Scene, quality) -> Callable:
    """A function result → () for a quality given by name (``QUALITIES``) or as a callable."""
    if callable(quality):
        if quality is slip_margin:          # (it failed inside: "missing 1 required positional argument")
            raise ValueError("quality=jsq.quality.slip_margin needs μ and the scene besides a result: pass "
                             "quality=\"slip_margin\" (both from the scene), or "
                             "lambda res: jsq.quality.slip_margin(res, mu, scene=scene)")
        return quality
    if quality == "slip_margin":
        return SceneSlipMargin(float(np.asarray(scene.friction)), scene.mesh, scene.contact, scene.friction_model)
    if quality in QUALITIES:
        if quality == "adversary_work" and scene.adversary is None:
            raise ValueError("quality 'adversary_work' needs an Adversary on the scene "
                             "(scene.replace(adversary=jsq.Adversary(s=..., push=...)); in a scene file for "
                             "`jaxsqueeze plan`: [plan] push = ... [m])")
        return {"squeeze_work": squeeze_work, "grip_force": grip_force, "adversary_work": adversary_work}[quality]
    raise ValueError(f"quality={quality!r}; choose one of {QUALITIES} or pass a function of a result.")


def _check_count(name, v, least) -> None:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < least:
        raise ValueError(f"{name}={v!r} must be an integer >= {least}.")


def _check_angle(angle) -> float:
    """The squeeze-direction offset as a float, or ValueError (a finite number [rad])."""
    ok = not isinstance(angle, (str, bytes, bool)) and kind(angle) != "O" and np.ndim(angle) == 0
    try:
        ok = ok and bool(np.isfinite(float(angle)))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"angle={angle!r} must be a finite number [rad] (the squeeze-direction offset).")
    return float(angle)


def _check_quality(summ: Summary, X) -> None:
    """ValueError when a successful squeeze got a non-finite quality (the quality function's fault)."""
    bad = np.flatnonzero((summ.status == Status.SUCCESS) & ~np.isfinite(summ.quality))
    if len(bad):
        raise ValueError(f"the quality is {summ.quality[bad[0]]} at {len(bad)} successful squeeze(s), e.g. the "
                         f"candidate (s_0, s_1, angle) = {np.asarray(X)[bad[0]].tolist()}: a quality must be finite "
                         "wherever the squeeze succeeds (check the quality function for 0/0, log(0), inf)")


def candidates(X, name: str = "X") -> np.ndarray:
    """``X`` as finite (k, 3) candidates (s_0 [m], s_1 [m], angle [rad]): from a (k, 3) or
    (k, 2) array (angle 0), one such row, a :class:`~jaxsqueeze.Placement` or a list of
    them. ValueError for any other shape, a non-number or a non-finite entry."""
    if isinstance(X, Placement):
        X = [X]
    if isinstance(X, (list, tuple)) and X and all(isinstance(p, Placement) for p in X):
        X = [np.append(np.asarray(p.s, float), float(p.angle)) for p in X]
    how = (f"{name} must be finite (k, 3) candidates (s_0, s_1, angle) [m, m, rad], (k, 2) ones (angle 0), "
           "one such row, or Placement objects")
    try:
        x = real_array(X, name)                  # no complex, boolean or text entries read as numbers
    except ValueError:
        raise ValueError(f"{name}={X!r:.200}: {how}.") from None
    x = x[None] if x.ndim == 1 else x
    if x.ndim != 2 or x.shape[1] not in (2, 3) or not len(x) or not np.all(np.isfinite(x)):
        raise ValueError(f"{name} of shape {np.shape(X)}: {how}.")
    return np.concatenate([x, np.zeros((len(x), 1))], 1) if x.shape[1] == 2 else x


def _check(scene: Scene, X, op, everywhere: bool = False):
    """The operator without its full-field map (maps keep no fields), after the eager checks
    of a squeeze of ``scene`` placed at the first candidate: inside a map or a search a bad
    number would only be a status (INVALID_INPUT in every cell, then "no feasible placement").
    Warns (:class:`~jaxsqueeze.simulation.validate.PlacementResolutionWarning`) where the
    boundary edges under the candidates (``everywhere``: all of the outer loop's, for a search)
    are too long for the fingertips: a map would show holes between the nodes, and a search
    would steer around them."""
    from ..simulation.api import check_scene
    op = check_scene(_placed(scene, X[0]), op)
    if isinstance(scene.mesh, Mesh) and scene.contact == "segment" and scene.friction_model == "coulomb":
        edges = _edges_under(scene, None if everywhere else X[:, :2])
        coarse = validate.placement_warning(float(edges.max()), float(scene.fingers.radius), float(scene.friction))
        if coarse:
            warnings.warn(coarse, validate.PlacementResolutionWarning, stacklevel=caller_level())
    return dataclasses.replace(op, field=None)   # (a static part: identity-hashed)


@contextlib.contextmanager
def _said_already():
    """No :class:`~jaxsqueeze.simulation.validate.PlacementResolutionWarning` inside: the caller
    has given it."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", validate.PlacementResolutionWarning)
        yield


def _edges_under(scene: Scene, s=None) -> np.ndarray:
    """The length [m] of the outer boundary loop's edge under each arc length ``s`` [m] (any
    shape, periodic in the perimeter): the edge between the two nodes a fingertip placed there
    lands between. ``None``: every edge of the loop."""
    outer = np.asarray(scene.mesh.boundary)[:scene.mesh.loops[0]]
    x = np.asarray(scene.mesh.points)[outer]
    edges = np.linalg.norm(np.roll(x, -1, axis=0) - x, axis=1)          # node k to node k + 1
    if s is None:
        return edges
    at = np.asarray(scene.arc_length(outer))
    s = np.mod(np.asarray(s, float), float(scene.curve().perimeter))
    return edges[np.clip(np.searchsorted(at, s, side="right") - 1, 0, len(at) - 1)]


def _placed(scene: Scene, x) -> Scene:
    return scene.replace(grip=None, placement=Placement(s=x[:2], angle=x[2]))


def _quality(qfn, res):
    """qfn(res) as a () float array, or an error naming what it returned (at trace time)."""
    try:
        q = qfn(res)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError,     # np.asarray, float(),
            jax.errors.TracerIntegerConversionError) as e:                                 # if, int()
        raise TypeError("the quality function needs concrete numbers, but maps and searches call it on traced "
                        "results (inside jit and vmap): compute it with jax.numpy (jnp.sum, jnp.where) instead of "
                        "numpy, float(), int() or an if on a value; JAX said: " + str(e).split("\n")[0]) from e
    try:
        q = jnp.asarray(q)
    except (TypeError, ValueError):                  # a string, None, a dict ...
        raise TypeError(f"the quality function returned {q!r}; it must return a number (a () array) "
                        "computed from the result") from None
    if q.shape != () or not (jnp.issubdtype(q.dtype, jnp.floating) or jnp.issubdtype(q.dtype, jnp.integer)):
        raise ValueError(f"the quality function returned an array of shape {q.shape} and dtype {q.dtype}; it must "
                         "return one real number (shape ()) per result, e.g. jnp.sum(...) of a vector")
    return q


def two_rows(qfn) -> bool:
    """Whether the quality function ``qfn`` is one of the named qualities, which read only the
    end of the squeeze phase, the last row and the engine's push work: maps and searches then
    squeeze with two rows kept (``history=False``; on the test ellipse a ``vmap`` batch ran
    1.14 → 0.73 ms per grasp and a search step 5.0 → 3.9 ms, the same qualities). A function
    of a result may read any row, so it gets the whole history."""
    return isinstance(qfn, SceneSlipMargin) or any(qfn is q for q in (squeeze_work, grip_force, adversary_work))


def _summary(scene: Scene, qfn, op, x) -> Summary:
    if isinstance(qfn, SceneSlipMargin):
        qfn = qfn._replace(friction=scene.friction)         # the scene's μ, traced (:func:`_keyed`)
    res = squeeze(_placed(scene, x), op=op, trim=False, history=not two_rows(qfn))
    ok = res.status == Status.SUCCESS
    q = jnp.where(ok, _quality(qfn, res), 0.0)
    return Summary(res.status, q, grip_force(res), res.final_depth, res.margin)   # (the squeeze's, not the push's)


@compiler.jit(static_argnums=(1,))
def _batch(scene, qfn, op, X):
    return jax.vmap(lambda x: _summary(scene, qfn, op, x))(X)


_one = compiler.jit(_summary, static_argnums=(1,))


@compiler.jit(static_argnums=(1, 5))
def _value_and_grad(scene, qfn, op, u, scale, vary_angle=False):
    """(Summary, d quality / du (3,)) at scaled coordinates u = x * scale, by ``jax.jacfwd`` in
    the arc lengths and, with ``vary_angle``, the angle (else its entry is 0: one tangent
    fewer, a foam-square search step 16.1 → 14.8 ms and its compile 0.9 s shorter).
    Module level, so every search on a scene of the same shapes reuses one compiled program."""
    k = 3 if vary_angle else 2

    def f(v):
        s = _summary(scene, qfn, op, jnp.concatenate([v, u[k:]]) / scale)
        return s.quality, s
    g, s = jax.jacfwd(f, has_aux=True)(u[:k])
    return s, jnp.concatenate([g, jnp.zeros(3 - k, g.dtype)])


def _scale(scene: Scene) -> np.ndarray:
    """(3,) the search's scaled coordinates u = x * scale: (2π s_0 / P, 2π s_1 / P, angle) [rad],
    P the perimeter [m]."""
    P = float(scene.curve().perimeter)
    return np.array([2 * math.pi / P, 2 * math.pi / P, 1.0])


def compile_search_ahead(scene: Scene, quality, op, vary_angle: bool = False) -> None:
    """Start compiling the program of the first steps of :func:`optimize_placement` on
    ``scene`` (``quality`` a name or a function; ``op`` its operator; ``vary_angle`` its
    argument) in a background thread (:meth:`jaxsqueeze.compiler.TopLevelJit.compile_ahead`):
    a map run meanwhile keeps one core busy, and the search's first step finds the program
    compiled."""
    scale = _scale(scene)
    _value_and_grad.compile_ahead(quick(scene), _keyed(quality_of(scene, quality)), dataclasses.replace(op, field=None),
                                  jnp.asarray(np.zeros(3) * scale), jnp.asarray(scale), bool(vary_angle))


def quick(scene: Scene) -> Scene:
    """The scene with its automatic capacities (``Settings.capacity`` / ``sliding_capacity``
    at None) fixed where an eager squeeze starts them (32 contact slots, one Newton system of
    8 sliding contacts for Coulomb): a smaller program that runs about 1.6× faster on the foam
    square. A traced squeeze cannot grow them, so the planner squeezes every candidate with
    this scene first and again with the scene itself where that gives ``Status.OVERFLOW``."""
    from ..simulation import api
    s = scene.settings
    cfg = api.config_of(scene, eager=True)
    return scene.replace(settings=dataclasses.replace(
        s, capacity=cfg.capacity, sliding_capacity=cfg.sliding or s.sliding_capacity))


def _capacities(scene: Scene):
    return scene.settings.capacity, scene.settings.sliding_capacity


def _run_key(scene: Scene):
    """The settings that tell the programs of :func:`quick` and :func:`_again` scenes apart."""
    s = scene.settings
    return s.capacity, s.sliding_capacity, s.max_steps, s.max_events


def _again(scene: Scene, run: Scene, status: int, depth: float) -> Scene | None:
    """The scene to squeeze a candidate of ``scene`` again with, after squeezing it with ``run``
    (first :func:`quick`) ended with ``status`` at the depth ``depth`` [m], or None: on
    ``OVERFLOW`` the scene's own capacities; on ``MAX_STEPS`` or ``EVENT_OVERFLOW`` of an
    automatic bound (``Settings.max_steps`` / ``max_events`` at None) both bounds longer, by
    the rule of an eager squeeze (x4, up to x16, within the memory limit:
    ``simulation.api._longer``)."""
    from ..simulation import api
    if status == Status.OVERFLOW and _capacities(run) != _capacities(scene):
        s = scene.settings
        return run.replace(settings=dataclasses.replace(run.settings, capacity=s.capacity,
                                                        sliding_capacity=s.sliding_capacity))
    if status in (Status.MAX_STEPS, Status.EVENT_OVERFLOW):
        cfg = api._longer(scene, api.config_of(run), status, depth)
        if cfg is not None:
            return run.replace(settings=dataclasses.replace(run.settings, max_steps=cfg.max_steps,
                                                            max_events=cfg.max_events))
    return None


def _progress(done, total, t0, label):
    if interactive():
        rate = done / max(time.perf_counter() - t0, 1e-9)
        print(f"\r{label}: {done}/{total} ({rate:.1f}/s)", end="" if done < total else "\n",
              file=sys.stderr, flush=True)


def _evaluate_part(scene: Scene, quality, op, X) -> Summary:
    """One worker's share of :func:`evaluate` with ``batch="processes"`` (module level: picklable)."""
    with _said_already():                        # (by the parent)
        return evaluate(scene, X, quality, op=op, batch="loop", progress=False)


@own_transfers
def evaluate(scene: Scene, X, quality="squeeze_work", op=None, batch: str = "auto", chunk: int | None = None,
             progress: bool = True, processes: int | None = None, cache=True) -> Summary:
    """Summaries of candidates ``X`` (B, 3) = (s_0 [m], s_1 [m], angle [rad]) as numpy arrays (B,)
    (also (B, 2) with angle 0, or :class:`~jaxsqueeze.Placement` objects: :func:`candidates`).

    ``batch``: "vmap" (one compiled ``vmap`` per chunk of ``chunk`` candidates, the last one
    padded), "loop" (one compiled squeeze called per candidate: a batched loop runs every
    lane's event location at every step, and each chunk as long as its longest squeeze),
    "processes" (chunks of ``chunk`` candidates looped in ``processes`` worker processes, one
    per core by default, through :func:`jaxsqueeze.batch.map_scenes`; ``cache`` is the workers'
    persistent compilation cache; ``quality`` must then be a name or a module-level function),
    or "auto" (vmap on an accelerator; a loop on the CPU, one program for a process's maps and
    searches of a scene: a map of the test ellipse's 1,378 pairs took 1.3 s so and 0.24–0.35 s
    as a vmap in chunks of 64, whose program compiles for ~5 s more: pass batch="vmap" for
    large or repeated maps). ``chunk`` (default: :data:`CHUNK`, and
    for "vmap" on an accelerator up to :data:`ACCELERATOR_CHUNK`, no more than the candidates)
    is one compiled program's batch there. A failed or infeasible candidate
    returns its status with quality 0 and costs only its first solve in a loop. Candidates are
    squeezed with the :func:`quick` capacities first; those that overflow them once more with
    the scene's own, and those that run out of the automatic loop or event bound once more with
    longer bounds, one at a time (:func:`_again`). ``progress``: a line on stderr after each
    chunk (each 16 squeezes of a loop) where stderr is a terminal or a Jupyter notebook's
    (:func:`jaxsqueeze.batch.interactive`).
    """
    progress = flag(progress, "progress")
    return _evaluate_with_runs(scene, X, quality, op, batch, chunk, progress, processes, cache)[0]


def _evaluate_with_runs(scene: Scene, X, quality, op, batch, chunk, progress, processes, cache):
    """(:func:`evaluate`'s summaries, for each candidate the scene whose settings gave its
    summary: :func:`quick` or what :func:`_again` made of it; None with batch="processes")."""
    X = candidates(X)
    if chunk is not None:
        _check_count("chunk", chunk, 1)
    if processes is not None:
        _check_count("processes", processes, 1)
    op = _check(scene, X, op)
    if batch != "processes":       # (the workers of "processes" loop through this function)
        fast = quick(scene)
        grown = _again(scene, fast, Status.OVERFLOW, 0.0)       # (compiled ahead at a loop's first overflow)
        summ = _evaluate(fast, X, quality, op, batch, chunk, progress, processes, cache, grown)
        runs = [fast] * len(X)
        todo = [(fast, np.arange(len(X)))]
        while todo:
            run, idx = todo.pop()
            groups = {}
            for k in idx:
                nxt = _again(scene, run, int(summ.status[k]), float(summ.depth[k]))
                if nxt is not None:
                    groups.setdefault(_run_key(nxt), (nxt, []))[1].append(k)
            for nxt, ks in groups.values():
                ks = np.asarray(ks)
                # longer bounds one candidate at a time (a vmap of thousands of rows each would
                # need gigabytes)
                longer = nxt.settings.max_steps != run.settings.max_steps
                again = _evaluate(nxt, X[ks], quality, op, "loop" if longer else batch, chunk, False, processes, cache)
                for a, b in zip(summ, again):
                    a[ks] = b
                for k in ks:
                    runs[k] = nxt
                todo.append((nxt, ks))
    else:
        summ = _evaluate(scene, X, quality, op, batch, chunk, progress, processes, cache)
        runs = [None] * len(X)
    _check_quality(summ, X)
    return summ, runs


def _default_chunk(batch: str, n: int, plat: str) -> int:
    """Candidates per chunk when ``evaluate`` is given none: a ``vmap`` on an accelerator
    takes up to :data:`ACCELERATOR_CHUNK` (one program for all of a smaller batch), else
    :data:`CHUNK`."""
    return min(ACCELERATOR_CHUNK, max(n, 1)) if batch == "vmap" and plat != "cpu" else CHUNK


def _evaluate(scene: Scene, X, quality, op, batch, chunk, progress, processes, cache, grown=None) -> Summary:
    """:func:`evaluate` with the scene's capacities as they are. ``grown``: the scene that
    candidates which overflow them will be squeezed again with, whose program a loop starts
    compiling in the background at the first overflow (the rest of the loop runs meanwhile)."""
    op = scene.operator() if op is None else op
    qfn = _keyed(quality_of(scene, quality))
    if batch == "auto":
        batch = "loop" if compiler.platform() == "cpu" else "vmap"
    if batch not in ("vmap", "loop", "processes"):
        raise ValueError(f"batch={batch!r}; choose 'auto', 'vmap', 'loop' or 'processes'")
    chunk = chunk or _default_chunk(batch, len(X), compiler.platform())
    if batch == "processes":
        from ..batch import map_scenes
        part = partial(_evaluate_part, scene, quality, dataclasses.replace(op, field=None))
        parts = [X[k:k + chunk] for k in range(0, len(X), chunk)]
        out = map_scenes(part, parts, processes=processes, chunk=1, progress=progress, cache=cache)
        return Summary(*(np.concatenate(a) for a in zip(*out)))
    out, t0 = [], time.perf_counter()
    if batch == "loop":
        for k, x in enumerate(X):
            out.append(jax.tree.map(lambda a: np.asarray(a)[None], _one(scene, qfn, op, jnp.asarray(x))))
            if grown is not None and out[-1].status[0] == Status.OVERFLOW:
                _one.compile_ahead(grown, qfn, op, jnp.asarray(x))
                grown = None
            if progress and (k % 16 == 15 or k == len(X) - 1):
                _progress(k + 1, len(X), t0, "grasp map")
        return Summary(*(np.concatenate(a) for a in zip(*out)))
    for start in range(0, len(X), chunk):
        part = X[start:start + chunk]
        # the last chunk padded to the whole chunk (its program exists); a batch of one short
        # chunk to a power of two only
        size = chunk if len(X) > chunk else min(chunk, 1 << (len(part) - 1).bit_length())
        pad = np.concatenate([part, np.repeat(part[-1:], size - len(part), 0)])
        s = _batch(scene, qfn, op, jnp.asarray(pad))
        out.append(jax.tree.map(lambda a: np.asarray(a)[:len(part)], s))
        if progress:
            _progress(min(start + chunk, len(X)), len(X), t0, "grasp map")
    return Summary(*(np.concatenate(a) for a in zip(*out)))


class GraspMap(NamedTuple):
    """A quality over pairs of boundary positions (finger 0 at s[i], finger 1 at s[j]).

    s: (n,) arc lengths [m]; quality, grip_force, margin: (n, n); status: (n, n) int (the
    diagonal, where both fingers would sit at one point, is INFEASIBLE_GRIP); angle: the
    squeeze-direction offset used [rad]; best: (k, 3) the best feasible candidates, best
    first; evaluations: squeezes run.
    """

    s: np.ndarray
    quality: np.ndarray
    status: np.ndarray
    grip_force: np.ndarray
    margin: np.ndarray
    angle: float
    best: np.ndarray
    evaluations: int

    def feasible(self) -> np.ndarray:
        return self.status == Status.SUCCESS

    def __repr__(self) -> str:
        n = len(self.s)
        gap = f" {float(self.s[1] - self.s[0]):.4g} m apart" if n > 1 else ""
        ok = self.feasible()
        at = f" at s = ({float(self.best[0, 0]):.4g}, {float(self.best[0, 1]):.4g}) m" if len(self.best) else ""
        best = f"best {float(np.max(self.quality[ok])):.4g}{at}" if ok.any() else "none feasible"
        return (f"GraspMap({n} positions{gap}, {self.evaluations} squeezes, {int(ok.sum())} of {n * n - n} "
                f"ordered pairs feasible, {best})")


def grid(scene: Scene, spacing=None) -> np.ndarray:
    """(n,) arc lengths [m] spaced evenly around the outer loop (default: the mean boundary
    edge, i.e. node spacing). ``ValueError`` for a spacing that is not a finite number > 0, that
    puts more than 10 positions per boundary node (a map squeezes every pair), or fewer than 3."""
    P = float(scene.curve().perimeter)
    m = scene.mesh.loops[0] if hasattr(scene.mesh, "loops") else scene.mesh.m
    if spacing is None:
        spacing = P / m
    if isinstance(spacing, (str, bytes, bool)) or kind(spacing) not in "iuf" or not (
            np.ndim(spacing) == 0 and np.isfinite(float(spacing)) and float(spacing) > 0):
        raise ValueError(f"spacing={spacing!r} must be a finite arc length > 0 m (the outer boundary is {P:.4g} m "
                         f"long; the default is its node spacing, {P / m:.3g} m).")
    ratio = P / float(spacing)                 # inf for a subnormal spacing
    if not ratio < 10 * m + 0.5:
        raise ValueError(f"spacing={float(spacing):.3g} m puts {ratio:.3g} positions on the {P:.4g} m outer boundary, "
                         f"more than 10 per boundary node ({m} nodes), and a map squeezes every pair of them; use a "
                         f"spacing of at least {P / (10 * m):.3g} m.")
    n = int(round(ratio))
    if n < 3:
        raise ValueError(f"spacing={float(spacing):.3g} m puts {n} position(s) on the {P:.4g} m outer boundary; a map "
                         f"needs at least 3: use a spacing of at most {P / 3:.3g} m.")
    return np.arange(n) * (P / n)


def roles_symmetric(scene: Scene, quality="squeeze_work") -> bool:
    """Whether swapping the two fingers' roles (which one squeezes) leaves ``quality``
    unchanged: true for a quality named in ``QUALITIES`` on fingers that rotate alike or not
    at all (the squeeze is then the same up to a rigid translation). A function of a result
    may tell the fingers apart (``finger_work(res)[0]``), and so do unequal rotation rows."""
    rot = scene.fingers.rotation
    alike = rot is None or (numeric(rot) and np.array_equal(np.asarray(rot)[0], np.asarray(rot)[1]))
    return isinstance(quality, str) and alike


def _pairs(n: int, ordered: bool):
    """(i, j) index arrays of every pair of n positions: i < j, or both orders."""
    return np.nonzero(~np.eye(n, dtype=bool)) if ordered else np.triu_indices(n, 1)


@own_transfers
def grasp_map(scene: Scene, quality="squeeze_work", spacing=None, angle: float = 0.0, op=None,
              batch: str = "auto", chunk: int | None = None, progress: bool = True, keep: int = 8,
              processes: int | None = None) -> GraspMap:
    """Evaluate ``quality`` over every pair of boundary positions at ``spacing`` [m]
    (``batch``, ``chunk`` and ``processes`` as in :func:`evaluate`).

    When swapping the finger roles changes nothing (:func:`roles_symmetric`: a named quality,
    fingers that rotate alike) each unordered pair is squeezed once and the map is mirrored;
    otherwise both orders are squeezed. Returns a :class:`GraspMap`.
    """
    _check_count("keep", keep, 1)
    angle = _check_angle(angle)
    s = grid(scene, spacing)
    n = len(s)
    mirror = roles_symmetric(scene, quality)
    i, j = _pairs(n, not mirror)
    X = np.stack([s[i], s[j], np.full(len(i), angle)], 1)
    summ = evaluate(scene, X, quality, op=op, batch=batch, chunk=chunk, progress=progress, processes=processes)
    full = {}
    for name in ("quality", "status", "grip_force", "margin"):
        a = np.full((n, n), Status.INFEASIBLE_GRIP if name == "status" else (0.0 if name != "margin" else -np.pi))
        v = getattr(summ, name)
        a[i, j] = v
        if mirror:
            a[j, i] = v
        full[name] = a
    ok = summ.status == Status.SUCCESS
    order = np.argsort(-np.where(ok, summ.quality, -np.inf))[:keep]
    best = X[order[ok[order]]]
    return GraspMap(s, full["quality"], full["status"].astype(int), full["grip_force"], full["margin"],
                    float(angle), best, len(X))


def candidate_pairs(scene: Scene, spacing=None, angle: float = 0.0, op=None, ordered: bool = False) -> np.ndarray:
    """(k, 3) candidates (s_0, s_1, angle) whose first contacts lie inside both friction cones,
    found without squeezing (the approach and the cone test only), best margin first; each
    pair once (s_0 < s_1), or in both orders with ``ordered`` (for fingers or a quality that
    tell the roles apart, :func:`roles_symmetric`)."""
    from ..simulation import api

    s = grid(scene, spacing)
    i, j = _pairs(len(s), flag(ordered, "ordered"))
    X = np.stack([s[i], s[j], np.full(len(i), _check_angle(angle))], 1)
    op = _check(scene, X, op)
    m = np.asarray(_margins(scene, op, api.config_of(_placed(scene, X[0])), jnp.asarray(X)))
    keep = np.flatnonzero(m >= 0)
    return X[keep[np.argsort(-m[keep])]]


@compiler.jit(static_argnums=(2,))
def _margins(scene: Scene, op, cfg, X):
    """(k,) cone margins of the first contacts of the placements X (k, 3) of ``scene``
    (no squeeze). Module level: a second search on the same scene and grid compiles nothing."""
    from ..simulation import api, engine
    return jax.vmap(lambda x: engine.make_model(op, api.grasp_of(_placed(scene, x), op), cfg).margin)(X)


class Step(NamedTuple):
    """One iteration of a search: placement (3,), quality, gradient norm, status, and whether
    the step was undone (it reached a failed or infeasible placement; the search went on from
    the step before at half the rate)."""

    x: np.ndarray
    quality: float
    grad_norm: float
    status: int
    undone: bool = False


class Search(NamedTuple):
    """Result of :func:`optimize_placement`.

    best: the best :class:`Placement` found; quality: its quality; history: one list of
    :class:`Step` per start; squeezes: forward squeezes run (each gradient is one squeeze
    carrying 2–3 tangents), including the coarse map's; screened: coarse pairs put through the
    cone test alone (no squeeze; only those that pass are squeezed).
    """

    best: Placement
    quality: float
    history: list
    squeezes: int
    screened: int = 0

    def __repr__(self) -> str:
        s = np.asarray(self.best.s, float)
        return (f"Search(best quality {float(self.quality):.4g} at s = ({s[0]:.4g}, {s[1]:.4g}) m, angle "
                f"{float(self.best.angle):.4g} rad; {len(self.history)} start{'s' * (len(self.history) != 1)}, {self.squeezes} squeezes, "
                f"{self.screened} screened)")


def _optax_promotion():
    """The dtype promotion rules the optimizer runs under: JAX's standard ones. optax mixes
    integer step counts with float moments (``b1 ** count``), which a user's
    ``jax_numpy_dtype_promotion="strict"`` refuses; the library's own code needs no
    implicit promotion."""
    return jax.numpy_dtype_promotion("standard")


def unit_step(optimizer) -> np.ndarray:
    """(3,) the optimizer's first step from a unit gradient at the origin, taken as the search
    takes one: ``optimizer.update(gradient, state, params)``."""
    u = jnp.zeros(3)
    with _optax_promotion():
        return np.asarray(optimizer.update(jnp.ones(3), optimizer.init(u), u)[0])


@own_transfers
def check_search(optimizer, steps, starts, budget, init) -> None:
    """ValueError/TypeError for arguments :func:`optimize_placement` cannot use, before any squeeze."""
    _check_count("steps", steps, 0)
    _check_count("starts", starts, 1)
    if budget is not None:
        _check_count("budget", budget, 1)
    if optimizer is not None and not (hasattr(optimizer, "init") and hasattr(optimizer, "update")):
        raise TypeError(f"optimizer={optimizer!r} is not an optax optimizer; pass one such as optax.adam(0.02) "
                        "(or None for that default).")
    if optimizer is not None:
        try:
            step = unit_step(optimizer)
        except TypeError as e:
            raise ValueError(f"the optimizer cannot take a step from a gradient alone ({e}); optimizers with a "
                             "line search (optax.lbfgs, ...) evaluate the quality themselves, which this search "
                             "does not support: use optax.adam, optax.sgd, optax.adabelief, ...") from None
        if not np.all(np.isfinite(step)):
            raise ValueError(f"the optimizer's step from a unit gradient is {step.tolist()}, not "
                             "finite: check its learning rate (a finite number > 0, e.g. optax.adam(0.02))")
        if float(np.sum(step)) > 0:            # optax minimizes: its step must go against the gradient
            raise ValueError(f"the optimizer's step from a unit gradient is {step.tolist()}: along the "
                             "gradient, so the search would walk downhill; pass a minimizer with a learning rate "
                             "> 0 (optax.adam(0.02), optax.sgd(0.01); optax.scale needs a negative factor)")
    if init is not None:
        candidates(init, "init")


@own_transfers
def optimize_placement(scene: Scene, quality="squeeze_work", init=None, optimizer=None, steps: int = 40,
                       starts: int = 5, coarse_spacing=None, vary_angle: bool = False, op=None,
                       progress: bool = True, budget: int | None = None) -> Search:
    """Gradient-based placement search (maximizes ``quality``).

    Args:
        scene: the scene (its grip/placement is replaced by the candidates).
        quality: a name in ``QUALITIES`` or a function result → ().
        init: (k, 2 or 3) starting candidates (s_0, s_1[, angle]) or Placements; default: the ``starts`` best
            cells of a coarse map (``coarse_spacing``, default perimeter / 16) on which only the
            pairs that pass the cone test (:func:`candidate_pairs`) are squeezed.
        optimizer: an optax optimizer (default ``optax.adam(0.02)``) acting on the scaled
            coordinates u = (2π s_0 / P, 2π s_1 / P, angle) [rad], P the perimeter.
        steps: iterations per start.
        vary_angle: also move the squeeze-direction offset (default: keep it).
        budget: the most squeezes to run, coarse map included (default: no limit). After the
            coarse map the rest is shared evenly by the starts: each runs at most
            ``budget_left // starts - 1`` iterations (and at most ``steps``).
        progress: the coarse map's progress line and one line per finished start (the best
            quality so far) on stderr, where it is a terminal or a Jupyter notebook's.
    Forward-mode gradients (``jax.jacfwd``) of the quality; a step that lands on a failed or
    infeasible placement is undone and the step scale halved (the constraint is the status;
    its margin is in the history). Steps squeeze as a map does (:func:`evaluate`: the quick
    capacities first, more where they run out); a start from the coarse map begins with what
    its cell needed, and a start keeps what it grew to. Returns a :class:`Search`.
    """
    import optax

    check_search(optimizer, steps, starts, budget, init)
    vary_angle, progress = flag(vary_angle, "vary_angle"), flag(progress, "progress")
    init = None if init is None else candidates(init, "init")
    op = _check(scene, np.zeros((1, 3)) if init is None else init, op, everywhere=True)
    qfn = _keyed(quality_of(scene, quality))
    P = float(scene.curve().perimeter)
    scale = _scale(scene)
    optimizer = optax.adam(0.02) if optimizer is None else optimizer
    squeezes = 0
    screened = 0
    start_runs = None
    if init is None:
        # the coarse map, screened: only pairs whose first contacts pass the cone test (the
        # approach and Section I-A's test, no squeeze) are squeezed
        spacing = P / 16 if coarse_spacing is None else coarse_spacing
        ordered = not roles_symmetric(scene, quality)
        n = len(grid(scene, spacing))
        screened = n * (n - 1) // (1 if ordered else 2)
        with _said_already():                    # (for the whole boundary, above)
            X = candidate_pairs(scene, spacing, op=op, ordered=ordered)
            if budget is not None and int(budget) <= len(X):         # known before any squeeze
                raise ValueError(f"budget={budget} squeezes is spent before the search starts (the coarse map "
                                 f"squeezes the {len(X)} pairs that pass the cone test, and each start needs at "
                                 "least 1 more): raise the budget, or use a coarser coarse_spacing")
            if len(X):
                compile_search_ahead(scene, qfn, op, vary_angle)        # on the other core, while the map runs
            summ, runs = _evaluate_with_runs(scene, X, qfn, op, "auto", None, progress, None, True) if len(X) \
                else (None, [])
        squeezes += len(X)
        ok = np.zeros(0, bool) if summ is None else summ.status == Status.SUCCESS
        order = np.argsort(-np.where(ok, summ.quality, -np.inf)) if len(X) else np.zeros(0, int)
        best = order[ok[order]][:starts]
        init, start_runs = X[best], [runs[i] for i in best]
        if len(init) == 0:
            seen = "no pair passed the cone test" if summ is None else ", ".join(
                f"{Status(int(k)).name} {int(c)}" for k, c in zip(*np.unique(summ.status, return_counts=True)))
            raise ValueError(f"no feasible placement on the coarse map ({seen}): pass a finer coarse_spacing "
                             "(or, in a scene file, a finer plan.spacing), or change the scene")
    if budget is not None:
        steps = min(steps, (int(budget) - squeezes) // len(init) - 1)
        if steps < 0:
            spent = f"{squeezes} on the coarse map" if squeezes else "no coarse map: init given"
            raise ValueError(f"budget={budget} squeezes is spent before the search starts ({spent}; each of the "
                             f"{len(init)} starts needs at least 1): raise the budget, or use fewer starts"
                             + (" or a coarser coarse_spacing" if squeezes else " (rows of init)"))
    mask = np.array([1.0, 1.0, 1.0 if vary_angle else 0.0])

    scale_ = jnp.asarray(scale)
    fast = quick(scene)
    turn = bool(vary_angle)
    # a start squeezes with what its cell of the coarse map needed (else the quick capacities)
    start_runs = [fast if r is None else r for r in (start_runs or [None] * len(init))]
    for r in {_run_key(r): r for r in start_runs if _run_key(r) != _run_key(fast)}.values():
        _value_and_grad.compile_ahead(r, qfn, op, jnp.asarray(init[0] * scale), scale_, turn)

    def value_and_grad(u, run):  # from run, then as evaluate does (_again); and the run that did
        s, g = _value_and_grad(run, qfn, op, u, scale_, turn)
        while (nxt := _again(scene, run, int(s.status), float(s.depth))) is not None:
            run = nxt
            s, g = _value_and_grad(run, qfn, op, u, scale_, turn)
        _check_quality(jax.tree.map(lambda a: np.asarray(a)[None], s), np.asarray(u)[None] / scale)
        return s, g, run

    histories, best_x, best_q = [], None, -np.inf
    for k, x0 in enumerate(init):
        u = jnp.asarray(x0 * scale)
        with _optax_promotion():
            state = optimizer.init(u)
        s, g, run = value_and_grad(u, start_runs[k])
        squeezes += 1
        step = lambda u, s, g, undone=False: Step(np.asarray(u) / scale, float(s.quality),  # noqa: E731
                                                  float(jnp.linalg.norm(g * mask)), int(s.status), undone)
        hist, damp = [step(u, s, g)], 1.0
        for it in range(steps):
            ok = int(s.status) == Status.SUCCESS
            if ok and float(s.quality) > best_q:
                best_q, best_x = float(s.quality), np.asarray(u) / scale
            with _optax_promotion():
                updates, new_state = optimizer.update(-g * mask, state, u)
            updates = jnp.where(mask > 0, updates, 0.0)       # vary_angle=False: the angle stays (weight decay, noise)
            finite = np.all(np.isfinite(np.asarray(jnp.where(mask > 0, g, 0.0)))) and np.all(np.isfinite(updates))
            if ok and not finite:
                raise ValueError(f"at the placement {np.round(np.asarray(u) / scale, 6).tolist()} (s_0, s_1 [m], angle "
                                 f"[rad]), which squeezes with SUCCESS, the quality's gradient is "
                                 f"{np.asarray(g).tolist()} and the optimizer's step {np.asarray(updates).tolist()}: "
                                 "not finite. Check the quality function's derivatives, or the optimizer's settings "
                                 "(optax.adam needs eps > 0)")
            u_new = u + damp * updates
            s_new, g_new, run_new = value_and_grad(u_new, run)
            squeezes += 1
            if int(s_new.status) != Status.SUCCESS and ok:
                damp *= 0.5                 # stepped onto a failed / infeasible placement: undo
                hist.append(step(u_new, s_new, g_new, undone=True))
                continue
            # a start keeps the capacities and bounds it grew to (its steps are near each other)
            u, state, s, g, run = u_new, new_state, s_new, g_new, run_new
            hist.append(step(u, s, g))
        if int(s.status) == Status.SUCCESS and float(s.quality) > best_q:
            best_q, best_x = float(s.quality), np.asarray(u) / scale
        histories.append(hist)
        if progress and interactive():
            print(f"start {k + 1}/{len(init)}: best {best_q:.6g}", file=sys.stderr)
    if best_x is None:
        ends = sorted({Status(h[-1].status).name for h in histories})
        raise ValueError(f"no start reached a successful squeeze (the {len(histories)} start(s) ended with "
                         f"{', '.join(ends)}); start from feasible placements: leave init out (the best "
                         "cells of a coarse grasp map), or pick feasible cells of jsq.grasp_map")
    return Search(Placement(s=best_x[:2], angle=float(best_x[2])), best_q, histories, squeezes, screened)
