"""What each effect costs: friction model and fingertip rotation (DESIGN 2.7).

The foam square of ``jaxsqueeze/scenes/foam_square.toml`` (1,265 nodes, m = 122) with a
CENTRED grip (bottom and top nodes with the same x, so that the frictionless model, whose cones are
the normals, accepts it),
squeezed 15 mm, once per ``friction_model`` ("coulomb", "frictionless", "stick") and with
fingertip rotation off (``rotation=None``: no rotation code compiled) or on
(``rotation=[[0, 0], [1.0, 0]]``: alpha_2 = 1 rad/m * d). Each configuration compiles its
own program. Columns as in ``squeeze.py`` (``compile_s`` = first call - best warm call,
``core_s`` = best of ``--reps`` runs of the jitted core, ``step_ms`` = core_s / rows).

    .venv/bin/python benchmarks/effects.py       # ~3 min on 2 cores
"""
from __future__ import annotations

import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)


def opposite_pair(mesh):
    """Bottom/top boundary nodes with the same x (closest to x = 0), so the grip axis is normal."""
    import numpy as np
    b = np.asarray(mesh.boundary)
    P = mesh.points[b] + mesh.offset
    bot, top = b[np.abs(P[:, 1] + 0.05) < 1e-9], b[np.abs(P[:, 1] - 0.05) < 1e-9]
    xb, xt = mesh.points[bot, 0], mesh.points[top, 0]
    d = np.abs(xb[:, None] - xt[None]) + 1e-3 * np.abs(xb[:, None] + mesh.offset[0])
    i, j = np.unravel_index(np.argmin(d), d.shape)
    return int(bot[i]), int(top[j])


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reps", type=int, default=5)
    p.add_argument("--out", default=os.path.join(HERE, "results"))
    a = p.parse_args(argv)
    import jax
    jax.config.update("jax_enable_x64", True)
    import jaxsqueeze as jsq
    from squeeze import foam, machine, measure, write_csv

    info = machine()
    print(info, flush=True)
    base = foam()
    base = base.replace(grip=opposite_pair(base.mesh))
    rows = []
    for rot in (None, [[0.0, 0.0], [1.0, 0.0]]):
        for model in ("coulomb", "frictionless", "stick"):
            sc = base.replace(friction_model=model, fingers=jsq.Fingers(radius=0.01, rotation=rot))
            r = dict(friction_model=model, rotation="on" if rot else "off")
            r.update(measure(sc, a.reps))
            rows.append(r)
            print(r, flush=True)
    os.makedirs(a.out, exist_ok=True)
    cols = ["friction_model", "rotation", "nodes", "boundary", "first_s", "compile_s", "warm_s", "core_s",
            "core_median_s", "rows", "events", "step_ms", "outcome", "F2y_N", "load_first", "load_core"]
    write_csv(os.path.join(a.out, "effects.csv"), rows, cols, info)
    ref = {r["rotation"]: r for r in rows if r["friction_model"] == "coulomb"}
    print("\n| friction model | rotation | compile [s] | core [s] | rows | events | per row [ms] | "
          "core vs coulomb | F2y [N] | load |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        c = ref[r["rotation"]]
        print(f"| {r['friction_model']} | {r['rotation']} | {r['compile_s']:.1f} | {r['core_s']:.3f} | {r['rows']} | "
              f"{r['events']} | {r['step_ms']:.2f} | {r['core_s'] / c['core_s']:.2f}x | {r['F2y_N']:.3f} | "
              f"{r['load_core']:.1f} |")


if __name__ == "__main__":
    sys.exit(main())
