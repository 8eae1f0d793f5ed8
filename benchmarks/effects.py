"""What each effect costs: friction model and fingertip rotation (DESIGN 2.7).

The foam square of ``jaxsqueeze/scenes/foam_square.toml`` (material, fingertips, μ = 0.2) on
its mesh refined at the CENTRES of the bottom and top edges instead of 5 mm beside them
(``rectangle(0.1, 0.1, 0.006, refine_near=[(0, ±0.05)], refine_edge=0.001)``), gripped there,
so that the frictionless model (whose cones are the normals) holds it (docs/numerics.md §5.1:
a grip near a corner would slide out, STALLED), squeezed 15 mm, once per ``friction_model`` ("coulomb", "frictionless", "stick"), with
fingertip rotation off (``rotation=None``: no rotation code compiled) or on
(``rotation=[[0, 0], [1.0, 0]]``: alpha_2 = 1 rad/m * d), and with segment contacts (the
paper's solids) or point contacts (one node per finger, as for bands). Each configuration
compiles its own program. Columns as in ``squeeze.py`` (``compile_s`` = first call - best warm
call, ``core_s`` = best of ``--reps`` runs of the jitted core, ``step_ms`` = core_s / rows).
Writes ``results/effects.csv`` and ``results/effects.png``.

    .venv/bin/python benchmarks/effects.py       # ~3 min on 2 cores
"""
from __future__ import annotations

import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)


def centred(scene):
    """``scene`` on the square meshed finer at the centres of its bottom and top edges, gripped
    at the boundary nodes nearest them."""
    import jaxsqueeze as jsq
    ends = [(0.0, -0.05), (0.0, 0.05)]
    mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=0.006, refine_near=ends, refine_edge=0.001)
    return scene.replace(mesh=mesh, grip=tuple(jsq.scene.nearest_boundary_node(mesh, p) for p in ends))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reps", type=int, default=20)
    p.add_argument("--out", default=os.path.join(HERE, "results"))
    a = p.parse_args(argv)
    import jax
    jax.config.update("jax_enable_x64", True)
    import jaxsqueeze as jsq
    from squeeze import foam, machine, measure, write_csv

    info = machine()
    print(info, flush=True)
    base = centred(foam())
    rows = []
    for contact in ("segment", "point"):
        for rot in (None, [[0.0, 0.0], [1.0, 0.0]]):
            for model in ("coulomb", "frictionless", "stick"):
                sc = base.replace(friction_model=model, contact=contact, fingers=jsq.Fingers(radius=0.01, rotation=rot))
                r = dict(contact=contact, friction_model=model, rotation="on" if rot else "off")
                r.update(measure(sc, a.reps))
                rows.append(r)
                print(r, flush=True)
    os.makedirs(a.out, exist_ok=True)
    cols = ["contact", "friction_model", "rotation", "nodes", "boundary", "first_s", "compile_s", "warm_s", "core_s",
            "core_median_s", "rows", "events", "step_ms", "outcome", "F2y_N", "load_first", "load_core"]
    write_csv(os.path.join(a.out, "effects.csv"), rows, cols, info)
    plot(rows, os.path.join(a.out, "effects.png"), info)
    ref = rows[0]                          # segment contacts, Coulomb, no rotation: the paper's scene
    print("\n| contact | friction model | rotation | compile [s] | core [ms] | rows | events | per row [ms] | "
          "core vs paper's | outcome | F2y [N] | load |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|---|---:|---:|")
    for r in rows:
        print(f"| {r['contact']} | {r['friction_model']} | {r['rotation']} | {r['compile_s']:.1f} | "
              f"{1e3 * r['core_s']:.1f} | {r['rows']} | {r['events']} | {r['step_ms']:.3f} | "
              f"{r['core_s'] / ref['core_s']:.2f}x | {r['outcome']} | {r['F2y_N']:.3f} | {r['load_core']:.1f} |")


def plot(rows, path, info):
    """Compile time and squeeze time (after compilation) of every configuration, as bars."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    labels = [f"{r['contact']}\n{r['friction_model']}\nrot. {r['rotation']}" for r in rows]
    fig, ax = plt.subplots(1, 2, figsize=(13, 4.2), dpi=80)
    for a, key, scale, title in ((ax[0], "compile_s", 1.0, "compile (first - warm call) [s]"),
                                 (ax[1], "core_s", 1e3, "one squeeze after compilation [ms]")):
        a.bar(range(len(rows)), [scale * r[key] for r in rows],
              color=["C0" if r["friction_model"] == "coulomb" else "C1" if r["friction_model"] == "stick" else "C2"
                     for r in rows])
        a.set_xticks(range(len(rows)), labels, fontsize=6)
        a.set_title(title)
        a.grid(True, axis="y", alpha=0.3)
    fig.suptitle(f"foam square, centred grip, 15 mm: what each effect costs — {info}", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    print(f"wrote {path}")


if __name__ == "__main__":
    sys.exit(main())
