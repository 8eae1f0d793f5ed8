"""Regenerate ``foam_disk.msh`` (used by ``foam_disk.toml``): a 40 mm radius foam disk,
refined to 1.5 mm near the two grip points. Any mesher that writes triangles through a
meshio-readable format (gmsh ``.msh``, ``.vtu``, ``.xdmf``, ...) works the same way.

    python examples/make_foam_disk_mesh.py
"""
import os

import numpy as np

import jaxsqueeze as jsq

R = 0.04
GRIP = [[0.0, -R], [R * np.cos(np.radians(80)), R * np.sin(np.radians(80))]]

if __name__ == "__main__":
    mesh = jsq.shapes.disk(R, max_edge=0.008, refine_near=GRIP, refine_edge=0.0015, refine_radius=0.006)
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "foam_disk.msh")
    jsq.write_mesh(path, mesh)
    print(f"wrote {path}: {mesh.n} nodes, {len(mesh.triangles)} triangles, {mesh.m} on the boundary")
    print("grip points:", np.round(GRIP, 6).tolist())
