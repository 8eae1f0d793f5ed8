"""Profile of one squeeze row and of its compilation (issue 11, "measure first").

The foam square of ``jaxsqueeze/scenes/foam_square.toml`` (1,265 nodes, m = 122, Coulomb
stick/slip, 15 mm). Three parts:

* **Program size.** Primitives in the traced squeeze (a ``jax.make_jaxpr`` walk through every
  nested jaxpr, as ``tests/simulation/test_squeeze.py::_primitives``) and instructions in the compiled HLO
  (``jax.jit(...).lower(...).compile().as_text()``), bucketed by the ``op_name`` metadata:
  the ``init`` and ``squeeze`` named scopes of ``engine.simulate``, and inside the loop body the
  one configuration solve (with its ``jvp``) and the phase branches of ``engine.step``
  (``switch`` branches 0-2: advance + locate_event with apply_event, check, prime).
* **Compilation by stage.** Each engine stage jitted alone on a representative state (its own
  trace + lower + compile time and HLO size): ``contacts.solve`` and its ``jvp``, ``reconcile``
  with one new contact (the bordering update of the inverse), ``apply_event``, ``finish``,
  ``step`` and ``init``.
* **Executed operations.** One run of the compiled squeeze under ``jax.profiler`` with
  XLA:CPU's per-operation trace events on: the operations (thunks) it executes per loop
  iteration, the copies among them, by part of the loop body (the named scopes of
  ``engine.step``) and by kind. On the CPU each costs a dispatch of a few tenths of a
  microsecond, which at this problem size is most of the time.
* **Time per stage.** Each of those stages jitted alone, best of ``--reps`` calls after its
  compile, on the state of a recorded row of the real squeeze (the contact set there, the next
  step's depth). Times are multiplied by how often a squeeze calls them (from its ``stats``)
  and compared with the whole squeeze's time.

Writes ``results/profile.csv`` (one row per measured item) and prints markdown tables.

    .venv/bin/python benchmarks/profile_row.py          # ~1 min on 2 cores
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


SCOPES = [  # (label, regex on op_name), first match wins: the named scopes of engine.step
    ("squeeze loop: the one solve and its jvp", r"squeeze/while/body/solve/"),
    ("squeeze loop: phases advance + locate_event, apply_event", r"squeeze/while/body/phase/cond/branch_0_fun"),
    ("squeeze loop: phase check (hypothesis, settle)", r"squeeze/while/body/phase/cond/branch_1_fun"),
    ("squeeze loop: phase prime", r"squeeze/while/body/phase/cond/branch_2_fun"),
    ("squeeze loop: the phase switch itself", r"squeeze/while/body/phase/"),
    ("squeeze loop: target (the next depth, the event estimate)", r"squeeze/while/body/target/"),
    ("squeeze loop: accept (record the row, status)", r"squeeze/while/body/accept/"),
    ("squeeze loop: reconcile (bordering updates of the slots)", r"squeeze/while/body/reconcile/"),
    ("squeeze loop: other", r"squeeze/"),
    ("init (first touch)", r"init/"),
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


PARTS = [  # (label, regex on op_name) for executed operations, first match wins
    ("solve: slip-angle Newton loop", r"/solve/.*newton"),
    ("solve: the rest of the configuration solve and its jvp", r"/solve/"),
    ("phase switch (advance + locate_event + apply_event, check, prime)", r"/phase/"),
    ("accept (record the row, status)", r"/accept/"),
    ("reconcile (bordering updates of the contact slots)", r"/reconcile/"),
    ("target (the depth of the solve)", r"/target/"),
]


def executed_ops(lowered, args, loop_iterations, tmp):
    """What one compiled squeeze executes on the CPU, from a profiler trace: XLA:CPU runs a
    program as a sequence of operations ("thunks": a fusion, a dot, a LAPACK call, a copy,
    a loop or a conditional), each with a dispatch cost of a few tenths of a microsecond.
    Returns [(label, count per loop iteration)]: every operation, the copies among them,
    by part of the loop body (``PARTS``, from the op_name of the HLO instruction), and the
    most frequent kinds."""
    import glob

    import jax
    from jax.profiler import ProfileData

    from jaxsqueeze import compiler
    comp = lowered.compile(compiler_options=dict(compiler.options()) | {"xla_cpu_enable_xprof_traceme": True})
    jax.block_until_ready(comp(*args))
    jax.profiler.start_trace(tmp)
    jax.block_until_ready(comp(*args))
    jax.profiler.stop_trace()
    names = collections.Counter()
    for f in glob.glob(os.path.join(tmp, "**", "*.xplane.pb"), recursive=True):
        for plane in ProfileData.from_file(f).planes:
            for line in plane.lines:
                if line.name.startswith("tf_XLA"):
                    names.update(ev.name for ev in line.events
                                 if not ev.name.startswith(("ThunkExecutor", "end:")))
    op_name = dict(re.findall(r'^\s+(?:ROOT )?%?(\S+) = .*?op_name="([^"]*)"', comp.as_text(), re.M))
    parts = collections.Counter()
    for name, n in names.items():
        label = "copies between control-flow regions (no op_name)" if name.startswith("copy") else "other"
        for lab, rx in PARTS:
            if re.search(rx, op_name.get(name, "")):
                label = lab
                break
        parts[label] += n
    kinds = collections.Counter()
    for name, n in names.items():
        kinds[re.sub(r"(\.\d+)+$", "", name)] += n
    per = lambda n: n / loop_iterations  # noqa: E731
    total = sum(names.values())
    return ([("all operations", per(total)), ("copies", per(sum(n for k, n in names.items() if k.startswith("copy"))))]
            + [(lab, per(parts[lab])) for lab, _ in PARTS] + [(lab, per(parts[lab])) for lab in
                                                                ("copies between control-flow regions (no op_name)", "other")]
            + [(f"kind: {k}", per(n)) for k, n in kinds.most_common(8)])


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
    gr, cfg = G.grasp_of(sc, op), G.eager_config(sc, op)
    sim = jax.jit(lambda o, g: E.simulate(o, g, cfg))
    st = jax.block_until_ready(sim(op0, gr))
    return sc, op0, gr, cfg, st, sim


def row_state(op0, gr, cfg, k):
    """The loop state at recorded row ``k``: the squeeze run again with ``max_steps = k`` stops
    there (its contact slots, modes, anchors and forces are those of row k)."""
    import jax

    from jaxsqueeze.simulation import engine as E
    cfg_k = dataclasses.replace(cfg, max_steps=k)
    return jax.jit(lambda o, g: E.simulate(o, g, cfg_k))(op0, gr)


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
        newton_iters=int(s.newton_iters), solves=int(s.solves))

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

    # ---- operations executed per loop iteration (one profiler trace of the compiled squeeze)
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        for label, n in executed_ops(G._run.lower(op0, gr, cfg), (op0, gr), int(s.solves), tmp):
            rec("executed", label, per_iteration=n)

    # ---- a representative row: the recorded row with the most sliding contacts
    modes = np.asarray(st.hist[1][:rows])
    k = a.row if a.row is not None else int(np.argmax((modes >= 2).sum(1) * 1000 + (modes > 0).sum(1)))
    k = min(k, rows - 2)
    srow = row_state(op0, gr, cfg, k)
    n_contact, n_slide = int((modes[k] > 0).sum()), int((modes[k] >= 2).sum())
    rec("row", "profiled row", row=k, contacts=n_contact, sliding=n_slide, depth_mm=float(st.hist[0][k] * op0.length) * 1e3)

    from jaxsqueeze.simulation import contacts
    from jaxsqueeze.simulation.laws import FREE, STICK
    model = model_fn(op0, gr)
    d1 = jnp.minimum(srow.d + model.h, model.D)
    adv = dataclasses.replace(srow, phase=jnp.asarray(E.ADVANCE, jnp.int32), status=jnp.asarray(E.RUNNING, jnp.int32))
    solve = lambda o, g, sr, d: contacts.solve(model_fn(o, g), sr.slots, sr.nodes, d)  # noqa: E731
    s1 = jax.jit(solve)(op0, gr, srow, d1)
    # one free node joins (what reconcile does after an event A): the nearest free node to a contact
    free = np.flatnonzero(modes[k] == FREE)
    new = int(free[np.argmin(np.min(np.abs(free[:, None] - np.flatnonzero(modes[k] > FREE)[None]), 1))])
    joined = dataclasses.replace(srow, nodes=srow.nodes._replace(mode=srow.nodes.mode.at[new].set(STICK)))
    stages = [
        ("an empty jitted call (dispatch overhead of a stand-alone stage)", lambda x: x + 1.0, (d1,)),
        ("contacts.solve (slip Newton + forces + gaps + event functions)", solve, (op0, gr, srow, d1)),
        ("jvp of contacts.solve (the one solve of a loop iteration)",
         lambda o, g, sr, d: jax.jvp(lambda dd: solve(o, g, sr, dd), (d,), (jnp.ones_like(d),)), (op0, gr, srow, d1)),
        ("reconcile with one new contact (bordering update of the inverse)",
         lambda o, g, sr: E.reconcile(model_fn(o, g), sr), (op0, gr, joined)),
        ("apply_event (refine d*, apply, log)", lambda o, g, sr: E.apply_event(model_fn(o, g), sr), (op0, gr, adv)),
        ("finish (record the row, status)", lambda o, g, sr: E.finish(model_fn(o, g), sr, jnp.array(True)), (op0, gr, adv)),
        ("step (one loop iteration, phase ADVANCE)", lambda o, g, sr: E.step(model_fn(o, g), sr), (op0, gr, adv)),
        ("init (first touch)", lambda o, g: E.init(model_fn(o, g)), (op0, gr)),
    ]
    times = {}
    for label, f, args in stages:
        tl, tc, text, comp = compile_time(f, *args)
        t = best(comp, *args, reps=a.reps)
        times[label.split(" (")[0]] = t
        rec("stage", label, trace_lower_s=tl, compile_s=tc, run_ms=1e3 * t, **hlo_stats(text))

    # how often a squeeze runs each stage (from its stats): one solve (with its jvp) per loop
    # iteration, one finish per recorded row
    est = dict(solve=int(s.solves) * times["jvp of contacts.solve"], finish=rows * times["finish"],
               step=int(s.solves) * times["step"])
    for k2, v in est.items():
        rec("budget", f"{k2}: count x stage time ({int(s.solves)} solves, {rows} rows)", seconds=v, share_of_run=v / run)

    # ---- NumPy reference of the same row (bordered solve, slip Newton, gap test)
    ref_in = row_inputs(op0, gr, cfg, srow, d1)
    t_ref, ref = reference_row(ref_in, reps=max(20, a.reps))
    idx = np.flatnonzero(modes[k] > 0)
    f_jax = np.asarray(s1.F)[idx]
    err = float(np.max(np.abs(ref["f"] - f_jax)) / np.max(np.abs(f_jax)))
    free_now = modes[k] == 0
    err_gap = float(np.max(np.abs(ref["gap"][free_now] - np.asarray(s1.e)[free_now])))
    rec("reference", "numpy row: LU of the bordered matrix + slip Newton + implicit rates + gap test",
        run_ms=1e3 * t_ref, newton_iters=ref["iters"], force_rel_err_vs_jax=err, gap_abs_err_vs_jax=err_gap,
        jax_solve_over_numpy=times["contacts.solve"] / t_ref)

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
            print(f"| {r['item']} | {r['trace_lower_s']:.2f} | {r['compile_s']:.2f} | {r['hlo_instructions']} | "
                  f"{r['run_ms']:.3f} | {r['load']:.1f} |")
    print("\n| compiled squeeze, HLO instructions by scope | count | share |")
    print("|---|---:|---:|")
    for r in out:
        if r["part"] == "hlo_scope":
            print(f"| {r['item']} | {r['count']} | {100 * r['share']:.0f} % |")
    print("\n| executed XLA operations per loop iteration | count |")
    print("|---|---:|")
    for r in out:
        if r["part"] == "executed":
            print(f"| {r['item']} | {r['per_iteration']:.1f} |")
    for r in out:
        if r["part"] in ("squeeze", "size", "row", "budget", "reference"):
            print(r)


if __name__ == "__main__":
    sys.exit(main())
