"""Cold compile time of the squeeze against the number m of boundary nodes (issue 11).

The program's shapes follow m, and so can LLVM's work on it: until 2026-12-06 a squeeze on a
mesh whose m was a multiple of 8 (up to 256) compiled about 2.5 times slower, because LLVM's
CRC-loop recogniser (LoopIdiomRecognize) walked every use-def path of the loop that takes the
minimum over the m nodes in ``engine.estimate`` (benchmarks/README.md). This script guards
against such spikes: for each m it builds a 0.1 m x 0.1 m square with exactly m boundary nodes
(``shapes.rectangle``; m a multiple of 4: alternately a multiple of 8 and not), a Coulomb
squeeze gripped about 6 degrees off the normals (mu = 0.5, 15 mm tips, 12 mm deep, float64), and in a fresh process (no persistent cache) traces, lowers
and compiles the program an eager ``jsq.squeeze`` runs (``api._run``), then times it (best of
``--reps`` calls).

Writes ``results/compile_sizes.csv`` and ``results/compile_sizes.png``.

    .venv/bin/python benchmarks/compile_sizes.py                  # ~3 min on 2 idle cores
    .venv/bin/python benchmarks/compile_sizes.py --sizes 64 68 72 --append --label before --pythonpath /tmp/old
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def worker(m: int, reps: int) -> dict:
    import dataclasses
    import warnings

    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np

    import jaxsqueeze as jsq
    from compile_options import timed_compile
    from jaxsqueeze.simulation import api
    warnings.simplefilter("ignore")          # (nearest-node ties on a coarse square)
    for edge in np.linspace(0.003, 0.02, 1200):
        mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=float(edge))
        if len(mesh.boundary) == m:
            break
    else:
        return dict(m=m, error="no square with that many boundary nodes")
    near = jsq.scene.nearest_boundary_node
    scene = jsq.Scene(mesh=mesh, material=jsq.Material(E=1e5, nu=0.3, thickness=0.0254),
                      fingers=jsq.Fingers(radius=0.015), grip=(near(mesh, (-0.005, -0.05)), near(mesh, (0.005, 0.05))),
                      friction=0.5, depth=0.012)
    op = scene.operator()
    op0 = dataclasses.replace(op, field=None)
    cfg, grasp = api.eager_config(scene, op), api.grasp_of(scene, op)
    times, _, out = timed_compile(api._run, (op0, grasp), cfg, reps)
    return dict(m=m, nodes=mesh.n, **times, rows=int(out[0].count), status=int(out[0].status),
                load=os.getloadavg()[0])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[56, 60, 64, 68, 72, 76, 80, 84, 88])
    p.add_argument("--reps", type=int, default=10)
    p.add_argument("--label", default="this tree", help="label of the rows (e.g. a commit)")
    p.add_argument("--pythonpath", default=None, help="import jaxsqueeze from this checkout instead")
    p.add_argument("--out", default=os.path.join(HERE, "results"))
    p.add_argument("--append", action="store_true", help="add to the CSV instead of replacing it")
    p.add_argument("--worker", nargs=2, type=int, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        print(json.dumps(worker(*a.worker)), flush=True)
        return
    env = dict(os.environ)
    if a.pythonpath:
        env["PYTHONPATH"] = a.pythonpath
    rows = []
    for m in a.sizes:
        r = subprocess.run([sys.executable, os.path.abspath(__file__), "--worker", str(m), str(a.reps)],
                           capture_output=True, text=True, env=env, timeout=600)
        if r.returncode != 0:
            raise RuntimeError(f"m = {m}: {r.stderr[-2000:]}")
        row = dict(label=a.label, **json.loads(r.stdout.strip().splitlines()[-1]))
        print(row, flush=True)
        if "error" not in row:
            rows.append(row)
    os.makedirs(a.out, exist_ok=True)
    path = os.path.join(a.out, "compile_sizes.csv")
    keys = ["label", "m", "nodes", "trace_lower_s", "compile_s", "run_ms", "rows", "status", "load"]
    old = []
    if a.append and os.path.exists(path):
        with open(path) as f:
            old = list(csv.DictReader(f))
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, keys, extrasaction="ignore")
        w.writeheader()
        w.writerows(old + rows)
    plot(old + rows, os.path.join(a.out, "compile_sizes.png"))
    print("| label | m | XLA compile [s] | trace + lower [s] | squeeze [ms] | rows |\n|---|---:|---:|---:|---:|---:|")
    for r in old + rows:
        print(f"| {r['label']} | {r['m']} | {float(r['compile_s']):.2f} | {float(r['trace_lower_s']):.2f} | "
              f"{float(r['run_ms']):.2f} | {r['rows']} |")


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 3.5))
    for label in dict.fromkeys(r["label"] for r in rows):
        pts = sorted((int(r["m"]), float(r["compile_s"])) for r in rows if r["label"] == label)
        ax.plot(*zip(*pts), "o-", label=label)
    for m in sorted({int(r["m"]) for r in rows}):
        if m % 8 == 0:
            ax.axvline(m, color="0.85", lw=0.8, zorder=0)
    ax.set_xlabel("boundary nodes m (grey: multiples of 8)")
    ax.set_ylabel("XLA compile of the squeeze [s]")
    ax.set_ylim(bottom=0)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
