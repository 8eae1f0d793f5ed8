"""Built-in planar shapes, meshed with Shewchuk's Triangle (the ``triangle`` package).

Every function returns a :class:`~jaxsqueeze.mesh.Mesh`; all lengths are in metres and all
coordinates are in the caller's frame (the mesh stores them centred, with ``offset``).

Mesh size. ``max_edge`` [m] is the target edge length: boundary edges are never longer
than it (the outline is subdivided before meshing and Triangle is told not to add boundary
nodes, ``-Y``, so boundary nodes lie exactly on the intended outline: straight edges,
circles, ellipses). Interior triangles are quality meshed (minimum angle 30 degrees) with
area at most ``AREA_FACTOR * sqrt(3)/4 * max_edge**2``; with ``AREA_FACTOR = 1.5`` the mean
interior edge is about ``max_edge`` (a 0.1 m square with ``max_edge=0.004`` has ~800 nodes).
Where the object is thinner than about ``max_edge``, Triangle cannot keep its angles without
boundary nodes it may not add: a mesh with angles under :data:`MIN_ANGLE` (20 degrees, less
at sharp outline corners) is refused with the thickness to use (one sliver across a 2 mm
strip made a squeeze 20x too stiff). A mesh one or two elements thick somewhere warns
(:func:`~jaxsqueeze.geometry.mesh.too_thin`): linear triangles are about 3.3 and 1.5 times too
stiff in bending there (1.1 with four elements across). A finest edge length larger than the object itself
(``max_edge``, or ``refine_edge`` where refined) warns: that mesh is little more than the
outline's vertices, most often a length in millimetres among metres.

Local refinement. With ``refine_near`` (k, 2) points, the target edge length becomes

    h(x) = min(max_edge, refine_edge + GRADING * max(0, d(x) - refine_radius)),

d(x) the distance to the nearest refinement point, ``GRADING = 0.3``. Defaults:
``refine_edge = max_edge / 4``, ``refine_radius = 2 * max_edge``. The outline is sampled
with spacing h(x); the interior is refined by a few Triangle ``-r`` passes with a per-
triangle area bound from h at each triangle's centroid.

Cost guard. Before meshing, every shape estimates its element count from the outline's
area and the target edge lengths (:func:`estimate_elements`) and refuses, with the
estimate and a hint about mixed units, above ``MAX_ELEMENTS`` (a setting: assign
``jaxsqueeze.geometry.shapes.MAX_ELEMENTS`` or set the environment variable
``JAXSQUEEZE_MAX_ELEMENTS``; default 2,000,000 triangles).
"""
from __future__ import annotations

import os
import warnings

import numpy as np
import triangle as tr

from ..numbers import positive, real_array
from ..tracing import caller_level
from .mesh import Mesh, RenumberedWarning, too_thin

AREA_FACTOR = 1.5
GRADING = 0.3
_SQRT3_4 = np.sqrt(3.0) / 4.0
_REFINE_PASSES = 4
MAX_ELEMENTS = int(float(os.environ.get("JAXSQUEEZE_MAX_ELEMENTS", 2_000_000)))
"""Largest estimated triangle count a shape function meshes (see the module docstring)."""


# ----------------------------------------------------------------------------- shapes


def polygon(vertices, holes=(), max_edge=None, refine_near=None, refine_edge=None,
            refine_radius=None) -> Mesh:
    """Mesh a simple polygon, convex or not, with optional polygonal holes.

    Args:
        vertices: (k, 2) outline vertices [m], k >= 3, either orientation; a repeated
            closing vertex is dropped. Every vertex becomes a mesh node.
        holes: sequence of (k_i, 2) hole outlines, each strictly inside the outline and
            not touching it or each other.
        max_edge: target edge length [m] (see module docstring); required.
        refine_near: optional (k, 2) points [m] near which edges are ``refine_edge`` long.
        refine_edge: edge length near ``refine_near`` [m]; default ``max_edge / 4``.
        refine_radius: radius of the fully refined zone [m]; default ``2 * max_edge``.

    Raises:
        ValueError: too few or non-finite vertices, zero-length edges, a self-intersecting
            outline, holes outside the outline or crossing it, bad sizes.
    """
    h = _sizing(max_edge, refine_near, refine_edge, refine_radius)
    outer = _as_ring(vertices, "outline")
    inner = [_as_ring(hole, f"hole {i}") for i, hole in enumerate(holes)]
    _check_rings(outer, inner)
    size = np.ptp(outer, axis=0).max()
    _guard(abs(_ring_area(outer)) - sum(abs(_ring_area(v)) for v in inner),
           sum(_perimeter(r) for r in [outer, *inner]), size, h)
    rings = [_sample_polyline(outer, h)] + [_sample_polyline(v, h) for v in inner]
    return _checked(_mesh_rings(rings, [_interior_point(v) for v in inner], h), size, h)


def rectangle(width, height, max_edge, center=(0.0, 0.0), **refine) -> Mesh:
    """Mesh an axis-aligned ``width`` x ``height`` rectangle [m] centred at ``center`` (2,).

    The four corners are nodes. ``refine`` takes ``refine_near``, ``refine_edge`` and
    ``refine_radius`` as in :func:`polygon`.
    """
    w, hh = positive(width, "width", "m") / 2, positive(height, "height", "m") / 2
    cx, cy = _center(center)
    corners = [(cx - w, cy - hh), (cx + w, cy - hh), (cx + w, cy + hh), (cx - w, cy + hh)]
    return polygon(corners, max_edge=max_edge, **refine)


def disk(radius, max_edge, center=(0.0, 0.0), **refine) -> Mesh:
    """Mesh a disk of ``radius`` [m] at ``center`` (2,); boundary nodes lie on the circle.

    ``refine`` takes ``refine_near``, ``refine_edge``, ``refine_radius`` (see :func:`polygon`).
    """
    return ellipse(positive(radius, "radius", "m"), radius, max_edge, center=center, **refine)


def ellipse(a, b, max_edge, center=(0.0, 0.0), **refine) -> Mesh:
    """Mesh an ellipse with semi-axes ``a`` (along x) and ``b`` (along y) [m] at ``center``.

    Boundary nodes lie on the ellipse. ``refine`` as in :func:`polygon`.
    """
    h = _sizing(max_edge, **refine)
    c = _center(center)
    a, b = positive(a, "a", "m"), positive(b, "b", "m")
    _guard(np.pi * a * b, 2 * np.pi * max(a, b), 2 * max(a, b), h)
    ring = _sample_ellipse(c, a, b, h)
    return _checked(_mesh_rings([ring], [], h), 2 * max(a, b), h)


def annulus(r_outer, r_inner, max_edge, center=(0.0, 0.0), **refine) -> Mesh:
    """Mesh the ring between circles of radii ``r_outer > r_inner > 0`` [m] at ``center``.

    Two boundary loops: the outer circle (counterclockwise) and the hole (clockwise).
    ``refine`` as in :func:`polygon`.
    """
    ro, ri = positive(r_outer, "r_outer", "m"), positive(r_inner, "r_inner", "m")
    if ri >= ro:
        raise ValueError(f"annulus needs r_inner < r_outer; got r_inner={ri}, r_outer={ro}")
    h = _sizing(max_edge, **refine)
    c = _center(center)
    _guard(np.pi * (ro ** 2 - ri ** 2), 2 * np.pi * (ro + ri), 2 * ro, h)
    rings = [_sample_ellipse(c, ro, ro, h), _sample_ellipse(c, ri, ri, h)]
    return _checked(_mesh_rings(rings, [c], h), 2 * ro, h)


# ----------------------------------------------------------------------------- validation


def _center(center) -> np.ndarray:
    c = real_array(center, "center", "m")
    if c.shape != (2,) or not np.all(np.isfinite(c)):
        raise ValueError(f"center must be a finite (x, y) pair; got {center!r}")
    return c


def _as_ring(vertices, what) -> np.ndarray:
    """Validated (k, 2) float64 polygon, closing duplicate removed."""
    v = real_array(vertices, f"{what} vertices", "m")
    if v.ndim != 2 or v.shape[1] != 2:
        raise ValueError(f"{what} vertices must have shape (k, 2); got {v.shape}")
    if len(v) > 3 and np.array_equal(v[0], v[-1]):
        v = v[:-1]
    if len(v) < 3:
        raise ValueError(f"{what} needs at least 3 distinct vertices; got {len(v)}")
    bad = np.flatnonzero(~np.all(np.isfinite(v), axis=1))
    if bad.size:
        raise ValueError(f"{what} has non-finite vertices at indices {bad.tolist()}")
    scale = float(np.ptp(v, axis=0).max())
    length = np.linalg.norm(np.roll(v, -1, axis=0) - v, axis=1)
    bad = np.flatnonzero(length <= 1e-12 * scale)
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"{what} has a zero-length edge between vertices {i} and "
                         f"{(i + 1) % len(v)} at {v[i].tolist()}; remove the repeated vertex")
    return v


def _cross(o, a, b):
    """z of (a - o) x (b - o), broadcast over leading axes."""
    u, v = a - o, b - o
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _segments_touch(p1, p2, q1, q2, eps):
    """Whether segments p1p2 and q1q2 (broadcast arrays (..., 2)) intersect or touch."""
    d1, d2 = _cross(p1, p2, q1), _cross(p1, p2, q2)
    d3, d4 = _cross(q1, q2, p1), _cross(q1, q2, p2)
    z1, z2, z3, z4 = (np.abs(d) <= eps for d in (d1, d2, d3, d4))
    proper = (d1 * d2 < 0) & (d3 * d4 < 0) & ~(z1 | z2 | z3 | z4)

    def on(a, b, p):  # p within the bounding box of segment ab (for collinear p)
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        return np.all((p >= lo - 1e-12) & (p <= hi + 1e-12), axis=-1)

    return (proper | (z1 & on(p1, p2, q1)) | (z2 & on(p1, p2, q2))
            | (z3 & on(q1, q2, p1)) | (z4 & on(q1, q2, p2)))


def _first_crossing(a, b, ring, local, size, eps, slack, block=256):
    """The first pair (i, j), i < j, of edges a[i]b[i], a[j]b[j] (k, 2) that touch and are not
    neighbours on one ring, or None. A sweep: edges sorted by their left ends, each block of
    them against the edges that start before the block's rightmost end, and only pairs whose
    bounding boxes meet (``slack`` [m] wider) tested exactly: O(k · block) memory and about
    O(k log k) time on an outline (a (k, k) test of a 20,000 vertex outline took 8 GB)."""
    lo, hi = np.minimum(a, b) - slack, np.maximum(a, b) + slack
    order = np.argsort(lo[:, 0], kind="stable")
    lo, hi = lo[order], hi[order]
    found = []
    for start in range(0, len(a), block):
        r = np.arange(start, min(start + block, len(a)))
        c = np.arange(start, np.searchsorted(lo[:, 0], hi[r, 0].max(), side="right"))
        meet = np.all((lo[r, None] <= hi[None, c]) & (lo[None, c] <= hi[r, None]), axis=-1) & (c[None] > r[:, None])
        R, C = np.nonzero(meet)
        I, J = np.minimum(order[r[R]], order[c[C]]), np.maximum(order[r[R]], order[c[C]])
        diff = (local[J] - local[I]) % size[I]
        near = (ring[I] == ring[J]) & ((diff == 1) | (diff == size[I] - 1))
        I, J = I[~near], J[~near]
        hit = _segments_touch(a[I], b[I], a[J], b[J], eps)
        found += list(zip(I[hit].tolist(), J[hit].tolist()))
    return min(found) if found else None


def _check_rings(outer, holes):
    """Raise if the outline or holes self-intersect, cross each other, or holes lie outside."""
    rings = [outer] + list(holes)
    names = ["outline"] + [f"hole {i}" for i in range(len(holes))]
    scale = float(np.ptp(np.concatenate(rings), axis=0).max())
    eps = 1e-12 * scale**2
    a = np.concatenate(rings)
    b = np.concatenate([np.roll(r, -1, axis=0) for r in rings])
    ring = np.concatenate([np.full(len(r), k) for k, r in enumerate(rings)])
    local = np.concatenate([np.arange(len(r)) for r in rings])
    size = np.array([len(r) for r in rings])[ring]
    first = _first_crossing(a, b, ring, local, size, eps, slack=1e-9 * scale + 1e-12)
    # Adjacent edges only meet badly if they fold back onto each other.
    nxt = np.concatenate([np.roll(r, -2, axis=0) for r in rings])
    e1, e2 = b - a, nxt - b
    fold = (np.abs(_cross(a, b, nxt)) <= eps) & (np.sum(e1 * e2, axis=1) < 0)
    for i in np.flatnonzero(fold):
        raise ValueError(f"{names[ring[i]]} folds back on itself at vertex "
                         f"{(local[i] + 1) % size[i]} {b[i].tolist()}; remove that spike")
    if first is not None:
        i, j = first
        raise ValueError(
            f"polygon edges intersect: {names[ring[i]]} edge {local[i]} {a[i].tolist()}->{b[i].tolist()} "
            f"meets {names[ring[j]]} edge {local[j]} {a[j].tolist()}->{b[j].tolist()}; outlines must be "
            "simple and holes must not touch the outline or each other")
    for k, hole in enumerate(holes):
        if not _inside(hole[0], outer):
            raise ValueError(f"hole {k} (first vertex {hole[0].tolist()}) is not inside the outline")
        for m, other in enumerate(holes):
            if m != k and _inside(hole[0], other):
                raise ValueError(f"hole {k} lies inside hole {m}; holes must not be nested")
    for k, r in enumerate(rings):
        if abs(_ring_area(r)) <= 1e-12 * scale**2:
            raise ValueError(f"{names[k]} encloses zero area")


def _inside(p, ring) -> bool:
    """Even-odd point-in-polygon test for point p (2,) and polygon ring (k, 2)."""
    a, b = ring, np.roll(ring, -1, axis=0)
    crosses = (a[:, 1] > p[1]) != (b[:, 1] > p[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        x = a[:, 0] + (p[1] - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return bool(np.count_nonzero(crosses & (x > p[0])) % 2)


def _ring_area(r) -> float:
    q = np.roll(r, -1, axis=0)
    return 0.5 * float(np.sum(r[:, 0] * q[:, 1] - q[:, 0] * r[:, 1]))


def _interior_point(ring) -> np.ndarray:
    """A point strictly inside polygon ``ring`` (centroid of its largest triangle)."""
    k = len(ring)
    seg = np.stack([np.arange(k), (np.arange(k) + 1) % k], axis=1)
    t = tr.triangulate(dict(vertices=ring, segments=seg), "pQ")
    p = t["vertices"][t["triangles"]]
    area = np.abs(_cross(p[:, 0], p[:, 1], p[:, 2]))
    return p[np.argmax(area)].mean(axis=0)


# ----------------------------------------------------------------------------- sizing


def estimate_elements(area, perimeter, h) -> float:
    """Estimated triangle count of meshing ``area`` [m^2] (outline length ``perimeter`` [m])
    with the sizing ``h`` of :func:`_sizing`: the area over the target triangle area at
    ``max_edge``, plus the refined zones at ``min_edge`` (each at most the whole area), plus
    the boundary nodes."""
    tri_area = lambda e: AREA_FACTOR * _SQRT3_4 * np.float64(e) ** 2 / 1.45  # noqa: E731  (1.45: fitted to Triangle's counts)
    with np.errstate(over="ignore"):      # an edge beyond 1e154 m: an infinite triangle, none counted
        n = area / tri_area(h.max_edge) + perimeter / h.min_edge
        if h.refined:
            reach = h.radius + (h.max_edge - h.min_edge) / GRADING
            zone = min(area, h.count * np.pi * np.float64(reach) ** 2)
            n += zone / tri_area(h.min_edge)
    return float(n)


def estimate(shape: str, *args, max_edge=None, center=None, holes=(), **refine) -> tuple[float, float]:
    """(triangles, boundary nodes) that ``shapes.<shape>(*args, max_edge=..., ...)`` would make,
    estimated without meshing (for cost guards before any work)."""
    h = _sizing(max_edge, **refine)
    if shape == "rectangle":
        w, hh = positive(args[0], "width", "m"), positive(args[1], "height", "m")
        area, per = w * hh, 2 * (w + hh)
    elif shape in ("disk", "ellipse"):
        a = positive(args[0], "radius" if shape == "disk" else "a", "m")
        b = a if shape == "disk" else positive(args[1], "b", "m")
        area, per = np.pi * a * b, 2 * np.pi * max(a, b)
    elif shape == "annulus":
        ro, ri = positive(args[0], "r_outer", "m"), positive(args[1], "r_inner", "m")
        area, per = np.pi * max(ro ** 2 - ri ** 2, 0.0), 2 * np.pi * (ro + ri)
    elif shape == "polygon":
        rings = [np.asarray(args[0], float).reshape(-1, 2)] + [np.asarray(v, float).reshape(-1, 2) for v in holes]
        area = abs(_ring_area(rings[0])) - sum(abs(_ring_area(v)) for v in rings[1:])
        per = sum(_perimeter(r) for r in rings)
    else:
        raise ValueError(f"unknown shape {shape!r}")
    return estimate_elements(area, per, h), per / h.min_edge


def _guard(area, perimeter, size, h):
    """Refuse before meshing when the estimated element count exceeds ``MAX_ELEMENTS``."""
    n = estimate_elements(area, perimeter, h)
    if not n <= MAX_ELEMENTS:
        hint = ""
        if size > 10 or h.max_edge < 1e-5 * size:
            hint = (f" The object is {size:.3g} m across and max_edge is {h.max_edge:.3g} m: all lengths are in "
                    "metres; if some are in millimetres, the units look mixed (divide those by 1000).")
        raise ValueError(f"max_edge = {h.max_edge:.3g} m" + (f" (refine_edge = {h.min_edge:.3g} m)" if h.refined
                                                              else "")
                         + f" on an object of area {area:.3g} m^2 would make about {n:.3g} triangles, more than "
                         f"the limit of {MAX_ELEMENTS:,} (jaxsqueeze.geometry.shapes.MAX_ELEMENTS, env "
                         f"JAXSQUEEZE_MAX_ELEMENTS); use a larger max_edge." + hint)


def _checked(mesh: Mesh, size, h) -> Mesh:
    """``mesh``, with a warning when the finest edge length asked for exceeds the object's
    ``size`` [m]: its mesh is little more than its outline's vertices (a 0.1 m square at
    max_edge=1 is 2 triangles); else when a ``refine_near`` point is too far from the object
    to refine any of it, and when the mesh is one or two elements thick somewhere
    (:func:`~jaxsqueeze.geometry.mesh.too_thin`)."""
    if h.min_edge > size:
        name = "refine_edge" if h.refined else "max_edge"
        warnings.warn(f"{name} = {h.min_edge:g} m exceeds the object ({size:g} m across), so its mesh is little "
                      "more than the outline's vertices and a squeeze of it means little; use edges of a few "
                      "percent of the object's size. Every length is in metres (a length in millimetres is 1000 "
                      "times too large)", stacklevel=caller_level())
        return mesh
    if h.refined:
        pts = np.asarray(mesh.points) + np.asarray(mesh.offset)
        for k, xy in enumerate(h.near):
            d = np.linalg.norm(pts - xy, axis=1)
            if d.min() > h.reach:
                warnings.warn(f"refine_near point {k} {xy.tolist()} is {d.min():.3g} m from the object's nearest "
                              f"node {pts[np.argmin(d)].tolist()}, beyond the {h.reach:.3g} m its refinement reaches: "
                              "nothing is refined for it. Points are in metres, in the shape's own frame (a "
                              "rectangle, disk, ellipse or annulus is centred on the origin)",
                              stacklevel=caller_level())
    thin = too_thin(mesh)
    if thin:
        warnings.warn(f"with max_edge = {h.max_edge:g} m the mesh is {thin[0]}; use max_edge (or refine_edge "
                      f"there) of at most a quarter of the thickness, here {thin[1] / 4:.3g} m",
                      stacklevel=caller_level())
    return mesh


def _perimeter(ring) -> float:
    return float(np.linalg.norm(np.roll(ring, -1, axis=0) - ring, axis=1).sum())


def _sizing(max_edge, refine_near=None, refine_edge=None, refine_radius=None):
    """Target edge length h(x): (k, 2) -> (k,) [m], with attributes ``max_edge``,
    ``min_edge`` and ``refined``."""
    if max_edge is None:
        raise ValueError("max_edge (target edge length in metres) is required")
    h_max = positive(max_edge, "max_edge", "m")
    if refine_near is None:
        if refine_edge is not None or refine_radius is not None:
            raise ValueError("refine_edge/refine_radius need refine_near (the points to refine near)")

        def h(x):
            return np.full(len(x), h_max)

        h.max_edge, h.min_edge, h.refined = h_max, h_max, False
        h.radius, h.count = 0.0, 0
        return h
    try:
        near = np.asarray(refine_near, dtype=np.float64)
    except (TypeError, ValueError):
        near = None
    ok = near is not None and near.size and near.shape[-1] == 2 and near.ndim <= 2 and np.all(np.isfinite(near))
    if not ok:
        raise ValueError(f"refine_near must be finite (k, 2) points in metres; got {refine_near!r}")
    near = near.reshape(-1, 2)
    h_min = h_max / 4 if refine_edge is None else positive(refine_edge, "refine_edge", "m")
    if h_min > h_max:
        raise ValueError(f"refine_edge ({h_min}) must not exceed max_edge ({h_max})")
    radius = 2 * h_max if refine_radius is None else float(refine_radius)
    if not np.isfinite(radius) or radius < 0:
        raise ValueError(f"refine_radius must be a non-negative length; got {refine_radius}")

    def h(x):
        d = np.sqrt(((x[:, None, :] - near[None]) ** 2).sum(-1)).min(axis=1)
        return np.minimum(h_max, h_min + GRADING * np.maximum(0.0, d - radius))

    h.max_edge, h.min_edge, h.refined = h_max, h_min, True
    h.radius, h.count = radius, len(near)
    h.near, h.reach = near, radius + (h_max - h_min) / GRADING       # beyond reach, h(x) = max_edge
    return h


def _sample_curve(curve, t0, t1, h) -> np.ndarray:
    """Nodes on ``curve(t)`` (vectorized, (k,) -> (k, 2)) for t in [t0, t1), spacing <= h(x).

    The first node is curve(t0) exactly; curve(t1) is left out (it starts the next piece).
    """
    coarse = curve(np.linspace(t0, t1, 65))
    length = np.linalg.norm(np.diff(coarse, axis=0), axis=1).sum()
    nfine = int(min(max(64, np.ceil(8 * length / h.min_edge)), 4_000_000)) + 1
    t = np.linspace(t0, t1, nfine)
    x = curve(t)
    ds = np.linalg.norm(np.diff(x, axis=0), axis=1)
    w = np.concatenate([[0.0], np.cumsum(ds / h(0.5 * (x[1:] + x[:-1])))])
    pieces = max(1, int(np.ceil(w[-1] - 1e-9)))
    tn = np.interp(np.linspace(0.0, w[-1], pieces + 1), w, t)
    tn[0] = t0
    return curve(tn[:-1])


def _sample_polyline(ring, h) -> np.ndarray:
    """Closed polygon ring (k, 2) subdivided edge by edge; every vertex is kept."""
    parts = []
    for a, b in zip(ring, np.roll(ring, -1, axis=0)):
        parts.append(_sample_curve(lambda t, a=a, b=b: a + t[:, None] * (b - a), 0.0, 1.0, h))
    return np.concatenate(parts)


#: fewest nodes on a curved outline (ellipse, disk, annulus rings)
MIN_CURVE_NODES = 8


def _sample_ellipse(c, a, b, h) -> np.ndarray:
    """Closed ellipse (semi-axes a, b at c) sampled counterclockwise from angle 0; ValueError
    naming ``max_edge`` when it leaves fewer than :data:`MIN_CURVE_NODES` nodes."""
    x = _sample_curve(lambda t: c + np.stack([a * np.cos(t), b * np.sin(t)], axis=1), 0.0, 2 * np.pi, h)
    if len(x) < MIN_CURVE_NODES:
        P = float(np.linalg.norm(np.diff(np.vstack([x, x[:1]]), axis=0), axis=1).sum()) if len(x) > 1 else 2 * np.pi * max(a, b)
        raise ValueError(f"max_edge = {h.max_edge:g} m leaves {len(x)} node(s) on a curved outline about {P:.3g} m "
                         f"long (semi-axes {a:g}, {b:g} m); use max_edge <= {P / MIN_CURVE_NODES:.3g} m for at least "
                         f"{MIN_CURVE_NODES} nodes")
    return x


# ----------------------------------------------------------------------------- meshing


def _mesh_rings(rings, hole_points, h) -> Mesh:
    """Quality-mesh the region bounded by sampled rings (outer first) without new boundary nodes.

    Coordinates are shifted and scaled to O(1) for Triangle (its area switch takes a plain
    decimal number); the exact input boundary nodes are put back afterwards (Triangle keeps
    input vertices first, in order).
    """
    verts = np.concatenate(rings)
    starts = np.cumsum([0] + [len(r) for r in rings[:-1]])
    seg = np.concatenate([s + np.stack([np.arange(len(r)), (np.arange(len(r)) + 1) % len(r)], axis=1)
                          for s, r in zip(starts, rings)])
    shift = 0.5 * (verts.min(axis=0) + verts.max(axis=0))
    scale = min(h.max_edge, float(np.ptp(verts, axis=0).max()))     # (a max_edge beyond the object: its size)
    data = dict(vertices=(verts - shift) / scale, segments=seg)
    if len(hole_points):
        data["holes"] = (np.asarray(hole_points, dtype=np.float64).reshape(-1, 2) - shift) / scale
    area = AREA_FACTOR * _SQRT3_4 * min(h.max_edge / scale, 1e3) ** 2     # (no bound on the object either way)
    out = tr.triangulate(data, f"pq30a{area:.12f}YQ")
    for _ in range(_REFINE_PASSES if h.refined else 0):
        p = out["vertices"][out["triangles"]]
        target = AREA_FACTOR * _SQRT3_4 * (h(p.mean(axis=1) * scale + shift) / scale) ** 2
        if np.all(0.5 * np.abs(_cross(p[:, 0], p[:, 1], p[:, 2])) <= target):
            break
        out = dict(out, triangle_max_area=target)
        if "holes" in data:
            out["holes"] = data["holes"]
        out = tr.triangulate(out, "rpq30aYQ")
    pts = out["vertices"] * scale + shift
    pts[: len(verts)] = verts
    _check_quality(pts, out["triangles"], rings, h)
    with warnings.catch_warnings():     # a vertex the mesher left out: no node number of the user's
        warnings.simplefilter("ignore", RenumberedWarning)
        return Mesh.from_arrays(pts, out["triangles"])


#: the smallest angle [degrees] :func:`_mesh_rings` accepts (Triangle keeps 30 degrees where the
#: boundary nodes allow it), or three quarters of the outline's sharpest corner if less: near
#: a corner of angle a Triangle cannot keep angles above about a
MIN_ANGLE = 20.0


def _angles(p) -> np.ndarray:
    """(t, 3) interior angles [degrees] of triangles p (t, 3, 2)."""
    a, b = np.roll(p, -1, axis=1) - p, np.roll(p, 1, axis=1) - p
    cos = (a * b).sum(-1) / np.maximum(np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1), 1e-300)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _check_quality(pts, tri, rings, h) -> None:
    """ValueError naming ``max_edge`` where the boundary spacing is too coarse for the outline:
    where the object is thinner than about ``max_edge`` (and Triangle may add no boundary
    nodes, ``-Y``), the elements across it are slivers, one element thick, whose stiffness is
    far off (a 2 mm strip meshed at 20 mm: 20x too stiff). The bound is :data:`MIN_ANGLE`, or
    less at sharp outline corners (a 20 degree wedge has triangles of ~18 degrees at its tip)."""
    corners = min(float(_angles(np.stack([np.roll(r, 1, axis=0), r, np.roll(r, -1, axis=0)], axis=1))[:, 1].min())
                  for r in rings)
    ang = _angles(pts[tri]).min(axis=1)
    k = int(np.argmin(ang))
    if ang[k] >= min(MIN_ANGLE, 0.75 * corners):
        return
    p = pts[tri[k]]
    thin = float(abs(_cross(p[0], p[1], p[2])) / np.linalg.norm(p - np.roll(p, 1, axis=0), axis=1).max())
    where = ", ".join(f"{c:.4g}" for c in p.mean(axis=0))
    raise ValueError(f"max_edge = {h.max_edge:g} m is too coarse for this outline: near ({where}) m the object is "
                     f"about {thin:.2g} m thin and the mesh puts one sliver across it (angles down to {ang[k]:.3g} "
                     f"degrees), far too stiff; use max_edge <= {thin / 4:.2g} m (four elements across; one is "
                     f"still about 3 times too stiff in bending), or refine_near that place with refine_edge <= "
                     f"{thin / 4:.2g} m.")
