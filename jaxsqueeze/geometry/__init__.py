"""Geometry layer: meshes, built-in shapes, closed curves and the boundary (normals, slots,
a smooth arc-length parametrization). Depends on nothing else in jaxsqueeze."""
