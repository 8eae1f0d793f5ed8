"""Mechanics layer: material, FEM assembly, compliance builds (solid and band), the bordered
solve of eq. (4) and small vmap-safe linear algebra. Depends only on :mod:`jaxsqueeze.geometry`."""
