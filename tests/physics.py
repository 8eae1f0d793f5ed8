"""Shared test helpers: exactly symmetric meshes and the invariants every squeeze state must hold."""
import contextlib
import os
import threading
from typing import NamedTuple

import jax
import numpy as np
import triangle

import jaxsqueeze as jsq

#: the repository root (the tests live in folders that mirror the package)
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def peel_scene():
    """Full stick on an ellipse 100 x 60 mm (5 mm edges), nu = -0.9, fingertips of 100 mm, grip
    nodes 43 and 48, 8 mm deep: a node next to a grip node touches and peels off again in
    cycles (float64: 8 A and 8 B events, SUCCESS)."""
    mesh = jsq.shapes.ellipse(0.05, 0.03, max_edge=0.005)
    return jsq.Scene(mesh=mesh, material=jsq.Material(E=1e5, nu=-0.9, thickness=0.0254), friction_model="stick",
                     fingers=jsq.Fingers(radius=0.1), grip=(43, 48), friction=0.5, depth=0.008)


def hexagon_scene():
    """A coarse hexagon 80 mm across (7 mm edges), nu = -0.9, mu = 1, fingertips of 3 L: node 30
    joins finger 1 at 0.73 mm with a force rate 0.0034 rad outside its cone (float32 once kept it
    sticking), and the grasp fails by total slip at 0.98 mm."""
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")               # (a coarse mesh: the thin-part warning)
        mesh = jsq.shapes.polygon([(0.04, 0), (0.02, 0.035), (-0.02, 0.035), (-0.04, 0), (-0.02, -0.035),
                                   (0.02, -0.035)], max_edge=0.007)
    return jsq.Scene(mesh=mesh, material=jsq.Material(E=1e5, nu=-0.9, thickness=0.0254),
                     fingers=jsq.Fingers(radius=0.24), grip=(11, 31), friction=1.0, depth=0.0064)


def symmetric_square(a=0.1, max_edge=0.005):
    """Mesh of [-a/2, a/2]^2, exactly mirror-symmetric about both axes (a quarter, mirrored)."""
    k = int(np.ceil(a / 2 / max_edge))
    t = np.linspace(0, a / 2, k + 1)
    h = a / 2 + 0 * t
    return symmetric_mesh(np.concatenate([np.c_[h, t], np.c_[t[::-1][1:], h[1:]]]), max_edge)


def symmetric_ellipse(a, b, max_edge):
    """Mesh of the ellipse with semi-axes a (x) and b (y), exactly mirror-symmetric about both axes."""
    n = int(np.ceil(0.5 * np.pi * max(a, b) / max_edge))
    t = np.linspace(0, np.pi / 2, n + 1)
    return symmetric_mesh(np.c_[a * np.cos(t), b * np.sin(t)], max_edge)


def symmetric_mesh(quarter, max_edge):
    """A mesh exactly mirror-symmetric about both axes: the first quadrant bounded by the polyline
    ``quarter`` (k, 2) from (x, 0) to (0, y) and the two axes, meshed once and mirrored."""
    cx, cy = quarter[0, 0], quarter[-1, 1]
    scale = 2 * max(cx, cy)
    kx, ky = int(np.ceil(cx / max_edge)), int(np.ceil(cy / max_edge))
    ax = np.c_[np.linspace(0, cx, kx + 1), np.zeros(kx + 1)]
    ay = np.c_[np.zeros(ky + 1), np.linspace(cy, 0, ky + 1)]
    outline = np.concatenate([ax[:-1], quarter[:-1], ay[:-1]])
    seg = np.c_[np.arange(len(outline)), (np.arange(len(outline)) + 1) % len(outline)]
    area = 1.5 * np.sqrt(3) / 4 * (max_edge / scale) ** 2
    tri = triangle.triangulate(dict(vertices=outline / scale, segments=seg), f"pq30a{area:.12f}YQ")
    P, T = tri["vertices"] * scale, tri["triangles"]
    pts, tris, off = [], [], 0
    for sx, sy in [(1, 1), (-1, 1), (-1, -1), (1, -1)]:
        pts.append(P * [sx, sy])
        tris.append((T if sx * sy > 0 else T[:, ::-1]) + off)
        off += len(P)
    P, T = np.concatenate(pts), np.concatenate(tris)
    key = np.round(P / scale * 1e9).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return jsq.Mesh.from_arrays(P[first], inv.reshape(-1)[T])


def nearest(mesh, xy):
    return jsq.scene.nearest_boundary_node(mesh, xy)


class Bounds(NamedTuple):
    """Tolerances of :func:`check_states`: ``balance`` of forces and torques, ``force`` for a
    pull, a stick force outside its cone or a slip force off its edge (both relative to the
    largest force), ``circle`` for a contact node off its fingertip circle and ``sink`` for a
    free node inside a fingertip (both in units of the object size L)."""
    balance: float
    circle: float
    sink: float
    force: float


#: float64: round-off, the default gap_tol of 1e-9 L far below ``sink``
FLOAT64 = Bounds(balance=1e-7, circle=1e-10, sink=1e-6, force=1e-6)
#: float32 (docs/numerics.md §3): positions O(1) in scaled units hold ~eps L = 1.2e-7 L, forces
#: balance to ~1e-6; the default gap_tol of 1e-5 L lets a free node sink that far before event A
#: fires, a little further where contacts made at one depth press it in (it joins at the next
#: event, 1e-7 L deeper); a polar angle holds a node's place on its tip to r eps |theta|, which
#: puts slip forces ~1e-5 of the largest force off their edge (more with tips much larger than L)
FLOAT32 = Bounds(balance=1e-5, circle=2e-6, sink=2e-5, force=1e-4)


def stress_energy(mesh, material, sig) -> float:
    """Strain energy [J] of per-triangle plane stresses sig (t, 3) = (σ_xx, σ_yy, τ_xy):
    h/2 Σ A σ·C σ with the plane-stress compliance C = [[1, −ν, 0], [−ν, 1, 0], [0, 0, 2(1 + ν)]] / E
    (textbook form, independent of the library's element code)."""
    E, nu, h = float(material.E), float(material.nu), float(material.thickness)
    C = np.array([[1, -nu, 0], [-nu, 1, 0], [0, 0, 2 * (1 + nu)]]) / E
    p = np.asarray(mesh.points)[np.asarray(mesh.triangles)]
    area = 0.5 * np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                        - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    sig = np.asarray(sig, float)
    return float(0.5 * h * np.sum(area * np.einsum("ti,ij,tj->t", sig, C, sig)))


def contact_work(res, row) -> float:
    """½ Σ F·u over the contact nodes of a recorded row [J]: the work of the contact forces,
    which equals the strain energy of the linear-elastic state they hold."""
    on = np.asarray(res.modes[row]) > 0
    F, u = np.asarray(res.forces[row], float), np.asarray(res.boundary_displacement[row], float)
    return float(0.5 * np.sum(F[on] * u[on]))


def check_states(res, mesh, mu, friction_model="coulomb", bounds=None):
    """Assert the invariants of every recorded state of a squeeze (SI units), to the
    :class:`Bounds` of the result's precision (``FLOAT32`` for float32 forces) unless given."""
    b = bounds or (FLOAT32 if np.asarray(res.forces).dtype == np.float32 else FLOAT64)
    P0 = mesh.points[mesh.boundary]
    scale = max(np.abs(res.forces).max(), 1e-300)
    L = np.ptp(mesh.points, axis=0).max()
    if res.final_depth <= 1e-12 * L:
        # the squeeze ended at the touch: every force is round-off (~1e-30 N) and relative
        # balances say nothing; the status carries the outcome
        assert np.all(np.isfinite(np.asarray(res.forces)))
        return
    r = float(res.radius)
    for k in range(int(res.count)):
        F, u, C = (np.asarray(a[k], dtype=np.float64) for a in (res.forces, res.boundary_displacement, res.centres))
        mode, fg = np.asarray(res.modes[k]), np.asarray(res.finger[k])
        x = P0 + u
        on = mode > 0
        # equilibrium of forces and torques (linear theory: undeformed lever arms)
        assert np.abs(F.sum(0)).max() <= b.balance * scale, f"row {k}: force imbalance {F.sum(0)}"
        torque = np.sum(P0[:, 0] * F[:, 1] - P0[:, 1] * F[:, 0])
        assert abs(torque) <= b.balance * scale * L, f"row {k}: torque imbalance {torque}"
        assert np.all(F[~on] == 0), f"row {k}: force at a free node"
        # contact nodes exactly on their fingertip circle (to round-off: a kept bordered inverse
        # that drifted put them 1e-6 L off on fine meshes, docs/numerics.md §3)
        rel = x - C[np.where(on, fg, 0)]
        dist = np.linalg.norm(rel, axis=1)
        assert np.abs(dist[on] - r).max(initial=0) <= b.circle * L, f"row {k}: contact node off its circle {np.abs(dist[on] - r).max() / L:.1e} L"
        # no free node inside a fingertip beyond tolerance
        for f in (0, 1):
            gap = np.linalg.norm(x - C[f], axis=1) - r
            assert gap[~on].min(initial=np.inf) >= -b.sink * L, f"row {k}: free node inside finger {f}"
        # force directions: compressive; stick inside the cone; slip on the edge opposing sliding
        nrm = rel / np.maximum(dist, 1e-300)[:, None]
        fn = np.sum(F * nrm, 1)
        ft = nrm[:, 0] * F[:, 1] - nrm[:, 1] * F[:, 0]
        tol = b.force * scale
        assert np.all(fn[on] >= -tol), f"row {k}: pulling contact force"
        stick, pos, neg = mode == 1, mode == 2, mode == 3
        if friction_model == "frictionless":
            assert not np.any(stick), f"row {k}: frictionless squeeze reports stick"
            # the drift rule (docs/numerics.md §5.1) exerts nothing on mirror-symmetric grasps and
            # at most a tiny-friction share on asymmetric meshes (measured 0.24 %; bound 0.3 %)
            tol_t = 3e-3 * scale
            assert np.abs(ft[on]).max(initial=0) <= tol_t, f"row {k}: tangential force without friction"
        elif friction_model == "coulomb":
            assert np.all(np.abs(ft[stick]) <= mu * fn[stick] + tol), f"row {k}: sticking force outside the cone"
            slide = pos | neg
            assert np.allclose(np.abs(ft[slide]), mu * fn[slide], atol=tol, rtol=1e-6), f"row {k}: slip force off the edge"
            assert np.all(ft[pos] <= tol) and np.all(ft[neg] >= -tol), f"row {k}: friction does not oppose sliding"


def sliding_against_friction(res, tol=1e-12):
    """(k, 2) array of (row, node index) where a node sliding in one mode over two consecutive
    rows moved against that mode (mode 2 toward larger polar angles, 3 toward smaller): its
    friction would then push it the way it moves. Empty for a sound squeeze (an unarmed jam,
    docs/numerics.md §6, may do it; the cases that call this have none)."""
    th, md = np.asarray(res.theta), np.asarray(res.modes)
    same = (md[1:] == md[:-1]) & (md[1:] >= 2)
    sign = np.where(md[1:] == 2, 1.0, -1.0)
    return np.argwhere(same & (sign * np.diff(th, axis=0) < -tol)) + [1, 0]


def replay_events(res, frictionless=False):
    """Replay a squeeze's event log from its grip (A joins sticking, or sliding when
    frictionless; B lets go; C slides; D sticks) and assert that every recorded row holds the
    contact set and the stick/slip modes the events up to its depth give: the log is the whole
    history of the modes. Rows that share a depth (an event located at the depth of the one
    before, seen in float32) are judged by the last of them. (A squeeze without an adversary:
    push events are at push displacements.)"""
    nodes, depth, modes = np.asarray(res.nodes), np.asarray(res.depth), np.asarray(res.modes)
    rows = res.events.rows()
    for r in range(len(depth)):
        if r + 1 < len(depth) and depth[r + 1] == depth[r]:
            continue
        held = {int(g): "slide" if frictionless else "stick" for g in res.grip}
        for d, n, kind, _ in rows:
            if d > depth[r]:
                break
            if kind == "B":
                held.pop(n, None)
            else:
                held[n] = "stick" if kind == "D" or (kind == "A" and not frictionless) else "slide"
        got = {int(nodes[i]): "stick" if modes[r, i] == 1 else "slide" for i in np.nonzero(modes[r] > 0)[0]}
        assert held == got, f"row {r} (d = {depth[r]:.6g} m): log {held}, rows {got}"


@contextlib.contextmanager
def compiles(where: bool = False):
    """The XLA compiles of the ``with`` block, one event name each (``jax.monitoring``); with
    ``where``, (program name, thread name) pairs instead (a load from the persistent cache
    counts: JAX times it as a compile)."""
    seen = []

    def listener(name, secs, fun_name=None, **kw):
        if name.endswith("backend_compile_duration"):
            seen.append((fun_name, threading.current_thread().name) if where else name)
    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield seen
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
