"""What the compile of the squeeze costs under XLA:CPU options and program shapes (issue 11).

The foam square of ``jaxsqueeze/scenes/foam_square.toml`` (1,265 nodes, m = 122, Coulomb,
15 mm, float64). Every variant runs in a fresh process (no persistent cache), which traces and
lowers ``api._run``, compiles it, then times the compiled squeeze (best of ``--reps``):

* ``plain``: ``jax.jit`` with XLA's defaults of the program an eager squeeze runs;
* ``library``: the top-level program an eager ``jsq.squeeze`` compiles
  (``jaxsqueeze.compiler.options()``: fusion emitters off, LLVM level 1; 32 contact slots and
  one 8-contact Newton system);
* ``XLA_FLAGS=...``: the plain program under one process-wide XLA flag each;
* ``traced defaults``: the program's shape a squeeze inside ``jit``/``vmap`` gets (64 slots,
  the 16-contact Newton system and the all-slot fallback), and the same with the all-slot
  Newton system only: what the program's shape costs.

Writes ``results/compile_options.csv`` and ``results/compile_options.png``.

    .venv/bin/python benchmarks/compile_options.py        # ~3 min on 2 idle cores
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

VARIANTS = [  # (label, XLA_FLAGS, worker arguments)
    ("plain", "", ["plain"]),
    ("library (compiler.options)", "", ["library"]),
    ("XLA_FLAGS fusion emitters off", "--xla_cpu_use_fusion_emitters=false", ["plain"]),
    ("XLA_FLAGS backend opt level 0", "--xla_backend_optimization_level=0", ["plain"]),
    ("XLA_FLAGS backend opt level 1", "--xla_backend_optimization_level=1", ["plain"]),
    ("XLA_FLAGS llvm expensive passes off", "--xla_llvm_disable_expensive_passes=true", ["plain"]),
    ("XLA_FLAGS codegen split 1", "--xla_cpu_parallel_codegen_split_count=1", ["plain"]),
    ("library, traced defaults (64 slots, both Newton systems)", "", ["library", "traced"]),
    ("library, 64 slots, the all-slot Newton system only", "", ["library", "traced", "fullonly"]),
]


def worker(args, reps):
    import jax
    jax.config.update("jax_enable_x64", True)
    from jaxsqueeze.simulation import api as G
    from jaxsqueeze.simulation import contacts
    from throughput import scene_inputs
    if "fullonly" in args:
        contacts.COMPACT = 10 ** 6
    sc, op0, gr, cfg, _ = scene_inputs(eager="traced" not in args)
    fn = G._run.plain if "plain" in args else G._run
    times, comp, out = timed_compile(fn, (op0, gr), cfg, reps)
    res = out[0]
    k = int(res.count)
    print(json.dumps(dict(**times, rows=k, force=float(res.total_force[k - 1, 1, 1]),
                          hlo_lines=len(comp.as_text().splitlines()))))


def timed_compile(fn, args, cfg, reps):
    """Trace and lower ``fn(*args, cfg)``, compile it, and run it ``reps`` times: ({trace_lower_s,
    compile_s, run_ms (best call)}, the compiled program, its last output)."""
    import jax
    t0 = time.perf_counter()
    low = fn.lower(*args, cfg)
    t1 = time.perf_counter()
    comp = low.compile()
    t2 = time.perf_counter()
    best = float("inf")
    for _ in range(reps):
        t = time.perf_counter()
        out = jax.block_until_ready(comp(*args))
        best = min(best, time.perf_counter() - t)
    return dict(trace_lower_s=t1 - t0, compile_s=t2 - t1, run_ms=1e3 * best), comp, out


def main():
    import argparse
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reps", type=int, default=7)
    p.add_argument("--out", default=os.path.join(HERE, "results"))
    p.add_argument("--worker", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.worker:
        return worker(a.worker, a.reps)
    from squeeze import load1, machine, write_csv
    info = machine() + time.strftime(" %H:%M UTC", time.gmtime())
    print(info, flush=True)
    rows = []
    for label, flags, args in VARIANTS:
        env = dict(os.environ, XLA_FLAGS=flags, PYTHONPATH=os.path.dirname(HERE))
        cmd = [sys.executable, os.path.abspath(__file__), "--reps", str(a.reps), "--worker", *args]
        r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
        out = [json.loads(ln) for ln in r.stdout.splitlines() if ln.startswith("{")]
        if not out:
            print(label, "failed:", r.stderr[-500:], flush=True)
            continue
        row = dict(variant=label, xla_flags=flags, load=load1(), **out[0])
        rows.append(row)
        print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()}, flush=True)
    os.makedirs(a.out, exist_ok=True)
    cols = ["variant", "xla_flags", "trace_lower_s", "compile_s", "run_ms", "rows", "force", "hlo_lines", "load"]
    write_csv(os.path.join(a.out, "compile_options.csv"), rows, cols, info)
    plot(rows, os.path.join(a.out, "compile_options.png"))


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for r in rows:
        ax.scatter(r["trace_lower_s"] + r["compile_s"], r["run_ms"], s=40)
        ax.annotate(r["variant"], (r["trace_lower_s"] + r["compile_s"], r["run_ms"]), fontsize=7,
                    xytext=(4, 3), textcoords="offset points")
    ax.set_xlabel("trace + lower + XLA compile of the squeeze [s] (fresh process)")
    ax.set_ylabel("one compiled squeeze [ms] (best of reps)")
    ax.set_yscale("log")
    ax.set_title("Foam square: compile time against run time")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
