"""Turn a :class:`~jaxsqueeze.grasp.SqueezeResult` into the paper's views (Section V-B).

Every function takes a result (and sometimes the mesh, the scene or the compliance operator)
and returns plain numpy arrays, lists and dicts. Only :func:`row_stress` runs JAX code (the
FEM's stress kernel); the views work on results loaded back from disk as well.

Conventions
-----------
* Rows index the recorded states of ``res`` (initial touch, every step, every event);
  ``row=-1`` is the final state. Boundary position ``k`` is mesh node ``res.nodes[k]``.
* Fingers are numbered 0 (still) and 1 (squeezing) everywhere, in arguments, tables and
  JSON, as in the result (the paper's fingers 1 and 2); an adversary's pusher is finger 2.
* Polar angles θ are those of the result: the angle of a contact node about its fingertip
  centre, in the fingertip frame [rad] (for rotating fingertips add ``res.alpha``).
* The *relative depth* is d / D0 with D0 the distance between the two grip nodes before the
  squeeze (the paper's "relative squeeze depth", Figs. 5 and 6).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..geometry.boundary import positions
from ..numbers import positive
from ..simulation.laws import EVENT_KINDS, EVENT_MEANING, FREE, MODE_NAMES, SLIP_NEG, SLIP_POS, STICK  # noqa: F401

EVENT_LETTERS = EVENT_KINDS   # A new contact, B break, C stick→slip, D slip→stick


def trimmed(res):
    """The result with only its valid rows and events.

    A result from ``jax.jit`` keeps its fixed capacity: ``count`` rows and ``n_events`` events
    are valid, the rest is padding (``jaxsqueeze.simulation.result.trim`` drops it). Every
    consumer in ``jaxsqueeze.post`` calls this first. A batched result (from ``vmap``) must be
    indexed to one lane first.
    """
    from ..simulation.result import SqueezeResult
    if not isinstance(res, SqueezeResult):
        raise TypeError(f"expected a squeeze result (the jsq.SqueezeResult jsq.squeeze returns), got "
                        f"{type(res).__name__}")
    count = getattr(res, "count", None)
    if count is None:
        return res
    res._one("a view or plot")                       # one concrete squeeze, else what to do
    k, e = int(count), int(res.n_events)
    if k == len(np.asarray(res.depth)) and e == len(np.asarray(res.events.depth)):
        return res
    from ..simulation.result import trim

    return trim(res)


def output_path(path, what: str = "output folder") -> str:
    """``path`` as an absolute str, or an error that says what it must be (a non-empty folder or
    file name, str or os.PathLike)."""
    import os

    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)) or not os.fspath(path):
        raise TypeError(f"{what} = {path!r}: expected a non-empty path (str or pathlib.Path)")
    return os.path.abspath(os.fspath(path))


def make_folder(path, what: str = "output folder") -> str:
    """:func:`output_path` of a folder, created if missing; ValueError when it cannot be, or
    when no file can be written in it (the writers failed inside PIL, h5py or meshio)."""
    import os
    import tempfile

    path = output_path(path, what)
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as e:
        raise ValueError(f"{what} {path!r} cannot be created ({e.strerror}); choose a writable folder") from None
    try:
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as e:
        raise ValueError(f"{what} {path!r} takes no files ({e.strerror}); choose a writable folder") from None
    return path


#: how far [share of the object's size] a grip node of the object may lie from where the result
#: had it: a result drawn on another object of the same node counts showed fingertips inside it
SAME_PLACE = 1e-4


def _kinds():
    from ..geometry.mesh import Mesh
    from ..mechanics.band import Band
    from ..mechanics.operator import Compliance
    from ..simulation.scene import Scene
    return {"scene": Scene, "mesh": Mesh, "band": Band, "operator": Compliance}


def check_object(res, obj, what: str = "mesh", takes=("scene", "mesh", "band")):
    """The mesh or band of ``obj`` (one of ``takes``: "scene", "mesh", "band", "operator" for
    the compliance operator); TypeError for another kind of object, ValueError unless it is the
    object ``res`` was computed for: as many boundary (and mesh) nodes, and its grip nodes
    where the result had them (:func:`grip_positions`, to :data:`SAME_PLACE`); a scene also
    its fingertip radius and, for a result that reached its depth, that depth."""
    fix = f"pass the {what} the result was computed for"
    kinds = _kinds()
    if not isinstance(obj, tuple(kinds[k] for k in takes)):
        names = " or ".join({"scene": "the jsq.Scene", "mesh": "its jsq.Mesh", "band": "its Band",
                             "operator": "its compliance operator (scene.operator())"}[k] for k in takes)
        raise TypeError(f"expected the {what} the result was computed for ({names}), got {type(obj).__name__}")
    if isinstance(obj, kinds["scene"]):
        from ..simulation.status import Status
        r, radius = float(res.radius), float(obj.fingers.radius)
        if not np.isclose(r, radius, rtol=1e-6, atol=0):
            raise ValueError(f"the {what}'s fingertip radius is {radius:g} m but the result's {r:g} m: {fix}")
        d, depth = float(res.final_depth), float(obj.depth)
        if int(res.status) == Status.SUCCESS and not np.isclose(d, depth, rtol=1e-6, atol=0):
            raise ValueError(f"the result reached depth {d:g} m (SUCCESS) but the {what} asks for {depth:g} m: {fix}")
    obj = getattr(obj, "mesh", obj)
    m = len(np.asarray(obj.boundary)) if hasattr(obj, "boundary") else obj.m
    got = np.shape(res.modes)[-1]
    if m != got:
        raise ValueError(f"the {what} has {m} boundary nodes but the result {got}: {fix}")
    u = getattr(res, "displacement", None)
    if u is not None and hasattr(obj, "n") and np.shape(u)[0] != obj.n:
        raise ValueError(f"the {what} has {obj.n} nodes but the result's displacement field {np.shape(u)[0]}: {fix}")
    grip = np.asarray(res.grip).reshape(-1)
    if hasattr(obj, "length"):         # a compliance operator: scaled boundary points, in boundary order
        if not np.array_equal(np.asarray(obj.nodes), np.asarray(res.nodes)):
            raise ValueError(f"the {what}'s boundary nodes are not the result's: {fix}")
        P = np.asarray(obj.points, float) * float(obj.length)
        at = P[positions(np.asarray(obj.nodes), grip)]
    else:
        P = np.asarray(obj.points, float)
        at = P[np.clip(grip, 0, len(P) - 1)]
    off = np.linalg.norm(at - grip_positions(res), axis=1)
    size = float(np.ptp(P, axis=0).max())
    if np.any(off > SAME_PLACE * size):          # (NaN: a grip node that never touched, nothing to compare)
        raise ValueError(f"the {what}'s grip nodes {grip.tolist()} lie {np.nanmax(off):.3g} m from where the result "
                         f"had them: {fix}")
    return obj


def _check_finger(finger) -> None:
    if isinstance(finger, (bool, np.bool_)) or finger not in (0, 1):      # (True == 1 took finger 1)
        raise ValueError(f"finger must be 0 (the still finger) or 1 (the squeezing finger); got {finger!r}")


def row_index(res, row: int) -> int:
    """Non-negative index of ``row`` (negative counts from the end) among the valid rows."""
    res = trimmed(res)
    k = len(np.asarray(res.depth))
    if isinstance(row, (bool, np.bool_)) or not isinstance(row, (int, np.integer)):
        raise TypeError(f"row = {row!r}: expected an integer row index (negative counts from the end)")
    r = int(row)
    if not -k <= r < k:
        raise IndexError(f"row {row} out of range: the result has {k} recorded rows")
    return r % k


def _unit(a):
    return np.stack([np.cos(a), np.sin(a)], axis=-1)


def grip_positions(res) -> np.ndarray:
    """(2, 2) positions of the two grip nodes before the squeeze [m] (centroid frame).

    Recovered from a row where the grip node ``res.grip[f]`` touches finger f (the first such
    row; the initial touch in a full history): a contact node lies on its fingertip circle, so
    its position before the squeeze is that point minus the node's recorded displacement. This
    holds for ``history=False`` results too, whose first row is the end of the squeeze. NaN
    for a finger whose grip node touches it in no row, and for both when a placed finger could
    not touch the object at all (``INFEASIBLE_GRIP`` with margin −π: its row 0 records where the
    fingertips were placed, not a touch).
    """
    res = trimmed(res)
    if float(np.asarray(res.margin)) <= -np.pi * (1 - 1e-9):
        return np.full((2, 2), np.nan)
    modes, finger = np.asarray(res.modes), np.asarray(res.finger)
    theta, C = np.asarray(res.theta, float), np.asarray(res.centres, float)
    alpha, U = np.asarray(res.alpha, float), np.asarray(res.boundary_displacement, float)
    r = float(res.radius)
    out = np.full((2, 2), np.nan)
    for f, k in enumerate(positions(res.nodes, res.grip)):
        rows = np.flatnonzero((modes[:, k] > FREE) & (finger[:, k] == f))
        if rows.size:
            i = rows[0]
            out[f] = C[i, f] + r * _unit(theta[i, k] + alpha[i, f]) - U[i, k]
    return out


def grip_distance(res) -> float:
    """D0: distance between the two grip nodes before the squeeze [m]."""
    res = trimmed(res)
    p = grip_positions(res)
    return float(np.linalg.norm(p[1] - p[0]))


def relative_depth(res) -> np.ndarray:
    """(k,) recorded depths divided by the initial grip distance D0."""
    res = trimmed(res)
    return np.asarray(res.depth, float) / grip_distance(res)


# ----------------------------------------------------------------------------- contact regions
def _runs(mask: np.ndarray, loops) -> list[np.ndarray]:
    """Contiguous runs of True positions along cyclic boundary loops (lists of positions)."""
    out, start = [], 0
    for n in loops:
        idx = np.arange(start, start + n)
        m = mask[idx]
        start += n
        if not m.any():
            continue
        if m.all():
            out.append(idx)
            continue
        # rotate so the loop starts at a False entry: runs then never wrap
        first_false = int(np.flatnonzero(~m)[0])
        rot = np.roll(idx, -first_false)
        mr = mask[rot]
        edges = np.diff(np.concatenate([[0], mr.astype(int), [0]]))
        for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
            out.append(rot[a:b])
    return out


def contact_regions(res, row: int = -1, loops=None) -> list[list[dict]]:
    """Contact regions on each finger at one recorded row (Fig. 4).

    Args:
        res: a squeeze result.
        row: recorded row (default: the final state).
        loops: lengths of the boundary loops (``mesh.loops``); default: one closed loop.
    Returns:
        ``[regions of finger 0, regions of finger 1]`` (and of the adversary, finger 2, when
        the scene has one); each region is a dict for one
        contiguous run of contact nodes along the boundary, in boundary order, with keys
        ``positions`` (boundary positions), ``nodes`` (mesh node ids), ``modes`` (names:
        "stick", "slip+", "slip-"), ``theta`` (polar angles [rad]), ``theta_range``
        ((min, max) [rad]), ``arc_length`` (r·(max − min) [m]), ``n_stick``, ``n_slip``.
        At depth 0 (row 0, and the only row of a squeeze that never started: INFEASIBLE_GRIP,
        INVALID_INPUT) the nodes where the fingers first touch are listed as "stick", with
        zero force.
    """
    res = trimmed(res)
    r = row_index(res, row)
    modes, finger = np.asarray(res.modes[r]), np.asarray(res.finger[r])
    theta = np.asarray(res.theta[r], float)
    nodes = np.asarray(res.nodes)
    radius = float(res.radius)
    loops = (len(modes),) if loops is None else tuple(int(v) for v in loops)
    if sum(loops) != len(modes) or min(loops) < 1:
        raise ValueError(f"loops={loops}: expected the lengths of the boundary loops (mesh.loops), adding up to "
                         f"the result's {len(modes)} boundary nodes")
    out = []
    for f in range(np.asarray(res.centres).shape[1]):
        regions = []
        for run in _runs((modes > FREE) & (finger == f), loops):
            th = np.unwrap(theta[run])
            md = modes[run]
            regions.append(dict(
                positions=[int(k) for k in run], nodes=[int(v) for v in nodes[run]],
                modes=[MODE_NAMES[int(v)] for v in md], theta=[float(v) for v in th],
                theta_range=(float(th.min()), float(th.max())),
                arc_length=float(radius * (th.max() - th.min())),
                n_stick=int(np.sum(md == STICK)), n_slip=int(np.sum(md >= SLIP_POS))))
        out.append(regions)
    return out


# ----------------------------------------------------------------------------- force profile
class ForceProfile(NamedTuple):
    """Contact forces of one finger at one row, ordered along the fingertip (Fig. 5).

    s: (c,) arc length on the fingertip, s = r (θ − θ_mid) with θ_mid the middle of the
        finger's contact extent [m]; theta: (c,) polar angles [rad]; density: (c,) force
        magnitude per unit contact length [N/m]; angle: (c,) polar angle of the force
        direction in the world frame [rad]; force: (c, 2) [N]; nodes: (c,) mesh node ids;
        modes: (c,) 1 stick, 2/3 slip; depth: the row's depth [m]; relative_depth: d / D0.
    """

    s: np.ndarray
    theta: np.ndarray
    density: np.ndarray
    angle: np.ndarray
    force: np.ndarray
    nodes: np.ndarray
    modes: np.ndarray
    depth: float
    relative_depth: float


def force_profile(res, row: int = -1, finger: int = 0, mesh=None) -> ForceProfile:
    """Force density and direction along one finger's contact at one row (Fig. 5).

    Each nodal force is divided by its tributary contact length: half the distance to each
    boundary neighbour, measured along the fingertip arc (r Δθ) when that neighbour is in
    contact with the same finger. Toward a free neighbour (the end of a contact run) the
    contact pressure falls to zero somewhere on the boundary edge between them; the half
    length of that edge is used, measured in the deformed state (this needs ``mesh``;
    without it the half arc gap on the other side is mirrored, and an isolated contact
    node gets a NaN density).
    """
    res = trimmed(res)
    mesh = None if mesh is None else check_object(res, mesh)
    r = row_index(res, row)
    _check_finger(finger)
    modes, fg = np.asarray(res.modes[r]), np.asarray(res.finger[r])
    theta = np.asarray(res.theta[r], float)
    F = np.asarray(res.forces[r], float)
    radius = float(res.radius)
    m = len(modes)
    on = (modes > FREE) & (fg == finger)
    loops = (m,) if mesh is None else tuple(mesh.loops)
    pos_all, ds_all = [], []
    if mesh is not None:
        x = np.asarray(mesh.points, float)[np.asarray(mesh.boundary)] + np.asarray(res.boundary_displacement[r], float)
    for run in _runs(on, loops):
        th = np.unwrap(theta[run])
        gaps = radius * np.abs(np.diff(th))                 # arc gaps inside the run
        left, right = np.full(len(run), np.nan), np.full(len(run), np.nan)
        left[1:], right[:-1] = gaps / 2, gaps / 2
        # ends of the run: half the deformed boundary edge to the free neighbour
        start = 0
        for n in loops:
            if start <= run[0] < start + n:
                break
            start += n
        prev_ = start + (run[0] - start - 1) % n
        next_ = start + (run[-1] - start + 1) % n
        if mesh is not None:
            left[0] = np.linalg.norm(x[run[0]] - x[prev_]) / 2
            right[-1] = np.linalg.norm(x[run[-1]] - x[next_]) / 2
        else:
            if len(run) > 1:
                left[0], right[-1] = right[0], left[-1]
        trib = left + right
        pos_all.append(run)
        ds_all.append(trib)
    if not pos_all:
        e = np.zeros(0)
        return ForceProfile(e, e, e, e, np.zeros((0, 2)), np.zeros(0, int), np.zeros(0, int),
                            float(res.depth[r]), float(relative_depth(res)[r]))
    pos = np.concatenate(pos_all)
    trib = np.concatenate(ds_all)
    th = theta[pos]
    th = th[0] + (np.unwrap(th - th[0]))
    order = np.argsort(th)
    pos, trib, th = pos[order], trib[order], th[order]
    mid = 0.5 * (th.min() + th.max())
    f = F[pos]
    with np.errstate(invalid="ignore", divide="ignore"):
        dens = np.linalg.norm(f, axis=1) / trib
    return ForceProfile(s=radius * (th - mid), theta=th, density=dens,
                        angle=np.arctan2(f[:, 1], f[:, 0]), force=f,
                        nodes=np.asarray(res.nodes)[pos], modes=modes[pos],
                        depth=float(res.depth[r]), relative_depth=float(relative_depth(res)[r]))


def spline(x, y, num: int = 100):
    """Cubic-spline interpolation of nodal values for plotting, as in the paper.

    Returns (xs, ys) with ``num`` points over [x.min(), x.max()]; falls back to the input
    when there are fewer than 3 points (no spline through 1 or 2 nodes) or NaNs.
    """
    from scipy.interpolate import CubicSpline

    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if len(x) < 3 or np.any(np.diff(x) <= 0):
        return x, y
    xs = np.linspace(x[0], x[-1], num)
    return xs, CubicSpline(x, y)(xs)


# ----------------------------------------------------------------------------- sliding profile
class SlidingProfile(NamedTuple):
    """Polar angles of one finger's contact nodes at every recorded row (Fig. 6).

    depth: (k,) [m]; relative_depth: (k,); nodes: (c,) mesh ids of every boundary node that
    touches this finger at some row; theta: (k, c) polar angle [rad], NaN while the node is
    not on this finger; modes: (k, c) 0 free, 1 stick, 2/3 slip.
    """

    depth: np.ndarray
    relative_depth: np.ndarray
    nodes: np.ndarray
    theta: np.ndarray
    modes: np.ndarray


def sliding_profile(res, finger: int = 0) -> SlidingProfile:
    """Polar angle of every contact node of ``finger`` (0 or 1) against depth (Fig. 6)."""
    res = trimmed(res)
    _check_finger(finger)
    modes, fg = np.asarray(res.modes), np.asarray(res.finger)
    theta = np.asarray(res.theta, float)
    on = (modes > FREE) & (fg == finger)
    cols = np.flatnonzero(on.any(axis=0))
    th = np.where(on[:, cols], theta[:, cols], np.nan)
    # keep angles continuous across the ±π cut: shift each column toward the first angle
    if np.isfinite(th).any():      # (an infeasible grip's only row has no angles)
        ref = np.nanmedian(th)
        th = ref + (th - ref + np.pi) % (2 * np.pi) - np.pi
    return SlidingProfile(np.asarray(res.depth, float), relative_depth(res), np.asarray(res.nodes)[cols],
                          th, np.where(on[:, cols], modes[:, cols], FREE))


# ----------------------------------------------------------------------------- tables
def event_table(res, grip_distance_m: float | None = None) -> list[dict]:
    """Events in order: dicts with phase ("squeeze", or "push" for an adversary's push),
    depth [m] (the squeeze depth; in the push phase the push displacement), relative_depth
    (depth / D0 in the squeeze phase, None in the push; D0 = ``grip_distance_m`` [m] if given,
    else read from the result: :func:`grip_distance`), node (mesh id), kind ('A'..'D'),
    meaning, finger (0 still, 1 squeezing, 2 the adversary's pusher)."""
    res = trimmed(res)
    D0 = grip_distance(res) if grip_distance_m is None else positive(grip_distance_m, "grip_distance_m", "m")
    return _events(res, D0)


def _events(res, D0: float) -> list[dict]:
    """:func:`event_table` of a trimmed result with the grip distance ``D0`` (NaN where no touch
    gives one: relative depths NaN)."""
    first = int(res.squeeze_events)
    out = []
    for e, (d, n, k, f) in enumerate(zip(*(np.asarray(a) for a in res.events))):
        letter = EVENT_LETTERS[int(k)]
        squeeze = e < first
        out.append(dict(phase="squeeze" if squeeze else "push", depth=float(d),
                        relative_depth=float(d) / D0 if squeeze else None, node=int(n), kind=letter,
                        meaning=EVENT_MEANING[letter], finger=int(f)))
    return out


def row_displacement(res, op, row: int = -1) -> np.ndarray:
    """(n, 2) displacement of every node at a recorded row [m], centroid frame.

    The result stores the full field only at the final depth; every other row is rebuilt
    exactly (DESIGN 2.1: the state at a row is the linear-elastic response to that row's
    contact forces) from the recorded contact forces through the operator's field map, plus
    the row's recorded rigid part g. ``op`` is ``scene.operator()``; it must carry a field map.
    """
    res = trimmed(res)
    check_object(res, op, "operator", takes=("operator",))
    from ..mechanics.operator import rigid_modes

    if op.field is None:
        raise ValueError("the compliance operator has no field map; cannot rebuild the full field")
    r = row_index(res, row)
    L, Fs = float(op.length), float(op.stiffness) * float(op.length)     # the force scale E h L [N]
    f_hat = np.asarray(res.forces[r], float).reshape(-1) / Fs
    u = np.asarray(op.field.solve(f_hat), float).reshape(-1, 2) * L
    g = np.asarray(res.rigid[r], float) / [L, L, 1.0]                 # scaled: (t_x / L, t_y / L, rotation)
    N_all = rigid_modes(np.asarray(op.field.points), xp=np)
    u = u + (N_all @ g).reshape(-1, 2) * L
    # an operator of the same object built for another material (E, ν, thickness) passes the
    # checks above and gives another field: its boundary must be the row's recorded one
    ub, want = u[np.asarray(op.nodes)], np.asarray(res.boundary_displacement[r], float)
    off, scale = float(np.max(np.abs(ub - want), initial=0.0)), float(np.max(np.abs(want), initial=0.0))
    if off > 1e-4 * scale:
        raise ValueError(f"the operator does not reproduce the result's boundary displacement at row {r} (off by "
                         f"{off:.3g} m of {scale:.3g} m): it was built for another material (E, nu, thickness) "
                         "than the result; pass scene.operator() of the squeezed scene")
    return u


def row_field(res, row: int = -1, op=None) -> np.ndarray | None:
    """(n, 2) exact displacement of every node at a recorded row [m], centroid frame: the
    stored field at the final row, rebuilt through ``op`` (:func:`row_displacement`) at the
    others; None where neither is at hand (no ``op``, or an operator without a field map)."""
    res = trimmed(res)
    r = row_index(res, row)
    if r == len(np.asarray(res.depth)) - 1 and res.displacement is not None:
        return np.asarray(res.displacement, float)
    if op is not None and op.field is not None:
        return row_displacement(res, op, r)
    return None


def scene_field(res, scene, row: int = -1) -> np.ndarray:
    """:func:`row_field` with the scene's operator: the stored field at the final row, else the
    row's field rebuilt through ``scene.operator()`` (built only then; cached per object)."""
    u = row_field(res, row)
    return row_field(res, row, scene.operator()) if u is None else u


def row_stress(res, scene, row: int = -1, op=None, displacement=None) -> np.ndarray:
    """(t, 3) plane stress (σ_xx, σ_yy, τ_xy) of every triangle at a recorded row [Pa]
    (constant per triangle, :func:`jaxsqueeze.fem.element_stress`; von Mises:
    :func:`jaxsqueeze.fem.von_mises`).

    ``scene`` is the squeezed :class:`~jaxsqueeze.Scene` of a solid mesh (it gives the
    triangles and the material). The displacement is ``displacement`` (n, 2) [m] if given,
    else the stored field at the final row, else the row's field rebuilt through ``op``
    (default ``scene.operator()``, cached per object).
    """
    from ..geometry.mesh import Mesh
    from ..mechanics.fem import element_stress

    res = trimmed(res)
    mesh = check_object(res, scene, "scene", takes=("scene",))
    if not isinstance(mesh, Mesh):
        raise ValueError("stresses need a solid mesh; a band (a curve with bending stiffness) has no triangles")
    if displacement is None:
        displacement = row_field(res, row, op)
    if displacement is None:
        displacement = scene_field(res, scene, row)
    return np.asarray(element_stress(mesh, scene.material, displacement), float)


def json_ready(x):
    """A JSON-ready copy of ``x``: numpy scalars and arrays as Python numbers and lists, NaN and
    infinities as None (JSON null), dict keys as strings."""
    if isinstance(x, dict):
        return {str(k): json_ready(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_ready(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_ready(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _largest_stress(res, scene) -> dict:
    """summary's ``stress``: the largest von Mises stress at the final row and where it is."""
    from ..mechanics.fem import von_mises

    vm = np.asarray(von_mises(row_stress(res, scene)), float)
    if not np.isfinite(vm).any():
        return dict(max_von_mises=None, triangle=None, at=None)
    k = int(np.nanargmax(vm))
    mesh = scene.mesh
    at = np.asarray(mesh.points, float)[np.asarray(mesh.triangles)[k]].mean(axis=0) + np.asarray(mesh.offset, float)
    return dict(max_von_mises=float(vm[k]), triangle=k, at=[float(v) for v in at])


def summary(res, scene=None, timings: dict | None = None) -> dict:
    """Everything a report needs, as JSON-ready Python types (:func:`json_ready`: a number that
    is NaN or infinite, as in a squeeze that failed at its first row, is None).

    Keys: status, advice, final_depth [m], target_depth [m] (with a scene), grip_distance [m],
    relative_depth, rows, n_events, events (see :func:`event_table`), event_sequence (letters),
    for INVALID_INPUT ``invalid`` (index, field, expected, fix: the first invalid input),
    total_force [N] per finger at the final depth ({"finger0": [fx, fy], "finger1": ...};
    "finger2" is an adversary's pusher), contact_regions per finger at the final depth (see
    :func:`contact_regions`; per finger also n_stick, n_slip), grip nodes (and, for a mesh
    whose unused points were dropped, grip_nodes_source: their numbers in the mesh file or the
    points given, ``mesh.source``), with an adversary
    squeeze_status and push [m] (the last push displacement), scene parameters (a band's nu is
    None and its method "band"; a placed scene's placement s [m] and angle [rad]), for the scene
    of a solid mesh ``stress`` at the final depth (:func:`row_stress`: max_von_mises [Pa], the
    triangle holding it and that triangle's undeformed centroid ``at`` [m, user frame]), and
    ``timings`` [s] if given.
    """
    res = trimmed(res)
    if scene is not None:
        check_object(res, scene, "scene", takes=("scene",))
    from ..simulation.status import Status

    st = Status(int(res.status))
    loops = None
    if scene is not None and hasattr(scene.mesh, "loops"):
        loops = scene.mesh.loops
    regions = contact_regions(res, -1, loops=loops)
    tf = np.asarray(res.finger_forces)[-1]
    D0 = grip_distance(res)
    if scene is not None and not np.isfinite(D0):       # no touch to read it from: the object's nodes
        P = np.asarray(scene.mesh.points, float)
        D0 = float(np.linalg.norm(np.subtract(*P[np.asarray(res.grip)])))
    events = _events(res, D0)
    out = dict(
        status=st.name, success=bool(st == Status.SUCCESS), advice=st.advice,
        final_depth=float(res.final_depth), grip_distance=D0,
        relative_depth=float(res.final_depth) / D0, rows=int(len(np.asarray(res.depth))),
        n_events=len(events), event_sequence="".join(e["kind"] for e in events), events=events,
        total_force={f"finger{f}": [float(v) for v in tf[f]] for f in range(len(tf))},
        total_force_magnitude={f"finger{f}": float(np.linalg.norm(tf[f])) for f in range(len(tf))},
        contact_regions={f"finger{f}": dict(
            regions=regions[f], n_stick=sum(g["n_stick"] for g in regions[f]),
            n_slip=sum(g["n_slip"] for g in regions[f])) for f in range(len(regions))},
    )
    k = int(np.asarray(res.invalid)) if res.invalid is not None else -1
    if st == Status.INVALID_INPUT and k >= 0:           # the advice says result.invalid names it: say it here
        from ..simulation.validate import RULES
        out["invalid"] = dict(index=k, field=RULES[k].field, expected=RULES[k].requirement, fix=RULES[k].fix)
    out["grip_nodes"] = [int(v) for v in np.asarray(res.grip)]      # where the fingers first touched
    source = getattr(getattr(scene, "mesh", None), "source", None)
    if source is not None:                    # a mesh whose unused points were dropped: the file's numbers
        out["grip_nodes_source"] = [int(np.asarray(source)[v]) for v in out["grip_nodes"]]
    if np.shape(res.centres)[-2] > 2:                                 # an adversary pushed (or tried to)
        out["squeeze_status"] = Status(int(res.squeeze_status)).name
        out["push"] = float(np.asarray(res.push)[-1])
    if scene is not None:
        from ..geometry.mesh import Mesh

        solid = isinstance(scene.mesh, Mesh)            # a band has no ν and one build
        out["target_depth"] = float(scene.depth)
        out["scene"] = dict(
            nodes=int(scene.mesh.n) if hasattr(scene.mesh, "n") else None,
            boundary_nodes=int(len(scene.boundary_nodes())),
            E=float(scene.material.E), nu=float(scene.material.nu) if solid else None,
            thickness=float(scene.material.thickness), radius=float(scene.fingers.radius),
            friction=float(scene.friction), friction_model=scene.friction_model, contact=scene.contact,
            method=scene.method if solid else "band")
        if solid and res.displacement is not None:
            out["stress"] = _largest_stress(res, scene)
        if scene.placement is not None:
            out["scene"]["placement"] = dict(s=[float(v) for v in np.asarray(scene.placement.s)],
                                             angle=float(scene.placement.angle))
    if timings is not None:
        out["timings"] = {k: float(v) for k, v in timings.items()}
    return json_ready(out)
