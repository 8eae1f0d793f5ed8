"""Plane-stress FEM on constant-strain triangles (Section II) and the compliance builds (DESIGN 2.2).

Internally the stiffness is assembled for E = 1 and thickness = 1 (``K_hat``); the physical
matrix is ``E * thickness * K_hat`` [N/m]. Node positions enter scaled by the object length
``L``, which leaves ``K_hat`` unchanged (CST stiffness is scale free in 2-D) but makes the
rigid modes and the compliance O(1) (DESIGN 2.3).
"""
from __future__ import annotations


import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from jax.experimental import sparse as jsparse
from threadpoolctl import threadpool_limits

from .material import Material, checked
from ..compiler import precise
from ..geometry.mesh import Mesh
from ..numbers import real_array
from ..tracing import as_array, is_concrete, own_transfers
from .operator import Compliance, FieldMap, rigid_modes

METHODS = ("sparse", "dense", "spectral")


# ----------------------------------------------------------------------------- element kernel
_D0 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 0.5))     # the plane-stress D: _D0 + ν _D1
_D1 = ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, -0.5))


def _strain_matrix(xy: jax.Array):
    """CST strain-displacement matrix B (3, 6), with ε = (ε_xx, ε_yy, γ_xy) = B u_e for DOFs
    (x0, y0, x1, y1, x2, y2), and the area of one counterclockwise triangle xy (3, 2)."""
    x, y = xy[:, 0], xy[:, 1]
    b = jnp.array([y[1] - y[2], y[2] - y[0], y[0] - y[1]])
    c = jnp.array([x[2] - x[1], x[0] - x[2], x[1] - x[0]])
    area = 0.5 * (b[0] * c[1] - b[1] * c[0])
    z = 0.0 * b      # (not zeros_like: a value that depends on no input is evaluated eagerly at compile time)
    Bm = jnp.stack([
        jnp.stack([b, z], 1).reshape(6),
        jnp.stack([z, c], 1).reshape(6),
        jnp.stack([c, b], 1).reshape(6),
    ]) / (2 * area)
    return Bm, area


def _elasticity(nu, dtype):
    """Plane-stress D (3, 3) for E = 1: [[1, ν, 0], [ν, 1, 0], [0, 0, (1 − ν)/2]] / (1 − ν²),
    from numpy constants (for the same reason as ``z`` above)."""
    nu = jnp.asarray(nu, dtype)
    return (np.array(_D0, dtype) + nu * np.array(_D1, dtype)) / (1 - nu**2)


def element_stiffness(xy: jax.Array, nu) -> jax.Array:
    """Plane-stress CST stiffness (6, 6) of one triangle for E = 1, thickness = 1.

    Args:
        xy: (3, 2) vertex coordinates, counterclockwise (any length unit).
        nu: Poisson's ratio.
    Returns:
        (6, 6) matrix for DOFs (x0, y0, x1, y1, x2, y2); energy (1) is ½ uᵀ k u.
    """
    Bm, area = _strain_matrix(xy)
    return area * Bm.T @ _elasticity(nu, xy.dtype) @ Bm


def _corner_stress(xy, ue, nu):
    Bm, _ = _strain_matrix(xy)
    return _elasticity(nu, xy.dtype) @ (Bm @ ue.reshape(6))


@jax.jit
@precise
def _stress(points, triangles, u, nu, E):
    sig = jax.vmap(_corner_stress, in_axes=(0, 0, None))(points[triangles].astype(u.dtype), u[triangles], nu)
    return jnp.asarray(E, sig.dtype) * sig


def _real(x, what: str, unit: str) -> jax.Array:
    """``x`` as a JAX array of real numbers: checked when concrete (no booleans, complex numbers
    or text), integers as the default float type."""
    if is_concrete(x):
        real_array(x, what, unit)
    x = as_array(x)
    return x.astype(jnp.asarray(0.0).dtype) if jnp.issubdtype(x.dtype, jnp.integer) else x


@own_transfers
def element_stress(mesh: Mesh, material: Material, displacement) -> jax.Array:
    """Plane stress of every triangle (t, 3) = (σ_xx, σ_yy, τ_xy) [Pa] for nodal displacements
    ``displacement`` (n, 2) [m], e.g. ``result.displacement`` or
    :func:`jaxsqueeze.views.row_displacement`. Linear CST elements: the strain, and so the
    stress, is constant over each triangle; σ = E D(ν) ε with ε = (ε_xx, ε_yy, γ_xy) (the
    engineering shear strain), σ_zz = 0; rigid motions give zero stress; a node's NaN
    displacement (a row a result does not define) gives NaN in its triangles. A pure JAX function of
    the displacement and the material: ``jax.jit`` (with the mesh static), ``vmap``, ``jvp``
    and ``grad`` apply."""
    checked(material)
    u = _real(displacement, "displacement", "m")     # (whole metres: the mesh's points must not round)
    if u.shape != (mesh.n, 2):
        raise ValueError(f"displacement must be (n, 2) = {(mesh.n, 2)} nodal displacements [m] of the mesh, "
                         f"got shape {u.shape}")
    # one compiled program (eager jnp operations on host arrays compile one small program each)
    return _stress(as_array(mesh.points), as_array(mesh.triangles), u, material.nu, material.E)


@own_transfers
def von_mises(stress) -> jax.Array:
    """Von Mises equivalent stress [Pa] of plane stresses (..., 3) = (σ_xx, σ_yy, τ_xy), σ_zz = 0:
    √(σ_xx² − σ_xx σ_yy + σ_yy² + 3 τ_xy²), with derivative 0 (not NaN) where the stress is 0,
    as for the other norms a search may differentiate (an unloaded triangle, a grip that never
    started)."""
    stress = _real(stress, "stress", "Pa")
    if stress.ndim < 1 or stress.shape[-1] != 3:
        raise ValueError(f"stress must be plane stresses (..., 3) = (σ_xx, σ_yy, τ_xy) [Pa], e.g. from "
                         f"element_stress; got shape {stress.shape}")
    return _von_mises(stress)


@jax.jit
def _von_mises(stress):
    sxx, syy, txy = stress[..., 0], stress[..., 1], stress[..., 2]
    q = sxx**2 - sxx * syy + syy**2 + 3 * txy**2
    pos = q > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, q, 1.0)), 0.0)


#: element stiffnesses (t, 6, 6) from the triangles' corners (t, 3, 2), lifted from the kernel
corner_matrices = jax.jit(precise(jax.vmap(element_stiffness, in_axes=(0, None))))


@jax.jit
@precise
def element_matrices(points: jax.Array, triangles: jax.Array, nu) -> jax.Array:
    """All element stiffnesses (t, 6, 6) for E = 1, thickness = 1."""
    return corner_matrices(points[triangles], nu)


def element_dofs(triangles) -> np.ndarray:
    """(t, 6) global DOF indices, interleaved x, y."""
    tri = np.asarray(triangles)
    return np.stack([2 * tri, 2 * tri + 1], axis=2).reshape(-1, 6)


def _coo(triangles):
    dofs = element_dofs(triangles)
    rows = np.repeat(dofs, 6, axis=1).ravel()
    cols = np.tile(dofs, (1, 6)).ravel()
    return rows, cols


# ----------------------------------------------------------------------------- stiffness
@own_transfers
def stiffness(mesh: Mesh, material: Material) -> jsparse.BCOO:
    """Global stiffness K (2n, 2n) [N/m] as a BCOO matrix, DOFs interleaved x0, y0, x1, ...

    Duplicate entries (one per element sharing a DOF pair) are kept and sum on use.
    """
    ke = element_matrices(jnp.asarray(mesh.points), jnp.asarray(mesh.triangles), checked(material).nu)
    rows, cols = _coo(mesh.triangles)
    scale = jnp.asarray(material.E, ke.dtype) * jnp.asarray(material.thickness, ke.dtype)
    data = scale * ke.reshape(-1)
    idx = jnp.asarray(np.stack([rows, cols], axis=1))
    return jsparse.BCOO((data, idx), shape=(2 * mesh.n, 2 * mesh.n))


def null_space(points) -> jax.Array:
    """Normalized null-space basis (2n, 3) of K: w_x, w_y, w_r about the node centroid (Section II)."""
    pts = jnp.asarray(points)
    pts = pts - pts.mean(axis=0, keepdims=True)
    w = rigid_modes(pts)
    return w / jnp.linalg.norm(w, axis=0, keepdims=True)


@own_transfers
def scipy_stiffness(mesh: Mesh, nu) -> sp.csc_matrix:
    """The stiffness matrix K (2n, 2n) as a scipy CSC matrix in float64 (the host-side build).

    The element kernel runs on the triangles' corners padded to a power of two (at least 256),
    so meshes of many sizes share a few compiled kernels (each new size cost 0.1 s to compile)."""
    xy = np.asarray(mesh.points, np.float64)[np.asarray(mesh.triangles)]
    t = xy.shape[0]
    pad = max(256, 1 << (t - 1).bit_length())
    xy = np.concatenate([xy, np.broadcast_to(xy[:1], (pad - t, 3, 2))])    # copies of a real triangle
    with jax.enable_x64(True):   # the host-side build is always float64
        ke = np.asarray(corner_matrices(xy, nu))[:t]
    rows, cols = _coo(mesh.triangles)
    return sp.csc_matrix((ke.ravel(), (rows, cols)), shape=(2 * mesh.n, 2 * mesh.n))


# ----------------------------------------------------------------------------- compliance builds
def object_length(mesh: Mesh) -> float:
    """Object length L [m] used for internal scaling: the larger bounding-box side."""
    return float(np.max(np.ptp(mesh.points, axis=0)))


def pinned_dofs(points_b: np.ndarray) -> np.ndarray:
    """Three DOFs forming a statically determinate support on the boundary.

    Both DOFs of boundary node 0, and the DOF of the boundary node farthest from it that is
    perpendicular to the dominant direction between them. Returns boundary-DOF positions (3,).
    """
    d = points_b - points_b[0]
    far = int(np.argmax(np.einsum("ij,ij->i", d, d)))
    along_x = abs(d[far, 0]) >= abs(d[far, 1])
    return np.array([0, 1, 2 * far + (1 if along_x else 0)])


@own_transfers
def compliance(mesh: Mesh, material: Material, method: str = "sparse") -> Compliance:
    """Boundary compliance operator of a solid mesh (DESIGN 2.2), in scaled units.

    Args:
        mesh: the object.
        material: E [Pa], nu, thickness [m]. E and thickness only set ``op.stiffness``.
        method: "sparse" (scipy sparse LU of pinned K, solved for the boundary DOFs; default),
            "dense" (JAX Cholesky of pinned dense K; differentiable in nu) or
            "spectral" (eigendecomposition of dense K; the paper's Section III).
    Returns:
        A :class:`~jaxsqueeze.operator.Compliance` over the boundary nodes.
    """
    if method not in METHODS:
        raise ValueError(f"method={method!r} is not a compliance build; choose one of {METHODS}.")
    checked(material)
    L = object_length(mesh)
    pts = mesh.points / L
    b = np.asarray(mesh.boundary)
    bdofs = np.stack([2 * b, 2 * b + 1], axis=1).reshape(-1)
    pins = bdofs[pinned_dofs(pts[b])]
    if method == "sparse":
        G, fmap = _sparse_build(mesh, material.nu, pts, bdofs, pins)
    else:
        build = _dense_build if method == "dense" else _spectral_build
        Gnb = build(jnp.asarray(pts), jnp.asarray(mesh.triangles), material.nu, jnp.asarray(bdofs), jnp.asarray(pins))
        G = Gnb[bdofs]
        fmap = None if isinstance(Gnb, jax.core.Tracer) else _matrix_field(np.asarray(Gnb), pts)
    dt = jax.dtypes.canonicalize_dtype(G.dtype)     # (float32 unless x64 is on)
    return Compliance(
        points=as_array(pts[b], dt), normals=as_array(mesh.normals, dt), G=as_array(G, dt),
        N=as_array(rigid_modes(pts[b], xp=np), dt), length=as_array(L, dt),
        stiffness=as_array(material.E * material.thickness, dt), nodes=as_array(b),
        nu=as_array(material.nu, dt),
        method=method, loops=tuple(mesh.loops), field=fmap)


def _matrix_field(Gnb: np.ndarray, pts: np.ndarray) -> FieldMap:
    return FieldMap(lambda f: Gnb @ f, pts)


def _dense_K(pts, triangles, nu):
    n2 = 2 * pts.shape[0]
    ke = element_matrices(pts, triangles, nu)
    dofs = jnp.stack([2 * triangles, 2 * triangles + 1], axis=2).reshape(-1, 6)
    return jnp.zeros((n2, n2), ke.dtype).at[dofs[:, :, None], dofs[:, None, :]].add(ke)


@jax.jit
@precise
def _dense_build(pts, triangles, nu, bdofs, pins):
    """(2n, 2m) columns of the pinned generalized inverse at the boundary DOFs."""
    K = _dense_K(pts, triangles, nu)
    n2 = K.shape[0]
    keep = jnp.ones(n2, bool).at[pins].set(False)
    Kp = jnp.where(keep[:, None] & keep[None, :], K, 0.0) + jnp.diag(jnp.where(keep, 0.0, 1.0))
    rhs = jnp.zeros((n2, bdofs.shape[0]), K.dtype).at[bdofs, jnp.arange(bdofs.shape[0])].set(1.0)
    rhs = jnp.where(keep[:, None], rhs, 0.0)
    return _spd_solve(Kp, rhs)


@jax.custom_jvp
def _spd_solve(A, B):
    """A⁻¹ B for a symmetric positive definite (k, k) A and (k, c) B, by Cholesky."""
    return jax.scipy.linalg.cho_solve(jax.scipy.linalg.cho_factor(A, lower=True), B)


@_spd_solve.defjvp
def _spd_solve_jvp(primals, tangents):
    """d(A⁻¹B) = A⁻¹(dB − dA A⁻¹B), with A's factor, after the value. JAX's own rules solve
    for Cholesky's tangent beside the value's solves; batched over a ``vmap`` on the CPU,
    jaxlib's LAPACK solves each hold an XLA pool thread while they wait for another, and two
    at once waited forever on 2 cores (``jax.vmap(jax.jacfwd(...))`` in ν: docs/numerics.md,
    finding 28). Here every solve needs the one before. Linear in (dA, dB): reverse mode works."""
    (A, B), (dA, dB) = primals, tangents
    chol = jax.scipy.linalg.cho_factor(A, lower=True)
    X = jax.scipy.linalg.cho_solve(chol, B)
    return X, jax.scipy.linalg.cho_solve(chol, dB - dA @ X)


@jax.jit
@precise
def _spectral_build(pts, triangles, nu, bdofs, pins):
    """(2n, 2m) columns of the pseudo-inverse K⁺ = Σ v vᵀ/λ over the 2n−3 positive modes (eq. 3)."""
    K = _dense_K(pts, triangles, nu)
    lam, V = jnp.linalg.eigh(K)
    lam, V = lam[3:], V[:, 3:]          # the three smallest are the rigid modes
    return (V / lam[None, :]) @ V[bdofs].T


def _sparse_build(mesh: Mesh, nu, pts, bdofs, pins, chunk: int = 128):
    K = scipy_stiffness(mesh, float(nu))
    n2 = K.shape[0]
    keep = np.ones(n2, bool)
    keep[pins] = False
    D = sp.diags(keep.astype(float))
    Kp = (D @ K @ D + sp.diags((~keep).astype(float))).tocsc()
    lu = spla.splu(Kp, permc_spec="COLAMD")
    G = np.empty((bdofs.size, bdofs.size))
    # SuperLU's triangular solves are memory bound: extra BLAS threads only contend.
    with threadpool_limits(1, "blas"):
        for start in range(0, bdofs.size, chunk):
            cols = np.arange(start, min(start + chunk, bdofs.size))
            rhs = np.zeros((n2, cols.size))
            rhs[bdofs[cols], np.arange(cols.size)] = keep[bdofs[cols]]
            G[:, cols] = lu.solve(rhs)[bdofs]
    G = 0.5 * (G + G.T)

    def solve(f_b):
        rhs = np.zeros(n2)
        rhs[bdofs] = f_b
        rhs[~keep] = 0.0
        return lu.solve(rhs)

    return G, FieldMap(solve, pts)
