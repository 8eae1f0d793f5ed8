"""TOML scene files: one file describes one squeeze (``jaxsqueeze run SCENE.toml``).

Schema (lengths in metres, forces in newtons, angles in radians; every key not marked
optional is required; unknown keys, at any level, are errors)::

    title = "foam square"          # optional, free text

    [object]                       # exactly one of `shape` / `mesh_file`
    shape = "rectangle"            # rectangle | disk | ellipse | annulus | polygon
    width = 0.1                    #   rectangle: width, height
    height = 0.1                   #   disk: radius;  ellipse: a, b;  annulus: r_outer, r_inner
                                   #   polygon: vertices = [[x, y], ...], holes = [[[x, y], ...]] (optional)
    center = [0.0, 0.0]            #   optional (not for polygon)
    max_edge = 0.004               #   target edge length (built-in shapes only)
    refine_edge = 0.001            #   optional: edge length near the grip points (needs grip.points)
    refine_radius = 0.008          #   optional: radius of the fully refined zone (default 2 max_edge)
    # mesh_file = "part.msh"       # instead of `shape`: any meshio format with triangles,
                                   #   path relative to this TOML file; z must be 0

    # --- or a band (ring-like object, Section V-A; jaxsqueeze.band) instead of shape/mesh_file:
    # band = "heart"               # heart | leaf | circle (jaxsqueeze.curves)
    # size = 0.08                  #   heart: width; leaf: length (its width is size/2, tip
                                   #   radius size/40); circle: diameter [m]
    # nodes = 128                  #   number of band nodes m (equal arc-length spacing)
    # width = 0.0005               #   optional: wall thickness in the plane w [m] (default 0.5 mm)
    # height = 0.005               #   optional: band height out of the plane h [m] (default
                                   #   material.thickness if given, else 5 mm)
    # A band's frame is its curve's: the heart and leaf are centred on their bounding box, the
    # circle on the origin; grip.points are in that frame. For a band, material.nu is ignored
    # (optional) and material.thickness is optional (it must equal object.height if both are
    # given); squeeze.contact defaults to "point"; --max-edge / --refine-edge do not apply.

    [material]
    E = 1.0e5                      # Young's modulus [Pa] > 0
    nu = 0.3                       # Poisson's ratio, -1 < nu <= 0.5
    thickness = 0.0254             # plate thickness [m] > 0

    [fingers]
    radius = 0.01                  # fingertip radius [m] > 0
    # rotation = [[0.0], [0.0]]    # optional: alpha_1(d), alpha_2(d) polynomial coefficients
                                   #   in d [m], highest power first, one row per finger

    [grip]                         # exactly one of `nodes` / `points`
    points = [[-0.005, -0.05], [0.005, 0.05]]   # finger 0 (still), finger 1 (moving): the
                                   #   nearest boundary nodes to these points (user frame)
    # nodes = [12, 57]             # or: mesh node indices on the boundary (a mesh file with
                                   #   unused nodes renumbers the rest: use points there)

    [squeeze]
    depth = 0.015                  # target squeeze depth [m] > 0; or instead:
    # relative_depth = 0.10        #   depth as a fraction rho of the initial grip distance
                                   #   (the paper's rho, Section V-A), 0 < rho < 1
    friction = 0.5                 # optional, Coulomb mu >= 0 (default 0.5)
    friction_model = "coulomb"     # optional: coulomb | frictionless | stick
    contact = "segment"            # optional: segment | point (default: point for a band)
    method = "sparse"              # optional: sparse | dense | spectral

    [accuracy]                     # optional table; every key optional (see jaxsqueeze.Settings)
    step = 0.0003                  # squeeze step [m] (default depth / 50)
    event_tol = 3e-8               # event bracket width [m] (default step * 1e-4)
    newton_tol = 1e-11             # slip-angle Newton tolerance [rad]
    gap_tol = 1e-10                # penetration tolerance for event A [m]
    capacity = 64                  # contact slots (default: chosen, grown on overflow)
    sliding_capacity = 16          # sliding contacts in the Newton system (default: chosen, grown)
    max_steps = 400                # loop iteration bound (default: 400, grown x4 up to 6,400)
    max_events = 256               # event log size (default: 256, grown x4 up to 4,096)
    newton_iters = 30
    bisect_iters = 40
    fused = false                  # the squeeze loop as one CPU kernel: ~40 % faster squeezes
                                   #   for ~2.4 s more compile (jaxsqueeze.Settings.fused)
    precision = "float64"          # float64 | float32 (the CLI sets JAX's precision from it)

    [plan]                         # optional table, read by `jaxsqueeze plan` only (every key optional)
    quality = "squeeze_work"       # squeeze_work | grip_force | slip_margin | adversary_work
                                   #   (default: adversary_work with a push, else squeeze_work)
    spacing = 0.01                 # map grid spacing along the boundary [m] (default perimeter / 24)
    starts = 5                     # search starts (from the best map cells)
    steps = 30                     # search iterations per start
    optimizer = "adam"             # an optax optimizer name
    learning_rate = 0.02           # its step on the scaled coordinates 2 pi s / perimeter [rad]
    push = 0.0                     # adversary push [m], 0 (none) <= push < object size
    push_at = 0.1                  # arc length of the pushed point [m] (default: a quarter of
                                   #   the perimeter past finger 0 of the [grip], for every grasp)
    push_angle = 0.0               # pusher direction from the inward normal [rad]
                                   #   (push_at and push_angle need push > 0)

Every problem raises :class:`SceneFileError` whose ``key`` names the offending entry
(``material.nu``, ``grip.points``, ...), so the message reads ``material.nu: ...``.
The library's own validation (``Material``, ``Scene``, ``shapes``) is reused and its
``ValueError`` is re-raised with the key that caused it.

Loading builds the mesh and validates everything (grip on the boundary, the initial
segment inside both friction cones) with numpy only: no JAX array is created, so a caller
can still choose JAX's precision afterwards (:func:`load` then ``spec.precision``).
"""
from __future__ import annotations

import math
import os
import re
import warnings as warnings_module
from dataclasses import dataclass
from typing import Any

import numpy as np


try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

SHAPES = {
    "rectangle": ("width", "height"),
    "disk": ("radius",),
    "ellipse": ("a", "b"),
    "annulus": ("r_outer", "r_inner"),
    "polygon": ("vertices",),
}
BANDS = ("heart", "leaf", "circle")
BAND_KEYS = {"band": True, "size": True, "nodes": True, "width": False, "height": False}
SHAPE_OPTIONAL = {"rectangle": ("center",), "disk": ("center",), "ellipse": ("center",),
                  "annulus": ("center",), "polygon": ("holes",)}
MESH_KEYS = ("max_edge", "refine_edge", "refine_radius")
TABLES = {
    "object": None,   # checked separately (depends on the shape)
    "material": {"E": True, "nu": True, "thickness": True},
    "fingers": {"radius": True, "rotation": False},
    "grip": {"nodes": False, "points": False},
    "squeeze": {"depth": False, "relative_depth": False, "friction": False, "friction_model": False, "contact": False, "method": False},
    "accuracy": {"step": False, "event_tol": False, "newton_tol": False, "gap_tol": False, "capacity": False,
                 "sliding_capacity": False, "max_steps": False, "max_events": False, "newton_iters": False, "bisect_iters": False,
                 "fused": False, "precision": False},
    "plan": {"quality": False, "spacing": False, "starts": False, "steps": False, "optimizer": False,
             "learning_rate": False, "push": False, "push_at": False, "push_angle": False},
}
REQUIRED_TABLES = ("object", "material", "fingers", "grip", "squeeze")
TOP_KEYS = ("title",)
PRECISIONS = ("float64", "float32")
METHODS = ("sparse", "dense", "spectral")


class SceneFileError(ValueError):
    """A bad scene file. ``key`` is the dotted name of the offending entry (or ``"file"``)."""

    def __init__(self, key: str, message: str):
        self.key = key
        self.message = message
        super().__init__(f"{key}: {message}")


@dataclass(frozen=True)
class SceneSpec:
    """A loaded scene file: the :class:`~jaxsqueeze.Scene`, the precision it asks for, its
    title and path, and the raw TOML data."""

    scene: Any
    precision: str
    title: str
    path: str
    data: dict
    warnings: tuple = ()


# ----------------------------------------------------------------------------- value checks
def _describe(v) -> str:
    if isinstance(v, str):
        return f"the string {v!r}"
    if isinstance(v, bool):
        return f"the boolean {str(v).lower()}"
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, list):
        return f"an array of {len(v)}" + ("" if all(isinstance(x, (int, float)) for x in v) else " (nested)")
    return repr(v)


def _number(key, v, positive=False, integer=False):
    if integer:
        if isinstance(v, bool) or not isinstance(v, int):
            raise SceneFileError(key, f"expected an integer, got {_describe(v)}")
        if v < 1:
            raise SceneFileError(key, f"expected a positive integer, got {v}")
        return v
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise SceneFileError(key, f"expected a number, got {_describe(v)}")
    try:
        v = float(v)
    except OverflowError:          # TOML integers have any number of digits
        raise SceneFileError(key, f"expected a finite number, got an integer of {len(str(abs(v)))} digits") from None
    if not math.isfinite(v):
        raise SceneFileError(key, f"expected a finite number, got {v}")
    if positive and v <= 0:
        raise SceneFileError(key, f"expected a number > 0, got {v}")
    return v


def _points(key, v, count=None, min_count=1):
    what = f"{count} points [[x, y], ...]" if count else "a list of points [[x, y], ...]"
    if not isinstance(v, list) or not all(isinstance(p, list) and len(p) == 2 for p in v):
        raise SceneFileError(key, f"expected {what}, got {_describe(v)}")
    if count is not None and len(v) != count:
        raise SceneFileError(key, f"expected {what}, got {len(v)} point(s)")
    if len(v) < min_count:
        raise SceneFileError(key, f"expected at least {min_count} points, got {len(v)}")
    return np.array([[_number(f"{key}[{i}]", x) for x in p] for i, p in enumerate(v)], float)


def _choice(key, v, options):
    if not isinstance(v, str) or v not in options:
        raise SceneFileError(key, f"expected one of {', '.join(repr(o) for o in options)}, got {_describe(v)}")
    return v


def _table(key, v):
    if not isinstance(v, dict):
        raise SceneFileError(key, f"expected a table [{key}], got {_describe(v)}")
    return v


def _unknown(prefix, table, allowed):
    for k in table:
        if k not in allowed:
            raise SceneFileError(f"{prefix}.{k}" if prefix else k,
                                 f"unknown key; allowed here: {', '.join(sorted(allowed))}")


def _wrap(err: ValueError, default: str, names: dict) -> SceneFileError:
    """Map a library ValueError to the key whose name its message mentions first (its advice
    may name others)."""
    msg = str(err)
    found = [(m.start(), k, key) for k, (pattern, key) in enumerate(names.items()) if (m := re.search(pattern, msg))]
    return SceneFileError(min(found)[2] if found else default, msg)


# ----------------------------------------------------------------------------- loading
def read(path) -> dict:
    """Parse a TOML file; syntax errors become ``SceneFileError("file", ...)``."""
    if os.path.isdir(path):
        raise SceneFileError("file", f"{path} is a folder, not a scene file")
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except FileNotFoundError:
        raise SceneFileError("file", f"no such scene file: {path}") from None
    except OSError as e:
        raise SceneFileError("file", f"cannot read {path}: {e.strerror or e}") from None
    try:
        text = raw.decode("utf-8-sig")          # a byte-order mark (Windows editors) is skipped
    except UnicodeDecodeError as e:
        raise SceneFileError("file", f"{path} is not UTF-8 text (byte {e.start}: {raw[e.start:e.start + 1]!r}); "
                             "a scene file is a TOML text file saved as UTF-8") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneFileError("file", f"{path} is not valid TOML: {e}") from None


def load(path, max_edge: float | None = None, refine_edge: float | None = None) -> SceneSpec:
    """Load and fully validate a scene file (see the module docstring for the schema).

    Args:
        path: the TOML file.
        max_edge: optional override of ``object.max_edge`` (built-in shapes only); a
            refined zone near the grip keeps its radius and edge length (at most max_edge).
        refine_edge: optional override of ``object.refine_edge``.
    Raises:
        SceneFileError: with the offending key.
    """
    data = read(path)
    return from_dict(data, base=os.path.dirname(os.path.abspath(path)), path=str(path), max_edge=max_edge,
                     refine_edge=refine_edge)


def load_text(text: str, base: str = ".", max_edge: float | None = None,
              refine_edge: float | None = None) -> SceneSpec:
    """Like :func:`load` from a TOML string; ``mesh_file`` paths are relative to ``base``."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneFileError("file", f"not valid TOML: {e}") from None
    return from_dict(data, base=base, path="<string>", max_edge=max_edge, refine_edge=refine_edge)


class _Collector:
    """Collects :class:`SceneFileError` s so a file with several problems lists them all."""

    def __init__(self):
        self.errors: list[SceneFileError] = []

    def add(self, err: SceneFileError):
        if not any(e.key == err.key and e.message == err.message for e in self.errors):
            self.errors.append(err)

    def run(self, fn, *args, **kw):
        """``fn(*args, **kw)``, or ``_BAD`` after recording its SceneFileError."""
        try:
            return fn(*args, **kw)
        except SceneFileError as e:
            self.add(e)
            return _BAD
        except KeyError:          # a required key that is missing: already reported as such
            return _BAD

    def raise_if_any(self):
        if len(self.errors) == 1:
            raise self.errors[0]
        if self.errors:
            raise SceneErrors(self.errors)


class SceneErrors(SceneFileError):
    """Several problems in one scene file; ``errors`` lists them (``key`` is the first's)."""

    def __init__(self, errors):
        self.errors = list(errors)
        first = self.errors[0]
        super().__init__(first.key, first.message)
        self.args = ("\n".join(str(e) for e in self.errors),)

    def __str__(self):
        return self.args[0]


_BAD = object()


def _bad(*values) -> bool:
    return any(v is _BAD for v in values)


# scene-file key of each validate.FIELDS entry (depth and grip depend on how they were given)
_FIELD_KEYS = {"material.E": "material.E", "material.nu": "material.nu", "material.thickness": "material.thickness",
               "fingers.radius": "fingers.radius", "friction": "squeeze.friction",
               "settings.step": "accuracy.step", "settings.event_tol": "accuracy.event_tol",
               "settings.newton_tol": "accuracy.newton_tol", "settings.gap_tol": "accuracy.gap_tol",
               "fingers.rotation": "fingers.rotation"}


def from_dict(data: dict, base: str = ".", path: str = "<dict>", max_edge: float | None = None,
              refine_edge: float | None = None) -> SceneSpec:
    """Build a :class:`SceneSpec` from parsed TOML data.

    Every independent problem is collected: a file with several problems raises one
    :class:`SceneErrors` (a :class:`SceneFileError`) that lists them all, like a compiler.
    """
    from ..mechanics.material import Material
    from ..simulation import validate
    from ..simulation.scene import Fingers, Scene, Settings

    errs = _Collector()
    warnings: list[str] = []
    errs.run(_unknown, "", data, set(TABLES) | set(TOP_KEYS))
    for t in REQUIRED_TABLES:
        if t not in data:
            errs.add(SceneFileError(t, f"missing table [{t}]"))
    tables = {}
    for t in TABLES:
        if t in data:
            tables[t] = errs.run(_table, t, data[t])
    tables.setdefault("accuracy", {})
    have = lambda t: isinstance(tables.get(t), dict)  # noqa: E731
    title = data.get("title", os.path.splitext(os.path.basename(path))[0])
    if not isinstance(title, str):
        errs.add(SceneFileError("title", f"expected a string, got {_describe(title)}"))
    elif not title.isprintable():        # (NUL, escape sequences: the report prints the title)
        errs.add(SceneFileError("title", f"expected printable text, got {title!r} (control characters)"))
    is_band = have("object") and "band" in tables["object"]
    for t, keys in TABLES.items():
        if keys is None or not have(t):
            continue
        errs.run(_unknown, t, tables[t], set(keys))
        for k, required in keys.items():
            if is_band and t == "material" and k in ("nu", "thickness"):
                continue                      # a band has no nu; its height may come from [object]
            if required and k not in tables[t]:
                errs.add(SceneFileError(f"{t}.{k}", "missing (required)"))
    sq = tables["squeeze"] if have("squeeze") else None
    if sq is not None and ("depth" in sq) == ("relative_depth" in sq):
        errs.add(SceneFileError("squeeze.depth", "give exactly one of squeeze.depth [m] or squeeze.relative_depth"))

    # accuracy (first: it holds the precision)
    acc = tables["accuracy"] if have("accuracy") else {}
    precision = errs.run(_choice, "accuracy.precision", acc.get("precision", "float64"), PRECISIONS)
    settings = {}
    for k in ("step", "event_tol", "newton_tol", "gap_tol"):
        if k in acc:
            settings[k] = errs.run(_number, f"accuracy.{k}", acc[k], positive=True)
    for k in ("capacity", "sliding_capacity", "max_steps", "max_events", "newton_iters", "bisect_iters"):
        if k in acc:
            settings[k] = errs.run(_number, f"accuracy.{k}", acc[k], integer=True)
    if "fused" in acc:
        if isinstance(acc["fused"], bool):
            settings["fused"] = acc["fused"]
        else:
            errs.add(SceneFileError("accuracy.fused", f"expected true or false, got {acc['fused']!r}"))
    if not _bad(settings.get("capacity")) and settings.get("capacity", 2) < 2:
        errs.add(SceneFileError("accuracy.capacity", "expected at least 2 (one contact per finger)"))
    if not _bad(settings.get("sliding_capacity")) and settings.get("sliding_capacity", 1) < 1:
        errs.add(SceneFileError("accuracy.sliding_capacity", "expected at least 1"))
    settings_ok = not _bad(*settings.values())
    dtype = np.float32 if precision == "float32" else np.float64

    # material
    material = errs.run(_material, tables["material"], tables.get("object") if have("object") else {},
                                is_band) if have("material") else _BAD
    band_height = material.thickness if is_band and not _bad(material) else None

    # fingers
    fingers = errs.run(_fingers, tables["fingers"]) if have("fingers") else _BAD

    # grip (points are needed for refinement)
    grip_points = grip_nodes = _BAD
    if have("grip"):
        grip_t = tables["grip"]
        if ("nodes" in grip_t) == ("points" in grip_t):
            errs.add(SceneFileError("grip", "give exactly one of grip.nodes = [i, j] or grip.points = "
                                    "[[x1, y1], [x2, y2]]"))
        elif "points" in grip_t:
            grip_points, grip_nodes = errs.run(_points, "grip.points", grip_t["points"], count=2), None
        else:
            g = grip_t["nodes"]
            if not (isinstance(g, list) and len(g) == 2 and all(isinstance(v, int) and not isinstance(v, bool)
                                                                 for v in g)):
                errs.add(SceneFileError("grip.nodes", f"expected two integer mesh node indices [i, j], got "
                                        f"{_describe(g)}"))
            else:
                grip_nodes, grip_points = g, None

    # cheap numbers of [squeeze] before meshing
    friction = fmodel = contact = method = depth_given = rho = _BAD
    if sq is not None:
        friction = errs.run(_number, "squeeze.friction", sq.get("friction", 0.5))
        fmodel = errs.run(_choice, "squeeze.friction_model", sq.get("friction_model", "coulomb"),
                          ("coulomb", "frictionless", "stick"))
        contact = errs.run(_choice, "squeeze.contact", sq.get("contact", "point" if is_band else "segment"),
                           ("segment", "point"))
        method = errs.run(_choice, "squeeze.method", sq.get("method", "sparse"), METHODS)
        if "relative_depth" in sq and "depth" not in sq:
            rho = errs.run(_number, "squeeze.relative_depth", sq["relative_depth"], positive=True)
            if not _bad(rho) and rho >= 1:
                errs.add(SceneFileError("squeeze.relative_depth",
                                        f"expected a fraction 0 < rho < 1 of the grip distance, got {rho}"))
                rho = _BAD
            depth_given = None
        elif "depth" in sq:
            depth_given = errs.run(_number, "squeeze.depth", sq["depth"])
    dkey = "squeeze.relative_depth" if sq is not None and "relative_depth" in sq else "squeeze.depth"

    # mesh, after guarding its cost (element count, compliance, history memory) before any work
    mesh = _BAD
    if have("object") and not _bad(grip_points, grip_nodes):
        if is_band:
            if not _bad(material):
                made = errs.run(_band, tables["object"], band_height, (max_edge, refine_edge))
                if not _bad(made):
                    mesh, said = made
                    warnings.extend(said)
        else:
            est = errs.run(_estimate, tables["object"], (max_edge, refine_edge), grip_points)
            if est is not None and not _bad(est):
                size, n_tri, m_est = est
                if not _bad(fingers, depth_given, material):
                    uerr, _ = validate.unit_problems(          # warnings: below, on the mesh made
                        size=size, radius=float(fingers.radius), E=float(material.E),
                        depth=depth_given if depth_given else None)
                    for msg in uerr:
                        errs.add(SceneFileError(dkey, msg))
                if settings_ok and not _bad(method):
                    s0 = Settings(**settings)
                    for msg in validate.check_costs(int(m_est), int(n_tri / 2 + m_est), method, s0.slots(int(m_est)),
                                                    *s0.bounds(), dtype):
                        errs.add(SceneFileError(_cost_key(msg), msg + " (estimated before meshing)"))
            if not errs.errors:
                made = errs.run(_object, tables["object"], base, grip_points, (max_edge, refine_edge))
                if not _bad(made):
                    mesh, said = made
                    warnings.extend(said)
    errs.raise_if_any()                                   # everything below needs all of the above

    # grip → nodes
    if grip_points is not None:
        grip = _grip_nodes(errs, warnings, mesh, grip_points)
        gkey = "grip.points"
        if grip[0] == grip[1]:
            errs.add(SceneFileError("grip.points", f"both points are nearest to the same boundary node {grip[0]}"))
    elif getattr(mesh, "source", None) is not None and np.any(mesh.source != np.arange(mesh.n)):
        dropped = np.setdiff1d(np.arange(int(mesh.source[-1]) + 1), mesh.source)
        errs.add(SceneFileError("grip.nodes", "the mesh file has nodes used by no triangle (file nodes "
                                f"{', '.join(map(str, dropped[:8].tolist()))}{' ...' if len(dropped) > 8 else ''}), "
                                "which are dropped and the rest renumbered, so file node numbers would name other "
                                "nodes; give grip.points = [[x0, y0], [x1, y1]] instead, or remove the unused nodes "
                                "from the file"))
        grip, gkey = tuple(grip_nodes), "grip.nodes"
    else:
        bad = [v for v in grip_nodes if not 0 <= v < mesh.n]
        if bad:
            errs.add(SceneFileError("grip.nodes", f"node(s) {bad} do not exist: the mesh has nodes 0..{mesh.n - 1}"))
        elif grip_nodes[0] == grip_nodes[1]:       # (before relative_depth makes a zero depth of it)
            errs.add(SceneFileError("grip.nodes", f"grip=({grip_nodes[0]}, {grip_nodes[1]}) names node {grip_nodes[0]} "
                                    "twice: give two different boundary nodes"))
        grip, gkey = tuple(grip_nodes), "grip.nodes"
    errs.raise_if_any()
    depth = rho * _grip_distance(mesh, grip) if rho is not None and depth_given is None else depth_given
    # mixed units and a deep squeeze, on the object as made (a mesh file or band included), in
    # the words and numbers an eager squeeze would warn with
    warnings.extend(validate.unit_problems(
        size=float(np.max(np.ptp(mesh.points, axis=0))), radius=float(fingers.radius), depth=float(depth),
        E=float(material.E), thickness=float(material.thickness), between=_grip_distance(mesh, grip))[1])
    scene = None
    try:
        scene = Scene(mesh=mesh, material=material, fingers=fingers, grip=grip, friction=friction, depth=depth,
                      friction_model=fmodel, contact=contact, method=method, settings=Settings(**settings))
    except ValueError as e:
        m = re.search(r"Settings\.(\w+)", str(e))
        if m:
            errs.add(SceneFileError(f"accuracy.{m.group(1)}", str(e)))
        else:
            errs.add(_wrap(e, "squeeze", {r"^friction=": "squeeze.friction", r"^depth=": dkey,
                                          r"^friction_model=": "squeeze.friction_model",
                                          r"^contact=": "squeeze.contact", r"^grip": gkey}))
    errs.raise_if_any()

    # one validation layer (the same rules as the engine's traced twin), in the run's precision
    keys = dict(_FIELD_KEYS, depth=dkey, grip=gkey, **{"grip.overlap": gkey})
    vals = validate.values_of(scene, eps=float(np.finfo(dtype).eps))
    for line in validate.problems(vals):
        field = line.split(" = ", 1)[0]
        errs.add(SceneFileError(keys.get(field, field), line))
    for msg in validate.scene_cost_problems(scene, dtype):
        errs.add(SceneFileError(_cost_key(msg), msg))
    if not errs.errors:
        errs.run(_check_cones, scene, gkey, precision)
    errs.raise_if_any()
    return SceneSpec(scene=scene, precision=precision, title=title, path=str(path), data=data,
                     warnings=tuple(warnings))


def _cost_key(msg: str) -> str:
    for k in ("capacity", "max_steps", "max_events"):
        if msg.startswith(f"settings.{k}"):
            return f"accuracy.{k}"
    return "object"


def _material(mat_t, obj_t, is_band):
    from ..mechanics.material import Material

    E = _number("material.E", mat_t["E"])
    nu = _number("material.nu", mat_t.get("nu", 0.3))         # a band ignores nu
    if is_band:
        band_height = _number("object.height", obj_t["height"], positive=True) if "height" in obj_t else None
        if "thickness" in mat_t:
            th = _number("material.thickness", mat_t["thickness"])
            if band_height is not None and not math.isclose(th, band_height, rel_tol=1e-9):
                raise SceneFileError("material.thickness", f"{th} m differs from object.height = {band_height} m; "
                                     "for a band both are its height out of the plane (give one of them)")
            band_height = th if band_height is None else band_height
        th = 5e-3 if band_height is None else band_height
    else:
        th = _number("material.thickness", mat_t["thickness"])
    try:
        return Material(E=E, nu=nu, thickness=th)
    except ValueError as e:
        raise _wrap(e, "material", {r"Material\.E\b": "material.E", r"Material\.nu\b": "material.nu",
                                    r"Material\.thickness\b": "material.thickness"}) from None


def _fingers(fin):
    from ..simulation.scene import Fingers

    radius = _number("fingers.radius", fin["radius"], positive=True)
    rotation = None
    if "rotation" in fin:
        rot = fin["rotation"]
        if not (isinstance(rot, list) and len(rot) == 2 and all(isinstance(r, list) and r for r in rot)
                and len(rot[0]) == len(rot[1])):
            raise SceneFileError("fingers.rotation", "expected two equally long, non-empty lists of "
                                 "polynomial coefficients [[...], [...]] (one per finger, highest power first)")
        rotation = np.array([[_number(f"fingers.rotation[{i}]", c) for c in r] for i, r in enumerate(rot)])
    try:
        return Fingers(radius=radius, rotation=rotation)
    except ValueError as e:
        raise _wrap(e, "fingers", {"radius": "fingers.radius", "rotation": "fingers.rotation"}) from None


def _grip_nodes(errs, warnings, mesh, points) -> tuple:
    """The boundary nodes the grip points snap to (:func:`~jaxsqueeze.simulation.scene.snap`).
    A point must lie within twice the boundary edges next to its node (not 50 m off the object,
    not at its centre); a point as near another node as to its own gets a warning (which one
    wins is round-off)."""
    from ..simulation.scene import snap
    grip = []
    for k, xy in enumerate(points):
        s = snap(mesh, xy)
        where = f"point {k + 1} {list(map(float, xy))}"
        if s.off_outline:
            errs.add(SceneFileError("grip.points", f"{where} is {s.distance:.3g} m from the nearest boundary node "
                                    f"{s.node} at {s.at}, more than twice the boundary edges "
                                    f"there ({s.edge:.3g} m): put the grip points on the object's outline"))
        elif s.tie is not None:
            warnings.append(f"grip.points: {where} is as near boundary node {s.tie} as node {s.node}, which is "
                            "used (a tie broken by round-off); put the point on the node you mean")
        grip.append(s.node)
    return tuple(grip)


def _grip_distance(mesh, grip) -> float:
    P = np.asarray(mesh.points)
    return float(np.linalg.norm(P[grip[0]] - P[grip[1]]))


def _check_cones(scene, key, precision: str = "float64"):
    """The segment between the grip nodes must lie in both friction cones.

    One cone test (:func:`jaxsqueeze.simulation.laws.grip_margin`, with numpy so no JAX
    array is created while loading), in one precision rule: the precision of the run, on the
    same scaled positions and normals the engine's operator holds (points / L). So a grip the
    squeeze would refuse in float32 is refused here, before any work.
    """
    from ..simulation.laws import cone_normals, grip_cone_angles, grip_half_angle, grip_margin

    dt = np.float32 if precision == "float32" else np.float64
    mesh = scene.mesh
    pos = {int(v): k for k, v in enumerate(np.asarray(scene.boundary_nodes()))}
    i, j = (int(v) for v in scene.grip)
    P, N = np.asarray(mesh.points), np.asarray(mesh.normals)
    L = float(np.max(np.ptp(P, axis=0)))
    Pb = (P[list(scene.boundary_nodes())] / L).astype(dt) if hasattr(mesh, "triangles") else (P / L).astype(dt)
    loops = mesh.loops if hasattr(mesh, "triangles") else (len(Pb),)
    Nb = cone_normals(Pb, N, loops, scene.contact, xp=np).astype(dt)
    p = np.stack([Pb[pos[i]], Pb[pos[j]]])
    inward = -np.stack([Nb[pos[i]], Nb[pos[j]]])
    mu = float(scene.friction)
    if grip_margin(p, inward, mu, scene.friction_model, xp=np) < 0:
        ang = np.degrees(grip_cone_angles(p, inward, xp=np).astype(np.float64))
        half = float(np.degrees(grip_half_angle(mu, scene.friction_model, xp=np)))
        hint = ""
        if dt == np.float32 and np.all(ang <= half + 0.05):
            hint = (" The angles are within float32 round-off of the cone: with precision = \"float32\" this "
                    "grip cannot be told apart from one outside it; use accuracy.precision = \"float64\" or some "
                    "friction")
        why, more = ((f"frictionless fingertips sit on the segment, which may turn at most {half:.3f}° from the "
                      f"normals (precision {precision})", "") if scene.friction_model == "frictionless" else
                     (f"the friction cones only allow {half:.3f}° (squeeze.friction = {mu:.3g}, friction_model = "
                      f"{scene.friction_model!r}, precision {precision})", " or more friction"))
        raise SceneFileError(key, (
            f"grip nodes ({i}, {j}): the segment between them makes {ang[0]:.3f}° and {ang[1]:.3f}° with the "
            f"inward normals, but {why}; choose more nearly opposite grip points{more}." + hint))


def _band(obj, height, overrides=(None, None)):
    """A :class:`~jaxsqueeze.band.Band` from an ``[object]`` table with ``band = ...``."""
    from ..geometry import curves
    from ..mechanics.band import Band
    from ..mechanics.material import Material
    from ..simulation.scene import compliance_of

    _unknown("object", obj, set(BAND_KEYS))
    for k, required in BAND_KEYS.items():
        if required and k not in obj:
            raise SceneFileError(f"object.{k}", "missing (required for a band)")
    for opt, v in zip(("--max-edge", "--refine-edge"), overrides):
        if v is not None:
            raise SceneFileError(opt, "this scene is a band (object.band); mesh sizes apply to built-in "
                                 "shapes only (a band's resolution is object.nodes)")
    kind = _choice("object.band", obj["band"], BANDS)
    size = _number("object.size", obj["size"], positive=True)
    m = _number("object.nodes", obj["nodes"], integer=True)
    width = _number("object.width", obj["width"], positive=True) if "width" in obj else 0.5e-3
    try:
        curve = {"heart": lambda: curves.heart(size), "leaf": lambda: curves.leaf(size, size / 2, size / 40),
                 "circle": lambda: curves.circle(size / 2)}[kind]()
        with warnings_module.catch_warnings(record=True) as caught:   # scene-file warnings are the spec's
            warnings_module.simplefilter("always")
            band = Band.from_function(curve, m, width=width, height=height)
            compliance_of(band, Material(1.0, 0.3, band.height))     # cached; checks the round-off
        return band, [f"object.width: {w.message}" for w in caught]
    except ValueError as e:
        raise _wrap(e, "object", {r"width": "object.width", r"height": "object.height",
                                  r"size|radius|length": "object.size", r"nodes|\bm\b": "object.nodes"}) from None


def _object(obj, base, grip_points, overrides=(None, None)):
    """(mesh, warnings) of the object table (a built-in shape or a mesh file)."""
    from ..geometry import shapes
    from ..geometry.mesh import RenumberedWarning, read_mesh

    obj = _table("object", obj)
    has_shape, has_file = "shape" in obj, "mesh_file" in obj
    if has_shape == has_file:
        raise SceneFileError("object", "give exactly one of object.shape (a built-in shape), object.mesh_file "
                             "or object.band")
    if has_file:
        _unknown("object", obj, {"mesh_file"})
        for opt, v in zip(("--max-edge", "--refine-edge"), overrides):
            if v is not None:
                raise SceneFileError(opt, "this scene reads its mesh from object.mesh_file; mesh sizes "
                                     "apply to built-in shapes only")
        f = obj["mesh_file"]
        if not isinstance(f, str):
            raise SceneFileError("object.mesh_file", f"expected a file name, got {_describe(f)}")
        path = f if os.path.isabs(f) else os.path.join(base, f)
        if not os.path.exists(path):
            raise SceneFileError("object.mesh_file", f"no such file: {path}")
        try:
            with warnings_module.catch_warnings(record=True) as caught:   # scene-file warnings are the spec's
                warnings_module.simplefilter("always")
                mesh = read_mesh(path)
            # the library's own warnings (not a reader's numpy ones); the file's node numbers are
            # checked below where grip.nodes uses them
            return mesh, [f"object.mesh_file: {w.message}" for w in caught
                          if issubclass(w.category, UserWarning) and not issubclass(w.category, RenumberedWarning)]
        except ValueError as e:
            raise SceneFileError("object.mesh_file", str(e)) from None
        except Exception as e:  # meshio's own read errors (unknown format, corrupt file)
            raise SceneFileError("object.mesh_file", f"cannot read {path}: {type(e).__name__}: {e}") from None

    shape, args, kw, names = _shape_args(obj, grip_points, overrides)
    try:
        with warnings_module.catch_warnings(record=True) as caught:   # scene-file warnings are the spec's
            warnings_module.simplefilter("always")
            mesh = getattr(shapes, shape)(*args, **kw)
        return mesh, [f"{_wrap(ValueError(str(w.message)), 'object', names).key}: {w.message}" for w in caught]
    except ValueError as e:
        raise _wrap(e, "object", names) from None


def _shape_args(obj, grip_points, overrides=(None, None)):
    """(shape, args, kwargs, error-key names) of the ``shapes`` call an ``[object]`` table asks for."""
    shape = _choice("object.shape", obj["shape"], tuple(SHAPES))
    req, opt = SHAPES[shape], SHAPE_OPTIONAL[shape]
    _unknown("object", obj, {"shape", *req, *opt, *MESH_KEYS})
    for k in (*req, "max_edge"):
        if k not in obj:
            raise SceneFileError(f"object.{k}", f"missing (required for shape = {shape!r})")
    kw: dict = {}
    file_max_edge = _number("object.max_edge", obj["max_edge"], positive=True)
    kw["max_edge"] = file_max_edge
    for k in ("refine_edge", "refine_radius"):
        if k in obj:
            kw[k] = _number(f"object.{k}", obj[k], positive=(k == "refine_edge"))
    refined = bool(kw.keys() & {"refine_edge", "refine_radius"})
    if refined and grip_points is None:
        raise SceneFileError("object.refine_edge" if "refine_edge" in kw else "object.refine_radius",
                             "refinement near the grip needs grip.points (node indices exist only after meshing)")
    max_edge_override, refine_override = overrides
    if max_edge_override is not None:
        # coarser or finer away from the fingers; the refined zone keeps its size
        kw["max_edge"] = float(max_edge_override)
        if refined:
            kw.setdefault("refine_radius", 2 * file_max_edge)
            kw["refine_edge"] = min(kw.get("refine_edge", file_max_edge / 4), kw["max_edge"])
    if refine_override is not None:
        if not refined:
            raise SceneFileError("--refine-edge", "this scene has no refinement near the grip (object.refine_edge)")
        kw["refine_edge"] = min(float(refine_override), kw["max_edge"])
    if refined:
        kw["refine_near"] = grip_points
    args = []
    if shape == "polygon":
        args.append(_points("object.vertices", obj["vertices"], min_count=3))
        if "holes" in obj:
            h = obj["holes"]
            if not isinstance(h, list):
                raise SceneFileError("object.holes", f"expected a list of point lists, got {_describe(h)}")
            kw["holes"] = [_points(f"object.holes[{i}]", v, min_count=3) for i, v in enumerate(h)]
    else:
        args = [_number(f"object.{k}", obj[k], positive=True) for k in req]
        if "center" in obj:
            c = obj["center"]
            if not (isinstance(c, list) and len(c) == 2):
                raise SceneFileError("object.center", f"expected one point [x, y], got {_describe(c)}")
            kw["center"] = _points("object.center", [c], count=1)[0]
    names = {r"outline edge \d+ [^;]*meets outline edge": "object.vertices",    # (its advice names holes too)
             r"refine_edge": "object.refine_edge", r"refine_radius": "object.refine_radius",
             r"refine_near": "grip.points", r"max_edge": "object.max_edge", r"center": "object.center",
             r"^hole|holes|hole \d": "object.holes", r"outline|vertices|polygon": "object.vertices"}
    names.update({rf"\b{k}\b": f"object.{k}" for k in req})
    return shape, args, kw, names


def _estimate(obj, overrides, grip_points):
    """(object size [m], triangles, boundary nodes) estimated before meshing; None for a mesh file."""
    from ..geometry import shapes

    obj = _table("object", obj)
    if "shape" not in obj or "mesh_file" in obj:
        return None
    shape, args, kw, names = _shape_args(obj, grip_points, overrides)
    if shape == "polygon":
        size = float(np.ptp(args[0], axis=0).max())
    elif shape == "rectangle":
        size = max(args)
    else:
        size = 2 * max(args)
    kw = {k: v for k, v in kw.items() if k != "center"}
    try:
        n_tri, m_est = shapes.estimate(shape, *args, **kw)
    except ValueError as e:
        raise _wrap(e, "object", names) from None
    if not n_tri <= shapes.MAX_ELEMENTS:
        hint = ""
        if size > 10 or kw["max_edge"] < 1e-5 * size:
            hint = (f" The object is {size:.3g} m across: every length is in metres; if some are in millimetres "
                    "the units look mixed (divide those by 1000).")
        raise SceneFileError("object.max_edge", f"max_edge = {kw['max_edge']:.3g} m would make about {n_tri:.3g} "
                             f"triangles on this {shape}, more than the limit of {shapes.MAX_ELEMENTS:,} "
                             "(jaxsqueeze.geometry.shapes.MAX_ELEMENTS, env JAXSQUEEZE_MAX_ELEMENTS); use a larger "
                             "max_edge (or --max-edge)." + hint)
    return size, n_tri, m_est
