"""A planning job, as the command line runs it: a grasp map, a gradient search on it, the best
grasp squeezed (and pushed by the adversary when the scene has one), and the pictures and
summary written to a folder. ``jaxsqueeze plan SCENE.toml --out DIR`` calls :func:`run_plan`."""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PlanSettings:
    """The ``[plan]`` section of a scene file.

    quality: a name in ``jaxsqueeze.plan.search.QUALITIES`` (default "squeeze_work"; with
        ``push`` the default is "adversary_work").
    spacing: grid spacing of the map [m] (default: perimeter / 24).
    starts: starts of the search (from the best map cells); steps: iterations per start.
    optimizer: an optax optimizer name ("adam", "sgd", "adabelief", ...); learning_rate: its
        step on the scaled coordinates 2πs/P [rad].
    push: adversary push [m] (0: none); push_at: arc length of the pushed point [m] (default:
        a quarter of the perimeter past finger 0); push_angle: offset from the inward normal [rad].
    """

    quality: str | None = None
    spacing: float | None = None
    starts: int = 5
    steps: int = 30
    optimizer: str = "adam"
    learning_rate: float = 0.02
    push: float = 0.0
    push_at: float | None = None
    push_angle: float = 0.0


KEYS = tuple(PlanSettings.__dataclass_fields__)


def feasible_pairs(ok: np.ndarray) -> int:
    """Pairs of map positions {i, j} with a successful squeeze in either order (a map of
    fingers that differ squeezes both orders; a mirrored map's are equal): ok (n, n) bool."""
    ok = np.asarray(ok, bool)
    return int(np.triu(ok | ok.T, 1).sum())


def plan_settings(table: dict) -> PlanSettings:
    """The :class:`PlanSettings` of a scene file's ``[plan]`` table; ``ValueError`` naming every
    bad key (unknown keys are refused by the scene-file loader)."""
    from ..plan.search import QUALITIES

    errors, out = [], {}
    for key, value in (table or {}).items():
        if key in ("quality", "optimizer"):
            ok = isinstance(value, str) and (key != "quality" or value in QUALITIES)
            want = f"one of {QUALITIES}" if key == "quality" else "an optax optimizer name, e.g. \"adam\""
        elif key in ("starts", "steps"):
            ok = isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= 10_000
            want = "an integer from 1 to 10000"
        else:
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and (
                value >= 0 if key in ("push",) else value > 0 if key in ("spacing", "learning_rate") else True)
            want = "a finite number" + (" >= 0" if key == "push" else " > 0" if key in ("spacing", "learning_rate") else "")
        if ok:
            out[key] = value
        else:
            errors.append(f"plan.{key}: expected {want}, got {value!r}")
    if "push_angle" in out and not math.cos(out["push_angle"]) > 0:
        errors.append(f"plan.push_angle: expected an angle from the inward normal below pi/2 in size [rad], got "
                      f"{out['push_angle']!r}: the pusher would move along the surface or away from it and push "
                      "nothing (every placement INFEASIBLE_GRIP)")
    if not out.get("push", 0.0) > 0:       # without a push there is no adversary to place or turn
        errors += [f"plan.{key}: sets the adversary's push, which needs plan.push > 0 [m]; got no push"
                   for key in ("push_at", "push_angle") if key in out]
    if errors:
        raise ValueError("\n".join(errors))
    return PlanSettings(**out)


def run_plan(scene, settings: PlanSettings, out: str, progress: bool = True, plots: bool = True) -> dict:
    """Map, search, squeeze the best grasp, write pictures (unless ``plots`` is False) and
    ``summary.json`` into ``out``.

    Returns the summary (a dict)."""
    import optax

    import jaxsqueeze as jsq
    from ..plan import quality as Q
    from ..plan.search import (check_search, compile_search_ahead, grasp_map, grid, optimize_placement, quality_of,
                               unit_step)
    from ..post import plots as figures
    from ..post.maps import plot_grasp_map
    from ..post.views import json_ready
    from ..simulation import api, validate
    from ..simulation.scene import Adversary, Placement

    P = float(scene.curve().perimeter)
    if scene.placement is None:
        try:
            scene = scene.replace(placement=Placement(s=scene.arc_length(scene.grip)), grip=None)
        except ValueError as e:
            raise ValueError(f"grip: planning places both fingers along the outer boundary and starts from the "
                             f"scene's grip, but grip {e} Give grip points on the outer boundary.") from None
    if settings.push > 0:
        s3 = settings.push_at if settings.push_at is not None else float(np.asarray(scene.placement.s)[0]) + P / 4
        size = float(np.ptp(validate.boundary_points(scene.mesh), axis=0).max())
        if not abs(s3) <= validate.MAX_WRAP * size:          # (before any compile; it wraps beyond)
            raise ValueError(f"plan.push_at: expected an arc length [m] within {validate.MAX_WRAP:,.0f} object "
                             f"sizes ({validate.MAX_WRAP * size:.4g} m) of the boundary's start, got {s3!r}; it "
                             f"wraps: take it modulo the perimeter, {P:.6g} m")
        try:
            scene = scene.replace(adversary=Adversary(s=s3, push=settings.push, angle=settings.push_angle))
        except ValueError as e:
            raise ValueError(f"plan.push: {e}") from None
    name = settings.quality or ("adversary_work" if settings.push > 0 else "squeeze_work")
    try:
        quality_of(scene, name)                 # a bad name, or adversary_work without a push, before any work
    except ValueError as e:
        raise ValueError(f"plan.quality: {e}") from None
    try:
        opt = getattr(optax, settings.optimizer)(settings.learning_rate)
        if not (hasattr(opt, "init") and hasattr(opt, "update")):
            raise TypeError
    except Exception:          # not in optax, or not an optimizer factory (optax.apply_updates, ...)
        raise ValueError(f"plan.optimizer={settings.optimizer!r} is not an optax optimizer taking a learning "
                         "rate; use e.g. \"adam\", \"sgd\" or \"adabelief\"") from None
    try:
        check_search(opt, settings.steps, settings.starts, None, None)     # before the map, not after it
        if not np.any(unit_step(opt)):          # a constant rate here: a zero first step is every step
            raise ValueError("its step from a unit gradient is zero, so the search would never move; use e.g. "
                             "\"adam\", \"sgd\" or \"adabelief\"")
    except ValueError as e:
        raise ValueError(f"plan.optimizer={settings.optimizer!r}: {e}") from None
    spacing = settings.spacing or P / 24
    try:
        grid(scene, spacing)                    # too many positions or too few, before any work
    except ValueError as e:
        raise ValueError(f"plan.spacing: {e}") from None
    op = scene.operator()
    if settings.push >= float(op.length):
        raise ValueError(f"plan.push: expected a push [m] shorter than the object ({float(op.length):.4g} m), "
                         f"got {settings.push}")
    compile_search_ahead(scene, name, op)      # compiles on the other core while the map runs
    gmap = grasp_map(scene, name, spacing=spacing, op=op, progress=progress, keep=settings.starts)
    if not len(gmap.best):                      # nothing to search from
        seen = ", ".join(f"{jsq.Status(int(k)).name} {int(c)}" for k, c in
                         zip(*np.unique(gmap.status[~np.eye(len(gmap.s), dtype=bool)], return_counts=True)))
        raise ValueError(f"no feasible grasp on the map of {len(gmap.s)} positions {gmap.s[1] - gmap.s[0]:.4g} m "
                         f"apart (ordered pairs: {seen}): use a finer plan.spacing, or change the scene (more "
                         "friction, other fingertips, a shallower squeeze)")
    # the best grasp's squeeze compiles while the search runs
    api.compile_ahead(scene.replace(placement=Placement(s=gmap.best[0, :2], angle=gmap.best[0, 2])), op)
    found = optimize_placement(scene, name, optimizer=opt, steps=settings.steps, starts=settings.starts,
                               init=gmap.best[:settings.starts], op=op, progress=progress)
    best = scene.replace(placement=found.best)
    res = jsq.squeeze(best, op=op)
    os.makedirs(out, exist_ok=True)
    paths = {}
    if plots:
        paths["map_png"] = os.path.join(out, "map.png")
        plot_grasp_map(gmap, found, label=name).savefig(paths["map_png"])
        paths["best_png"] = os.path.join(out, "best.png")
        figures.plot_deformed(res, scene, title=f"best grasp: {name} = {found.quality:.4g}").savefig(
            paths["best_png"])
    ok = gmap.feasible()
    summary = {
        "quality": name,
        "best": {"s": np.asarray(found.best.s).tolist(), "angle": float(found.best.angle), "quality": found.quality,
                 "status": res.outcome.name, "grip_force_N": float(Q.grip_force(res)),
                 "squeeze_work_J": float(Q.squeeze_work(res))},
        "map": {"spacing_m": float(gmap.s[1] - gmap.s[0]), "positions": len(gmap.s), "squeezes": gmap.evaluations,
                "feasible_pairs": feasible_pairs(ok),
                "best": [{"s": [float(x[0]), float(x[1])], "angle": float(x[2])} for x in gmap.best]},
        "search": {"squeezes": found.squeezes, "starts": len(found.history),
                   "paths": [[{"s": h.x[:2].tolist(), "angle": float(h.x[2]), "quality": h.quality,
                               "grad_norm": h.grad_norm, "status": int(h.status), "undone": bool(h.undone)}
                              for h in hist]
                             for hist in found.history]},
        "perimeter_m": P,
        "files": paths,
    }
    if scene.adversary is not None:
        summary["best"].update(adversary_work_J=float(Q.adversary_work(res)),
                               finger_work_J=np.asarray(Q.finger_work(res)).tolist(),
                               failure_push_m=float(Q.failure_push(res)),
                               squeeze_status=jsq.Status(int(res.squeeze_status)).name)
    with open(os.path.join(out, "summary.json"), "w", encoding="utf-8") as f:
        json.dump(json_ready(summary), f, indent=2, allow_nan=False)
    return summary
