"""Grasp planning at scale (issue: grasp planning; DESIGN 2.9).

1. Squeezes per second for a grasp map: one compiled squeeze called per candidate ("loop"),
   one compiled vmap per chunk ("vmap"), on this machine.
2. Search against the exhaustive map, on three objects (a foam square, an ellipse and a
   non-convex L-shaped polygon, each meshed coarsely so a *fine* exhaustive map at node
   spacing stays affordable): the best quality of the fine map; the best quality that
   ``optimize_placement`` (5 starts from a coarse map at perimeter / 12, 12 steps each)
   reaches; their ratio; and the squeezes each needed.

Quality: squeeze_work (the strain energy stored by squeezing to the same depth, IJRR 2014's
"stable squeeze"). Writes results/planning.csv and results/planning.png.

    .venv/bin/python benchmarks/planning.py            # ~1.5 min on 2 cores (2026-12-03)
    .venv/bin/python benchmarks/planning.py --quick    # one object, well under a minute
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

COLS = ["object", "nodes", "boundary", "fine_pairs", "fine_s", "fine_best", "search_best", "ratio",
        "search_squeezes", "squeeze_fraction", "search_s", "loop_per_s", "vmap_per_s", "processes_per_s", "load"]


def objects(quick):
    import jaxsqueeze as jsq
    out = {"foam square": jsq.shapes.rectangle(0.1, 0.1, max_edge=0.006)}
    if not quick:
        out["ellipse"] = jsq.shapes.ellipse(0.06, 0.04, max_edge=0.006)
        out["L-shape"] = jsq.shapes.polygon([(0, 0), (0.1, 0), (0.1, 0.05), (0.05, 0.05), (0.05, 0.1), (0, 0.1)],
                                            max_edge=0.006)
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", default=os.path.join(HERE, "results"))
    a = p.parse_args(argv)

    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np

    import jaxsqueeze as jsq
    from jaxsqueeze import plan
    from squeeze import write_csv

    rows = []
    for name, mesh in objects(a.quick).items():
        sc = jsq.Scene(mesh=mesh, material=jsq.Material(1e5, 0.3, 0.0254), fingers=jsq.Fingers(radius=0.01),
                       placement=plan.Placement(s=(0.0, 0.1)), friction=0.5, depth=0.008)
        op = sc.operator()
        P = float(sc.curve().perimeter)
        # throughput: loop vs vmap on the same 64 candidates (compiled first)
        X = plan.search.grid(sc, P / 12)
        i, j = np.triu_indices(len(X), 1)
        C = np.stack([X[i], X[j], np.zeros(len(i))], 1)[:16]
        rates = {}
        for batch in ("loop", "vmap"):
            plan.evaluate(sc, C[:8], op=op, batch=batch, chunk=8, progress=False)       # compile
            t = time.perf_counter()
            plan.evaluate(sc, C, op=op, batch=batch, chunk=8, progress=False)
            rates[batch] = len(C) / (time.perf_counter() - t)
        # a process pool pays its workers' start-up and compile (or cache load): a longer batch
        t = time.perf_counter()
        C2 = np.stack([X[i], X[j], np.zeros(len(i))], 1)[:128]
        plan.evaluate(sc, C2, op=op, batch="processes", chunk=16, progress=False)
        rates["processes"] = len(C2) / (time.perf_counter() - t)
        print(f"{name}: loop {rates['loop']:.2f}/s, vmap {rates['vmap']:.2f}/s, "
              f"processes {rates['processes']:.2f}/s", flush=True)
        t = time.perf_counter()
        fine = plan.grasp_map(sc, "squeeze_work", op=op, progress=True)
        fine_s = time.perf_counter() - t
        best = float(fine.quality[fine.feasible()].max())
        t = time.perf_counter()
        found = plan.optimize_placement(sc, "squeeze_work", starts=5, steps=12, coarse_spacing=P / 12, op=op,
                                        progress=True)
        search_s = time.perf_counter() - t
        row = dict(object=name, nodes=mesh.n, boundary=mesh.m, fine_pairs=fine.evaluations, fine_s=round(fine_s, 1),
                   fine_best=best, search_best=found.quality, ratio=found.quality / best,
                   search_squeezes=found.squeezes, squeeze_fraction=found.squeezes / fine.evaluations,
                   search_s=round(search_s, 1), loop_per_s=round(rates["loop"], 2), vmap_per_s=round(rates["vmap"], 2),
                   processes_per_s=round(rates["processes"], 2),
                   load=round(os.getloadavg()[0], 2))
        rows.append(row)
        print({k: (f"{v:.4g}" if isinstance(v, float) else v) for k, v in row.items()}, flush=True)
        if name == "foam square":
            from jaxsqueeze.post.maps import plot_grasp_map
            fig = plot_grasp_map(fine, found, label="squeeze work [J]")
            os.makedirs(a.out, exist_ok=True)
            fig.savefig(os.path.join(a.out, "planning.png"))
    info = f"{platform.node()} {platform.processor() or platform.machine()} {os.cpu_count()} cores, " \
           f"jax {jax.__version__}, {time.strftime('%Y-%m-%d')}"
    write_csv(os.path.join(a.out, "planning.csv"), rows, COLS, info)


if __name__ == "__main__":
    main()
