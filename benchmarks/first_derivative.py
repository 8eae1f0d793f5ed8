"""What a user's first derivative and first batch cost: the README's placed foam-square
squeeze differentiated by an eager ``jax.jacfwd`` and mapped by an eager ``jax.vmap`` (issue 11).

Each worker is a fresh process (no persistent cache) that runs, as the README does, the
squeeze of the 10 cm square with fingers placed by arc length (μ = 0.2, 10 mm fingertips,
15 mm deep, float64), then times:

* ``squeeze``: the first eager ``jsq.squeeze(placed)`` (operator build, compile, run);
* ``jacfwd``: the first ``jax.jacfwd`` of ``quality.squeeze_work`` in the two arc lengths
  (the README's ``dwork`` line), and ``jacfwd again``: a second one at other arc lengths (the
  derivative's run time);
* ``vmap``: the first ``jax.vmap`` of ``squeeze_work`` over 4 placements, and ``vmap again``.

For each: wall and process time [s], and the XLA compiles (count and seconds, from
``jax.monitoring``). ``--tree LABEL=PATH`` (repeatable) imports ``jaxsqueeze`` from another
checkout; the workers of the trees alternate, ``--reps`` rounds.

Writes ``results/first_derivative.csv`` and ``results/first_derivative.png``.

    .venv/bin/python benchmarks/first_derivative.py                    # ~2 min on 2 idle cores
    .venv/bin/python benchmarks/first_derivative.py --reps 3 --tree before=/tmp/old --tree after=.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
KEYS = ["label", "rep", "what", "wall_s", "cpu_s", "compiles", "compile_s", "load"]


def worker() -> list[dict]:
    import warnings

    import jax
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    import jaxsqueeze as jsq
    from jaxsqueeze.plan import quality
    warnings.simplefilter("ignore")            # (the README's PlacementResolutionWarning)
    compiles = []
    jax.monitoring.register_event_duration_secs_listener(
        lambda name, secs, **kw: compiles.append(secs) if name.endswith("backend_compile_duration") else None)
    rows = []

    def timed(what, fn):
        n, w, c = len(compiles), time.perf_counter(), time.process_time()
        out = jax.block_until_ready(fn())
        rows.append(dict(what=what, wall_s=time.perf_counter() - w, cpu_s=time.process_time() - c,
                         compiles=len(compiles) - n, compile_s=sum(compiles[n:]), load=os.getloadavg()[0]))
        return out

    mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=0.006, refine_near=[[-0.005, -0.05], [0.005, 0.05]],
                                refine_edge=0.001)
    scene = jsq.Scene(mesh=mesh, material=jsq.Material(E=1e5, nu=0.3, thickness=0.0254),
                      fingers=jsq.Fingers(radius=0.01), grip=None, friction=0.2, depth=0.015,
                      placement=jsq.Placement(s=(0.0, 0.2)))
    P = float(scene.curve().perimeter)
    placed = scene.replace(placement=jsq.Placement(s=(0.0, P / 2)))
    work = lambda s: quality.squeeze_work(jsq.squeeze(placed.replace(placement=jsq.Placement(s=s))))  # noqa: E731
    timed("squeeze", lambda: jsq.squeeze(placed).grip_force)
    timed("jacfwd", lambda: jax.jacfwd(work)(jnp.array([0.0, P / 2])))
    timed("jacfwd again", lambda: jax.jacfwd(work)(jnp.array([0.002, P / 2 + 0.002])))
    S = jnp.stack([jnp.array([0.004 * k, P / 2 - 0.003 * k]) for k in range(4)])
    timed("vmap", lambda: jax.vmap(work)(S))
    timed("vmap again", lambda: jax.vmap(work)(S + 0.001))
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--reps", type=int, default=2)
    p.add_argument("--tree", action="append", default=None, metavar="LABEL=PATH",
                   help="import jaxsqueeze from PATH for the rows labelled LABEL (default: this checkout)")
    p.add_argument("--out", default=os.path.join(HERE, "results"))
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        print(json.dumps(worker()), flush=True)
        return
    trees = [t.split("=", 1) for t in (a.tree or [f"this tree={ROOT}"])]
    rows = []
    for rep in range(a.reps):
        for label, path in trees:
            env = dict(os.environ, PYTHONPATH=os.path.abspath(path))
            env.pop("JAX_COMPILATION_CACHE_DIR", None)
            r = subprocess.run([sys.executable, os.path.abspath(__file__), "--worker"], capture_output=True,
                               text=True, env=env, timeout=900, cwd=HERE)
            if r.returncode != 0:
                raise RuntimeError(f"{label}: {r.stderr[-2000:]}")
            for row in json.loads(r.stdout.strip().splitlines()[-1]):
                rows.append(dict(label=label, rep=rep, **row))
                print(rows[-1], flush=True)
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, "first_derivative.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, KEYS)
        w.writeheader()
        w.writerows(rows)
    plot(rows, os.path.join(a.out, "first_derivative.png"))
    print("| tree | what | wall [s] | process [s] | XLA compiles | XLA compile [s] | load |\n"
          "|---|---|---:|---:|---:|---:|---:|")
    for label, _ in trees:
        for what in dict.fromkeys(r["what"] for r in rows):
            mine = [r for r in rows if r["label"] == label and r["what"] == what]
            best = min(mine, key=lambda r: r["wall_s"])
            print(f"| {label} | {what} | {best['wall_s']:.2f} ({max(r['wall_s'] for r in mine):.2f}) | "
                  f"{best['cpu_s']:.2f} | {best['compiles']} | {best['compile_s']:.2f} | "
                  f"{min(r['load'] for r in mine):.1f}–{max(r['load'] for r in mine):.1f} |")


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    labels = list(dict.fromkeys(r["label"] for r in rows))
    whats = list(dict.fromkeys(r["what"] for r in rows))
    fig, ax = plt.subplots(figsize=(7, 3.5))
    width = 0.8 / len(labels)
    for i, label in enumerate(labels):
        best = [min(r["wall_s"] for r in rows if r["label"] == label and r["what"] == w) for w in whats]
        xla = [min((r for r in rows if r["label"] == label and r["what"] == w), key=lambda r: r["wall_s"])["compile_s"]
               for w in whats]
        x = np.arange(len(whats)) + (i - (len(labels) - 1) / 2) * width
        ax.bar(x, best, width, label=f"{label}: wall (best)")
        ax.bar(x, xla, width * 0.5, color="k", alpha=0.35, label="of which XLA compile" if i == 0 else None)
    ax.set_xticks(range(len(whats)), whats)
    ax.set_ylabel("seconds, fresh process")
    ax.set_title("README's placed squeeze: first derivative and batch")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
