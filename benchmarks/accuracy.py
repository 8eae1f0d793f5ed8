"""What accuracy costs: error against time for each accuracy knob (DESIGN 2.8).

The foam square of ``jaxsqueeze/scenes/foam_square.toml`` squeezed 15 mm. One knob varies
at a time, the others stay at their defaults; each knob's reference is its finest setting.

* ``mesh``: ``max_edge`` 12 … 2.5 mm (refine_edge 1 mm, as in the scene file), sparse build.
* ``step``: squeeze step depth/10 … depth/200 (``max_steps=1000``; one compile).
* ``event_tol``: step x 1e-1 … 1e-9.
* ``newton_tol``: 1e-3 … 1e-13 rad.
* ``precision``: float32 (a subprocess with x64 off) against float64.
* ``build``: sparse (reference), dense, spectral.

Errors: ``force_err`` = |F2 - F2_ref| / |F2_ref| for the final total force F2 of finger 2;
``event_err`` = the largest |depth - depth_ref| of the events matched to the reference by
(node, kind, finger) in order, divided by the target depth (mesh knob: the nodes differ,
not compared); ``unmatched`` = events of either run without a partner. Time: ``core_s`` is
the best of two runs of the jitted core (compile excluded); ``total_s`` adds the
compliance build for the mesh and build knobs.

    .venv/bin/python benchmarks/accuracy.py        # ~6 min on 2 cores
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
DEPTH = 0.015


def one(scene, reps=2):
    """Squeeze once (compiling if needed), then time the core; return the numbers compared."""
    import jax

    import jaxsqueeze as jsq
    from squeeze import load1, time_core
    t = time.perf_counter()
    op = scene.operator()
    jax.block_until_ready(op.G)
    build = time.perf_counter() - t
    res = jsq.squeeze(scene)
    core, _, _ = time_core(scene, reps)
    ev = [(float(d), int(n), k, int(f)) for d, n, k, f in res.events.rows()]
    return dict(nodes=scene.mesh.n, build_s=build, core_s=core, rows=int(res.count), outcome=res.outcome.name,
                F2=np.asarray(res.total_force[-1, 1]).tolist(), events=ev, load=load1())


def compare(r, ref, events=True):
    F, F0 = np.asarray(r["F2"]), np.asarray(ref["F2"])
    r["force_err"] = float(np.linalg.norm(F - F0) / np.linalg.norm(F0))
    if not events:
        r["event_err"], r["unmatched"] = float("nan"), -1
        return r
    pool = {}
    for d, n, k, f in ref["events"]:
        pool.setdefault((n, k, f), []).append(d)
    errs, un = [], 0
    for d, n, k, f in r["events"]:
        lst = pool.get((n, k, f))
        if lst:
            errs.append(abs(d - lst.pop(0)))
        else:
            un += 1
    un += sum(len(v) for v in pool.values())
    r["event_err"] = max(errs) / DEPTH if errs else float("nan")
    r["unmatched"] = un
    return r


def worker_f32():
    """float32 run of the demo scene (x64 off), printed as JSON."""
    import jax
    jax.config.update("jax_enable_x64", False)
    import jaxsqueeze as jsq
    from squeeze import foam
    sc = foam()
    t = time.perf_counter()
    jsq.squeeze(sc)
    first = time.perf_counter() - t
    r = one(sc)
    r["first_s"] = first
    print("JSON" + json.dumps(r))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--worker-f32", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--out", default=os.path.join(HERE, "results"))
    a = p.parse_args(argv)
    if a.worker_f32:
        return worker_f32()
    import jax
    jax.config.update("jax_enable_x64", True)
    import jaxsqueeze as jsq
    from squeeze import foam, machine, write_csv

    info = machine()
    print(info, flush=True)
    base = foam()
    rows = []

    def series(knob, values, make, events=True, label=str):
        runs = [(v, one(make(v))) for v in values]
        ref = runs[-1][1]
        for v, r in runs:
            r = compare(dict(r), ref, events)
            r.update(knob=knob, value=label(v), reference=label(values[-1]))
            r["total_s"] = r["core_s"] + (r["build_s"] if knob in ("mesh", "build") else 0.0)
            rows.append(r)
            print({k: r[k] for k in ("knob", "value", "nodes", "outcome", "core_s", "total_s", "rows", "force_err",
                                     "event_err", "unmatched", "load")}, flush=True)

    series("mesh", [0.012, 0.006, 0.004, 0.0025], lambda h: foam(h, min(h, 0.001)), events=False,
           label=lambda h: f"max_edge {1e3 * h:g} mm")
    series("step", [10, 25, 50, 100, 200],
           lambda k: base.replace(settings=jsq.Settings(step=DEPTH / k, max_steps=1000)), label=lambda k: f"depth/{k}")
    step = DEPTH / 50
    series("event_tol", [1e-1, 1e-2, 1e-4, 1e-6, 1e-9],
           lambda e: base.replace(settings=jsq.Settings(event_tol=step * e)), label=lambda e: f"step x {e:g}")
    series("newton_tol", [1e-3, 1e-5, 1e-7, 1e-10, 1e-13],
           lambda e: base.replace(settings=jsq.Settings(newton_tol=e)), label=lambda e: f"{e:g} rad")
    series("build", ["dense", "spectral", "sparse"], lambda m: base.replace(method=m))

    out = subprocess.run([sys.executable, os.path.abspath(__file__), "--worker-f32"], capture_output=True, text=True)
    line = [ln for ln in out.stdout.splitlines() if ln.startswith("JSON")]
    ref64 = [r for r in rows if r["knob"] == "build" and r["value"] == "sparse"][0]
    if line:
        r32 = compare(json.loads(line[0][4:]), ref64)
        r32.update(knob="precision", value="float32", reference="float64", total_s=r32["core_s"])
        r64 = dict(ref64, knob="precision", value="float64", reference="float64", force_err=0.0, event_err=0.0,
                   unmatched=0)
        rows += [r32, r64]
        print({k: r32[k] for k in ("knob", "value", "core_s", "rows", "force_err", "event_err", "unmatched")})
    else:
        print("float32 worker failed:\n", out.stderr[-3000:])

    cols = ["knob", "value", "reference", "nodes", "build_s", "core_s", "total_s", "rows", "outcome", "force_err",
            "event_err", "unmatched", "load"]
    write_csv(os.path.join(a.out, "accuracy.csv"), rows, cols, info)
    plot(rows, os.path.join(a.out, "accuracy.png"), info)
    print("\n| knob | setting | nodes | time [s] | rows | force error | event-depth error | unmatched events | load |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        ev = "n/a" if np.isnan(r["event_err"]) else f"{r['event_err']:.1e}"
        un = "n/a" if r["unmatched"] < 0 else r["unmatched"]
        print(f"| {r['knob']} | {r['value']}{' (ref)' if r['value'] == r['reference'] else ''} | {r['nodes']} | "
              f"{r['total_s']:.3f} | {r['rows']} | {r['force_err']:.1e} | {ev} | {un} | {r['load']:.1f} |")


def plot(rows, path, info):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker  # noqa: F401
    knobs = list(dict.fromkeys(r["knob"] for r in rows))
    fig, axs = plt.subplots(2, 3, figsize=(13, 7.5), dpi=80)
    floor = 1e-16
    for ax, knob in zip(axs.flat, knobs):
        rs = [r for r in rows if r["knob"] == knob and r["value"] != r["reference"]]
        t = [r["total_s"] for r in rs]
        ax.loglog(t, [max(r["force_err"], floor) for r in rs], "o-", label="final force, finger 2 (rel.)")
        ev = [r["event_err"] for r in rs]
        if not all(np.isnan(ev)):
            ax.loglog(t, [max(e, floor) for e in ev], "s--", label="event depths (/ depth)")
        for r in rs:
            ax.annotate(r["value"].replace("max_edge ", ""), (r["total_s"], max(r["force_err"], floor)),
                        fontsize=7, xytext=(3, 3), textcoords="offset points")
        ref = [r for r in rows if r["knob"] == knob and r["value"] == r["reference"]][0]
        ax.axvline(ref["total_s"], color="gray", lw=0.8, ls=":")
        ax.set_title(f"{knob} (ref: {ref['value']}, dotted = its time)", fontsize=9)
        ax.set_xlabel("time [s]" + (" (build + squeeze)" if knob in ("mesh", "build") else " (squeeze)"))
        ax.set_ylabel("error")
        ax.grid(True, which="both", alpha=0.3)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())   # no overlapping labels
        ax.legend(fontsize=7, loc="best")
    for ax in list(axs.flat)[len(knobs):]:
        ax.axis("off")
    fig.suptitle(f"foam square 15 % squeeze: error vs time per knob (floor 1e-16) — {info}", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    print(f"wrote {path}")


if __name__ == "__main__":
    sys.exit(main())
