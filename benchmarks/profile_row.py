"""Profile of one squeeze row and of its compilation (issue 11, "measure first").

The foam square of ``jaxsqueeze/scenes/foam_square.toml`` (1,265 nodes, m = 122, Coulomb
stick/slip, 15 mm). Three parts:

* **Program size.** Primitives in the traced squeeze (a ``jax.make_jaxpr`` walk through every
  nested jaxpr, as ``tests/simulation/test_squeeze.py::_primitives``) and instructions in the compiled HLO
  (``jax.jit(...).lower(...).compile().as_text()``), bucketed by the ``op_name`` metadata:
  the ``init`` and ``loop`` named scopes of ``engine.simulate``, and inside the loop body the
  ``advance`` and ``event`` branches of ``engine.step`` (``cond/branch_0_fun``, ``branch_1_fun``).
* **Compilation by stage.** Each engine stage jitted alone on a representative state (its own
  trace + lower + compile time and HLO size): ``pack``, ``solve_at``, ``locate_event``,
  ``apply_event``, ``step`` and ``init``.
* **Time per stage.** Each of those stages jitted alone, best of ``--reps`` calls after its
  compile, on the state of a recorded row of the real squeeze (the contact set there, the next
  step's depth). Times are multiplied by how often a squeeze calls them (from its ``stats``)
  and compared with the whole squeeze's time.

Writes ``results/profile.csv`` (one row per measured item) and prints markdown tables.

    .venv/bin/python benchmarks/profile_row.py          # ~3 min on 2 cores
"""
from __future__ import annotations

import argparse
import collections
import dataclasses
import os
import re
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)


def primitive_count(fn, *args):
    """Counter of primitives in ``jax.make_jaxpr(fn)(*args)`` including every nested jaxpr."""
    import jax
    closed = jax.make_jaxpr(fn)(*args)
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


def hlo_stats(text: str) -> dict:
    """Instruction and computation counts of a compiled HLO module's text."""
    return dict(hlo_chars=len(text), hlo_instructions=len(re.findall(r"^\s+(?:ROOT )?\S+ = ", text, re.M)),
                hlo_computations=len(re.findall(r"^(?:ENTRY )?%?\S+ .*\{\s*$", text, re.M)))


SCOPES = [  # (label, regex on op_name), first match wins
    ("loop / step: event branch / jvp of solve_at at hi (apply_event)", r"loop/while/body/cond/branch_1_fun/jvp\("),
    ("loop / step: event branch / locate_event while", r"loop/while/body/cond/branch_1_fun/while"),
    ("loop / step: event branch / other (solves at d*, hypothesis, re-solve, log)", r"loop/while/body/cond/branch_1_fun"),
    ("loop / step: advance branch (settle, finish)", r"loop/while/body/cond/branch_0_fun"),
    ("loop / step: pack + solve at d1 (before the cond)", r"loop/"),
    ("init (first touch, hypothesis, first solve)", r"/init/"),
    ("other (to_result, make_model)", r""),
]


def hlo_by_scope(text: str) -> list:
    names = re.findall(r'op_name="([^"]*)"', text)
    c = collections.Counter()
    for n in names:
        for label, rx in SCOPES:
            if re.search(rx, n):
                c[label] += 1
                break
    untagged = hlo_stats(text)["hlo_instructions"] - len(names)
    return [(label, c[label]) for label, _ in SCOPES] + [("(no op_name: parameters, tuples, constants)", untagged)]


def best(f, *args, reps=7):
    import jax
    jax.block_until_ready(f(*args))
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        jax.block_until_ready(f(*args))
        ts.append(time.perf_counter() - t)
    return min(ts)


def compile_time(f, *args):
    """(trace+lower seconds, compile seconds, compiled HLO text) of ``jax.jit(f)`` at ``args``."""
    import jax
    t = time.perf_counter()
    low = jax.jit(f).lower(*args)
    t1 = time.perf_counter()
    comp = low.compile()
    t2 = time.perf_counter()
    return t1 - t, t2 - t1, comp.as_text(), comp


def setup(scene=None):
    """(scene, op without field, grasp, cfg, final state of the squeeze, run time of the core)."""
    import jax

    from jaxsqueeze.simulation import api as G
    from jaxsqueeze.simulation import engine as E
    from squeeze import foam
    sc = scene or foam()
    op = sc.operator()
    op0 = dataclasses.replace(op, field=None)
    gr, cfg = G.grasp_of(sc, op), G.config_of(sc)
    sim = jax.jit(lambda o, g: E.simulate(o, g, cfg))
    st = jax.block_until_ready(sim(op0, gr))
    return sc, op0, gr, cfg, st, sim


def row_state(model_fn, op0, gr, st, k):
    """A loop state rebuilt from recorded row ``k`` of the final state ``st`` (history arrays)."""
    import jax
    import jax.numpy as jnp

    from jaxsqueeze.simulation import engine as E
    st0 = jax.jit(lambda o, g: E.init(model_fn(o, g)))(op0, gr)
    depth, mode, finger, theta, F, u, *_ = st.hist
    return dataclasses.replace(st0, d=depth[k], mode=mode[k].astype(jnp.int32), finger=finger[k].astype(jnp.int32),
                               theta=theta[k], F=F[k], u=u[k], status=jnp.array(E.RUNNING, jnp.int32),
                               armed=jnp.ones_like(st0.armed))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reps", type=int, default=7)
    p.add_argument("--row", type=int, default=None, help="recorded row to profile (default: most sliding contacts)")
    p.add_argument("--out", default=os.path.join(HERE, "results"))
    a = p.parse_args(argv)

    import jax
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    from jaxsqueeze.simulation import api as G
    from jaxsqueeze.simulation import engine as E
    from squeeze import load1, machine, write_csv
    from throughput import reference_row, row_inputs

    info = machine()
    print(info, flush=True)
    out = []

    def rec(part, item, **kw):
        r = dict(part=part, item=item, load=load1(), **kw)
        out.append(r)
        print(r, flush=True)

    sc, op0, gr, cfg, st, sim = setup()
    model_fn = lambda o, g: E.make_model(o, g, cfg)  # noqa: E731
    rows, s = int(st.count), st.stats
    run = best(sim, op0, gr, reps=max(3, a.reps // 2))
    rec("squeeze", "simulate (jitted core, no to_result)", seconds=run, rows=rows, per_row_ms=1e3 * run / rows,
        steps=int(s.steps), events=int(s.events), bracket_iters=int(s.bracket_iters),
        newton_iters=int(s.newton_iters))

    # ---- program size
    prims = primitive_count(lambda g: E.simulate(op0, g, cfg), gr)
    rec("size", "jaxpr primitives (all nested)", count=sum(prims.values()),
        top=", ".join(f"{k} {v}" for k, v in prims.most_common(8)))
    for name in ("while", "cond", "custom_root", "pjit", "dot_general", "scatter", "gather", "custom_vmap_call"):
        if prims.get(name):
            rec("size", f"jaxpr primitive {name}", count=prims[name])
    tl, tc, text, _ = compile_time(lambda o, g: G._run(o, g, cfg), op0, gr)
    hs = hlo_stats(text)
    rec("size", "compiled HLO of jsq.squeeze core (_run)", trace_lower_s=tl, compile_s=tc, **hs)
    for label, n in hlo_by_scope(text):
        rec("hlo_scope", label, count=n, share=n / hs["hlo_instructions"])

    # ---- a representative row: the recorded row with the most sliding contacts
    modes = np.asarray(st.hist[1][:rows])
    k = a.row if a.row is not None else int(np.argmax((modes >= 2).sum(1) * 1000 + (modes > 0).sum(1)))
    k = min(k, rows - 2)
    srow = row_state(model_fn, op0, gr, st, k)
    n_contact, n_slide = int((modes[k] > 0).sum()), int((modes[k] >= 2).sum())
    rec("row", "profiled row", row=k, contacts=n_contact, sliding=n_slide, depth_mm=float(st.hist[0][k] * op0.length) * 1e3)

    pack = lambda o, g, sr: E.pack(model_fn(o, g), sr.mode, sr.finger, sr.theta, sr.armed)  # noqa: E731
    c = jax.jit(pack)(op0, gr, srow)
    model = model_fn(op0, gr)
    d1 = jnp.minimum(srow.d + model.h, model.D)
    s1 = jax.jit(lambda o, g, c, sr, d: E.solve_at(model_fn(o, g), c, sr.mode, d))(op0, gr, c, srow, d1)

    def bordered_only(o, g, sr):
        from jaxsqueeze.mechanics.bordered import bordered_matrix, slot_dofs
        S = cfg.capacity
        idx = jnp.nonzero(sr.mode > 0, size=S, fill_value=0)[0]
        active = jnp.arange(S) < jnp.sum(sr.mode > 0)
        dofs = slot_dofs(idx)
        return bordered_matrix(o.G[dofs][:, dofs], o.N[dofs], active)

    M = jax.jit(bordered_only)(op0, gr, srow)
    from jaxsqueeze.mechanics import linalg
    stages = [
        ("an empty jitted call (dispatch overhead of a stand-alone stage)", lambda x: x + 1.0, (d1,)),
        ("pack (gather A, B; bordered matrix; explicit inverse)", pack, (op0, gr, srow)),
        ("  bordered matrix alone (gather + assemble, 2S+3 = %d)" % (2 * cfg.capacity + 3), bordered_only, (op0, gr, srow)),
        ("  linalg.inv of the bordered matrix alone", lambda M: linalg.inv(M), (M,)),
        ("slip_angles (Newton on system S)", lambda o, g, c, d: E.slip_angles(model_fn(o, g), c, d), (op0, gr, c, d1)),
        ("slip_rates (implicit dθ/dε)", lambda o, g, c, d: E.slip_rates(model_fn(o, g), c, c.theta0, d),
         (op0, gr, c, d1)),
        ("solve_at (Newton + forces + gaps + event functions)",
         lambda o, g, c, sr, d: E.solve_at(model_fn(o, g), c, sr.mode, d), (op0, gr, c, srow, d1)),
        ("jvp of solve_at (apply_event's bracket end)",
         lambda o, g, c, sr, d: jax.jvp(lambda dd: E.solve_at(model_fn(o, g), c, sr.mode, dd), (d,), (jnp.ones_like(d),)),
         (op0, gr, c, srow, d1)),
        ("locate_event (whole bracket, full step [d, d+h])",
         lambda o, g, c, sr, d0, d1, e1: E.locate_event(model_fn(o, g), c, sr.mode, d0, d1, e1),
         (op0, gr, c, srow, srow.d, d1, jnp.asarray(-1e-3, d1.dtype))),
        ("locate_event in a lane without an event (what a vmap lane pays at every step)",
         lambda o, g, c, sr, d0, d1, e1: E.locate_event(model_fn(o, g), c, sr.mode, d0, d1, e1),
         (op0, gr, c, srow, srow.d, d1, jnp.abs(jnp.min(jnp.where(jnp.isfinite(s1.e), s1.e, 1.0))) + 1e-6)),
        ("apply_event (refine, apply, hypothesis, re-solve)",
         lambda o, g, sr, c, lo, hi: E.apply_event(model_fn(o, g), sr, c, lo, hi),
         (op0, gr, srow, c, srow.d + 0.5 * model.h, d1)),
        ("finish (record the row, status)", lambda o, g, sr: E.finish(model_fn(o, g), sr, jnp.array(True)),
         (op0, gr, srow)),
        ("step (one loop iteration, whichever branch)", lambda o, g, sr: E.step(model_fn(o, g), sr), (op0, gr, srow)),
        ("init (first touch)", lambda o, g: E.init(model_fn(o, g)), (op0, gr)),
    ]
    times = {}
    for label, f, args in stages:
        tl, tc, text, comp = compile_time(f, *args)
        t = best(comp, *args, reps=a.reps)
        times[label.strip()] = t
        extra = {}
        if label.startswith("locate_event"):
            extra["bracket_iters"] = int(comp(*args)[2])
        rec("stage", label, trace_lower_s=tl, compile_s=tc, run_ms=1e3 * t, **hlo_stats(text), **extra)

    # how often a squeeze runs each stage (from its stats): solve_at in step, at the bracket
    # ends and inside it, at d* and after the event, and in each hypothesis test; pack once per
    # step plus twice per event (hypothesis, re-solve)
    n_solve = rows + int(s.events) * 4 + int(s.bracket_iters)
    n_pack = rows + 2 * int(s.events)
    est = dict(solve_at=n_solve * times["solve_at (Newton + forces + gaps + event functions)"],
               pack=n_pack * times["pack (gather A, B; bordered matrix; explicit inverse)"],
               jvp=int(s.events) * times["jvp of solve_at (apply_event's bracket end)"],
               finish=rows * times["finish (record the row, status)"])
    for k2, v in est.items():
        rec("budget", f"{k2}: count x stage time", seconds=v, share_of_run=v / run)

    # ---- NumPy reference of the same row (bordered solve, slip Newton, gap test)
    ref_in = row_inputs(op0, gr, cfg, srow, d1)
    t_ref, ref = reference_row(ref_in, reps=max(20, a.reps))
    f_jax = np.asarray(s1.f)[np.asarray(c.active)]
    err = float(np.max(np.abs(ref["f"] - f_jax)) / np.max(np.abs(f_jax)))
    eA = np.asarray(s1.e)
    free = np.asarray(srow.mode) == 0
    err_gap = float(np.max(np.abs(ref["gap"][free] - eA[free])))
    rec("reference", "numpy row: LU of the bordered matrix + slip Newton + implicit rates + gap test",
        run_ms=1e3 * t_ref, newton_iters=ref["iters"], force_rel_err_vs_jax=err, gap_abs_err_vs_jax=err_gap,
        jax_solve_at_over_numpy=times["solve_at (Newton + forces + gaps + event functions)"] / t_ref)

    os.makedirs(a.out, exist_ok=True)
    cols = sorted({key for r in out for key in r}, key=lambda x: (x not in ("part", "item"), x))
    write_csv(os.path.join(a.out, "profile.csv"), out, cols, info)
    report(out, info)


def report(out, info):
    print(f"\n{info}\n")
    print("| stage (jitted alone) | trace+lower [s] | compile [s] | HLO instructions | run [ms] | load |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in out:
        if r["part"] in ("stage",):
            it = f" ({r['bracket_iters']} iterations)" if "bracket_iters" in r else ""
            print(f"| {r['item']}{it} | {r['trace_lower_s']:.2f} | {r['compile_s']:.2f} | {r['hlo_instructions']} | "
                  f"{r['run_ms']:.3f} | {r['load']:.1f} |")
    print("\n| compiled squeeze, HLO instructions by scope | count | share |")
    print("|---|---:|---:|")
    for r in out:
        if r["part"] == "hlo_scope":
            print(f"| {r['item']} | {r['count']} | {100 * r['share']:.0f} % |")
    for r in out:
        if r["part"] in ("squeeze", "size", "row", "budget", "reference"):
            print(r)


if __name__ == "__main__":
    sys.exit(main())
