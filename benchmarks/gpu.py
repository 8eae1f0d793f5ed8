"""One squeeze and a ``jax.vmap`` over candidate grips, on GPU against CPU (DESIGN 2.9).

The foam square of ``jaxsqueeze/scenes/foam_square.toml`` (default mesh: 1,265 nodes,
m = 122 boundary nodes; ``--max-edge 0.0016`` gives about 5,100 nodes, m = 286) with
mu = 0.5 so that every candidate grip lies inside the friction cones. The candidates put
finger 1 on the bottom edge at x1 in [-30, 30] mm and finger 2 on the top edge at
x1 + dx, dx in [-8, 8] mm (B = 64: 16 x 4, B = 256: 64 x 4).

The compliance operator is built once on the host (scipy, ``sparse``) and copied to each
device. For each device and batch size B: ``compile_s`` (lower + compile of the jitted
``vmap`` of the core ``jaxsqueeze.grasp._run``; B = 1 is the plain core), ``run_s`` (best
of ``--reps`` calls, outputs on the device, ``block_until_ready``), ``per_grasp_ms`` and
``max_rows`` (a batched ``while_loop`` runs until its longest member stops).

    python benchmarks/gpu.py --out benchmarks/results              # every device JAX sees
    python benchmarks/gpu.py --devices cpu --batches 1 16 --out /tmp
"""
from __future__ import annotations

import argparse
import csv
import dataclasses
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)


def candidates(mesh, B):
    import jaxsqueeze as jsq
    nx = B // 4
    xs = np.linspace(-0.03, 0.03, nx)
    dxs = np.linspace(-0.008, 0.008, 4)
    g = [(jsq.scene.nearest_boundary_node(mesh, (x, -0.05)), jsq.scene.nearest_boundary_node(mesh, (x + dx, 0.05)))
         for x in xs for dx in dxs]
    return np.asarray(g, np.int64)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--devices", nargs="+", default=None, help="platforms to time (default: gpu if present, cpu)")
    p.add_argument("--batches", type=int, nargs="+", default=[1, 64, 256])
    p.add_argument("--max-edge", type=float, nargs="+", default=[None])
    p.add_argument("--reps", type=int, default=3)
    p.add_argument("--x32", action="store_true", help="float32 instead of float64")
    p.add_argument("--eager", action="store_true",
                   help="an eager squeeze's contact slots (32, 8 sliding) instead of the traced default (64)")
    p.add_argument("--out", default=os.path.join(HERE, "results"))
    a = p.parse_args(argv)

    import jax
    jax.config.update("jax_enable_x64", not a.x32)
    import jax.numpy as jnp

    from jaxsqueeze.simulation import api as G
    from squeeze import foam, load1, machine

    info = machine()
    print(info, flush=True)
    plats = a.devices or ([d for d in ("gpu", "cpu") if any(x.platform == d for x in _devices(jax, d))])
    rows = []
    for h in a.max_edge:
        sc = foam(h, None if h is None else min(h, 0.001), friction=0.5)
        op = sc.operator()
        op0 = dataclasses.replace(op, field=None)
        gr = G.grasp_of(sc, op)
        cfg = G.eager_config(sc, op) if a.eager else G.config_of(sc)
        pos = np.full(int(np.max(np.asarray(op.nodes))) + 1, -1)
        pos[np.asarray(op.nodes)] = np.arange(op.m)
        for plat in plats:
            dev = _devices(jax, plat)[0]
            o = jax.device_put(op0, dev)
            g0 = jax.device_put(gr, dev)
            for B in a.batches:
                if B == 1:
                    def fn(o, g0, grips):
                        res, F, _ = G._run(o, dataclasses.replace(g0, grip=grips[0]), cfg)
                        return res.status, res.count, F
                else:
                    def fn(o, g0, grips):
                        res, F, _ = jax.vmap(lambda q: G._run(o, dataclasses.replace(g0, grip=q), cfg))(grips)
                        return res.status, res.count, F
                grips = pos[candidates(sc.mesh, max(B, 4))[:B]]
                grips = jax.device_put(jnp.asarray(grips), dev)
                t = time.perf_counter()
                comp = jax.jit(fn).lower(o, g0, grips).compile()
                tc = time.perf_counter() - t
                ts = []
                for _ in range(a.reps):
                    t = time.perf_counter()
                    out = jax.block_until_ready(comp(o, g0, grips))
                    ts.append(time.perf_counter() - t)
                status, count = np.asarray(out[0]), np.asarray(out[1])
                r = dict(device=f"{plat}:{getattr(dev, 'device_kind', '')}", nodes=sc.mesh.n, boundary=sc.mesh.m,
                         dtype="float32" if a.x32 else "float64", slots=cfg.capacity, batch=B, compile_s=tc,
                         run_s=min(ts),
                         per_grasp_ms=1e3 * min(ts) / B, max_rows=int(count.max()),
                         success=int((status == 0).sum()), load=load1())
                rows.append(r)
                print(r, flush=True)
                save(rows, a.out, info)   # after every point: a timed-out run keeps what it measured
    print("\n| device | nodes | m | slots | batch | compile [s] | run [s] | per grasp [ms] | max rows | success | load |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['device']} | {r['nodes']} | {r['boundary']} | {r['slots']} | {r['batch']} | {r['compile_s']:.1f} | "
              f"{r['run_s']:.3f} | {r['per_grasp_ms']:.2f} | {r['max_rows']} | {r['success']}/{r['batch']} | "
              f"{r['load']:.1f} |")


def save(rows, out, info):
    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, "gpu.csv")
    with open(path, "w", newline="") as f:
        f.write(f"# {info}\n")
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def _devices(jax, plat):
    try:
        return jax.devices(plat)
    except RuntimeError:
        return []


if __name__ == "__main__":
    sys.exit(main())
