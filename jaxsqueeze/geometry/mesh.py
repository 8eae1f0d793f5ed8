"""Triangle meshes of planar objects (Section II): container, validation, boundary, I/O."""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import warnings
from dataclasses import dataclass

import numpy as np

from ..numbers import real_array
from ..tracing import caller_level
from .boundary import crossing, neighbours


class RenumberedWarning(UserWarning):
    """A mesh was built from points some of which no triangle uses: they were dropped and node
    numbers after them shifted (``Mesh.source`` maps back). Scene files, which check their own
    node numbers, leave it out."""


class ByContent:
    """Equality and hash by the content of a frozen dataclass's fields (arrays by dtype, shape
    and bytes): an object rebuilt from the same data is the same static part of a pytree, so
    ``jit`` programs that take a scene (maps, searches) reuse their compilation instead of
    compiling again for every new, equal mesh object. The digest is computed once."""

    @functools.cached_property
    def _digest(self) -> bytes:
        h = hashlib.blake2b(type(self).__name__.encode(), digest_size=20)
        for f in dataclasses.fields(self):
            if f.name == "source":             # bookkeeping of the input numbering, not the object
                continue
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray):
                h.update(f"{f.name}{v.dtype.str}{v.shape}".encode())
                h.update(np.ascontiguousarray(v).tobytes())
            else:
                h.update(f"{f.name}={v!r}".encode())
        return h.digest()

    def __eq__(self, other) -> bool:
        return self is other or (type(other) is type(self) and self._digest == other._digest)

    def __hash__(self) -> int:
        return hash(self._digest)

    def _fill(self, values) -> None:
        """Set the fields of a frozen dataclass, in their order, from ``values`` (an
        ``__init__`` of its own)."""
        for f, v in zip(dataclasses.fields(self), values, strict=True):
            object.__setattr__(self, f.name, v)


@dataclass(frozen=True, eq=False, init=False)
class Mesh(ByContent):
    """A validated triangle mesh of a planar object: ``jsq.Mesh(points, triangles)`` (the same
    as :meth:`from_arrays`), :func:`read_mesh` or :mod:`jaxsqueeze.geometry.shapes`.

    Attributes:
        points: (n, 2) float64 node positions [m], translated so the node centroid is at the
            origin (Section II).
        triangles: (t, 3) int64 node indices, each triangle counterclockwise.
        boundary: (m,) int64 boundary node indices, loop by loop, outer loop first, then holes.
            Every loop is ordered with the material on its left: the outer loop runs
            counterclockwise, holes run clockwise.
        loops: tuple of loop lengths (outer first), summing to m.
        normals: (m, 2) outward unit normals at the boundary nodes (the normalized sum of
            the unit normals of the two adjacent boundary edges; at a corner this is the
            bisector).
        offset: (2,) position of the node centroid in the user's original frame [m];
            ``points + offset`` gives the original coordinates.
        source: (n,) int64 index of each node among the points given (or in the mesh file),
            when nodes used by no triangle were dropped and the rest renumbered; None when
            every node was kept (the numbering is the caller's).

    Two meshes with the same arrays are equal and hash alike (:class:`ByContent`).
    """

    points: np.ndarray
    triangles: np.ndarray
    boundary: np.ndarray
    loops: tuple
    normals: np.ndarray
    offset: np.ndarray
    source: np.ndarray | None = None

    def __init__(self, points, triangles, boundary=None, loops=None, normals=None, offset=None, source=None):
        """``Mesh(points, triangles)``: validated, oriented and centered (:meth:`from_arrays`,
        whose errors it raises). Every field given (the library's own construction, and
        ``dataclasses.replace``) takes them as they are."""
        rest = (boundary, loops, normals, offset)
        if all(v is None for v in rest + (source,)):
            built = type(self).from_arrays(points, triangles)
            values = [getattr(built, f.name) for f in dataclasses.fields(built)]
        elif any(v is None for v in rest):
            raise TypeError("build a mesh as jsq.Mesh(points, triangles) (or Mesh.from_arrays, read_mesh, "
                            "jsq.shapes): boundary, loops, normals and offset are derived from them")
        else:
            values = [points, triangles, boundary, loops, normals, offset, source]
        self._fill(values)

    def __repr__(self) -> str:
        w, h = np.ptp(np.asarray(self.points, float), axis=0) if self.n else (0.0, 0.0)
        k = len(self.loops)
        return (f"Mesh({self.n} nodes, {len(self.triangles)} triangles, {self.m} boundary nodes in {k} "
                f"loop{'s' * (k != 1)}, {w:.4g} × {h:.4g} m)")

    @property
    def n(self) -> int:
        return int(self.points.shape[0])

    @property
    def m(self) -> int:
        return int(self.boundary.shape[0])

    @classmethod
    def from_arrays(cls, points, triangles) -> "Mesh":
        """Validate, orient and center a triangle mesh given in the user's frame.

        Args:
            points: (n, 2) node coordinates [m] in the user's frame.
            triangles: (t, 3) integer node indices.

        Nodes used by no triangle are dropped and the rest renumbered in their order
        (``source`` maps back to the caller's indices); a consistently
        clockwise mesh is flipped to counterclockwise; points are translated so the node
        centroid is at the origin (``offset`` keeps it). Boundary loops are chained from the
        edges used by one triangle: outer loop (largest enclosed area) first, then holes by
        decreasing enclosed area (equal ones by the place they start); each loop starts at
        the node seen from the loop's node centroid in the direction closest to +x (ties: the
        one below the axis, then the farthest from the centroid). Node numbering changes
        neither order nor start.

        Raises:
            ValueError: on bad shapes, non-finite coordinates, out-of-range indices,
                degenerate or inverted triangles, duplicate nodes, hanging nodes
                (T-junctions), non-manifold edges or vertices, a mesh in more than one piece, or
                a boundary that crosses itself (a mesh that overlaps itself). Messages use the
                caller's node and triangle indices.
        """
        pts, tri = _check_arrays(points, triangles)
        _check_resolution(pts)
        used = np.unique(tri)  # original index of each kept node
        source = used.astype(np.int64) if len(used) < len(pts) else None
        if source is not None and source[-1] >= len(used):        # some kept node changes its number
            dropped = np.setdiff1d(np.arange(len(pts)), used)
            warnings.warn(RenumberedWarning(
                f"points has {len(dropped)} node(s) used by no triangle ({_few(dropped)}): they are dropped "
                f"and the nodes after them renumbered (mesh.source[k] is your index of node k), so node "
                "numbers of yours (a grip, deform's nodes) name other nodes here; pick nodes on this mesh "
                "(jsq.scene.nearest_boundary_node) or remove the unused points"), stacklevel=caller_level())
        tri = np.searchsorted(used, tri)
        pts = pts[used]
        tri = _orient(pts, tri, used)
        _check_duplicates(pts, used)
        _check_hanging(pts, tri, used)
        bnext = _boundary_edges(tri, used)
        _check_connected(tri)
        offset = pts.mean(axis=0)
        pts = pts - offset
        loops = _chain_loops(pts, bnext)
        boundary = np.concatenate(loops)
        _check_crossing(pts, boundary, loops, used)
        normals = np.concatenate([_loop_normals(pts[lp]) for lp in loops])
        arrays = [pts, tri.astype(np.int64), boundary.astype(np.int64), normals, offset]
        for a in arrays + ([source] if source is not None else []):
            a.setflags(write=False)
        pts, tri, boundary, normals, offset = arrays
        return cls(pts, tri, boundary, tuple(len(lp) for lp in loops), normals, offset, source)

    def boundary_index(self, nodes) -> np.ndarray:
        """Positions in ``boundary`` of mesh node indices ``nodes`` (any shape, int64)."""
        nodes = np.asarray(nodes, dtype=np.int64)
        lookup = np.full(self.n, -1, dtype=np.int64)
        lookup[self.boundary] = np.arange(self.m)
        bad = (nodes < 0) | (nodes >= self.n)
        pos = np.where(bad, -1, lookup[np.clip(nodes, 0, self.n - 1)])
        if np.any(pos < 0):
            raise ValueError(f"nodes {_few(nodes[pos < 0])} are not boundary nodes of this mesh "
                             f"(boundary nodes are Mesh.boundary; node indices run 0..{self.n - 1})")
        return pos

    def edge_length(self) -> float:
        """Mean boundary edge length [m]."""
        nxt = np.concatenate([np.roll(lp, -1) for lp in np.split(self.boundary, np.cumsum(self.loops)[:-1])])
        return float(np.linalg.norm(self.points[nxt] - self.points[self.boundary], axis=1).mean())

    def min_angle(self) -> float:
        """Smallest interior angle over all triangles [degrees]."""
        p = self.points[self.triangles]                      # (t, 3, 2)
        a, b = np.roll(p, -1, axis=1) - p, np.roll(p, 1, axis=1) - p
        cos = (a * b).sum(-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
        return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).min())


def _few(items, k: int = 8) -> str:
    """Short printable list of the first ``k`` items."""
    items = [x.tolist() if isinstance(x, np.ndarray) else x for x in list(items)]
    more = f" ... ({len(items)} in all)" if len(items) > k else ""
    return ", ".join(str(x) for x in items[:k]) + more


def _check_arrays(points, triangles):
    """Shapes, finiteness and index range; returns float64 (n, 2) and int64 (t, 3)."""
    pts = real_array(points, "points", "m")
    tri = real_array(triangles, "triangles")       # (node indices are exact in float64)
    if pts.size == 0 or tri.size == 0:
        raise ValueError(f"empty mesh: points {pts.shape}, triangles {tri.shape}; "
                         "a mesh needs (n, 2) points and at least one (3,) triangle")
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must have shape (n, 2) (x, y per node); got {pts.shape}. "
                         "Drop a z column with points[:, :2].")
    if tri.ndim != 2 or tri.shape[1] != 3:
        raise ValueError(f"triangles must have shape (t, 3) (three node indices per triangle); "
                         f"got {tri.shape}")
    if not np.all(np.isfinite(tri)) or np.any(tri != np.round(tri)):
        raise ValueError("triangles must hold integer node indices")
    tri = tri.astype(np.int64)
    bad = np.flatnonzero(~np.all(np.isfinite(pts), axis=1))
    if bad.size:
        raise ValueError(f"non-finite (NaN or inf) coordinates at nodes {_few(bad)}: "
                         f"{_few(pts[bad])}; fix or remove these nodes")
    bad = np.flatnonzero(np.any((tri < 0) | (tri >= len(pts)), axis=1))
    if bad.size:
        raise ValueError(f"node indices out of range 0..{len(pts) - 1} in triangles {_few(bad)}: "
                         f"{_few(tri[bad])}; indices are 0-based")
    return pts, tri


def signed_areas(pts, tri):
    """Signed areas of triangles (t,) [m^2]; positive for counterclockwise."""
    a, b, c = pts[tri[:, 0]], pts[tri[:, 1]], pts[tri[:, 2]]
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


#: the coarsest accepted coordinate resolution, as a share of the object's size
RESOLUTION = 1e-6
#: the accepted object sizes [m]: beyond them float64 products of coordinates (areas, size²)
#: or their squares (the boundary-crossing test) overflow or underflow (at 1e300 m a square's
#: areas were NaN and it read as "degenerate")
SIZES = (1e-50, 1e50)


def _check_resolution(pts) -> None:
    """Refuse an object so small or large that float64 cannot hold its areas (size outside
    :data:`SIZES`), or coordinates so far from the origin that float64 cannot resolve the
    object: the spacing of float64 numbers there, over the object's size, above
    :data:`RESOLUTION` (at 1e13 m a 0.1 m object had 1 mm of coordinate noise and 4 % force error)."""
    if not len(pts):
        return
    with np.errstate(over="ignore"):
        size = float(np.max(np.ptp(pts, axis=0)))
    far = float(np.max(np.abs(pts)))
    if size > 0 and not SIZES[0] <= size <= SIZES[1]:
        raise ValueError(f"the object is {size:.3g} m across: coordinates are in metres, and float64 holds the "
                         f"areas of objects from {SIZES[0]:.0e} to {SIZES[1]:.0e} m across only")
    ulp = float(np.spacing(far))
    if size > 0 and ulp > RESOLUTION * size:
        raise ValueError(f"the points lie up to {far:.3g} m from the origin for an object {size:.3g} m across: "
                         f"float64 resolves them only to {ulp:.3g} m ({ulp / size:.2g} of the object); translate "
                         "the coordinates near the origin")


def _orient(pts, tri, used):
    """Reject degenerate and inverted triangles; flip a clockwise mesh to counterclockwise."""
    area = signed_areas(pts, tri)
    p = pts[tri]
    mean_edge = np.linalg.norm(np.roll(p, -1, axis=1) - p, axis=2).mean(axis=1)
    bad = np.flatnonzero(np.abs(area) <= 1e-12 * mean_edge**2)
    if bad.size:
        raise ValueError(f"degenerate (zero-area) triangles {_few(bad)} with nodes "
                         f"{_few(used[tri[bad]])}; remove them or move their nodes apart")
    # The majority orientation wins (ties: the sign of the total area); the rest are inverted.
    sign = np.sign(np.sum(np.sign(area))) or np.sign(area.sum()) or 1.0
    bad = np.flatnonzero(np.sign(area) != sign)
    if bad.size:
        raise ValueError(f"inverted triangle(s) {_few(bad)} with nodes {_few(used[tri[bad]])}: "
                         f"their orientation is opposite to the rest of the mesh (folded elements); "
                         "reorder their nodes or fix the node positions")
    return tri if sign > 0 else tri[:, [0, 2, 1]]


def _check_crossing(pts, boundary, loops, used):
    """Reject a boundary that crosses itself: consistently oriented triangles that overlap (a
    strip wound past a full turn, a fold whose triangles all keep their orientation)."""
    sizes = tuple(len(lp) for lp in loops)
    hit = crossing(pts[boundary], sizes)
    if hit is not None:
        _, nxt = neighbours(sizes, len(boundary))
        a, b = (used[boundary[[k, nxt[k]]]].tolist() for k in hit)
        raise ValueError(f"the boundary crosses itself: edge {a} crosses edge {b} (caller's node indices), so the "
                         "mesh overlaps itself; remesh the object so that no two triangles overlap")


def _check_duplicates(pts, used):
    """Reject two nodes closer than 1e-12 times the bounding-box diagonal."""
    from scipy.spatial import cKDTree

    tol = 1e-12 * float(np.linalg.norm(np.ptp(pts, axis=0)))
    pairs = cKDTree(pts).query_pairs(r=tol, output_type="ndarray")
    if len(pairs):
        raise ValueError(f"duplicate nodes (same coordinates): node pairs {_few(used[pairs])} at "
                         f"{_few(pts[pairs[:, 0]])}; merge them and renumber the triangles (a crack or slit of zero width "
                         "is not supported, its two faces would touch unseen: give it a width of a few "
                         "percent of its edges)")


def _check_hanging(pts, tri, used):
    """Reject hanging nodes (T-junctions): a node inside an edge of a neighbouring triangle
    without being one of its corners cracks the object there (the two sides are not joined)."""
    from scipy.spatial import cKDTree

    directed, inverse, counts = _edge_table(tri)
    edges = directed[counts[inverse] == 1]               # edges used by one triangle
    if not len(edges):
        return
    cand = np.unique(edges)
    a, b = pts[edges[:, 0]], pts[edges[:, 1]]
    mid, half = 0.5 * (a + b), 0.5 * np.linalg.norm(b - a, axis=1)
    tree = cKDTree(pts[cand])
    hits = []
    for e, near in enumerate(tree.query_ball_point(mid, half * (1 + 1e-9))):
        for c in near:
            node = cand[c]
            if node in (edges[e, 0], edges[e, 1]):
                continue
            d = b[e] - a[e]
            L2 = float(d @ d)
            t = float((pts[node] - a[e]) @ d) / L2
            off = abs(float(d[0] * (pts[node, 1] - a[e, 1]) - d[1] * (pts[node, 0] - a[e, 0]))) / np.sqrt(L2)
            if 1e-9 < t < 1 - 1e-9 and off <= 1e-9 * np.sqrt(L2):
                hits.append((node, e))
    if hits:
        nodes = sorted({int(used[n]) for n, _ in hits})
        pairs = [tuple(int(v) for v in used[edges[e]]) for _, e in hits]
        raise ValueError(f"hanging nodes (T-junctions) {_few(nodes)}: they lie inside the edges (nodes) "
                         f"{_few(pairs)} of neighbouring triangles without being their corners, so the object "
                         "would be cracked there; split those triangles at the hanging node (a conforming mesh)")


def _edge_table(tri):
    """Directed edges (3t, 2) of the triangles, the undirected edge id of each, and the
    number of triangles using each undirected edge."""
    directed = tri[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    lo, hi = directed.min(axis=1), directed.max(axis=1)
    _, inverse, counts = np.unique(lo * (tri.max() + 1) + hi, return_inverse=True, return_counts=True)
    return directed, inverse.ravel(), counts


def _boundary_edges(tri, used):
    """Check edge and vertex manifoldness; map each boundary node to the next one (dict)."""
    directed, inverse, counts = _edge_table(tri)
    bad = np.flatnonzero(counts > 2)
    if bad.size:
        tris = [np.flatnonzero(inverse == e) // 3 for e in bad[:8]]
        nodes = [np.sort(used[directed[np.argmax(inverse == e)]]) for e in bad[:8]]
        raise ValueError(f"non-manifold edges shared by more than 2 triangles: edges (nodes) "
                         f"{_few(nodes)}, triangles {_few(tris)}; each edge may border at most "
                         "two triangles")
    # An interior edge must be traversed in opposite directions by its two triangles.
    forward = np.bincount(inverse, weights=directed[:, 0] < directed[:, 1], minlength=len(counts))
    bad = np.flatnonzero((counts == 2) & (forward != 1))
    if bad.size:
        tris = [np.flatnonzero(inverse == e) // 3 for e in bad[:8]]
        raise ValueError(f"inverted triangle(s): triangle pairs {_few(tris)} lie on the same side of "
                         "their shared edge (folded or overlapping elements); fix the node positions")
    edges = directed[counts[inverse] == 1]
    starts, n_out = np.unique(edges[:, 0], return_counts=True)
    bad = starts[n_out > 1]
    if bad.size:
        raise ValueError(f"non-manifold (bow-tie) boundary vertices {_few(used[bad])}: the boundary "
                         "passes through them more than once; split the node or fill the gap")
    return dict(zip(edges[:, 0].tolist(), edges[:, 1].tolist()))


def _check_connected(tri):
    """Reject a mesh whose triangles form more than one edge-connected piece."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    t = len(tri)
    _, inverse, counts = _edge_table(tri)
    # Bipartite graph triangle <-> edge; its components give the triangle pieces.
    rows = np.repeat(np.arange(t), 3)
    size = t + len(counts)
    graph = coo_matrix((np.ones(3 * t), (rows, t + inverse)), shape=(size, size))
    k, label = connected_components(graph, directed=False)
    if k > 1:
        sizes = np.bincount(label[:t])
        pieces = [f"{s} triangles incl. triangle {int(np.argmax(label[:t] == i))}"
                  for i, s in enumerate(sizes)]
        raise ValueError(f"mesh has {k} pieces not connected through shared edges "
                         f"({_few(pieces, 4)}); mesh one object at a time")


def _chain_loops(pts, bnext):
    """Boundary loops as node-index arrays, outer first, each at its deterministic start."""
    loops, left = [], set(bnext)
    while left:
        start = min(left)
        loop = [start]
        node = bnext[start]
        while node != start:
            loop.append(node)
            node = bnext[node]
        left.difference_update(loop)
        loops.append(np.array(loop, dtype=np.int64))
    loops = [_loop_start(pts, lp) for lp in loops]
    area = np.abs([_loop_area(pts[lp]) for lp in loops])
    start = np.round(pts[[lp[0] for lp in loops]] / np.abs(pts).max(), 9)    # equal holes: by place
    order = np.lexsort((start[:, 1], start[:, 0], np.round(-area / area.max(), 9)))
    return [loops[i] for i in order]


def _loop_area(p):
    """Signed area enclosed by a closed polygon p (k, 2) [m^2]; positive if CCW."""
    q = np.roll(p, -1, axis=0)
    return 0.5 * float(np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))


def _loop_start(pts, loop):
    """Roll ``loop`` to start at the node in direction closest to +x from its node centroid
    (below the +x axis first, then the farthest from the centroid: a non-convex loop can meet
    the ray twice). Every key is geometry rounded past the centroid's summation round-off, so
    the start, the origin of :class:`~jaxsqueeze.Placement` arc lengths, does not depend on how
    the nodes are numbered."""
    d = pts[loop] - pts[loop].mean(axis=0)
    ang = np.arctan2(d[:, 1], d[:, 0])
    r = np.hypot(d[:, 0], d[:, 1])
    keys = (np.round(-r / r.max(), 9), np.round(ang, 9), np.round(np.abs(ang), 9))
    first = np.lexsort(keys)[0]
    return np.roll(loop, -first)


def _loop_normals(p):
    """Outward unit normals (k, 2) at the nodes of a loop p (k, 2) with material on its left."""
    e = np.roll(p, -1, axis=0) - p
    n = np.stack([e[:, 1], -e[:, 0]], axis=1) / np.linalg.norm(e, axis=1, keepdims=True)
    s = n + np.roll(n, 1, axis=0)
    norm = np.linalg.norm(s, axis=1, keepdims=True)
    return np.where(norm > 1e-12, s / np.maximum(norm, 1e-300), n)


#: boundary steps along one loop within which a place 1 or 2 elements thick is the tip of a
#: corner rather than a thin part: a wedge's tip is thin at any mesh size (at 20 degrees one
#: element thick up to 6 steps wide, two up to 14); sharper wedges warn
CORNER_STEPS = {1: 6, 2: 14}
#: how many times too stiff in bending linear triangles make a thin part 1 and 2 elements thick
#: (a ring at w/R = 0.1, ``tests/simulation/test_band_squeeze.py``; 4 across: 1.1)
TOO_STIFF = {1: 3.3, 2: 1.5}


def too_thin(mesh: Mesh) -> tuple[str, float] | None:
    """Where ``mesh`` is one or two elements thick: None, or (what to say, the thinnest such
    place [m]), for the fewest elements across found.

    A place one element thick is an interior edge joining two boundary nodes that lie on
    different loops or more than ``CORNER_STEPS[1]`` steps apart along one; two elements
    thick, an interior node joined to two boundary nodes on different loops or more than
    ``CORNER_STEPS[2]`` steps apart. Linear triangles are :data:`TOO_STIFF` times too stiff in
    bending there."""
    directed, edge, count = _edge_table(np.asarray(mesh.triangles))
    edges = directed[(count[edge] == 2) & (directed[:, 0] < directed[:, 1])]      # each interior edge once
    loop, step = np.full(mesh.n, -1), np.zeros(mesh.n, dtype=int)
    for k, nodes in enumerate(np.split(np.asarray(mesh.boundary), np.cumsum(mesh.loops)[:-1])):
        loop[nodes], step[nodes] = k, np.arange(len(nodes))

    def far(i, j, steps):
        d = np.abs(step[i] - step[j])
        return (loop[i] != loop[j]) | (np.minimum(d, np.asarray(mesh.loops)[loop[i]] - d) > steps)

    on = loop[edges] >= 0
    across = edges[on.all(axis=1)]
    pairs = {1: across[far(across[:, 0], across[:, 1], CORNER_STEPS[1])]}
    mixed = on[:, 0] != on[:, 1]                                      # interior node -- boundary node
    v = np.where(on[mixed, 0], edges[mixed, 1], edges[mixed, 0])
    b = np.where(on[mixed, 0], edges[mixed, 0], edges[mixed, 1])
    order = np.argsort(v, kind="stable")
    v, b = v[order], b[order]
    two = [np.c_[b[:-k], b[k:]][v[:-k] == v[k:]] for k in range(1, int(np.bincount(v).max(initial=0)))]
    two = np.concatenate([np.zeros((0, 2), int), *two])
    pairs[2] = two[far(two[:, 0], two[:, 1], CORNER_STEPS[2])]
    for k, found in pairs.items():
        if len(found):
            length = np.linalg.norm(mesh.points[found[:, 0]] - mesh.points[found[:, 1]], axis=1)
            i = int(np.argmin(length))
            return (f"{('one element', 'two elements')[k - 1]} thick at {len(found)} place(s) from boundary to "
                    f"boundary (the thinnest {length[i]:.3g} m, between boundary nodes {int(found[i, 0])} and "
                    f"{int(found[i, 1])}): linear triangles are about {TOO_STIFF[k]} times too stiff in bending "
                    "there (a ring with 1, 2 and 4 elements across its wall: 3.3, 1.5 and 1.1 times)",
                    float(length[i]))
    return None


def read_mesh(path) -> Mesh:
    """Read a planar triangle mesh from any file format meshio knows (.msh, .vtu, .xdmf, ...).

    All ``triangle`` cell blocks are kept, other cells ignored; coordinates are x, y [m] (a z
    column must hold one value: the mesh's plane z = c, e.g. a CAD sketch plane, is dropped).
    Unused nodes (e.g. of line cells only, or a circle's centre point) are dropped and the rest
    renumbered: ``mesh.source`` gives each node's index in the file, and node indices (grips,
    results) are the mesh's.

    Raises:
        ValueError: no triangle cells in the file, or triangle nodes off one plane z = c, or any
            :meth:`Mesh.from_arrays` error.

    Warns (``UserWarning``) when the mesh is one or two elements thick somewhere
    (:func:`too_thin`): it would be several times too stiff in bending there.
    """
    import os

    import meshio

    path = os.fsdecode(path)                 # (a bytes path: meshio compares its suffix with str)
    if os.path.isdir(path):
        raise ValueError(f"mesh file {path} is a folder, not a mesh file")
    if os.path.exists(path) and not os.path.isfile(path):
        raise ValueError(f"mesh file {path} is not a regular file (a device, pipe or socket); give a mesh file")
    if not os.path.isfile(path):
        raise ValueError(f"no such mesh file: {path}")
    if os.path.getsize(path) == 0:
        raise ValueError(f"mesh file {path} is empty (0 bytes)")
    import contextlib
    import io
    import warnings

    noise = io.StringIO()         # meshio prints its own "Error: ..." before sys.exit; ours says it
    try:
        with contextlib.redirect_stderr(noise), contextlib.redirect_stdout(noise), warnings.catch_warnings():
            # meshio's STL reader sniffs for the binary format with a multiplication that
            # overflows on ASCII files: a numpy RuntimeWarning about its own guess, not the mesh
            warnings.filterwarnings("ignore", category=RuntimeWarning, module=r"meshio(\.|$)")
            m = meshio.read(path)
    except (KeyboardInterrupt, MemoryError):
        raise
    except SystemExit:     # meshio calls sys.exit on some unreadable files (text, renamed images)
        raise ValueError(f"mesh file {path} could not be read: meshio gave up on it (wrong format for its "
                         "suffix, or not a mesh file); export it again, e.g. as gmsh .msh or .vtu") from None
    except BaseException as exc:  # noqa: BLE001 - meshio's errors are of many types
        raise ValueError(f"mesh file {path} could not be read as a mesh: {type(exc).__name__}: {exc}. "
                         "Check that the file is a mesh in the format its suffix says (.msh, .vtu, ...) and "
                         "holds at least one triangle cell block") from None
    blocks = [c.data for c in m.cells if c.type == "triangle"]
    if not blocks:
        found = sorted({c.type for c in m.cells}) or ["no cells"]
        raise ValueError(f"no triangle cells in {path}; found: {', '.join(found)}. "
                         "jaxsqueeze needs linear 3-node triangles (mesh with element order 1)")
    # other area cells beside the triangles would be dropped (a hole where they were): refuse
    start, other = 0, []
    for k, c in enumerate(m.cells):
        if c.type not in ("triangle", "vertex", "line", "line3"):
            other.append(f"{len(c.data)} {c.type} cells (block {k}, cells {start}..{start + len(c.data) - 1} "
                         "counting all blocks)")
        start += len(c.data)
    if other:
        raise ValueError(f"{path} mixes triangles with {'; '.join(other)}; jaxsqueeze would have to drop them "
                         "(half an object). Mesh with 3-node triangles only (gmsh: no Recombine, element order 1)")
    pts = np.asarray(m.points, dtype=np.float64)
    if pts.ndim == 2 and pts.shape[1] == 3:
        xy, z = pts[:, :2], pts[:, 2]
        ok = np.all(np.isfinite(xy), axis=1)         # a node NaN in x or y: from_arrays names it
        used = np.zeros(len(pts), bool)              # (nodes of no triangle are dropped: their z is no matter)
        used[np.concatenate(blocks, axis=0).ravel().clip(0, len(pts) - 1).astype(np.int64)] = True
        ok &= used
        scale = float(np.ptp(xy[ok], axis=0).max()) if ok.any() else 0.0
        zs = z[ok & np.isfinite(z)]
        z0 = float(np.median(zs)) if zs.size else 0.0
        bad = np.flatnonzero(ok & ~(np.abs(z - z0) <= 1e-9 * max(scale, abs(z0), 1e-300)))     # NaN z too
        if bad.size:
            span = f" (z from {zs.min():.6g} to {zs.max():.6g})" if zs.size else ""
            raise ValueError(f"mesh in {path} is not planar: nodes {_few(bad)} have z = {_few(z[bad])}, off the "
                             f"plane z = {z0:.6g} of the median node{span}; jaxsqueeze needs a mesh in one plane "
                             "z = constant")
        pts = xy
    mesh = Mesh.from_arrays(pts, np.concatenate(blocks, axis=0))
    thin = too_thin(mesh)
    if thin:
        warnings.warn(f"the mesh in {path} is {thin[0]}; mesh it again with edges of at most a quarter of the "
                      f"thickness there, here {thin[1] / 4:.3g} m", stacklevel=caller_level())
    return mesh


def write_mesh(path, mesh: Mesh, point_data=None, file_format=None) -> None:
    """Write ``mesh`` with meshio, in the user's frame (``points + offset``, z = 0 added).

    Args:
        path: output file; the format follows the suffix unless ``file_format`` is given.
            ``.msh`` files default to ``"gmsh22"`` (which keeps point data).
        mesh: the mesh.
        point_data: optional dict of extra per-node arrays, each (n,) or (n, k).
        file_format: optional meshio format name.

    Raises ``ValueError`` for a folder, or a name whose suffix names no format meshio knows
    (without ``file_format``). The point data always includes ``"boundary"`` (n,) int: 1 at boundary nodes, else 0.
    """
    import os

    import meshio

    if not isinstance(mesh, Mesh):
        raise TypeError(f"write_mesh(path, mesh) takes a jsq.Mesh, got {type(mesh).__name__} (a scene's is scene.mesh; "
                        "arrays: jsq.Mesh(points, triangles))")
    name = path = os.fsdecode(path)                 # (a bytes path: meshio compares its suffix with str)
    if os.path.isdir(name):
        raise ValueError(f"{name} is a folder; write_mesh needs a file name such as {os.path.join(name, 'mesh.vtu')}")
    if file_format is None and not any(name.lower().endswith(e) for e in meshio.extension_to_filetypes):
        raise ValueError(f"cannot tell a mesh format from the name {name!r}: end it in .vtu (ParaView), .msh "
                         "(gmsh), .xdmf, .vtk or another suffix meshio knows, or pass file_format=")
    pts = np.column_stack([mesh.points + mesh.offset, np.zeros(mesh.n)])
    flag = np.zeros(mesh.n, dtype=np.int64)
    flag[mesh.boundary] = 1
    data = {"boundary": flag, **{k: np.asarray(v) for k, v in (point_data or {}).items()}}
    if file_format is None and str(path).lower().endswith(".msh"):
        file_format = "gmsh22"
    cell_data = {}
    if file_format is not None and file_format.startswith("gmsh"):
        tags = np.ones(len(mesh.triangles), dtype=np.int64)
        cell_data = {"gmsh:physical": [tags], "gmsh:geometrical": [tags]}
    out = meshio.Mesh(pts, [("triangle", np.asarray(mesh.triangles))], point_data=data, cell_data=cell_data)
    meshio.write(path, out, file_format=file_format)
