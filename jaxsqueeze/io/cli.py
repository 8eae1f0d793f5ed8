"""Command line: ``jaxsqueeze run SCENE.toml --out DIR``, ``jaxsqueeze plan SCENE.toml --out DIR``
and ``jaxsqueeze demo``."""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time

EPILOG = """\
examples:
  jaxsqueeze demo                          # built-in foam square, outputs in ./demo_out
  jaxsqueeze demo --out results/foam
  jaxsqueeze run examples/foam_disk.toml --out out/disk
  jaxsqueeze run scene.toml --out out --max-edge 0.008 --verbose
  jaxsqueeze plan scene.toml --out out/plan  # choose a grasp (see `jaxsqueeze plan --help`)
  python -m jaxsqueeze --help

outputs (in DIR):
  summary.json        status, depths, events, contact regions, total forces, largest stress, timings
  deformed.png        deformed object, fingertips, stick (blue) / slip (red) nodes (Fig. 4)
  stress.png          the deformed object coloured by von Mises stress
  force_profile.png   force density and direction along each contact (Fig. 5)
  sliding_profile.png polar angle of every contact node against depth (Fig. 6)
  events.png          timeline of the contact events A-D
  squeeze.xdmf/.h5    ParaView time series, one step per recorded state
  final.vtu           ParaView file of the final state

exit status: 0 the squeeze reached its depth, 1 it ended otherwise (e.g. SLIP_FAILURE;
outputs are still written), 2 bad command line or scene file (nothing is written),
3 internal error (the full traceback is written to a file named in the message),
130 interrupted (Ctrl-C or SIGTERM; the previous outputs, if any, are left as they were).
Outputs are written into a temporary folder beside DIR and moved in place at the end.
See docs/errors.md for every status and exit code.
The scene file format is described in jaxsqueeze.scenefile (python -m pydoc jaxsqueeze.scenefile).
"""

PLAN_EPILOG = """\
examples:
  jaxsqueeze plan examples/foam_disk.toml --out out/plan
  jaxsqueeze plan scene.toml --out out/plan --max-edge 0.01 --no-plots

The [plan] table of the scene file (optional, every key optional) sets quality, spacing,
starts, steps, optimizer, learning_rate and an adversary push (push, push_at, push_angle);
see jaxsqueeze.scenefile.

outputs (in DIR):
  summary.json        the best grasp (arc lengths, angle, quality, status, forces), the map's
                      best cells and feasible pairs, every search path
  map.png             the quality over every pair of finger positions, with the search paths
  best.png            the deformed object under the best grasp

exit status: 0 the best grasp's squeeze reached its depth, 1 it ended otherwise, 2 bad
command line or scene file, or no feasible grasp found (nothing is written), 3 internal
error, 130 interrupted. See docs/errors.md.
"""


class _Progress:
    """One line per phase on stderr, with the elapsed time; silent unless enabled."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.t0 = time.perf_counter()
        self.timings: dict = {}
        self._phase = None
        self._start = None

    def start(self, phase: str, label: str):
        self.done()
        self._phase, self._start = phase, time.perf_counter()
        if self.enabled:
            print(f"[{self._start - self.t0:6.1f} s] {label} ...", file=sys.stderr, flush=True)

    def done(self):
        if self._phase is not None:
            self.timings[self._phase] = time.perf_counter() - self._start
            self._phase = None


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="jaxsqueeze",
        description="Simulate a two-finger squeeze grasp of a soft planar object (Guo, Lin & Jia) "
                    "and write a summary, plots and ParaView files.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    from .. import __version__
    p.add_argument("--version", action="version", version=f"jaxsqueeze {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    def common(sp, default_out=None):
        sp.add_argument("--out", metavar="DIR", default=default_out, required=default_out is None,
                        help="output folder: a new or empty one, or an earlier output folder (replaced whole)"
                        + (f"; default {default_out}" if default_out else ""))
        sp.add_argument("--max-edge", type=float, metavar="M", default=None,
                        help="override object.max_edge [m] (coarser = faster)")
        sp.add_argument("--refine-edge", type=float, metavar="M", default=None,
                        help="override object.refine_edge [m], the edge length near the grip points")
        sp.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
        sp.add_argument("-v", "--verbose", action="store_true", help="progress on stderr even when it is not a terminal")
        sp.add_argument("-q", "--quiet", action="store_true", help="no progress and no summary on stdout")
        sp.add_argument("--no-cache", dest="cache", action="store_false",
                        help="do not use the persistent compilation cache (~/.cache/jaxsqueeze/jax)")

    r = sub.add_parser("run", help="squeeze the scene of a TOML file",
                       description="Squeeze the scene described by a TOML scene file.",
                       epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("scene", metavar="SCENE.toml", help="scene file (see jaxsqueeze.scenefile)")
    common(r)
    pl = sub.add_parser("plan", help="choose a grasp: grasp map, gradient search, best grasp",
                        description="Map a grasp quality over every pair of finger positions, search it with "
                                    "forward-mode gradients, squeeze the best grasp (the [plan] table of the "
                                    "scene file sets quality, spacing, starts, steps, optimizer, learning_rate "
                                    "and an adversary push). Writes map.png, best.png and summary.json.",
                        epilog=PLAN_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    pl.add_argument("scene", metavar="SCENE.toml", help="scene file (see jaxsqueeze.scenefile)")
    common(pl)
    d = sub.add_parser("demo", help="squeeze the built-in foam square",
                       description="Squeeze the built-in foam-square scene (jaxsqueeze/scenes/foam_square.toml).",
                       epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    common(d, default_out="demo_out")
    d.add_argument("--print-scene", action="store_true", help="print the demo scene file and exit")
    return p


def demo_scene_text() -> str:
    from importlib import resources

    return resources.files("jaxsqueeze").joinpath("scenes/foam_square.toml").read_text(encoding="utf-8")


def _error(msg: str) -> int:
    """Exit 2: one ``error: ...`` line per problem (a scene file lists all of its problems)."""
    lines = [ln for ln in str(msg).splitlines() if ln.strip()] or ["invalid input"]
    if lines[0].startswith("invalid input:"):
        lines = lines[1:] or lines
    for ln in lines:
        print(f"error: {ln.strip()}", file=sys.stderr)
    return 2


class _Interrupted(BaseException):
    """SIGTERM, turned into an exception so the temporary output folder is cleaned up."""


def _on_sigterm(signum, frame):  # pragma: no cover - exercised in a subprocess test
    raise _Interrupted()


def main(argv=None) -> int:
    """Run the command line; returns the exit status (never raises for anything a scene file
    can cause: see the exit statuses in ``jaxsqueeze --help``)."""
    import signal
    import threading

    old = None
    if threading.current_thread() is threading.main_thread():
        old = signal.signal(signal.SIGTERM, _on_sigterm)
    scene_path = None
    try:
        args = _parser().parse_args(argv)
        scene_path = getattr(args, "scene", None) or "<demo scene>"
        from ..tracing import own_transfers       # every transfer of the program is the library's own
        return own_transfers(_main)(args)
    except (KeyboardInterrupt, _Interrupted):
        print("jaxsqueeze: interrupted; no new outputs were written", file=sys.stderr)
        return 130
    except ValueError as e:                       # the library's word on bad input
        return _error(str(e))
    except Exception as e:  # noqa: BLE001 - exit 3 with a pointer to the traceback
        import traceback

        fd, tb_path = tempfile.mkstemp(prefix="jaxsqueeze-traceback-", suffix=".txt")
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(f"jaxsqueeze {' '.join(sys.argv[1:] if argv is None else map(str, argv))}\n"
                     f"scene: {scene_path}\n\n")
            traceback.print_exc(file=fh)
        print(f"jaxsqueeze: internal error ({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}) "
              f"while running {scene_path}; the full traceback is in {tb_path} (please report it)",
              file=sys.stderr)
        return 3
    finally:
        if old is not None:
            signal.signal(signal.SIGTERM, old)


#: the files ``run``, ``plan`` and ``demo`` write into ``--out``: the only entries an existing
#: output folder may hold, since a new run replaces that folder whole
OUTPUT_FILES = frozenset({"summary.json", "squeeze.xdmf", "squeeze.h5", "final.vtu"} | {
    f"{name}.png" for name in ("deformed", "stress", "force_profile", "sliding_profile", "events", "cones", "map", "best")})


def _check_out(out: str) -> None:
    """``--out`` must be a folder we can create, or one we may replace: empty or holding only
    what an earlier run wrote (a run replaces the folder whole, so ``--out .`` or a folder of
    the user's is refused, never emptied). Checked before any work."""
    from .scenefile import SceneFileError

    if os.path.lexists(out) and not os.path.exists(out):      # (``out`` is resolved: what is left is a loop)
        raise SceneFileError("--out", f"{out} is a symbolic link that leads nowhere (a loop of links); give a "
                             "folder")
    if os.path.exists(out) and not os.path.isdir(out):
        raise SceneFileError("--out", f"{out} exists and is not a folder")
    if os.path.isdir(out):
        foreign = sorted(e.name for e in os.scandir(out) if e.name not in OUTPUT_FILES or not e.is_file())
        if foreign:
            shown = ", ".join(foreign[:3]) + (", ..." if len(foreign) > 3 else "")
            raise SceneFileError("--out", f"{out} holds files that jaxsqueeze did not write ({shown}); a run "
                                 "replaces its output folder whole, so give a new or empty folder, or an earlier "
                                 "output folder")
    if os.path.commonpath([out, os.path.realpath(os.getcwd())]) == out:
        raise SceneFileError("--out", f"{out} is the current folder or holds it; a run replaces its output folder "
                             "whole, so give a folder below or beside it, e.g. --out results")
    parent = os.path.dirname(out)
    probe = parent
    while probe and not os.path.exists(probe):
        probe = os.path.dirname(probe)
    if probe and not os.path.isdir(probe):
        raise SceneFileError("--out", f"{out} is below {probe}, which is a file, not a folder")
    try:
        longest = os.pathconf(probe or ".", "PC_NAME_MAX")
    except (OSError, ValueError):
        longest = 255
    for name in os.path.relpath(out, probe or ".").split(os.sep):
        if len(os.fsencode(name)) > longest:
            raise SceneFileError("--out", f"the name {name[:20]}... is {len(os.fsencode(name))} bytes long, and "
                                 f"this file system takes at most {longest}; give a shorter folder name")
    try:             # a real try: permissions do not tell (root, read-only or virtual file systems)
        os.rmdir(tempfile.mkdtemp(prefix=".jaxsqueeze-probe-", dir=probe or "."))
    except OSError as e:
        raise SceneFileError("--out", f"cannot write into {probe or '.'}: {(e.strerror or str(e)).lower()}") from None


def _staging(out: str) -> str:
    """A new temporary folder beside ``out`` (moved there by :func:`_publish` when complete),
    with the permissions of a folder made under the user's umask (not mkdtemp's 0700)."""
    parent = os.path.dirname(out)
    os.makedirs(parent, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix=f".{os.path.basename(out)[:64]}.tmp-", dir=parent)   # (a legal name)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)
    return tmp


def _main(args) -> int:
    if args.command == "demo" and args.print_scene:
        sys.stdout.write(demo_scene_text())
        return 0
    progress = _Progress(enabled=not args.quiet and (args.verbose or sys.stderr.isatty()))

    from . import scenefile

    # ---- read and validate everything (and the output folder) before any work
    if not args.out.strip():
        raise scenefile.SceneFileError("--out", "an empty path would name the current folder; give an output "
                                       "folder, e.g. --out results")
    out = os.path.realpath(args.out)      # a link to an earlier output folder: that folder is replaced
    _check_out(out)
    progress.start("meshing", "reading the scene and meshing")
    for opt in ("max_edge", "refine_edge"):
        v = getattr(args, opt)
        if v is not None and not (0 < v < float("inf")):
            raise scenefile.SceneFileError("--" + opt.replace("_", "-"), f"expected a length > 0 m, got {v}")
    sizes = dict(max_edge=args.max_edge, refine_edge=args.refine_edge)
    if args.command == "demo":
        from importlib import resources

        with resources.as_file(resources.files("jaxsqueeze").joinpath("scenes/foam_square.toml")) as path:
            spec = scenefile.load(path, **sizes)
    else:
        spec = scenefile.load(args.scene, **sizes)
    _plan_table(spec)
    if not args.quiet:
        for w in spec.warnings:
            print(f"warning: {w}", file=sys.stderr)

    # ---- precision: before the first JAX array
    import jax

    jax.config.update("jax_enable_x64", spec.precision == "float64")
    if args.cache and not os.environ.get("JAXSQUEEZE_NO_CACHE"):
        from .. import compile_cache

        compile_cache.enable()        # a second process reuses the compiled squeeze
    if args.command == "plan":
        return _plan(spec, out, args, progress)
    return _simulate(spec, out, args, progress)


def _plan_table(spec):
    """The scene file's ``[plan]`` table as :class:`~jaxsqueeze.io.planning.PlanSettings`, checked
    for every command (``run`` does not plan, but a file with a bad table is a bad file)."""
    from .planning import plan_settings

    return plan_settings(spec.data.get("plan", {}))


def _said(spec, caught, quiet: bool) -> list:
    """The scene file's warnings and, after them, each distinct library warning ``caught``
    (``warnings.catch_warnings(record=True)``), printed as ``warning:`` lines unless ``quiet``
    (the scene file's own were printed when it loaded)."""
    said = list(spec.warnings)
    for w in caught:
        text = str(w.message)
        if not any(s.endswith(text) for s in said):          # the scene file's own, under its key
            said.append(text)
            if not quiet:
                print(f"warning: {text}", file=sys.stderr)
    return said


def _plan(spec, out, args, progress) -> int:
    import shutil
    import warnings

    from ..post.views import json_ready
    from .planning import run_plan

    settings = _plan_table(spec)
    progress.start("plan", "mapping and searching grasps")
    tmp = _staging(out)
    try:
        with warnings.catch_warnings(record=True) as caught:     # the library's warnings, as warning: lines
            warnings.simplefilter("always")
            summary = run_plan(spec.scene, settings, tmp, progress=progress.enabled, plots=not args.no_plots)
        said = _said(spec, caught, args.quiet)
        if said:
            summary["warnings"] = said
        summary["files"] = {k: os.path.join(out, os.path.basename(v)) for k, v in summary["files"].items()}
        with open(os.path.join(tmp, "summary.json"), "w", encoding="utf-8") as f:
            json.dump(json_ready(summary), f, indent=2, allow_nan=False)
        _publish(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    progress.done()
    if not args.quiet:
        b = summary["best"]
        print(f"best grasp: s = ({b['s'][0]:.4f}, {b['s'][1]:.4f}) m, {summary['quality']} = {b['quality']:.6g}, "
              f"{b['status']}; map {summary['map']['squeezes']} squeezes, search {summary['search']['squeezes']}; "
              f"outputs in {out}")
    return 0 if summary["best"]["status"] == "SUCCESS" else 1


def _publish(tmp: str, out: str) -> None:
    """Move the finished temporary folder to ``out``, replacing an old one whole."""
    import shutil

    old = None
    if os.path.isdir(out):
        old = tmp + ".old"
        os.rename(out, old)
    os.rename(tmp, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _simulate(spec, out, args, progress) -> int:
    import shutil

    import numpy as np

    from ..post import export
    from ..post import views
    from ..simulation.api import squeeze
    from ..simulation.status import Status

    scene = spec.scene
    progress.start("operator", f"building the compliance operator ({scene.mesh.n} nodes, "
                   f"{len(scene.boundary_nodes())} on the boundary)")
    import warnings
    with warnings.catch_warnings(record=True) as caught:     # the library's warnings, as warning: lines
        warnings.simplefilter("always")
        op = scene.operator()
        progress.start("squeeze", "compiling + squeezing")
        res = squeeze(scene)
    progress.done()
    said = _said(spec, caught, args.quiet)

    tmp = _staging(out)
    try:
        paths = {}
        if not args.no_plots:
            progress.start("plots", "plotting")
            from ..post import plots

            paths.update({f"{k}_png": v for k, v in plots.save_all(res, scene, tmp).items()})
        progress.start("export", "writing ParaView files")
        paths["xdmf"] = export.write_paraview(tmp, res, scene, op=op)
        paths["vtu"] = export.write_final_vtu(os.path.join(tmp, "final.vtu"), res, scene)
        progress.done()
        progress.timings["total"] = time.perf_counter() - progress.t0

        summ = views.summary(res, scene, progress.timings)
        summ = dict(title=spec.title, scene_file=spec.path, precision=spec.precision, **summ)
        if said:
            summ["warnings"] = said
        paths["summary"] = os.path.join(tmp, "summary.json")
        summ["outputs"] = {k: os.path.basename(v) for k, v in paths.items()}
        with open(paths["summary"], "w", encoding="utf-8") as fh:
            fh.write(json.dumps(views.json_ready(summ), indent=2, allow_nan=False))
            fh.write("\n")
        _publish(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if not args.quiet:
        print(_report(summ, res, out, np))
    return 0 if res.outcome == Status.SUCCESS else 1


def _num(x, spec: str = ".3f", scale: float = 1.0) -> str:
    """A number of the summary for the report; ``None`` (a non-finite number: summary.json
    writes null) as "n/a"."""
    return "n/a" if x is None else format(float(x) * scale, spec)


def _stress(x) -> str:
    """A stress [Pa] of the summary in Pa, kPa, MPa or GPa (3 significant digits); None as "n/a"."""
    if x is None:
        return "n/a Pa"
    k = min(max(int(math.floor(math.log10(abs(x)) / 3)), 0), 3) if x else 0
    return f"{x / 1e3 ** k:.3g} {('Pa', 'kPa', 'MPa', 'GPa')[k]}"


def _report(s, res, out, np) -> str:
    mm = 1e3
    lines = [f"jaxsqueeze: {s['title']}  ({s['scene_file']})",
             f"  status       {s['status']}: {s['advice']}",
             f"  final depth  {_num(s['final_depth'], scale=mm)} mm of {_num(s.get('target_depth'), scale=mm)} mm "
             f"({_num(s['relative_depth'], '.1f', 100)} % of the grip distance {_num(s['grip_distance'], '.1f', mm)} "
             f"mm), {s['rows']} recorded states"]
    from ..post.views import EVENT_LETTERS

    seq = s["event_sequence"]
    counts = ", ".join(f"{k} {seq.count(k)}" for k in EVENT_LETTERS)
    shown = seq if len(seq) <= 60 else seq[:57] + "..."
    lines.append(f"  events       {s['n_events']} ({counts}): {shown or '-'}")
    for f in range(len(s["contact_regions"])):
        cr = s["contact_regions"][f"finger{f}"]
        F = s["total_force"][f"finger{f}"]
        regs = "; ".join(
            f"nodes {r['nodes'][0]}..{r['nodes'][-1]}, polar angle {_num(r['theta_range'][0], '.1f', 180 / np.pi)}.."
            f"{_num(r['theta_range'][1], '.1f', 180 / np.pi)} deg" for r in cr["regions"]) or "no contact"
        lines.append(f"  finger {f}     {cr['n_stick']} stick + {cr['n_slip']} slip nodes in "
                     f"{len(cr['regions'])} region(s) [{regs}]")
        size = None if None in F else np.hypot(*F)
        lines.append(f"               total force on the object ({_num(F[0])}, {_num(F[1])}) N, |F| = {_num(size)} N")
    st = s.get("stress")
    if st is not None:
        at = st["at"] or [None, None]
        lines.append(f"  stress       largest von Mises {_stress(st['max_von_mises'])}, in triangle "
                     f"{st['triangle'] if st['triangle'] is not None else 'n/a'} at ({_num(at[0], '.1f', mm)}, "
                     f"{_num(at[1], '.1f', mm)}) mm")
    t = s.get("timings", {})
    lines.append("  time         " + ", ".join(f"{k} {v:.1f} s" for k, v in t.items()))
    lines.append(f"  outputs      {out}/: " + ", ".join(s["outputs"].values()))
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
