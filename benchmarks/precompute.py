"""Benchmark: cost of building the compliance operator (DESIGN 2.2) with each build.

For a 0.1 m x 0.1 m square meshed at about 500 ... 20,000 nodes, measures for each build
("sparse", "dense", "spectral"):

* build time of ``jaxsqueeze.fem.compliance`` with JAX compilation excluded, and the
  compile-inclusive first-call time (dense and spectral are jitted per mesh size);
* peak resident memory (``ru_maxrss``) of a fresh subprocess per (method, size) point;
* the time of one ``deform`` call with s = 10 prescribed nodes on the built operator
  (including the displacement of every node);
* for "sparse", a breakdown: assembly, ``splu`` factorization, and the chunked solves for
  the boundary compliance (same steps as ``jaxsqueeze.fem._sparse_build``).

Usage::

    .venv/bin/python benchmarks/precompute.py                      # default, < ~10 min
    .venv/bin/python benchmarks/precompute.py --sizes 500 1000 --max-spectral 1000
    .venv/bin/python benchmarks/precompute.py --worker sparse 4000  # one point, prints JSON

Writes ``benchmarks/results/precompute.csv`` and ``precompute.png`` and prints a markdown
table.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results"
METHODS = ("sparse", "dense", "spectral")
FIELDS = ["method", "target_nodes", "nodes", "boundary_nodes", "max_edge_m", "build_s",
          "build_timing", "first_call_s", "compile_s", "deform_s10_s", "deform_s10_first_s",
          "peak_rss_mb", "base_rss_mb", "assemble_s", "splu_s", "solves_s", "lu_nnz"]

# ----------------------------------------------------------------------------- worker side


def _square(max_edge):
    """0.1 m square mesh: jaxsqueeze.shapes.rectangle when present, else triangle directly."""
    try:
        import jaxsqueeze.shapes as shapes
        return shapes.rectangle(0.1, 0.1, max_edge)
    except ImportError:
        import numpy as np
        import triangle

        import jaxsqueeze as jsq
        c = [(-0.05, -0.05), (0.05, -0.05), (0.05, 0.05), (-0.05, 0.05)]
        pts = []
        for a, b in zip(np.array(c), np.roll(np.array(c), -1, axis=0)):
            k = max(1, int(np.ceil(np.linalg.norm(b - a) / max_edge)))
            pts.extend(a + (b - a) * i / k for i in range(k))
        pts = np.array(pts)
        seg = np.stack([np.arange(len(pts)), (np.arange(len(pts)) + 1) % len(pts)], axis=1)
        area = np.sqrt(3) / 4 * max_edge**2
        out = triangle.triangulate(dict(vertices=pts, segments=seg), f"pq30a{area:.15f}")
        return jsq.Mesh.from_arrays(out["vertices"], out["triangles"])


def square_mesh(target: int):
    """Square mesh with about ``target`` nodes (within a few percent)."""
    h = 0.1 / (1.07 * target) ** 0.5
    for _ in range(6):
        mesh = _square(h)
        if abs(mesh.n - target) <= 0.03 * target:
            break
        h *= (mesh.n / target) ** 0.5
    return mesh, h


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0   # Linux: KiB


def _compile_seconds():
    """Listener accumulating JAX tracing / lowering / compile durations."""
    import jax

    total = [0.0]
    names = ("jaxpr_trace_duration", "jaxpr_to_mlir_module_duration", "backend_compile_duration")

    def listener(event, duration, **kw):
        if event.rsplit("/", 1)[-1] in names:
            total[0] += duration

    jax.monitoring.register_event_duration_secs_listener(listener)
    return total


def _sparse_breakdown(mesh, nu, chunk=128):
    """Time the steps of fem._sparse_build separately (same operations, same options)."""
    import numpy as np
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from jaxsqueeze import fem

    t0 = time.perf_counter()
    K = fem.scipy_stiffness(mesh, float(nu))
    b = np.asarray(mesh.boundary)
    bdofs = np.stack([2 * b, 2 * b + 1], axis=1).reshape(-1)
    pts = mesh.points / fem.object_length(mesh)
    pins = bdofs[fem.pinned_dofs(pts[b])]
    n2 = K.shape[0]
    keep = np.ones(n2, bool)
    keep[pins] = False
    D = sp.diags(keep.astype(float))
    Kp = (D @ K @ D + sp.diags((~keep).astype(float))).tocsc()
    t2 = time.perf_counter()
    from threadpoolctl import threadpool_limits

    lu = spla.splu(Kp, permc_spec="COLAMD")          # as fem._sparse_build
    t3 = time.perf_counter()
    with threadpool_limits(1, "blas"):
        for start in range(0, bdofs.size, chunk):
            cols = np.arange(start, min(start + chunk, bdofs.size))
            rhs = np.zeros((n2, cols.size))
            rhs[bdofs[cols], np.arange(cols.size)] = keep[bdofs[cols]]
            lu.solve(rhs)
    t4 = time.perf_counter()
    return dict(assemble_s=t2 - t0, splu_s=t3 - t2, solves_s=t4 - t3, lu_nnz=int(lu.L.nnz + lu.U.nnz))


def worker(method: str, target: int, repeat_below: float = 20.0) -> dict:
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    import jaxsqueeze as jsq
    from jaxsqueeze import fem

    mat = jsq.Material(E=1e6, nu=0.3, thickness=0.01)
    # warm-up on a small mesh: imports, XLA backend start, first-jit overheads
    small, _ = square_mesh(200)
    op = fem.compliance(small, mat, method)
    jsq.deform(op, small.boundary[:: max(1, small.m // 10)][:10], np.zeros((10, 2)))
    mesh, h = square_mesh(target)
    base = _rss_mb()

    comp = _compile_seconds()
    t0 = time.perf_counter()
    op = fem.compliance(mesh, mat, method)
    jax.block_until_ready(op.G)
    first = time.perf_counter() - t0
    compile_s = comp[0]
    if first < repeat_below:           # cheap enough: measure a second, fully warm call
        t0 = time.perf_counter()
        op = fem.compliance(mesh, mat, method)
        jax.block_until_ready(op.G)
        build, how = time.perf_counter() - t0, "measured"
    else:                              # expensive: first call minus the JAX compile events
        build, how = first - compile_s, "first-minus-compile"

    rng = np.random.default_rng(0)
    nodes = mesh.boundary[np.linspace(0, mesh.m, 10, endpoint=False).astype(int)]
    t0 = time.perf_counter()
    jax.block_until_ready(jsq.deform(op, nodes, 1e-3 * rng.standard_normal((10, 2))))
    deform_first = time.perf_counter() - t0
    times = []
    for _ in range(5):
        d = 1e-3 * rng.standard_normal((10, 2))
        t0 = time.perf_counter()
        jax.block_until_ready(jsq.deform(op, nodes, d))
        times.append(time.perf_counter() - t0)
    peak = _rss_mb()

    row = dict(method=method, target_nodes=target, nodes=mesh.n, boundary_nodes=mesh.m,
               max_edge_m=h, build_s=build, build_timing=how, first_call_s=first,
               compile_s=compile_s, deform_s10_s=float(np.median(times)),
               deform_s10_first_s=deform_first, peak_rss_mb=peak, base_rss_mb=base)
    if method == "sparse":
        row.update(_sparse_breakdown(mesh, mat.nu))
    return row


# ----------------------------------------------------------------------------- driver side


def run_point(method: str, target: int, timeout: float) -> dict | None:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", method, str(target)]
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    t0 = time.perf_counter()
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env, check=True)
    except subprocess.TimeoutExpired:
        print(f"  {method} {target}: timed out after {timeout:.0f} s", file=sys.stderr)
        return None
    except subprocess.CalledProcessError as e:
        print(f"  {method} {target}: failed\n{e.stderr[-2000:]}", file=sys.stderr)
        return None
    row = json.loads(out.stdout.strip().splitlines()[-1])
    print(f"  {method:8s} n={row['nodes']:6d}  build {row['build_s']:9.3f} s  first {row['first_call_s']:9.3f} s"
          f"  deform {1e3 * row['deform_s10_s']:8.2f} ms  peak {row['peak_rss_mb']:7.0f} MB"
          f"  (wall {time.perf_counter() - t0:.0f} s)", flush=True)
    return row


def markdown(rows) -> str:
    lines = ["| method | nodes | boundary | build [s] | first call (with compile) [s] | deform s=10 [ms] | peak RSS [MB] |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        mark = "" if r["build_timing"] == "measured" else " *"
        lines.append(f"| {r['method']} | {r['nodes']} | {r['boundary_nodes']} | {r['build_s']:.3f}{mark} | "
                     f"{r['first_call_s']:.3f} | {1e3 * r['deform_s10_s']:.2f} | {r['peak_rss_mb']:.0f} |")
    sparse = [r for r in rows if r["method"] == "sparse"]
    if sparse:
        lines += ["", "| sparse: nodes | assembly [s] | splu [s] | boundary solves [s] | nnz(L+U) |",
                  "|---:|---:|---:|---:|---:|"]
        lines += [f"| {r['nodes']} | {r['assemble_s']:.3f} | {r['splu_s']:.3f} | {r['solves_s']:.3f} | {r['lu_nnz']} |"
                  for r in sparse]
    return "\n".join(lines)


def plot(rows, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.6), dpi=90)
    for method, style in zip(METHODS, ("o-", "s-", "^-")):
        rs = sorted((r for r in rows if r["method"] == method), key=lambda r: r["nodes"])
        if not rs:
            continue
        n = [r["nodes"] for r in rs]
        ax1.loglog(n, [r["build_s"] for r in rs], style, label=method)
        ax2.loglog(n, [r["peak_rss_mb"] for r in rs], style, label=method)
    ax1.set(xlabel="nodes", ylabel="build time [s]", title="compliance build (compile excluded)")
    ax2.set(xlabel="nodes", ylabel="peak RSS [MB]", title="peak memory (own process)")
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[500, 1000, 2000, 4000, 8000, 20000])
    p.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    p.add_argument("--max-spectral", type=int, default=4000, help="largest node count for spectral")
    p.add_argument("--max-dense", type=int, default=8000, help="largest node count for dense")
    p.add_argument("--timeout", type=float, default=300.0, help="seconds per (method, size) point")
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument("--worker", nargs=2, metavar=("METHOD", "NODES"), help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.worker[0], int(args.worker[1]))))
        return
    limit = {"sparse": float("inf"), "dense": args.max_dense, "spectral": args.max_spectral}
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"load average {os.getloadavg()[0]:.2f}", flush=True)
    rows = []
    for method in args.methods:
        for n in args.sizes:
            if n <= limit[method]:
                row = run_point(method, n, args.timeout)
                if row:
                    rows.append(row)
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "precompute.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=FIELDS)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in FIELDS})
    plot(rows, args.out / "precompute.png")
    print()
    print(markdown(rows))
    by = {(r["method"], r["target_nodes"]): r for r in rows}
    for n in sorted({r["target_nodes"] for r in rows}):
        if ("sparse", n) in by and ("spectral", n) in by:
            print(f"\nspeed-up sparse vs spectral at {by['sparse', n]['nodes']} nodes: "
                  f"{by['spectral', n]['build_s'] / by['sparse', n]['build_s']:.0f}x")
    print("\n* build time estimated as first call minus JAX compile time (second call too slow to repeat)")


if __name__ == "__main__":
    main()
