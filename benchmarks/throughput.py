"""Throughput of the squeeze on the built-in foam square (issue 11, "Speed").

The foam square of ``jaxsqueeze/scenes/foam_square.toml`` (1,265 nodes, m = 122, Coulomb
stick/slip, 15 mm, float64), in one run:

* ``squeeze``: one squeeze after compilation (the jitted core ``api._run``, best of ``--reps``;
  and ``jsq.squeeze`` with its validation and trimming), per squeeze and per recorded row;
  the same core in float32 in a fresh process with x64 off.
* ``reference``: a plain NumPy/SciPy row written here (:func:`numpy_row`: LU of the bordered
  matrix of eq. 4 for the s contacts, Newton on the slip angles with the analytic Jacobian,
  the implicit slip rates, the gaps of every boundary node and the cone margins) on the
  recorded row with the most sliding contacts, checked against the engine's
  ``contacts.solve`` there; the ratios of the engine's ``contacts.solve`` and of its time per recorded row to it.
* ``compile``: trace + lower + compile of the squeeze in a fresh process without the
  persistent cache (cold), and in two fresh processes sharing a new cache folder (the second
  one loads it: warm), with the cache hits JAX reports; and a user's whole first
  ``jsq.squeeze`` of the scene in a fresh process (operator build to result), with the
  number of programs it compiled.
* ``batch`` on the CPU for ``--batches`` (1/16/64/256) candidate grips: a plain loop of
  ``jsq.squeeze`` (best of ``--reps``, up to ``--loop-max``: 256), ``jax.vmap`` of the core in a fresh process (stopped
  after ``--vmap-timeout`` s and then reported as a bound), and :func:`jaxsqueeze.batch.map_scenes`
  (one single-threaded process per core, wall time including the workers' start-up and
  compile or cache load), and :func:`jaxsqueeze.batch.split_vmap` in a fresh process with one
  host device per core (the batch split over them, each device vmapping its chunk); evaluations
  per minute.
* ``gpu``: where ``jax.devices()[0].platform == "gpu"``, ``vmap`` at 1/256/1,024/4,096, with the
  traced default of 64 contact slots and with ``Settings(capacity=32, sliding_capacity=8)``
  (``--gpu-only``: the scene, one squeeze and this section alone; ``throughput_gpu.*``).

Every row records the 1-minute load average. Writes ``results/throughput.csv`` and
``results/throughput.png`` (``throughput_quick.*`` with ``--quick``).

    .venv/bin/python benchmarks/throughput.py            # ~4 min on 2 idle cores (3x under load)
    .venv/bin/python benchmarks/throughput.py --quick    # smoke run: ~1.5 min idle
"""
from __future__ import annotations

import dataclasses
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)


# ----------------------------------------------------------------------------- NumPy reference row
def row_inputs(op0, gr, cfg, st, d) -> dict:
    """The numbers one row needs, as numpy (scaled units, as the engine sees them): the
    operator, the contact set of loop state ``st`` (its per-node modes) and the fingers at depth ``d``."""
    from jaxsqueeze.simulation import engine as E
    if cfg.rotation or cfg.contact != "segment" or cfg.friction_model != "coulomb":
        raise NotImplementedError("the reference row covers Coulomb, segment contacts, no rotation")
    model = E.make_model(op0, gr, cfg)
    C = np.asarray(model.centres(d))
    ns = st.nodes
    return dict(G=np.asarray(op0.G), N=np.asarray(op0.N), P=np.asarray(op0.points), mode=np.asarray(ns.mode),
                finger=np.asarray(ns.finger), theta=np.asarray(ns.theta), C=C, e=np.asarray(model.dirn[1]),
                r=float(model.r[0]), phi=float(model.phi), gap_tol=float(model.gap_tol), tol=float(model.newton_tol),
                iters=cfg.newton_iters)


def numpy_row(G, N, P, mode, finger, theta, C, e, r, phi, gap_tol, tol, iters):
    """One row as a user would write it with numpy/scipy: LU of the bordered matrix of eq. (4)
    for the s contacts (no padding), Newton on the slip angles of the sliding contacts with the
    analytic Jacobian, the implicit slip rates dθ/dε, the gaps of every boundary node to both
    fingertips (event A) and the normal/tangential forces and cone margins (events B, C)."""
    from scipy.linalg import lu_factor, lu_solve
    idx = np.flatnonzero(mode > 0)
    s = idx.size
    dofs = np.stack([2 * idx, 2 * idx + 1], 1).ravel()
    B = N[dofs]
    M = np.zeros((2 * s + 3, 2 * s + 3))
    M[:2 * s, :2 * s] = G[np.ix_(dofs, dofs)]
    M[:2 * s, 2 * s:] = B
    M[2 * s:, :2 * s] = B.T
    lu = lu_factor(M)
    md, fg, p = mode[idx], finger[idx], P[idx]
    Cf = C[fg]
    th = theta[idx].copy()
    js = np.flatnonzero(md >= 2)
    sign = np.where(md[js] == 2, 1.0, -1.0)
    k = js.size

    def solve(th):
        disp = (Cf + r * np.stack([np.cos(th), np.sin(th)], 1) - p).ravel()
        x = lu_solve(lu, np.concatenate([disp, np.zeros(3)]))
        return x[:2 * s].reshape(s, 2), x[2 * s:]

    def cross(a, b):
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    def jac(th, f):
        edge = th[js] - sign * phi
        ue = np.stack([np.cos(edge), np.sin(edge)], 1)
        D = np.zeros((2 * s + 3, k))
        D[2 * js, np.arange(k)] = -r * np.sin(th[js])
        D[2 * js + 1, np.arange(k)] = r * np.cos(th[js])
        dF = lu_solve(lu, D)[:2 * s].reshape(s, 2, k)[js]          # (k, 2, k)
        J = dF[:, 0, :] * ue[:, 1:2] - dF[:, 1, :] * ue[:, 0:1]
        J[np.arange(k), np.arange(k)] += cross(f[js], np.stack([-np.sin(edge), np.cos(edge)], 1))
        return J, cross(f[js], ue), ue

    it = 0
    f, g = solve(th)
    if k:
        for it in range(1, iters + 1):
            J, R, _ = jac(th, f)
            dx = np.linalg.solve(J, R)
            th[js] -= dx
            f, g = solve(th)
            if np.max(np.abs(dx)) <= tol:
                break
        # slip rates dθ/dε = -J⁻¹ ∂R/∂ε (finger 2 moves along e)
        J, R, ue = jac(th, f)
        Dd = np.zeros(2 * s + 3)
        Dd[:2 * s] = np.where(fg[:, None] == 1, e[None], 0.0).ravel()
        dFd = lu_solve(lu, Dd)[:2 * s].reshape(s, 2)[js]
        rate = -np.linalg.solve(J, cross(dFd, ue))
    else:
        rate = np.zeros(0)
    u = (G[:, dofs] @ f.ravel() + N @ g).reshape(-1, 2)
    x = P + u
    gap = np.min(np.linalg.norm(x[:, None, :] - C[None], axis=-1), axis=1) - r + gap_tol
    axis = np.stack([np.cos(th), np.sin(th)], 1)
    fn = np.sum(f * axis, 1)
    ft = cross(axis, f)
    a = phi + 1e-7
    margin = np.sin(a) * fn - np.cos(a) * np.abs(ft)
    return dict(f=f, g=g, th=th, gap=gap, fn=fn, ft=ft, margin=margin, rate=rate, iters=it)


def reference_row(inp: dict, reps: int = 20):
    """(best time of :func:`numpy_row` [s], its result) on ``inp`` from :func:`row_inputs`."""
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        out = numpy_row(**inp)
        ts.append(time.perf_counter() - t)
    return min(ts), out


# ----------------------------------------------------------------------------- the driver
TARGETS = {   # issue 11, "where it should be"
    "per_squeeze": "<= 5 ms", "per_row": "<= 0.1 ms", "compile": "<= 2 s idle; 2nd process reuses it",
    "vmap": "no slower than a loop per grasp, both cores", "evals_per_min": ">= 10,000",
    "gpu": "<= 0.5 ms per grasp at batch >= 1,024",
}
_WORKER_CACHE: dict = {}


def scene_inputs(eager: bool = False, fused: bool = False):
    """(scene, op without field map, grasp, config, grip positions for candidates) of the foam
    square; the config's contact slots are an ``eager`` ``jsq.squeeze``'s (32) or a traced one's
    (64, what ``vmap`` runs); ``fused``: its loop compiled as one kernel (``Settings.fused``)."""
    from jaxsqueeze.simulation import api as G
    from squeeze import foam
    sc = foam()
    op = sc.operator()
    op0 = dataclasses.replace(op, field=None)
    pos = np.full(int(np.max(np.asarray(op.nodes))) + 1, -1)
    pos[np.asarray(op.nodes)] = np.arange(op.m)
    cfg = G.eager_config(sc, op) if eager else G.config_of(sc)
    return sc, op0, G.grasp_of(sc, op), dataclasses.replace(cfg, fused=fused), pos


def grips(mesh, B):
    """B candidate grips (mesh node pairs) spread over the 256 of ``gpu.candidates`` (finger 1 on
    the bottom edge at x in [-30, 30] mm, finger 2 on the top edge at x + dx, dx in [-8, 8] mm);
    for B > 256, ``gpu.candidates(mesh, B)``."""
    from gpu import candidates
    if B > 256:
        return candidates(mesh, B)
    allc = candidates(mesh, 256)
    return allc[np.linspace(0, 255, B).round().astype(int)] if B > 1 else allc[[128]]


def evaluate_grip(grip):
    """One grasp evaluation as a planner would run it (``jsq.squeeze`` of the foam square at a
    new grip): returns (status, rows, grip force [N]). Module level: pool workers import it."""
    import jaxsqueeze as jsq
    if "scene" not in _WORKER_CACHE:
        from squeeze import foam
        sc = foam()
        _WORKER_CACHE["scene"], _WORKER_CACHE["op"] = sc, sc.operator()
    sc = _WORKER_CACHE["scene"].replace(grip=tuple(int(g) for g in grip))
    res = jsq.squeeze(sc, op=_WORKER_CACHE["op"])
    return int(res.status), int(res.count), float(res.total_force[-1, 1, 1])


def best_of(f, reps):
    ts, out = [], None
    for _ in range(reps):
        t = time.perf_counter()
        out = f()
        ts.append(time.perf_counter() - t)
    return min(ts), out


def worker(argv):
    """Subprocess entry points; each prints one JSON line per result."""
    import json
    kind = argv[0]
    if kind == "split":         # split B: the batch over one host device per core (set before JAX starts)
        from jaxsqueeze.batch import host_devices_flag
        os.environ["XLA_FLAGS"] = host_devices_flag()
    import jax
    jax.config.update("jax_enable_x64", kind != "core32")
    if kind == "core32":        # core32 REPS: the eager program in float32 (x64 off), best of REPS
        from jaxsqueeze.simulation import api as G
        sc, op0, gr, cfg, pos = scene_inputs(eager=True)
        core = G._run.lower(op0, gr, cfg).compile()
        t_run, out = best_of(lambda: jax.block_until_ready(core(op0, gr)), int(argv[1]))
        print(json.dumps(dict(run_s=t_run, rows=int(out[0].count), status=int(out[0].status))), flush=True)
    elif kind == "compile":       # compile [CACHE_DIR | plain | fused]
        events = {}
        jax.monitoring.register_event_listener(lambda name, **kw: events.__setitem__(name, events.get(name, 0) + 1))
        plain, fused = argv[1:] == ["plain"], argv[1:] == ["fused"]
        if len(argv) > 1 and not (plain or fused):
            from jaxsqueeze import compile_cache
            compile_cache.enable(argv[1])
        t0 = time.perf_counter()
        from jaxsqueeze.simulation import api as G
        sc, op0, gr, cfg, pos = scene_inputs(eager=True, fused=fused)
        t1 = time.perf_counter()
        # an eager jsq.squeeze compiles _run as a top-level program with compiler.options();
        # "plain" is the same program without them (what a squeeze inside a user's jit compiles)
        low = (G._run.plain if plain else G._run).lower(op0, gr, cfg)
        t2 = time.perf_counter()
        low.compile()
        t3 = time.perf_counter()
        print(json.dumps(dict(setup_s=t1 - t0, trace_lower_s=t2 - t1, compile_s=t3 - t2,
                              cache_hits=events.get("/jax/compilation_cache/cache_hits", 0))), flush=True)
    elif kind == "first":       # first: a user's first jsq.squeeze of the scene in a fresh process
        events = []
        jax.monitoring.register_event_duration_secs_listener(
            lambda name, secs, **kw: events.append(name) if name.endswith("backend_compile_duration") else None)
        import jaxsqueeze as jsq
        from squeeze import foam
        t0 = time.perf_counter()
        res = jsq.squeeze(foam())       # the operator build, validation, compile, run, field, trim
        print(json.dumps(dict(first_s=time.perf_counter() - t0, programs=len(events), rows=int(res.count))), flush=True)
    elif kind in ("vmap", "split"):        # vmap B [reps [eager | fused]] / split B [reps [eager | fused]]
        import jax.numpy as jnp

        from jaxsqueeze.batch import split_vmap
        from jaxsqueeze.simulation import api as G
        B = int(argv[1])
        fused = argv[3:] == ["fused"]      # the eager capacities, the loop as one kernel
        sc, op0, gr, cfg, pos = scene_inputs(eager=fused or argv[3:] == ["eager"], fused=fused)
        dev = jax.devices()[0]
        q = jnp.asarray(pos[grips(sc.mesh, B)])

        def one(o, g0, qq):
            res, F, _ = G._run(o, dataclasses.replace(g0, grip=qq), cfg)
            return res.status, res.count
        fn = split_vmap(one, in_axes=(None, None, 0)) if kind == "split" else jax.jit(jax.vmap(one, in_axes=(None, None, 0)))
        t = time.perf_counter()
        comp = fn.lower(op0, gr, q).compile()
        print(json.dumps(dict(compile_s=time.perf_counter() - t, platform=dev.platform, devices=jax.device_count())),
              flush=True)
        reps = int(argv[2]) if len(argv) > 2 else 1
        t_run, (status, count) = best_of(lambda: jax.block_until_ready(comp(op0, gr, q)), reps)
        print(json.dumps(dict(run_s=t_run, max_rows=int(np.max(count)), mean_rows=float(np.mean(count)),
                              success=int(np.sum(np.asarray(status) == 0)))), flush=True)


def sub(args, timeout):
    """Run ``throughput.py --worker ARGS`` in a fresh process: (list of JSON results, timed out)."""
    import json
    import subprocess
    env = dict(os.environ, PYTHONPATH=os.path.dirname(HERE) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", *map(str, args)]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
        out, timed_out = p.stdout, False
        if p.returncode != 0:
            print(p.stderr[-2000:], file=sys.stderr)
    except subprocess.TimeoutExpired as exc:
        out, timed_out = exc.stdout or "", True
        out = out.decode() if isinstance(out, bytes) else out
    return [json.loads(ln) for ln in out.splitlines() if ln.startswith("{")], timed_out


def main(argv=None):
    import argparse
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="~1-2 min smoke run: small batches, 2 repeats")
    p.add_argument("--reps", type=int, default=5)
    p.add_argument("--batches", type=int, nargs="+", default=[1, 16, 64, 256], help="CPU batch sizes")
    p.add_argument("--gpu-batches", type=int, nargs="+", default=[1, 256, 1024, 4096])
    p.add_argument("--gpu-only", action="store_true",
                   help="on a GPU machine: the scene, one squeeze and the GPU batches only (throughput_gpu.*)")
    p.add_argument("--gpu-reps", type=int, default=3, help="repeats per GPU batch (best of)")
    p.add_argument("--gpu-timeout", type=float, default=600.0, help="seconds per GPU batch point (fresh process)")
    p.add_argument("--vmap-timeout", type=float, default=90.0,
                   help="seconds per CPU vmap point (compile + one run) before it is stopped and reported as a bound")
    p.add_argument("--loop-max", type=int, default=256, help="largest batch timed as a plain loop")
    p.add_argument("--processes", type=int, default=None, help="pool workers (default: one per core)")
    p.add_argument("--out", default=os.path.join(HERE, "results"))
    p.add_argument("--worker", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        return worker(a.worker)
    if a.quick:     # every code path once, smallest sizes; no separate cold-compile process
        a.reps, a.batches, a.gpu_batches, a.vmap_timeout, a.loop_max = 1, [4], [1, 256], 30.0, 4

    import jax
    jax.config.update("jax_enable_x64", True)
    import jaxsqueeze as jsq
    from jaxsqueeze.batch import cpu_count, map_scenes
    from jaxsqueeze.simulation import api as G
    from jaxsqueeze.simulation import engine as E
    import squeeze as squeeze_mod
    from squeeze import load1, machine, write_csv
    import throughput as T      # pool workers import evaluate_grip from the module "throughput"

    info = machine().replace(squeeze_mod.DATE, time.strftime("%Y-%m-%d"))
    print(info, flush=True)
    rows = []

    def rec(section, item, **kw):
        r = dict(section=section, item=item, load=load1(), **kw)
        rows.append(r)
        print({k: (round(v, 5) if isinstance(v, float) else v) for k, v in r.items()}, flush=True)
        return r

    sc, op0, gr, cfg, pos = scene_inputs(eager=True)
    cfg_traced = scene_inputs()[3]
    rec("scene", "foam square", nodes=sc.mesh.n, m=sc.mesh.m, friction_model=cfg.friction_model,
        capacity=cfg.capacity, capacity_traced=cfg_traced.capacity, threads=cpu_count())

    # ---- one squeeze after compilation
    t = time.perf_counter()
    core = G._run.lower(op0, gr, cfg).compile()      # the program an eager jsq.squeeze runs
    jax.block_until_ready(core(op0, gr))
    rec("compile", "in this process (first call of the core, incl. trace)", seconds=time.perf_counter() - t)
    t_core, out = best_of(lambda: jax.block_until_ready(core(op0, gr)), a.reps)
    res = out[0]
    n_rows = int(res.count)
    rec("squeeze", "core (jitted _run), best of reps", seconds=t_core, rows=n_rows, per_row_ms=1e3 * t_core / n_rows,
        events=int(res.n_events), bracket_iters=int(res.stats.bracket_iters), target=TARGETS["per_squeeze"])
    from threadpoolctl import threadpool_limits

    def core_1blas():
        with threadpool_limits(1, "blas"):     # jaxlib's CPU LAPACK calls run in scipy's OpenBLAS
            return jax.block_until_ready(core(op0, gr))
    core64 = G._run.lower(op0, gr, cfg_traced).compile()
    jax.block_until_ready(core64(op0, gr))
    t64, _ = best_of(lambda: jax.block_until_ready(core64(op0, gr)), a.reps)
    rec("squeeze", f"core with the traced default of {cfg_traced.capacity} slots (what vmap runs)", seconds=t64,
        rows=n_rows, per_row_ms=1e3 * t64 / n_rows)
    t_1b, _ = best_of(core_1blas, a.reps)
    rec("squeeze", "core with OpenBLAS limited to 1 thread (threadpoolctl)", seconds=t_1b, rows=n_rows,
        per_row_ms=1e3 * t_1b / n_rows, note="the squeeze's LAPACK calls are tiny; BLAS threads only wait")
    cfg_fused = dataclasses.replace(cfg, fused=True)
    if a.gpu_only:
        return gpu_section(a, rows, rec, info)
    t = time.perf_counter()
    core_f = G._run.lower(op0, gr, cfg_fused).compile()
    rec("compile", "in this process, the loop as one kernel (Settings.fused)", seconds=time.perf_counter() - t)
    t_f, out_f = best_of(lambda: jax.block_until_ready(core_f(op0, gr)), a.reps)
    F0, F1 = np.asarray(out[0].forces), np.asarray(out_f[0].forces)
    rec("squeeze", "core, the loop as one kernel (Settings.fused), best of reps", seconds=t_f, rows=int(out_f[0].count),
        per_row_ms=1e3 * t_f / int(out_f[0].count), target=TARGETS["per_squeeze"],
        note=f"same rows: {int(out_f[0].count) == n_rows}; forces differ by {np.max(np.abs(F1 - F0)):.1e} N")
    op = sc.operator()
    t_sq, _ = best_of(lambda: jsq.squeeze(sc.replace(friction=0.2 + 1e-9 * np.random.rand()), op=op), a.reps)
    rec("squeeze", "jsq.squeeze (incl. validation and trim)", seconds=t_sq, rows=n_rows,
        per_row_ms=1e3 * t_sq / n_rows)
    got, _ = sub(["core32", a.reps], timeout=300)
    if got:
        rec("squeeze", "core in float32 (fresh process, x64 off), best of reps", seconds=got[0]["run_s"],
            rows=got[0]["rows"], per_row_ms=1e3 * got[0]["run_s"] / got[0]["rows"],
            note="float32 programs compile without region analysis (compiler.NOT_FLOAT32)")

    # ---- the NumPy reference row on a representative recorded row (most sliding contacts): the
    # squeeze is run again with max_steps = k, so its final state is the contact set of row k
    from jaxsqueeze.simulation import contacts
    st = jax.jit(lambda o, g: E.simulate(o, g, cfg))(op0, gr)
    modes = np.asarray(st.hist[1][:n_rows])
    k = min(int(np.argmax((modes >= 2).sum(1) * 1000 + (modes > 0).sum(1))), n_rows - 2)
    cfg_k = dataclasses.replace(cfg, max_steps=k)
    srow = jax.jit(lambda o, g: E.simulate(o, g, cfg_k))(op0, gr)
    assert int(srow.count) == k + 1 and np.array_equal(np.asarray(srow.nodes.mode), modes[k])
    model = E.make_model(op0, gr, cfg)
    d1 = jax.numpy.minimum(srow.d + model.h, model.D)
    inp = row_inputs(op0, gr, cfg, srow, d1)
    t_ref, ref = reference_row(inp, reps=max(20, 4 * a.reps))
    one = jax.jit(lambda o, g, sr, d: contacts.solve(E.make_model(o, g, cfg), sr.slots, sr.nodes, d))
    s1 = jax.block_until_ready(one(op0, gr, srow, d1))
    t_one, _ = best_of(lambda: jax.block_until_ready(one(op0, gr, srow, d1)), max(20, 4 * a.reps))
    idx = np.flatnonzero(modes[k] > 0)
    err = float(np.max(np.abs(ref["f"] - np.asarray(s1.F)[idx])) / np.max(np.abs(ref["f"])))
    per_row = t_core / n_rows
    rec("reference", f"numpy/scipy row (row {k}: {int((modes[k] > 0).sum())} contacts, "
        f"{int((modes[k] >= 2).sum())} sliding, {ref['iters']} Newton its)", per_row_ms=1e3 * t_ref,
        rel_err_vs_jax=err, note="LU of 2s+3 bordered matrix, slip Newton, dtheta/deps, gaps, cone margins")
    with threadpool_limits(1, "blas"):
        t_ref1, _ = reference_row(inp, reps=max(20, 4 * a.reps))
    rec("reference", "numpy/scipy row, OpenBLAS limited to 1 thread", per_row_ms=1e3 * t_ref1,
        ratio_to_numpy=t_ref1 / t_ref)
    rec("reference", "jax contacts.solve alone on the same row (jitted, S = capacity slots)", per_row_ms=1e3 * t_one,
        ratio_to_numpy=t_one / t_ref)
    rec("reference", "jax per recorded row in a squeeze (core / rows)", per_row_ms=1e3 * per_row,
        ratio_to_numpy=per_row / t_ref, target=TARGETS["per_row"])
    rec("reference", "jax per squeeze vs numpy rows x recorded rows", seconds=t_core, numpy_s=t_ref * n_rows,
        ratio_to_numpy=t_core / (t_ref * n_rows))

    # ---- compilation: fresh processes, without and with the persistent cache
    import tempfile
    r, to = sub(["compile"], 300) if not a.quick else ([], False)
    if r:
        rec("compile", "cold, fresh process, no persistent cache", seconds=r[0]["trace_lower_s"] + r[0]["compile_s"],
            **r[0], target=TARGETS["compile"])
        r, _ = sub(["compile", "plain"], 300)
        if r:
            rec("compile", "cold, fresh process, plain jax.jit (no compiler options)",
                seconds=r[0]["trace_lower_s"] + r[0]["compile_s"], **r[0])
        r, _ = sub(["compile", "fused"], 300)
        if r:
            rec("compile", "cold, fresh process, the loop as one kernel (Settings.fused)",
                seconds=r[0]["trace_lower_s"] + r[0]["compile_s"], **r[0])
        r, _ = sub(["first"], 300)
        if r:
            rec("compile", f"first jsq.squeeze in a fresh process: operator build, validation, {r[0]['programs']} "
                "compiled programs, the squeeze and its field", seconds=r[0]["first_s"], rows=r[0]["rows"])
    with tempfile.TemporaryDirectory() as tmp:
        r1, _ = sub(["compile", tmp], 300)
        r2, _ = sub(["compile", tmp], 300)
        if r1:
            rec("compile", "fresh process, empty persistent cache (writes it)",
                seconds=r1[0]["trace_lower_s"] + r1[0]["compile_s"], **r1[0])
        if r2:
            rec("compile", "second fresh process, persistent cache warm",
                seconds=r2[0]["trace_lower_s"] + r2[0]["compile_s"], **r2[0], target=TARGETS["compile"])

    # ---- batches on the CPU: a plain loop, vmap, and the process pool
    loop_pg = None
    for B in a.batches:
        q = grips(sc.mesh, B)
        if B <= a.loop_max:
            dt, outs = best_of(lambda: [evaluate_grip(g) for g in q], a.reps)    # as the vmap: best of reps
            loop_pg = dt / B
            rec("batch", "loop of jsq.squeeze (one process, XLA default threads)", batch=B, seconds=dt,
                per_grasp_ms=1e3 * dt / B, evals_per_min=60 * B / dt, mean_rows=float(np.mean([o[1] for o in outs])),
                success=sum(o[0] == 0 for o in outs))
        r, to = sub(["vmap", B, a.reps], a.vmap_timeout)
        if to:
            comp_s = r[0]["compile_s"] if r else float("nan")
            bound = a.vmap_timeout - (comp_s if r else 0.0)
            rec("batch", "jax.vmap of the core (stopped: lower bound)", batch=B, compile_s=comp_s,
                seconds=f">{bound:.0f}", per_grasp_ms=f">{1e3 * bound / B:.0f}", evals_per_min=f"<{60 * B / bound:.0f}",
                note=f"did not finish within {a.vmap_timeout:.0f} s", target=TARGETS["vmap"])
        elif len(r) >= 2:
            rec("batch", "jax.vmap of the core", batch=B, compile_s=r[0]["compile_s"], seconds=r[1]["run_s"],
                per_grasp_ms=1e3 * r[1]["run_s"] / B, evals_per_min=60 * B / r[1]["run_s"], max_rows=r[1]["max_rows"],
                mean_rows=r[1]["mean_rows"], success=r[1]["success"],
                ratio_to_loop=(r[1]["run_s"] / B) / loop_pg if loop_pg else "", target=TARGETS["vmap"])
        if B > 1:
            for variant, what in ((), " (one per core)"), (("eager",), ", the eager capacities (32 slots, 8 sliding)"), (
                    ("fused",), ", the loop as one kernel (Settings.fused, eager capacities: 32 slots, 8 sliding)"):
                r, to = sub(["split", B, a.reps, *variant], a.vmap_timeout)
                if len(r) >= 2:
                    rec("batch", f"batch.split_vmap over {r[0]['devices']} host devices{what}",
                        batch=B, compile_s=r[0]["compile_s"], seconds=r[1]["run_s"],
                        per_grasp_ms=1e3 * r[1]["run_s"] / B, evals_per_min=60 * B / r[1]["run_s"],
                        max_rows=r[1]["max_rows"], success=r[1]["success"],
                        ratio_to_loop=(r[1]["run_s"] / B) / loop_pg if loop_pg else "", target=TARGETS["evals_per_min"])
            with tempfile.TemporaryDirectory() as tmp:
                t = time.perf_counter()
                outs = map_scenes(T.evaluate_grip, list(q), processes=a.processes, cache=tmp, progress=False)
                dt = time.perf_counter() - t
            rec("batch", f"batch.map_scenes pool ({a.processes or cpu_count()} processes, 1 XLA thread each; "
                "incl. start-up and compile)", batch=B, seconds=dt, per_grasp_ms=1e3 * dt / B,
                evals_per_min=60 * B / dt, success=sum(o[0] == 0 for o in outs),
                ratio_to_loop=(dt / B) / loop_pg if loop_pg else "", target=TARGETS["evals_per_min"])
            if B == max(a.batches) and not a.quick:   # the same pool again, compiled programs now in the cache
                with tempfile.TemporaryDirectory() as tmp:
                    map_scenes(T.evaluate_grip, list(q[:2 * (a.processes or cpu_count())]), processes=a.processes,
                               cache=tmp, progress=False)
                    t = time.perf_counter()
                    map_scenes(T.evaluate_grip, list(q), processes=a.processes, cache=tmp, progress=False)
                    dt = time.perf_counter() - t
                rec("batch", "batch.map_scenes pool, persistent cache warm (incl. start-up)", batch=B, seconds=dt,
                    per_grasp_ms=1e3 * dt / B, evals_per_min=60 * B / dt,
                    ratio_to_loop=(dt / B) / loop_pg if loop_pg else "", target=TARGETS["evals_per_min"])

    gpu_section(a, rows, rec, info)


def gpu_section(a, rows, rec, info):
    """``vmap`` of the core over ``a.gpu_batches`` candidate grips on the GPU, each batch in a
    fresh process; writes the CSV and the plot (``throughput_gpu.*`` with ``--gpu-only``)."""
    import jax

    from squeeze import write_csv
    cols = ["section", "item", "batch", "seconds", "per_row_ms", "per_grasp_ms", "evals_per_min", "ratio_to_numpy",
            "ratio_to_loop", "compile_s", "trace_lower_s", "setup_s", "cache_hits", "rows", "mean_rows", "max_rows",
            "events", "bracket_iters", "success", "numpy_s", "rel_err_vs_jax", "nodes", "m", "load", "target", "note"]
    name = "throughput_gpu" if a.gpu_only else "throughput_quick" if a.quick else "throughput"
    if jax.devices()[0].platform == "gpu":
        kind = jax.devices()[0].device_kind
        for variant, what in (((), "the traced default: 64 slots"),
                              (("eager",), "Settings(capacity=32, sliding_capacity=8)")):
            for B in a.gpu_batches:
                r, to = sub(["vmap", B, a.gpu_reps, *variant], a.gpu_timeout)
                if len(r) >= 2:
                    rec("gpu", f"jax.vmap of the core on {kind}, {what}", batch=B,
                        compile_s=r[0]["compile_s"], seconds=r[1]["run_s"], per_grasp_ms=1e3 * r[1]["run_s"] / B,
                        evals_per_min=60 * B / r[1]["run_s"], max_rows=r[1]["max_rows"], mean_rows=r[1]["mean_rows"],
                        success=r[1]["success"], target=TARGETS["gpu"])
                else:
                    rec("gpu", f"jax.vmap of the core on {kind}, {what} (failed or timed out)", batch=B,
                        compile_s=r[0]["compile_s"] if r else "", note=f"timed out after {a.gpu_timeout:.0f} s: {to}")
                write_csv(os.path.join(a.out, name + ".csv"), rows, cols, info)    # a stopped run keeps its points
    else:
        rec("gpu", "no GPU here: GPU batches 1/256/1024/4096 not run", note=jax.devices()[0].platform)
    write_csv(os.path.join(a.out, name + ".csv"), rows, cols, info)
    plot(rows, os.path.join(a.out, name + ".png"), info)
    report(rows)


def _num(v):
    try:
        return float(str(v).lstrip("<>"))
    except ValueError:
        return float("nan")


def plot(rows, path, info):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.2), dpi=80)
    series = {}
    for r in rows:
        if r["section"] in ("batch", "gpu") and "batch" in r:
            key = r["item"].split(" (")[0] + (" (lower bound)" if "lower bound" in r["item"] else "")
            series.setdefault(key, []).append((r["batch"], _num(r["per_grasp_ms"])))
    for key, pts in series.items():
        b, v = zip(*sorted(pts))
        ax[0].loglog(b, v, "v--" if "bound" in key else "o-", label=key)
    ax[0].axhline(6.0, color="k", lw=0.8, ls=":", label="10,000 evaluations/min")
    if any(r["section"] == "gpu" and "batch" in r for r in rows):
        ax[0].axhline(0.5, color="r", lw=0.8, ls=":", label="GPU target 0.5 ms (B >= 1,024)")
    ax[0].set_xlabel("batch (grasps)")
    ax[0].set_ylabel("wall time per grasp [ms]")
    ax[0].grid(True, which="both", alpha=0.3)
    ax[0].legend(fontsize=7)
    comp = [r for r in rows if r["section"] == "compile"]
    ax[1].barh([r["item"][:48] for r in comp], [_num(r["seconds"]) for r in comp])
    ax[1].axvline(2.0, color="k", lw=0.8, ls=":", label="target 2 s")
    ax[1].set_xlabel("trace + lower + compile of the squeeze [s]")
    ax[1].tick_params(axis="y", labelsize=7)
    ax[1].legend(fontsize=7)
    fig.suptitle(f"foam square throughput: {info}", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    print(f"wrote {path}")


def report(rows):
    print("\n| section | what | batch | time [s] | per row [ms] | per grasp [ms] | evals/min | ratio | load |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        def f(key, nd=3):
            v = r.get(key, "")
            return f"{v:.{nd}f}" if isinstance(v, float) else str(v)
        ratio = r.get("ratio_to_numpy", r.get("ratio_to_loop", ""))
        ratio = f"{ratio:.2f}x" if isinstance(ratio, float) else ratio
        print(f"| {r['section']} | {r['item']} | {r.get('batch', '')} | {f('seconds')} | {f('per_row_ms')} | "
              f"{f('per_grasp_ms', 1)} | {f('evals_per_min', 0)} | {ratio} | {r['load']:.2f} |")


if __name__ == "__main__":
    sys.exit(main())
