"""ParaView output through meshio: an XDMF time series of the whole squeeze and a VTU of the
final state.

Coordinates are in the user's frame (``mesh.points + mesh.offset``) with z = 0; vectors get a
zero z component so ParaView's "Warp By Vector" works directly.

Point data written at every recorded row (``res`` rows: initial touch, each step, each event):

=========================  =======  ============================================================
name                       shape    meaning
=========================  =======  ============================================================
``displacement``           (n, 3)   displacement of every node [m] (see below)
``boundary_displacement``  (n, 3)   recorded displacement of boundary nodes [m]; 0 inside
``contact_force``          (n, 3)   force the fingertip exerts on the node [N]; 0 elsewhere
``mode``                   (n,)     -1 interior node, 0 free, 1 stick, 2/3 slip (toward
                                    larger/smaller polar angle)
``finger``                 (n,)     the finger a node touches: 0, 1 (2: an adversary's
                                    pusher); -1 for a node in no contact
``full_field``             (n,)     1 where ``displacement`` is the exact full field at this row
``depth``                  (n,)     the row's squeeze depth [m] (the same at every node)
``push``                   (n,)     the row's adversary push [m] (0 in squeeze rows and without
                                    an adversary)
``source_node``            (n,)     only for a mesh whose unused points were dropped: each
                                    node's index in the mesh file or the points given
                                    (``mesh.source``; the output numbers nodes as the mesh does)
=========================  =======  ============================================================

Cell data, written when the object passed is the squeezed scene of a solid mesh (it gives the
material; the CLI passes it), one value per triangle (the plane stress of linear triangles is
constant in each, :func:`jaxsqueeze.views.row_stress`):

=========================  =======  ============================================================
``stress_xx``              (t,)     plane stress σ_xx [Pa]
``stress_yy``              (t,)     plane stress σ_yy [Pa]
``stress_xy``              (t,)     plane shear stress τ_xy [Pa]
``von_mises``              (t,)     von Mises equivalent stress [Pa]
=========================  =======  ============================================================

They are NaN at rows whose full displacement field is unknown (``full_field`` 0, see below).

The full displacement field. A result stores it only at the final depth. Linear elasticity
with a fixed contact set is linear in the contact data but not in the depth across events, so
rows are never interpolated. Instead, when the compliance operator is given (``op=`` i.e.
``scene.operator()``), each row's field is rebuilt *exactly* from that row's recorded contact
forces and boundary displacements (:func:`jaxsqueeze.views.row_displacement`), and
``full_field`` is 1 everywhere. Without ``op`` only the final row carries the full field; at
other rows ``displacement`` equals ``boundary_displacement`` (interior nodes 0) and
``full_field`` is 0.

Time. Several rows share a depth (events are resolved at a fixed depth), and ParaView merges
equal time values, so the XDMF time value of row k is k itself; the depth is in the ``depth``
field and in ``summary.json``.
"""
from __future__ import annotations

import os

import numpy as np

from . import views


def _pad3(a):
    a = np.asarray(a, float)
    return np.column_stack([a, np.zeros(len(a))])


def _points3(mesh):
    return _pad3(np.asarray(mesh.points, float) + np.asarray(mesh.offset, float))


def row_point_data(res, mesh, row: int, op=None) -> dict:
    """The point data dict of one recorded row (see the module docstring)."""
    res = views.trimmed(res)
    mesh = views.check_object(res, mesh)
    r = views.row_index(res, row)
    n = mesh.n
    B = np.asarray(mesh.boundary)
    modes = np.asarray(res.modes[r]).astype(np.int32)
    fg = np.asarray(res.finger[r]).astype(np.int32)
    ub = np.zeros((n, 2))
    ub[B] = np.asarray(res.boundary_displacement[r], float)
    F = np.zeros((n, 2))
    F[B] = np.where((modes > 0)[:, None], np.asarray(res.forces[r], float), 0.0)
    mode = np.full(n, -1, np.int32)
    mode[B] = modes
    finger = np.full(n, -1, np.int32)
    finger[B] = np.where(modes > 0, fg, -1)
    u = views.row_field(res, r, op)
    u, full = (ub, 0) if u is None else (u, 1)
    out = dict(displacement=_pad3(u), boundary_displacement=_pad3(ub), contact_force=_pad3(F),
               mode=mode, finger=finger, full_field=np.full(n, full, np.int32),
               depth=np.full(n, float(res.depth[r])), push=np.full(n, float(np.asarray(res.push)[r])))
    source = getattr(mesh, "source", None)
    if source is not None:
        out["source_node"] = np.asarray(source, np.int64)
    return out


STRESS_FIELDS = ("stress_xx", "stress_yy", "stress_xy", "von_mises")


def row_cell_data(res, scene, row: int, displacement=None) -> dict:
    """The cell data dict of one recorded row (see the module docstring), in meshio's layout:
    one list with a (t,) array per field. ``displacement`` (n, 2) [m] is the row's full field
    (as in its point data); without it, the stored final field at the last row, NaN elsewhere."""
    from ..mechanics.fem import von_mises

    u = views.row_field(res, row) if displacement is None else displacement
    if u is None:
        sig = np.full((len(np.asarray(scene.mesh.triangles)), 3), np.nan)
    else:
        sig = views.row_stress(res, scene, row, displacement=u)
    cols = (sig[:, 0], sig[:, 1], sig[:, 2], np.asarray(von_mises(sig), float))
    return {name: [col] for name, col in zip(STRESS_FIELDS, cols)}


def _stress_scene(obj):
    """The scene whose material gives the stresses: ``obj`` when it is a scene of a solid mesh."""
    from ..geometry.mesh import Mesh
    from ..simulation.scene import Scene
    return obj if isinstance(obj, Scene) and isinstance(obj.mesh, Mesh) else None


def write_paraview(path_dir, res, mesh, op=None, name: str = "squeeze") -> str:
    """Write ``<path_dir>/<name>.xdmf`` (+ ``.h5``): one time step per recorded row.

    Args:
        path_dir: output folder (created if missing).
        res: squeeze result; mesh: its :class:`~jaxsqueeze.mesh.Mesh` (or band, or the scene:
            the scene of a solid mesh adds the stresses as cell data).
        op: optional compliance operator (``scene.operator()``) to write the exact full
            displacement field at every row (see the module docstring).
    Returns the path of the .xdmf file. Read it back with ``meshio.xdmf.TimeSeriesReader``.
    """
    import meshio

    res = views.trimmed(res)
    scene = _stress_scene(mesh)
    mesh = views.check_object(res, mesh)
    if op is not None:
        views.check_object(res, op, "operator", takes=("operator",))
    if isinstance(name, str) and name.lower().endswith(".xdmf"):       # (it wrote x.xdmf.xdmf, x.XDMF.xdmf)
        name = name[:-len(".xdmf")]
    if not isinstance(name, str) or not name.strip() or os.sep in name or name in (".", ".."):
        raise ValueError(f"name = {name!r}: expected a file name without a folder (e.g. 'squeeze')")
    path_dir = views.make_folder(path_dir)
    path = os.path.join(path_dir, f"{name}.xdmf")
    cells = [_cells(mesh)]
    with _TimeSeriesWriter(path) as w:
        w.write_points_cells(_points3(mesh), cells)
        for k in range(len(np.asarray(res.depth))):
            pd = row_point_data(res, mesh, k, op)
            u = pd["displacement"][:, :2] if pd["full_field"][0] else None
            w.write_data(k, point_data=pd, cell_data=None if scene is None else row_cell_data(res, scene, k, u))
    return path


def _TimeSeriesWriter(path):  # noqa: N802
    """meshio's XDMF time-series writer with its .h5 file beside the .xdmf (an absolute
    path, no ``os.chdir``); the .xdmf refers to the .h5 by its base name, so the pair can
    be moved together."""
    import meshio

    class Writer(meshio.xdmf.TimeSeriesWriter):
        def __enter__(self):
            import h5py

            self.h5_filename = str(self.filename.with_suffix(".h5"))
            self.h5_file = h5py.File(self.h5_filename, "w")
            return self

    return Writer(path)


def write_final_vtu(path, res, mesh) -> str:
    """Write the final state as one VTU (undeformed coordinates + point data as above, and the
    stresses as cell data when ``mesh`` is the scene of a solid mesh; use "Warp By Vector" on
    ``displacement`` to see the deformed shape)."""
    import meshio

    res = views.trimmed(res)
    scene = _stress_scene(mesh)
    mesh = views.check_object(res, mesh)
    path = views.output_path(path, "VTU file")
    if os.path.isdir(path) or os.path.splitext(path)[1].lower() not in (".vtu", ".vtk"):
        raise ValueError(f"VTU file {path!r}: expected a file name ending in .vtu (or .vtk)")
    views.make_folder(os.path.dirname(path))
    data = row_point_data(res, mesh, -1)
    cells = None if scene is None else row_cell_data(res, scene, -1)
    meshio.write(path, meshio.Mesh(_points3(mesh), [_cells(mesh)], point_data=data, cell_data=cells))
    return str(path)


def _cells(mesh):
    """Triangles of a solid mesh, or the closed polyline ("line" cells) of a band."""
    import meshio

    tri = np.asarray(mesh.triangles, np.int64)
    if len(tri):
        return meshio.CellBlock("triangle", tri)
    return meshio.CellBlock("line", np.asarray(mesh.segments(), np.int64))
