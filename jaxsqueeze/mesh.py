"""Triangle meshes of planar objects (Section II): container, validation, boundary, I/O."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Mesh:
    """A validated triangle mesh of a planar object.

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
    """

    points: np.ndarray
    triangles: np.ndarray
    boundary: np.ndarray
    loops: tuple
    normals: np.ndarray
    offset: np.ndarray

    @property
    def n(self) -> int:
        return int(self.points.shape[0])

    @property
    def m(self) -> int:
        return int(self.boundary.shape[0])

    @classmethod
    def from_arrays(cls, points, triangles) -> "Mesh":
        """Validate, orient and center a triangle mesh given in the user's frame."""
        raise NotImplementedError
