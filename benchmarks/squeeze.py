"""Cost of a whole squeeze against mesh size (issue 3; DESIGN 2.2, 2.8).

Two series on the 0.1 m foam square of ``jaxsqueeze/scenes/foam_square.toml`` (E = 0.1 MPa,
nu = 0.3, mu = 0.2, grip 5 mm off centre, squeezed 15 mm = 15 %):

* ``size``: the scene file's mesh with ``max_edge`` overridden (1 mm near the grip points),
  once per compliance build ``sparse`` and ``spectral`` (the paper's eigendecomposition,
  O(n^3), only up to ``--max-spectral`` nodes).
* ``interior``: meshes built here with Triangle on one FIXED boundary polyline (2.5 mm
  spacing, m = 160 boundary nodes) and a growing interior node count (``pq30a{area}YQ``:
  no Steiner points on the boundary), ``sparse`` build. Same m, same settings: one compile
  serves the whole series, and the per-step time should not depend on the interior.

For each point: ``build_s`` (compliance build), ``first_s`` (first ``jsq.squeeze``, with the
compile), ``warm_s`` (best ``jsq.squeeze`` with friction nudged by 1e-7: same shapes, no
compile, includes the eager post-processing ``to_result``; best of ``--reps``), ``core_s``
(best of ``--reps`` runs of the jitted core ``jaxsqueeze.grasp._run`` alone; the median is
``core_median_s``: best-of is the robust statistic on a shared, loaded machine), ``rows`` (recorded rows = steps + events),
``step_ms = core_s / rows`` and the 1-minute load average at the time of each timing.

    .venv/bin/python benchmarks/squeeze.py                 # ~8 min on 2 cores
    .venv/bin/python benchmarks/squeeze.py --quick         # two small sizes
"""
from __future__ import annotations

import argparse
import csv
import dataclasses
import os
import platform
import statistics
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
SCENE = os.path.join(ROOT, "jaxsqueeze", "scenes", "foam_square.toml")
DATE = time.strftime("%Y-%m-%d")   # the day of the run


def machine() -> str:
    """One line: CPU model, cores, JAX version and backend."""
    import jax
    try:
        model = [ln.split(":", 1)[1].strip() for ln in subprocess.run(
            ["lscpu"], capture_output=True, text=True).stdout.splitlines() if ln.startswith("Model name")][0]
    except Exception:   # noqa: BLE001
        model = platform.processor() or "unknown CPU"
    dev = jax.devices()[0]
    return (f"{model}, {os.cpu_count()} cores, JAX {jax.__version__} on {dev.platform} "
            f"({getattr(dev, 'device_kind', '')}), Python {platform.python_version()}, {DATE}")


def load1() -> float:
    return round(os.getloadavg()[0], 2)


def foam(max_edge=None, refine_edge=None, **changes):
    """The demo scene, with an optional mesh override and scene changes."""
    from jaxsqueeze.io.scenefile import load
    sc = load(SCENE, max_edge=max_edge, refine_edge=refine_edge).scene
    return sc.replace(**changes) if changes else sc


def fixed_boundary_mesh(interior_edge: float, spacing: float = 0.0025, width: float = 0.1):
    """Square with boundary nodes every ``spacing`` and interior triangles of edge ~interior_edge."""
    import triangle as tr

    import jaxsqueeze as jsq
    k = int(round(width / spacing))
    s = np.arange(k) * spacing - width / 2
    e = np.full(k, width / 2)
    ring = np.concatenate([np.stack([s, -e], 1), np.stack([e, s], 1),
                           np.stack([-s, e], 1), np.stack([-e, -s], 1)])
    seg = np.stack([np.arange(len(ring)), (np.arange(len(ring)) + 1) % len(ring)], 1)
    area = np.sqrt(3) / 4 * (interior_edge / width) ** 2       # scaled to a unit square
    out = tr.triangulate(dict(vertices=ring / width, segments=seg), f"pq30a{area:.12f}YQ")
    pts = out["vertices"] * width
    pts[: len(ring)] = ring
    return jsq.Mesh.from_arrays(pts, out["triangles"])


def grip_of(mesh, a=(-0.005, -0.05), b=(0.005, 0.05)):
    import jaxsqueeze as jsq
    return (jsq.scene.nearest_boundary_node(mesh, a), jsq.scene.nearest_boundary_node(mesh, b))


def core_inputs(scene):
    """The compiled core's inputs, with the configuration an eager ``jsq.squeeze`` runs."""
    from jaxsqueeze.simulation import api as G
    op = scene.operator()
    return dataclasses.replace(op, field=None), G.grasp_of(scene, op), G.eager_config(scene, op)


def time_core(scene, reps=3):
    """Median wall time of the jitted core (already compiled) and its final state."""
    import jax

    from jaxsqueeze.simulation import api as G
    op0, gr, cfg = core_inputs(scene)
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        st = jax.block_until_ready(G._run(op0, gr, cfg))
        ts.append(time.perf_counter() - t)
    return min(ts), statistics.median(ts), st


def measure(scene, reps=3, nudge=1e-7) -> dict:
    """Build, first (compiling) call, warm calls and core timings of one scene."""
    import jax

    import jaxsqueeze as jsq
    from jaxsqueeze.simulation import scene as scene_module
    scene_module._operators.clear()           # time the operator build as a first call pays it
    row = dict(nodes=scene.mesh.n, boundary=scene.mesh.m, method=scene.method)
    t = time.perf_counter()
    op = scene.operator()
    jax.block_until_ready(op.G)
    row["build_s"], row["load_build"] = time.perf_counter() - t, load1()
    t = time.perf_counter()
    res = jsq.squeeze(scene)
    jax.block_until_ready(res.forces)
    row["first_s"], row["load_first"] = time.perf_counter() - t, load1()
    warm = []
    for k in range(reps):
        t = time.perf_counter()
        r2 = jsq.squeeze(scene.replace(friction=float(scene.friction) + nudge * (k + 1)))
        jax.block_until_ready(r2.forces)
        warm.append(time.perf_counter() - t)
    row["warm_s"], row["load_warm"] = min(warm), load1()
    row["core_s"], row["core_median_s"], _ = time_core(scene, reps)
    row["load_core"] = load1()
    row["rows"], row["events"] = int(res.count), int(res.n_events)
    row["step_ms"] = 1e3 * row["core_s"] / row["rows"]
    row["compile_s"] = row["first_s"] - row["warm_s"]
    row["outcome"] = res.outcome.name
    row["final_depth_mm"] = 1e3 * res.final_depth
    row["F2y_N"] = float(res.total_force[-1, 1, 1])
    return row


COLS = ["series", "method", "nodes", "boundary", "interior_edge_mm", "build_s", "first_s", "compile_s", "warm_s",
        "core_s", "core_median_s", "rows", "events", "step_ms", "outcome", "final_depth_mm", "F2y_N", "load_build", "load_first",
        "load_warm", "load_core"]


def write_csv(path, rows, cols, info):
    """One CSV per benchmark: a comment line with the machine, then the rows."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w", newline="") as f:
        f.write(f"# {info}\n")
        w = csv.DictWriter(f, cols, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    print(f"wrote {path}")


def fmt(v, nd=3):
    if isinstance(v, float):
        return f"{v:.{nd}f}" if abs(v) < 1e4 else f"{v:.0f}"
    return str(v)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--max-edge", type=float, nargs="+", default=[0.006, 0.003, 0.0016, 0.0012, 0.001],
                   help="max_edge values of the size series [m] (default ~1.3k, 2.1k, 5.1k, 8.7k, 12k nodes)")
    p.add_argument("--interior-edge", type=float, nargs="+", default=[0.005, 0.003, 0.002, 0.0014, 0.001],
                   help="interior edge lengths of the fixed-boundary series [m]")
    p.add_argument("--max-spectral", type=int, default=2500, help="largest node count for the spectral build")
    p.add_argument("--reps", type=int, default=5)
    p.add_argument("--quick", action="store_true", help="two small sizes only")
    p.add_argument("--out", default=os.path.join(HERE, "results"))
    a = p.parse_args(argv)
    if a.quick:
        a.max_edge, a.interior_edge = [0.006, 0.003], [0.005, 0.003]

    import jax
    jax.config.update("jax_enable_x64", True)
    info = machine()
    print(info, flush=True)
    rows = []

    def run(series, scene, extra=None):
        r = dict(series=series, interior_edge_mm="")
        r.update(extra or {})
        r.update(measure(scene, a.reps))
        rows.append(r)
        print(" | ".join(f"{k}={fmt(r[k])}" for k in COLS if k in r), flush=True)

    for h in a.max_edge:
        sc = foam(h, min(h, 0.001))
        run("size", sc)
        if sc.mesh.n <= a.max_spectral:
            run("size", sc.replace(method="spectral"))
    base = foam()
    for h in a.interior_edge:
        mesh = fixed_boundary_mesh(h)
        sc = base.replace(mesh=mesh, grip=grip_of(mesh))
        run("interior", sc, dict(interior_edge_mm=1e3 * h))

    write_csv(os.path.join(a.out, "squeeze.csv"), rows, COLS, info)
    plot(rows, os.path.join(a.out, "squeeze.png"), info)
    report(rows)


def plot(rows, path, info):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 3, figsize=(13, 4), dpi=80)
    for (series, method), style in {("size", "sparse"): "o-", ("size", "spectral"): "s--",
                                    ("interior", "sparse"): "^-"}.items():
        rs = [r for r in rows if r["series"] == series and r["method"] == method]
        if not rs:
            continue
        n = [r["nodes"] for r in rs]
        lab = f"{method}, boundary grows" if series == "size" else "sparse, fixed boundary (m=160)"
        ax[0].loglog(n, [r["build_s"] + r["core_s"] for r in rs], style, label=lab)
        ax[1].semilogx(n, [r["compile_s"] for r in rs], style, label=lab)      # (~0 where nothing compiled)
        ax[2].semilogx(n, [r["step_ms"] for r in rs], style, label=lab)
    ax[0].set_title("build + squeeze (after compile) [s]")
    ax[1].set_title("compile (first - warm call) [s]")
    ax[2].set_title("time per recorded row [ms]")
    for x in ax:
        x.set_xlabel("mesh nodes")
        x.grid(True, which="both", alpha=0.3)
    ax[1].set_ylim(bottom=0)
    ax[2].set_ylim(bottom=0)
    ax[2].legend(fontsize=8)
    fig.suptitle(f"foam square, 15 % squeeze — {info}", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    print(f"wrote {path}")


def report(rows):
    print("\n| series | build | nodes | m | build [s] | first call [s] | compile [s] | warm call [ms] | "
          "core [ms] | rows | per row [ms] | load (1 min) |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['series']} | {r['method']} | {r['nodes']} | {r['boundary']} | {r['build_s']:.2f} | "
              f"{r['first_s']:.2f} | {r['compile_s']:.2f} | {1e3 * r['warm_s']:.1f} | {1e3 * r['core_s']:.1f} | "
              f"{r['rows']} | {r['step_ms']:.3f} | {r['load_core']:.1f} |")


if __name__ == "__main__":
    sys.exit(main())
