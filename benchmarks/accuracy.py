"""What accuracy costs in time: error against time for each accuracy knob (DESIGN 2.8).

The foam square of ``jaxsqueeze/scenes/foam_square.toml`` squeezed 15 mm. One knob varies at
a time, the others stay at the scene's defaults; every knob's reference is its finest setting.

Knobs:

* ``mesh``: uniform refinement. ``max_edge`` and ``refine_edge`` (the edge length in the
  zone of radius 12 mm around each grip point, where the contact grows) are scaled by the
  same factor s: (max_edge, refine_edge) = (12 mm, 2 mm) x s. Five members, s = 2, sqrt2, 1,
  1/sqrt2, 1/2 (max_edge 24, 17, 12, 8.5, 6 mm; refine_edge 4, 2.8, 2, 1.4, 1 mm; the last is
  the scene file's mesh), against a reference 2x finer than the finest member, s = 1/4
  (3 mm / 0.5 mm, 4,250 nodes). ``--reference S`` moves the whole series (members 2 to 8
  times coarser than the reference). The demo's grip has no finer reference: from 0.35 mm
  contact zones down the squeeze ends with SLIP_FAILURE in its first 0.1 mm (0.35 mm at 0.10,
  0.3 mm at 0.079 mm, the same with the engine before the rewrite: the paper's rule that a
  finger whose contacts all slide has lost the grip, see benchmarks/README.md); 0.4 mm
  (6,382 nodes) reaches 15 mm since the kept bordered inverse is checked for drift
  (it STALLED at 13.0 mm before). The centred series below has the much finer reference.
  The meshes are built with ``jsq.shapes.rectangle`` as the scene file's loader builds them
  (the zone radius stays the file's 2 x 6 mm; the loader itself refuses the 1.5 mm / 0.25 mm
  mesh on its pre-meshing size estimate). Only the grading between the two zones
  (slope 0.3, a constant of the mesher) is not scaled; the contact zone is refined exactly
  uniformly. The event log and the step bound grow with the expected number of contact
  nodes (``settings_for``); the contact and sliding slots are the library's automatic ones
  (an eager squeeze grows them until the contact set fits; the ``capacity`` column is what
  the timed program used, contact / sliding slots). The order of convergence p of each error is the least-squares slope
  of log(error) against log(h), h = refine_edge (the spacing of the boundary nodes in the
  contact zone; max_edge is proportional to it, so the slope is the same for either).
* ``mesh, centred grip``: a second mesh series with a much finer reference: the same square
  gripped at the middles of two opposite edges, mu = 0.5, squeezed 15 mm like the demo;
  contact zones refined to 4, 2.8, 2, 1.4, 1, 0.7 and 0.5 mm (max_edge 6 x that, uniform x
  sqrt2 refinement) against 0.25 mm (15,442 nodes; 2 x finer than the finest member, 16 x the
  coarsest). (Until the kept inverse was checked for drift this grip STALLED at 5.1 mm on the
  0.25 mm mesh and the series ran to 4 mm.) It has its own fitted orders and is left out of
  the Pareto front and the recommendations, which are the demo's.
* ``step``: squeeze step depth/10 ... depth/200 (default depth/50).
* ``event_tol``: step x 1e-1 ... 1e-9 (default step x 1e-4).
* ``newton_tol``: 1e-3 ... 1e-13 rad (default 1e-11 in float64).
* ``precision``: float32 (the same scene built and run inside ``jax.enable_x64(False)``, with
  float32's default tolerances; same result as a process with x64 off) against float64. (It
  stalled at 12.0 mm until a new contact's pull test judged the sign of the force's rate
  instead of its round-off value at the event depth.)
* ``build``: compliance build dense, spectral against sparse (the default).

Errors, each against the knob's reference:

* ``force_err`` = |F - F_ref| / |F_ref|, F the final total force of finger 0 (the still
  finger; |F| is ``result.grip_force``).
* ``width_err`` = |w - w_ref| / w_ref, w the width of finger 0's contact at the final depth:
  the arc on the fingertip between its outermost contact nodes, r (theta_max - theta_min)
  (``views.contact_regions``' ``arc_length``; the span of all regions if there are several).
  The contact ends at a node, so a mesh's width is quantized by its node spacing: on the
  mesh series expect a width error of the order of ``spacing / width`` (the table prints it
  next to the error), and a ragged order.
* ``event_err`` = the largest |depth - depth_ref| of the events matched to the reference by
  (node, kind, finger) in order, over the target depth; ``unmatched`` = events of either run
  without a partner (not for the mesh series: the nodes differ).

Errors of the non-mesh knobs are measured on the default 6 mm / 1 mm mesh against that knob's
finest setting: they are each knob's own contribution. The mesh contributes its own error
on top (printed with the recommendations); only the mesh series tells how far from the
converged answer a squeeze is.

Times: every distinct program is compiled (a first ``jsq.squeeze``) before any timing.
``time_s`` is the minimum over ``--reps`` repeats (default 5) of one warm call of the jitted
core (``squeeze.time_core``: the engine's while loop, no validation, no compile); ``build_s``
the minimum of as many compliance builds (``jsq.fem.compliance``, uncached), timed for the
mesh, build and precision knobs (the other knobs share the default build, whose time they
show); ``total_s = build_s + time_s`` is the cost of one squeeze of a new object. The repeats
are interleaved across a knob's settings (repeat 1 of every setting, then repeat 2, ...), so a
slow drift of the machine's load hits every setting alike; ``load_min``/``load_max`` are the
1-minute load average over a point's repeats. A point whose squeeze does not reach the target
depth (status other than SUCCESS) is printed, written with its status and not timed.

Outputs (``--out``, default ``benchmarks/results``; ``--quick`` writes to a temporary folder
so a smoke run leaves the committed results alone): ``accuracy.csv`` (one row per point),
``accuracy_orders.csv`` (fitted orders), ``accuracy.png`` (error against time per knob),
``accuracy_pareto.png`` (force error against time for every point of every knob, two panels:
squeeze only and build + squeeze, Pareto fronts, lines at 1 %, 0.1 %, 0.01 %), and markdown
tables: every point, and for each of those levels the cheapest point that reaches it (by
squeeze time and by build + squeeze time) and a whole setting that does (every knob at its
cheapest value whose own error stays below the level).

    .venv/bin/python benchmarks/accuracy.py            # ~5 min on 2 busy cores (estimated)
    .venv/bin/python benchmarks/accuracy.py --quick    # smoke run, ~2 min

``--quick``: the three coarsest mesh members (24, 17, 12 mm) against the 6 mm / 1 mm mesh as
reference, the coarsest and finest setting of every other knob, 2 repeats; it took 2 min
(load 3.7 on 2 cores), from which the full run's time is estimated. Most of the time is
compiling, 15-20 s per distinct program: one per mesh (the 6 mm / 1 mm one is the default
program, shared by every other knob), per build method, for float32 and for any capacity
raised, 9 in all; then the spectral builds (eigendecomposition, ~15 s each at load 3.6, 6 of
them). The timed squeezes themselves take 0.005-0.15 s each, so on a loaded machine their
minimum is still noisy by tens of percent: raise ``--reps`` for steadier times.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import os
import sys
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
RESULTS = os.path.join(HERE, "results")
QUICK_OUT = os.path.join(tempfile.gettempdir(), "jaxsqueeze_accuracy_quick")   # a smoke run keeps results/ intact
DEPTH = 0.015
UNIT = (0.012, 0.002)                         # (max_edge, refine_edge) at mesh scale s = 1 [m]
REFERENCE = 1 / 4                             # scale of the mesh reference: 3 mm / 0.5 mm
MEMBERS = (8, 4 * 2 ** 0.5, 4, 2 * 2 ** 0.5, 2)   # scales of the mesh series over the reference's
CONTACT_WIDTH = 0.014                         # finger 0's contact width at 15 mm (measured) [m]
LEVELS = (1e-2, 1e-3, 1e-4)
#: a second mesh series whose reference is much finer: the same square gripped at the middles of
#: two opposite edges, mu = 0.5, squeezed 15 mm (the demo's grip has no finer reference that
#: reaches 15 mm, see the docstring). Not part of the Pareto front and the recommendations,
#: which are for the demo scene.
CENTRED_KNOB = "mesh, centred grip"
CENTRED = dict(points=((0.0, -0.05), (0.0, 0.05)), friction=0.5, depth=DEPTH)
CENTRED_EDGES = (0.004, 0.0028, 0.002, 0.0014, 0.001, 0.0007, 0.0005, 0.00025)   # refine_edge of the members and the reference [m]
SHARED_BUILD = ("step", "event_tol", "newton_tol")   # knobs that keep the default operator: its build time
COLUMNS = ["knob", "setting", "reference", "nodes", "boundary", "capacity", "spacing_mm", "time_s", "build_s",
           "total_s", "force_err", "width_err", "width_mm", "event_err", "unmatched", "rows", "status",
           "load_min", "load_max", "repeats"]


@dataclass
class Point:
    """One setting of one knob: its scene, what its squeeze gave and its timings."""

    knob: str
    setting: str
    scene: object
    f32: bool = False                          # run inside jax.enable_x64(False)
    builds: bool = False                       # time the compliance build too
    spacing: float = float("nan")              # boundary node spacing in the contact zone [m]
    got: dict = field(default_factory=dict)    # status, rows, force, width, events
    times: list = field(default_factory=list)
    build_times: list = field(default_factory=list)
    loads: list = field(default_factory=list)
    capacity: str = ""                         # contact / sliding slots of the timed program

    def precision(self):
        import jax
        return jax.enable_x64(False) if self.f32 else contextlib.nullcontext()

    @property
    def ok(self) -> bool:
        return self.got.get("status") == "SUCCESS"


# ----------------------------------------------------------------------------- scenes
def settings_for(refine_edge: float):
    """An event log and a step bound that fit a mesh whose contact zone has this spacing (the
    defaults 256 / 400 down to 0.7 mm); the contact slots are automatic (grown on overflow)."""
    import jaxsqueeze as jsq
    per_finger = CONTACT_WIDTH / refine_edge
    events = max(256, 32 * math.ceil(6 * per_finger / 32))
    return jsq.Settings(max_events=events, max_steps=max(400, events + 150))


def mesh_scene(base, scale: float):
    """The demo scene on the uniformly scaled mesh (max_edge, refine_edge) = UNIT x scale,
    built as the scene-file loader builds it (refined zone radius 2 x the file's max_edge)."""
    import jaxsqueeze as jsq
    from jaxsqueeze.io.scenefile import read
    from squeeze import SCENE, grip_of
    data = read(SCENE)
    obj, points = data["object"], [tuple(p) for p in data["grip"]["points"]]
    max_edge, refine_edge = UNIT[0] * scale, UNIT[1] * scale
    mesh = jsq.shapes.rectangle(obj["width"], obj["height"], max_edge=max_edge, refine_near=points,
                                refine_edge=refine_edge, refine_radius=2 * obj["max_edge"])
    return base.replace(mesh=mesh, grip=grip_of(mesh, *points), settings=settings_for(refine_edge))


def centred_scene(base, refine_edge: float):
    """The square gripped at the middles of two opposite edges (``CENTRED``), meshed with
    max_edge = 6 x refine_edge and the contact zones refined to ``refine_edge``."""
    import jaxsqueeze as jsq
    from squeeze import grip_of
    pts = CENTRED["points"]
    mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=6 * refine_edge, refine_near=pts, refine_edge=refine_edge,
                                refine_radius=0.012)
    return base.replace(mesh=mesh, grip=grip_of(mesh, *pts), friction=CENTRED["friction"], depth=CENTRED["depth"],
                        settings=settings_for(refine_edge))


def knobs(base, quick: bool, reference: float) -> list[list[Point]]:
    """Every knob's points, its reference (finest setting) last. ``--quick``: the three
    coarsest mesh members against the finest member as reference, 2 settings per knob."""
    import jaxsqueeze as jsq
    pick = (lambda v: [v[0], v[-1]]) if quick else (lambda v: v)
    step = DEPTH / 50
    scales = [reference * k for k in (MEMBERS[:3] + MEMBERS[-1:] if quick else MEMBERS + (1,))]
    mesh = [Point("mesh", f"{1e3 * UNIT[0] * s:.2g} / {1e3 * UNIT[1] * s:.2g} mm", mesh_scene(base, s),
                  builds=True, spacing=UNIT[1] * s) for s in scales]

    def tuned(knob, values, label, value):
        """One point per value of a tolerance of ``Settings`` (no new program)."""
        return [Point(knob, label(v), base.replace(settings=jsq.Settings(**{knob: value(v)}))) for v in pick(values)]

    return [
        mesh,
        tuned("step", [10, 25, 50, 100, 200], lambda k: f"depth/{k}", lambda k: DEPTH / k),
        tuned("event_tol", [1e-1, 1e-2, 1e-4, 1e-6, 1e-9], lambda x: f"step x {x:g}", lambda x: step * x),
        tuned("newton_tol", [1e-3, 1e-5, 1e-7, 1e-10, 1e-13], lambda x: f"{x:g} rad", lambda x: x),
        [Point("precision", "float32", mesh_scene(base, 1 / 2), f32=True, builds=True),
         Point("precision", "float64", base, builds=True)],
        [Point("build", m, base.replace(method=m), builds=True) for m in pick(["dense", "spectral", "sparse"])],
    ] + ([] if quick else [[Point(CENTRED_KNOB, f"{6e3 * h:.3g} / {1e3 * h:.3g} mm", centred_scene(base, h),
                                  builds=True, spacing=h) for h in CENTRED_EDGES]])


# ----------------------------------------------------------------------------- running and timing
GROW = {"OVERFLOW": "capacity", "EVENT_OVERFLOW": "max_events", "MAX_STEPS": "max_steps"}


def prepare(p: Point, tries: int = 3) -> None:
    """Squeeze once (compiling the program); while it runs out of a static capacity, double
    that capacity and squeeze again. Keeps the numbers compared in ``p.got``."""
    import jaxsqueeze as jsq
    with p.precision():
        for _ in range(tries):
            res = jsq.squeeze(p.scene)
            grow = GROW.get(res.outcome.name)
            if grow is None:
                break
            s = p.scene.settings
            if getattr(s, grow) is None:      # an automatic capacity that could not grow further
                break
            print(f"  {p.knob} {p.setting}: {res.outcome.name}, {grow} -> {2 * getattr(s, grow)}", flush=True)
            p.scene = p.scene.replace(settings=dataclasses.replace(s, **{grow: 2 * getattr(s, grow)}))
        from jaxsqueeze.simulation import api as G
        cfg = G.eager_config(p.scene, p.scene.operator())
        p.capacity = f"{cfg.capacity} / {cfg.sliding}"
    p.got = dict(status=res.outcome.name, rows=int(res.count), depth=float(res.final_depth),
                 force=np.asarray(res.total_force[-1, 0], float), width=contact_width(res),
                 events=[(d, n, k, f) for d, n, k, f in res.events.rows()])
    if not p.ok:
        print(f"  {p.knob} {p.setting}: {p.got['status']} at depth {1e3 * p.got['depth']:.3f} mm, "
              "not timed", flush=True)


def contact_width(res) -> float:
    """Arc on the fingertip spanned by finger 0's contact nodes at the final row [m]."""
    from jaxsqueeze.post.views import contact_regions
    regions = contact_regions(res)[0]
    if not regions:
        return float("nan")
    lo = min(r["theta_range"][0] for r in regions)
    hi = max(r["theta_range"][1] for r in regions)
    return float(res.radius) * (hi - lo)


def build_time(scene) -> float:
    """Wall time of one uncached compliance build of the scene's object."""
    import jax

    import jaxsqueeze as jsq
    t = time.perf_counter()
    op = jsq.fem.compliance(scene.mesh, jsq.Material(1.0, scene.material.nu, 1.0), scene.method)
    jax.block_until_ready(op.G)
    return time.perf_counter() - t


def time_knob(points: list[Point], reps: int) -> None:
    """Repeat r of every point, then repeat r + 1, ...: interleaved, warm calls only."""
    from squeeze import load1, time_core
    for _ in range(reps):
        for p in filter(lambda p: p.ok, points):
            with p.precision():
                if p.builds:
                    p.build_times.append(build_time(p.scene))
                p.times.append(time_core(p.scene, 1)[0])
            p.loads.append(load1())


# ----------------------------------------------------------------------------- errors
def row_of(p: Point, ref: Point) -> dict:
    """The CSV row of a point, with its errors against the knob's reference."""
    nan = float("nan")
    r = dict(knob=p.knob, setting=p.setting, reference=ref.setting, nodes=p.scene.mesh.n, boundary=p.scene.mesh.m,
             capacity=p.capacity, spacing_mm=1e3 * p.spacing, status=p.got["status"],
             rows=p.got["rows"], repeats=len(p.times), time_s=min(p.times, default=nan),
             build_s=min(p.build_times, default=nan), load_min=min(p.loads, default=nan),
             load_max=max(p.loads, default=nan), width_mm=1e3 * p.got["width"])
    good = p.ok and ref.ok
    F, F0 = p.got["force"], ref.got["force"]
    r["force_err"] = float(np.linalg.norm(F - F0) / np.linalg.norm(F0)) if good else nan
    r["width_err"] = abs(p.got["width"] - ref.got["width"]) / ref.got["width"] if good else nan
    r["event_err"], r["unmatched"] = event_errors(p.got["events"], ref.got["events"]) \
        if good and not p.knob.startswith("mesh") else (nan, -1)
    return r


def event_errors(events, ref_events):
    """Largest depth difference of matched events / depth, and the count of unmatched events."""
    pool = {}
    for d, n, k, f in ref_events:
        pool.setdefault((n, k, f), []).append(d)
    errs, unmatched = [], 0
    for d, n, k, f in events:
        lst = pool.get((n, k, f))
        if lst:
            errs.append(abs(d - lst.pop(0)))
        else:
            unmatched += 1
    unmatched += sum(len(v) for v in pool.values())
    return (max(errs) / DEPTH if errs else float("nan")), unmatched


def fit_orders(rows) -> list[dict]:
    """Order p of each mesh series' errors: least-squares slope of log(error) against
    log(refine_edge)."""
    out = []
    for knob in ("mesh", CENTRED_KNOB):
        members = [r for r in rows if r["knob"] == knob and r["setting"] != r["reference"]]
        for q in ("force_err", "width_err"):
            pts = [(r["spacing_mm"], r[q]) for r in members if r[q] > 0]     # NaN and exact 0 drop out
            p = np.polyfit(np.log([h for h, _ in pts]), np.log([e for _, e in pts]), 1)[0] if len(pts) >= 2 \
                else float("nan")
            if members:
                out.append(dict(knob=knob, quantity=q, order=float(p), h="refine_edge (= max_edge / 6)",
                                fit_points=len(pts), reference=members[0]["reference"]))
    return out


# ----------------------------------------------------------------------------- Pareto and recommendations
def timed(rows, t):
    """Points of the demo scene with a measured time and a positive force error (references
    have none)."""
    return [r for r in rows if np.isfinite(r[t]) and r["force_err"] > 0 and r["knob"] != CENTRED_KNOB]


def pareto(rows, t):
    """The points no other point beats in both time and force error, fastest first."""
    front, best = [], float("inf")
    for r in sorted(timed(rows, t), key=lambda r: (r[t], r["force_err"])):
        if r["force_err"] < best:
            front.append(r)
            best = r["force_err"]
    return front


def cheapest(rows, t, level):
    """The fastest point (by column ``t``) whose force error is at most ``level``."""
    ok = [r for r in timed(rows, t) if r["force_err"] <= level]
    return min(ok, key=lambda r: r[t]) if ok else None


def setting_for(rows, level) -> str:
    """Every knob at its cheapest value (build + squeeze) whose own force error is at most
    ``level``, its reference included: a whole setting, since the knobs' errors add up."""
    picks = []
    for knob in dict.fromkeys(r["knob"] for r in rows if r["knob"] != CENTRED_KNOB):
        ok = [r for r in rows if r["knob"] == knob and r["force_err"] <= level and np.isfinite(r["total_s"])]
        best = min(ok, key=lambda r: r["total_s"], default=None)
        picks.append(f"{knob} {best['setting']}{' (ref)' if best['setting'] == best['reference'] else ''}"
                     if best else f"{knob}: none")
    return ", ".join(picks)


# ----------------------------------------------------------------------------- main
def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reps", type=int, default=None, help="timed repeats per point (default 5, --quick 2)")
    p.add_argument("--reference", type=float, default=REFERENCE,
                   help=f"scale s of the mesh reference: (max_edge, refine_edge) = s x {UNIT} m (default "
                        f"{REFERENCE:g}); the members are 2 to 8 times coarser")
    p.add_argument("--quick", action="store_true", help="smoke run: 3 mesh members, 2 settings per knob, 2 repeats")
    p.add_argument("--out", default=None, help=f"output folder (default {RESULTS}; --quick: {QUICK_OUT})")
    a = p.parse_args(argv)
    reps = a.reps or (2 if a.quick else 5)
    out = a.out or (QUICK_OUT if a.quick else RESULTS)
    import jax
    jax.config.update("jax_enable_x64", True)
    from squeeze import foam, machine, write_csv

    info = machine()
    print(info, flush=True)
    t0 = time.perf_counter()
    rows = []
    for points in knobs(foam(), a.quick, a.reference):
        for pt in points:
            prepare(pt)
        time_knob(points, reps)
        for r in (row_of(pt, points[-1]) for pt in points):
            rows.append(r)
            print(f"{r['knob']:10s} {r['setting']:18s} {r['status']:8s} rows {r['rows']:3d}  time "
                  f"{num(r['time_s'], '.4f')} s  build {num(r['build_s'], '.3f')} s  force err "
                  f"{sci(r['force_err'])}  width err {sci(r['width_err'])}  load {num(r['load_max'], '.2f')}",
                  flush=True)
    default_build = next(r["build_s"] for r in rows if r["knob"] == "build" and r["setting"] == "sparse")
    for r in rows:
        r["build_s"] = default_build if r["knob"] in SHARED_BUILD else r["build_s"]
        r["total_s"] = r["build_s"] + r["time_s"]
    orders = fit_orders(rows)

    write_csv(os.path.join(out, "accuracy.csv"), rows, COLUMNS, info)
    write_csv(os.path.join(out, "accuracy_orders.csv"), orders, ["knob", "quantity", "order", "h", "fit_points",
                                                                  "reference"], info)
    plot_knobs(rows, os.path.join(out, "accuracy.png"), info)
    plot_pareto(rows, os.path.join(out, "accuracy_pareto.png"), info)
    report(rows, orders)
    print(f"\nwall time {time.perf_counter() - t0:.0f} s")


def num(v, spec):
    return f"{v:{spec}}" if np.isfinite(v) else "—"


def sci(v):
    return "—" if not np.isfinite(v) else ("0" if v == 0 else f"{v:.1e}")


def report(rows, orders):
    print("\n| knob | setting | nodes | m | capacity | time [s] | build [s] | rows | force error | "
          "width error (spacing / width) | event error | unmatched | status | load |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|")
    for r in rows:
        ref = " (ref)" if r["setting"] == r["reference"] else ""
        q = f" ({r['spacing_mm'] / r['width_mm']:.2f})" if r["knob"].startswith("mesh") else ""
        un = "—" if r["unmatched"] < 0 else r["unmatched"]
        load = f"{r['load_min']:.1f}–{r['load_max']:.1f}" if r["repeats"] else "—"
        print(f"| {r['knob']} | {r['setting']}{ref} | {r['nodes']} | {r['boundary']} | {r['capacity']} | "
              f"{num(r['time_s'], '.3f')} | {num(r['build_s'], '.2f')} | {r['rows']} | {sci(r['force_err'])} | "
              f"{sci(r['width_err'])}{q} | {sci(r['event_err'])} | {un} | {r['status']} | {load} |")
    print("\nOrder of convergence (least squares of log error vs log refine_edge): "
          + ", ".join(f"{o['knob']}: {o['quantity']} p = {o['order']:.2f} ({o['fit_points']} points)" for o in orders))
    print("\n| force error ≤ | cheapest point, squeeze only | cheapest point, build + squeeze | "
          "whole setting (each knob's own error ≤ level) |")
    print("|---:|---|---|---|")
    for level in LEVELS:
        cells = []
        for t in ("time_s", "total_s"):
            r = cheapest(rows, t, level)
            cells.append("none" if r is None else f"{r['knob']} {r['setting']} ({r[t]:.3f} s, {sci(r['force_err'])})")
        print(f"| {100 * level:g} % | {cells[0]} | {cells[1]} | {setting_for(rows, level)} |")
    base = [r for r in rows if r["knob"] == "mesh" and r["setting"] == "6 / 1 mm" and r["reference"] != "6 / 1 mm"]
    if base:
        print(f"\nThe non-mesh knobs' errors are against their finest setting on the default 6 mm / 1 mm mesh, "
              f"whose own force error against the mesh reference is {sci(base[0]['force_err'])}: a single point "
              "of a non-mesh knob reaches a level only for that knob's part of the error.")


# ----------------------------------------------------------------------------- figures
def plot_knobs(rows, path, info):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    knobs_ = list(dict.fromkeys(r["knob"] for r in rows))
    nrow = math.ceil(len(knobs_) / 3)
    fig, axs = plt.subplots(nrow, 3, figsize=(13, 3.75 * nrow), dpi=80, squeeze=False)
    floor = 1e-16
    for ax, knob in zip(axs.flat, knobs_):
        rs = [r for r in rows if r["knob"] == knob and r["setting"] != r["reference"] and np.isfinite(r["time_s"])]
        t = [r["total_s"] if knob.startswith("mesh") or knob == "build" else r["time_s"] for r in rs]
        for key, style, lab in (("force_err", "o-", "final force, finger 0 (rel.)"),
                                ("width_err", "s--", "contact width, finger 0 (rel.)"),
                                ("event_err", "^:", "event depths (/ depth)")):
            err = [r[key] for r in rs]
            if np.any(np.isfinite(err)):
                ax.loglog(t, [max(v, floor) for v in err], style, label=lab)
        for r, x in zip(rs, t):
            ax.annotate(r["setting"], (x, max(r["force_err"], floor)), fontsize=7, xytext=(3, 3),
                        textcoords="offset points")
        failed = [f"{r['setting']}: {r['status']}" for r in rows if r["knob"] == knob and r["status"] != "SUCCESS"]
        if failed:
            ax.text(0.02, 0.02, "\n".join(failed), transform=ax.transAxes, fontsize=8, color="red")
        ref = [r for r in rows if r["knob"] == knob and r["setting"] == r["reference"]][0]
        ax.set_title(f"{knob} (ref: {ref['setting']})", fontsize=9)
        ax.set_xlabel("time [s]" + (" (build + squeeze)" if knob.startswith("mesh") or knob == "build"
                                    else " (squeeze)"))
        ax.set_ylabel("error")
        ax.grid(True, which="both", alpha=0.3)
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())   # no overlapping labels
        if ax.lines:
            ax.legend(fontsize=7, loc="best")
    for ax in list(axs.flat)[len(knobs_):]:
        ax.axis("off")
    fig.suptitle(f"foam square 15 % squeeze (last panel: centred grip, mu = 0.5): error vs time per knob "
                 f"(floor 1e-16) — {info}", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    print(f"wrote {path}")


def plot_pareto(rows, path, info):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    knobs_ = list(dict.fromkeys(r["knob"] for r in rows if r["knob"] != CENTRED_KNOB))
    markers = dict(zip(knobs_, "osD^vP"))
    fig, axs = plt.subplots(1, 2, figsize=(13, 5.5), dpi=80, sharey=True)
    for ax, t, title in ((axs[0], "time_s", "squeeze only (operator reused)"),
                         (axs[1], "total_s", "compliance build + squeeze (new object)")):
        for knob in knobs_:
            rs = [r for r in timed(rows, t) if r["knob"] == knob]
            if rs:
                ax.loglog([r[t] for r in rs], [r["force_err"] for r in rs], markers[knob], ls="none", alpha=0.8,
                          label=knob)
        front = pareto(rows, t)
        if front:
            ax.step([r[t] for r in front], [r["force_err"] for r in front], "k-", where="post", lw=1,
                    label="Pareto front")
            for r in front:
                ax.annotate(f"{r['knob']} {r['setting']}", (r[t], r["force_err"]), fontsize=7, xytext=(4, -9),
                            textcoords="offset points")
        for level in LEVELS:
            ax.axhline(level, color="gray", lw=0.8, ls="--")
            ax.annotate(f"{100 * level:g} %", (0, level), xycoords=("axes fraction", "data"), fontsize=7,
                        xytext=(2, 2), textcoords="offset points", color="gray")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("time [s] (min of the repeats)")
        ax.grid(True, which="both", alpha=0.3)
    axs[0].set_ylabel("final force error, finger 0 (rel. to the knob's reference)")
    handles, labels = axs[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8)
    fig.suptitle(f"foam square 15 % squeeze: force error vs time, all knobs — {info}", fontsize=8)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    fig.savefig(path)
    print(f"wrote {path}")


if __name__ == "__main__":
    sys.exit(main())
