"""Tests of the plane-stress FEM (jaxsqueeze.fem) and the bordered solve (jaxsqueeze.bordered).

Checks against independent oracles written here: a loop-based numpy assembler, the energy
integral (1) of the paper, the patch test, uniaxial tension, a direct elimination solve, and
agreement of the three compliance builds (DESIGN 2.2). Runs in float64 (conftest).
"""
from __future__ import annotations

import functools
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsqueeze as jsq
from jaxsqueeze.geometry import shapes
from jaxsqueeze.mechanics import bordered, fem
from jaxsqueeze.mechanics.material import Material
from physics import compiles

MAT = Material(E=2.5e6, nu=0.35, thickness=0.01)
METHODS = ("sparse", "dense", "spectral")


# ----------------------------------------------------------------------------- meshes
L_SHAPE = [(0, 0), (0.08, 0), (0.08, 0.03), (0.03, 0.03), (0.03, 0.07), (0, 0.07)]


@functools.lru_cache(maxsize=None)
def mesh_of(name: str, max_edge: float = 0.01) -> jsq.Mesh:
    if name == "rectangle":      # 0.1 m x 0.06 m
        return shapes.rectangle(0.1, 0.06, max_edge)
    if name == "annulus":        # r 0.05 / 0.02 m: a hole
        return shapes.annulus(0.05, 0.02, max_edge)
    if name == "lshape":         # non-convex polygon
        return shapes.polygon(L_SHAPE, max_edge=max_edge)
    raise KeyError(name)


SHAPES = ("rectangle", "annulus", "lshape")


@functools.lru_cache(maxsize=None)
def op_of(name: str, method: str, max_edge: float = 0.01):
    return fem.compliance(mesh_of(name, max_edge), MAT, method)


def dense_K(mesh, mat=MAT) -> np.ndarray:
    return np.asarray(fem.stiffness(mesh, mat).todense())


def rel_err(a, b) -> float:
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def interior(mesh) -> np.ndarray:
    mask = np.ones(mesh.n, bool)
    mask[mesh.boundary] = False
    return np.flatnonzero(mask)


# ----------------------------------------------------------------------------- independent oracle
def _shape_gradients(xy):
    """Gradients (2, 3) of the linear shape functions and the area, from inverting [1 x y]."""
    C = np.column_stack([np.ones(3), xy])          # row i: [1, x_i, y_i]
    coef = np.linalg.inv(C)                         # N_i(x, y) = coef[:, i] . [1, x, y]
    return coef[1:, :], 0.5 * abs(np.linalg.det(C))


def reference_stiffness(points, triangles, E, nu, h) -> np.ndarray:
    """Plane-stress CST stiffness by a plain loop over triangles (textbook form)."""
    n = len(points)
    D = E / (1 - nu**2) * np.array([[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]])
    K = np.zeros((2 * n, 2 * n))
    for tri in np.asarray(triangles):
        dN, area = _shape_gradients(np.asarray(points)[tri])
        B = np.zeros((3, 6))
        B[0, 0::2] = dN[0]           # eps_x = du/dx
        B[1, 1::2] = dN[1]           # eps_y = dv/dy
        B[2, 0::2] = dN[1]           # gamma = du/dy + dv/dx
        B[2, 1::2] = dN[0]
        ke = h * area * B.T @ D @ B
        dofs = np.ravel([[2 * i, 2 * i + 1] for i in tri])
        K[np.ix_(dofs, dofs)] += ke
    return K


def element_gradients(points, triangles, u) -> np.ndarray:
    """Displacement gradient H (t, 2, 2) of each element: u(x) = a + H x fitted to its vertices."""
    out = []
    for tri in np.asarray(triangles):
        C = np.column_stack([np.ones(3), np.asarray(points)[tri]])
        out.append(np.linalg.solve(C, np.asarray(u)[tri])[1:].T)   # (2, 2): H[i, j] = du_i/dx_j
    return np.array(out)


def energy_integral(points, triangles, u, E, nu, h) -> float:
    """Strain energy (1) of the paper, integrated element by element (strains are constant)."""
    H = element_gradients(points, triangles, u)
    ex, ey, gxy = H[:, 0, 0], H[:, 1, 1], H[:, 0, 1] + H[:, 1, 0]
    p = np.asarray(points)[np.asarray(triangles)]
    area = 0.5 * np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                        - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    dens = (ex**2 + 2 * nu * ex * ey + ey**2) / (1 - nu) + gxy**2 / 2
    return float(h * E / (2 * (1 + nu)) * np.sum(area * dens))


def traction_forces(mesh, sigma, h) -> np.ndarray:
    """Nodal forces (n, 2) of the traction sigma . n of a uniform stress on the boundary.

    Boundary edges are the triangle edges used once; a ccw triangle has the material on the
    left of each of its edges, so the outward normal times length of edge a->b is
    (y_b - y_a, -(x_b - x_a)). Linear shape functions give each end node half.
    """
    tri = np.asarray(mesh.triangles)
    e = tri[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    key = np.sort(e, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    e = e[cnt[inv.ravel()] == 1]
    d = mesh.points[e[:, 1]] - mesh.points[e[:, 0]]
    nl = np.stack([d[:, 1], -d[:, 0]], axis=1)
    t = 0.5 * h * nl @ np.asarray(sigma).T
    f = np.zeros((mesh.n, 2))
    np.add.at(f, e[:, 0], t)
    np.add.at(f, e[:, 1], t)
    return f


def cross(p, f) -> np.ndarray:
    return p[..., 0] * f[..., 1] - p[..., 1] * f[..., 0]


# ----------------------------------------------------------------------------- stiffness
@pytest.mark.parametrize("name", SHAPES)
def test_stiffness_symmetric_psd_rank_and_null_space(name):
    mesh = mesh_of(name)
    K = dense_K(mesh)
    scale = np.abs(K).max()
    assert K.shape == (2 * mesh.n, 2 * mesh.n)
    assert np.abs(K - K.T).max() <= 1e-14 * scale
    lam = np.linalg.eigvalsh(K)
    assert lam.min() >= -1e-12 * lam.max()                     # positive semi-definite
    assert int(np.sum(lam > 1e-10 * lam.max())) == 2 * mesh.n - 3
    assert np.linalg.matrix_rank(K) == 2 * mesh.n - 3
    W = np.asarray(fem.null_space(mesh.points))
    assert W.shape == (2 * mesh.n, 3)
    np.testing.assert_allclose(W.T @ W, np.eye(3), atol=1e-12)   # normalized, orthogonal (centred)
    assert np.abs(K @ W).max() <= 1e-12 * np.linalg.norm(K, 2)
    # columns are x translation, y translation, rotation about the centroid
    assert np.allclose(W[0::2, 0], W[0, 0]) and np.allclose(W[1::2, 0], 0)
    assert np.allclose(W[1::2, 1], W[1, 1]) and np.allclose(W[0::2, 1], 0)
    p = mesh.points - mesh.points.mean(axis=0)
    r = np.stack([-p[:, 1], p[:, 0]], axis=1).ravel()
    np.testing.assert_allclose(W[:, 2], r / np.linalg.norm(r), atol=1e-14)


@pytest.mark.parametrize("name", SHAPES)
def test_stiffness_matches_loop_reference(name):
    mesh = mesh_of(name)
    K = dense_K(mesh)
    K_ref = reference_stiffness(mesh.points, mesh.triangles, MAT.E, MAT.nu, MAT.thickness)
    assert np.abs(K - K_ref).max() <= 1e-12 * np.abs(K_ref).max()


def test_element_stiffness_is_translation_and_scale_free():
    xy = jnp.array([[0.0, 0.0], [0.02, 0.001], [0.004, 0.015]])
    k = np.asarray(fem.element_stiffness(xy, 0.3))
    dN, area = _shape_gradients(np.asarray(xy))
    assert np.abs(k - k.T).max() <= 1e-15 * np.abs(k).max()
    np.testing.assert_allclose(np.asarray(fem.element_stiffness(xy * 1000 + 3.0, 0.3)), k, rtol=1e-9, atol=1e-12)
    ref = reference_stiffness(np.asarray(xy), np.array([[0, 1, 2]]), 1.0, 0.3, 1.0)
    np.testing.assert_allclose(k, ref, rtol=0, atol=1e-13 * np.abs(ref).max())


@pytest.mark.parametrize("name", SHAPES)
def test_energy_equals_integral_of_paper(name):
    mesh = mesh_of(name)
    K = dense_K(mesh)
    rng = np.random.default_rng(0)
    for _ in range(3):
        u = 1e-3 * rng.standard_normal((mesh.n, 2))
        U_K = 0.5 * u.ravel() @ K @ u.ravel()
        U_int = energy_integral(mesh.points, mesh.triangles, u, MAT.E, MAT.nu, MAT.thickness)
        assert U_K == pytest.approx(U_int, rel=1e-12)


# ----------------------------------------------------------------------------- patch test, uniaxial
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", ["lshape", "annulus"])
def test_patch_test_linear_field(name, method):
    mesh, op = mesh_of(name), op_of(name, method)
    a = np.array([2e-4, -1e-4])
    H = np.array([[1.0e-3, 4.0e-4], [-2.5e-4, -6.0e-4]])
    u_lin = a + mesh.points @ H.T
    b = mesh.boundary
    sol = jsq.deform(op, b, u_lin[b])
    u = np.asarray(sol.displacement)
    scale = np.abs(u_lin).max()
    # every node, interior included, follows the linear field
    assert np.abs(u[interior(mesh)] - u_lin[interior(mesh)]).max() <= 1e-10 * scale
    assert np.abs(u - u_lin).max() <= 1e-10 * scale
    # every element's strain is sym(H)
    Hs = element_gradients(mesh.points, mesh.triangles, u)
    eps = 0.5 * (Hs + np.swapaxes(Hs, 1, 2))
    assert np.abs(eps - 0.5 * (H + H.T)).max() <= 1e-10 * np.abs(H).max()
    # forces: equilibrium, = K u, = traction of the uniform stress integrated on the boundary
    f = np.asarray(sol.forces)
    fscale = np.abs(f).max()
    assert np.abs(f.sum(axis=0)).max() <= 1e-10 * fscale
    assert abs(cross(mesh.points[b], f).sum()) <= 1e-10 * fscale * fem.object_length(mesh)
    Ku = (dense_K(mesh) @ u_lin.ravel()).reshape(-1, 2)
    assert np.abs(Ku[interior(mesh)]).max() <= 1e-10 * fscale
    assert rel_err(f, Ku[b]) <= 1e-9
    e = 0.5 * (H + H.T)
    E, nu = MAT.E, MAT.nu
    sx = E / (1 - nu**2) * (e[0, 0] + nu * e[1, 1])
    sy = E / (1 - nu**2) * (e[1, 1] + nu * e[0, 0])
    txy = E / (2 * (1 + nu)) * 2 * e[0, 1]
    sigma = np.array([[sx, txy], [txy, sy]])
    assert rel_err(f, traction_forces(mesh, sigma, MAT.thickness)[b]) <= 1e-9


@pytest.mark.parametrize("name", ["lshape", "annulus"])
def test_element_stress_is_hookes_law_and_its_energy_the_stiffness_energy(name):
    """fem.element_stress: a linear field plus a rigid motion (a small rotation about the
    centroid and a translation) gives every triangle Hooke's plane stress of sym(H), exactly;
    the rigid part alone gives none; von Mises of uniaxial stress is |σ|, of pure shear √3 τ.
    For a random field, h/2 Σ A σ·C σ (physics.stress_energy, the textbook compliance C)
    equals ½ uᵀ K u of the assembled stiffness. jit, vmap, jvp and grad apply."""
    from physics import stress_energy

    mesh = mesh_of(name)
    P = mesh.points
    H = np.array([[1.0e-3, 4.0e-4], [-2.5e-4, -6.0e-4]])
    rigid = np.array([2e-4, -1e-4]) + 3e-3 * np.c_[-P[:, 1], P[:, 0]]
    sig = np.asarray(fem.element_stress(mesh, MAT, P @ H.T + rigid))
    e = 0.5 * (H + H.T)
    E, nu = MAT.E, MAT.nu
    hooke = np.array([E / (1 - nu**2) * (e[0, 0] + nu * e[1, 1]), E / (1 - nu**2) * (e[1, 1] + nu * e[0, 0]),
                      E / (1 + nu) * e[0, 1]])
    assert sig.shape == (len(mesh.triangles), 3)
    assert np.abs(sig - hooke).max() <= 1e-9 * np.abs(hooke).max()
    assert np.abs(np.asarray(fem.element_stress(mesh, MAT, rigid))).max() <= 1e-9 * np.abs(hooke).max()
    np.testing.assert_allclose(fem.von_mises(np.array([[-3.0, 0, 0], [0, 2.0, 0], [0, 0, 1.5]])), [3, 2, 1.5 * 3**0.5])
    # its derivative: (2σ_xx − σ_yy, 2σ_yy − σ_xx, 6τ_xy) / 2σ_vm where loaded, 0 (not NaN) unloaded
    s0 = np.array([[2.0, -1.0, 0.5], [0.0, 0.0, 0.0]])
    g = np.asarray(jax.grad(lambda s: fem.von_mises(s).sum())(jnp.asarray(s0)))
    vm = float(fem.von_mises(s0[0]))
    np.testing.assert_allclose(g[0], [5.0 / (2 * vm), -4.0 / (2 * vm), 3.0 / (2 * vm)], rtol=1e-14)
    np.testing.assert_array_equal(g[1], 0.0)
    u = np.random.default_rng(4).normal(size=(mesh.n, 2)) * 1e-4
    want = 0.5 * u.ravel() @ dense_K(mesh) @ u.ravel()
    assert abs(stress_energy(mesh, MAT, fem.element_stress(mesh, MAT, u)) - want) <= 1e-12 * want
    with pytest.raises(ValueError, match=r"displacement must be \(n, 2\)"):
        fem.element_stress(mesh, MAT, u[:-1])
    # whole-metre (integer) displacements cast the mesh's points to integers (NaN stresses);
    # booleans and complex numbers were read as numbers; a von Mises of the wrong shape failed
    # with an IndexError
    whole = (mesh.points[:, :1] > 0) * np.array([[1, 0]])
    np.testing.assert_array_equal(fem.element_stress(mesh, MAT, whole), fem.element_stress(mesh, MAT, whole * 1.0))
    for bad, dtype in ((u > 0, "bool"), (u + 0j, "complex128")):
        with pytest.raises(ValueError, match=rf"displacement must be real numbers \[m\]; got dtype {dtype}"):
            fem.element_stress(mesh, MAT, bad)
    assert float(fem.von_mises(np.array([0, 2, 0]))) == 2.0
    with pytest.raises(ValueError, match=r"stress must be plane stresses \(\.\.\., 3\) .* got shape \(4, 2\)"):
        fem.von_mises(np.zeros((4, 2)))
    # transforms: jit with the mesh static, vmap over fields, jvp in the field (it is linear),
    # grad in nu against central differences
    du = np.roll(u, 1, axis=0)
    one = jax.jit(fem.element_stress, static_argnums=0)
    np.testing.assert_allclose(jax.vmap(lambda v: one(mesh, MAT, v))(np.stack([u, du]))[1],
                               fem.element_stress(mesh, MAT, du), rtol=1e-12, atol=0)
    _, tangent = jax.jvp(lambda v: fem.element_stress(mesh, MAT, v), (u,), (du,))
    np.testing.assert_allclose(tangent, fem.element_stress(mesh, MAT, du), rtol=1e-12, atol=0)
    size = lambda nu: jnp.sum(fem.element_stress(mesh, Material(MAT.E, nu, MAT.thickness), u) ** 2)  # noqa: E731
    h = 1e-6
    fd = (size(MAT.nu + h) - size(MAT.nu - h)) / (2 * h)
    assert abs(jax.grad(size)(MAT.nu) - fd) <= 1e-7 * abs(fd)


def test_converges_at_second_order_to_an_exact_solution():
    """Convergence under mesh refinement against an exact plane-stress solution that linear
    triangles cannot represent: u = grad(phi) with the harmonic phi = a^2 e^(x/a) cos(y/a) has
    div u = 0 and curl u = 0, so it satisfies Navier's equations without body force for any
    E and nu. Prescribed on every boundary node through the bordered system (jsq.deform), the
    interior displacement converges at second order (nodal error ~ h^2), and the element
    strains and stresses (fem.element_stress) at first order (structured meshes, so the
    refinement is exactly uniform)."""
    a = 0.05
    exact = lambda P: 1e-3 * a * np.exp(P[:, 0] / a)[:, None] * np.c_[np.cos(P[:, 1] / a), -np.sin(P[:, 1] / a)]  # noqa: E731
    errs, strain_errs, stress_errs = [], [], []
    for k in (8, 16, 32):             # uniform refinement: k x k squares of a 0.1 m square, two triangles each
        g = np.linspace(-0.05, 0.05, k + 1)
        X, Y = np.meshgrid(g, g, indexing="ij")
        n = np.arange((k + 1) ** 2).reshape(k + 1, k + 1)
        q = np.c_[n[:-1, :-1].ravel(), n[1:, :-1].ravel(), n[1:, 1:].ravel(), n[:-1, 1:].ravel()]
        mesh = jsq.Mesh.from_arrays(np.c_[X.ravel(), Y.ravel()], np.r_[q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
        P = mesh.points + mesh.offset                    # the user's frame: the field is not translation-free
        u_ex = exact(P)
        sol = jsq.deform(fem.compliance(mesh, MAT), mesh.boundary, u_ex[mesh.boundary])
        u = np.asarray(sol.displacement)
        errs.append(np.abs(u - u_ex)[interior(mesh)].max() / np.abs(u_ex).max())
        grad = element_gradients(mesh.points, mesh.triangles, u)
        c = P[mesh.triangles].mean(axis=1)              # the exact strain at element centroids
        e = 1e-3 * np.exp(c[:, 0] / a)
        exact_grad = np.stack([np.c_[e * np.cos(c[:, 1] / a), -e * np.sin(c[:, 1] / a)],
                               np.c_[-e * np.sin(c[:, 1] / a), -e * np.cos(c[:, 1] / a)]], axis=1)
        strain_errs.append(np.abs(grad - exact_grad).max() / np.abs(exact_grad).max())
        eps = np.c_[exact_grad[:, 0, 0], exact_grad[:, 1, 1], exact_grad[:, 0, 1] + exact_grad[:, 1, 0]]
        exact_sig = MAT.E / (1 - MAT.nu**2) * np.c_[eps[:, 0] + MAT.nu * eps[:, 1], eps[:, 1] + MAT.nu * eps[:, 0],
                                                    (1 - MAT.nu) / 2 * eps[:, 2]]
        stress_errs.append(np.abs(np.asarray(fem.element_stress(mesh, MAT, u)) - exact_sig).max()
                           / np.abs(exact_sig).max())
    order = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    strain_order = np.log2(np.array(strain_errs[:-1]) / np.array(strain_errs[1:]))
    stress_order = np.log2(np.array(stress_errs[:-1]) / np.array(stress_errs[1:]))
    print("exact-solution convergence: nodal errors", errs, "orders", order, "strain orders", strain_order,
          "stress (fem.element_stress) orders", stress_order)
    assert errs[-1] < 1e-3
    assert np.all(order > 1.8) and np.all(strain_order > 0.9) and np.all(stress_order > 0.9)


@pytest.mark.parametrize("method", METHODS)
def test_uniaxial_tension_of_rectangle(method):
    mesh, op = mesh_of("rectangle"), op_of("rectangle", method)
    sigma = 1.0e4                                   # Pa, strain 4e-3
    E, nu, h = MAT.E, MAT.nu, MAT.thickness
    x, y = mesh.points[:, 0], mesh.points[:, 1]
    u_exact = np.stack([sigma / E * x, -nu * sigma / E * y], axis=1)
    b = mesh.boundary
    sol = jsq.deform(op, b, u_exact[b])
    f = np.asarray(sol.forces)
    xb = mesh.points[b, 0]
    right, left = np.isclose(xb, x.max(), atol=1e-9), np.isclose(xb, x.min(), atol=1e-9)
    height = np.ptp(y)
    assert f[right, 0].sum() == pytest.approx(sigma * h * height, rel=1e-9)
    assert f[left, 0].sum() == pytest.approx(-sigma * h * height, rel=1e-9)
    # traction-free top and bottom: the remaining (non-end) nodes carry no force
    fmax = np.abs(f).max()
    assert np.abs(f[~(right | left)]).max() <= 1e-9 * fmax
    assert np.abs(f[right | left, 1]).max() <= 1e-9 * fmax
    u = np.asarray(sol.displacement)
    assert rel_err(u[interior(mesh)], u_exact[interior(mesh)]) <= 1e-9
    assert rel_err(u, u_exact) <= 1e-9


# ----------------------------------------------------------------------------- builds, direct solve
def _random_case(mesh, s, rng):
    nodes = rng.choice(mesh.boundary, size=s, replace=False)
    d = 1e-3 * rng.standard_normal((s, 2))
    return nodes, d


@pytest.mark.parametrize("name, max_edge", [(n, 0.01) for n in SHAPES] + [("rectangle", 0.005), ("annulus", 0.006)])
def test_three_builds_agree(name, max_edge):
    mesh = mesh_of(name, max_edge)
    ops = {m: op_of(name, m, max_edge) for m in METHODS}
    if name == "rectangle" and max_edge == 0.01:    # README, "Your JAX settings": the same numbers
        pinch = lambda op: jsq.deform(op, mesh.boundary[:2], np.full((2, 2), 1e-3)).forces  # noqa: E731
        with jax.numpy_rank_promotion("raise"), jax.numpy_dtype_promotion("strict"):
            raised = {m: pinch(fem.compliance(mesh, MAT, method=m)) for m in METHODS}
        for m in METHODS:
            np.testing.assert_array_equal(np.asarray(raised[m]), np.asarray(pinch(ops[m])))
    rng = np.random.default_rng(1)
    for s in (range(2, 7) if mesh.n < 200 else (2, 6)):
        nodes, d = _random_case(mesh, s, rng)
        sols = {m: jsq.deform(ops[m], nodes, d) for m in METHODS}
        ref = sols["spectral"]
        for m in ("sparse", "dense"):     # README: "to ~1e-14" (at most 2.9e-14 here, 2026-12-05)
            assert rel_err(sols[m].forces, ref.forces) <= 2e-13, (m, s)
            assert rel_err(sols[m].displacement, ref.displacement) <= 2e-13, (m, s)
            np.testing.assert_allclose(np.asarray(sols[m].displacement)[nodes], d, rtol=0,
                                       atol=1e-12 * np.abs(d).max())


def test_rigid_part_is_in_each_builds_gauge():
    """README: g is measured in the build's gauge (sparse/dense from the pinned support,
    spectral from the mean rigid motion): a mirror-symmetric pinch has g = (0, t_y, 0) in the
    spectral build but not in the sparse one, while forces and displacements agree."""
    from physics import nearest, symmetric_square
    mesh = symmetric_square(0.1, 0.01)
    top, bottom = nearest(mesh, (0.0, 0.05)), nearest(mesh, (0.0, -0.05))
    scene = jsq.Scene(mesh=mesh, material=jsq.Material(E=1e5, nu=0.3, thickness=0.01),
                      fingers=jsq.Fingers(radius=0.01), grip=(top, bottom), depth=0.01)
    ops = {m: scene.replace(method=m).operator() for m in ("sparse", "spectral")}
    d = np.array([[0.0, -1e-3], [0.0, 1e-3]])
    sols = {m: jsq.deform(ops[m], [top, bottom], d) for m in ops}
    assert rel_err(sols["sparse"].forces, sols["spectral"].forces) <= 1e-9
    assert rel_err(sols["sparse"].displacement, sols["spectral"].displacement) <= 1e-9
    g_sp, g_sparse = np.asarray(sols["spectral"].g), np.asarray(sols["sparse"].g)
    assert abs(g_sp[0]) < 1e-12 and abs(g_sp[2]) < 1e-9                    # no drift, no spin
    assert abs(g_sparse[0]) > 1e-6 or abs(g_sparse[2]) > 1e-6             # the pinned support's gauge


# vmap of jacfwd in nu of the dense build, on a mesh where it waited forever (edge 6 mm:
# 4 of 4 tries on 2 cores before the fix), in a child process so that a regression fails
# instead of hanging the suite
VMAP_JACFWD_NU = r"""
import json, sys
import jax
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp, numpy as np
from jaxsqueeze.mechanics import fem
from jaxsqueeze.mechanics.material import Material
from physics import symmetric_square
mesh = symmetric_square(0.1, 0.006)
v = np.random.default_rng(0).normal(size=2 * len(mesh.boundary))
work = lambda nu: v @ fem.compliance(mesh, Material(E=1e5, nu=nu, thickness=0.01), method="dense").G @ v
nus = jnp.array([0.2, 0.45])
batched = jax.vmap(jax.jacfwd(work))(nus)
loop = [float(jax.jacfwd(work)(nu)) for nu in nus]
fd = [float((work(nu + 1e-6) - work(nu - 1e-6)) / 2e-6) for nu in (0.2, 0.45)]
print(json.dumps(dict(batched=np.asarray(batched).tolist(), loop=loop, fd=fd)))
"""


def test_vmap_of_jacfwd_in_nu_of_the_dense_build_finishes():
    """docs/numerics.md, finding 28: the dense build's tangent is solved after its value, so
    batched LAPACK solves never wait on each other; the batch equals the loop of single
    jacfwds and central differences."""
    import json
    import os
    import subprocess
    import sys
    here = os.path.dirname(os.path.abspath(__file__))
    root = os.path.dirname(os.path.dirname(here))
    env = dict(os.environ, JAX_PLATFORMS="cpu",
               PYTHONPATH=os.pathsep.join([root, os.path.dirname(here), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", VMAP_JACFWD_NU], capture_output=True, text=True, env=env,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    r = json.loads(out.stdout.strip().splitlines()[-1])
    np.testing.assert_allclose(r["batched"], r["loop"], rtol=1e-12)
    np.testing.assert_allclose(r["batched"], r["fd"], rtol=1e-6)


def test_dense_build_differentiates_in_nu_in_reverse_mode_too():
    """The dense build's own tangent rule is linear, so jax.grad through it equals jax.jacfwd
    (the test above checks jacfwd against central differences)."""
    from physics import symmetric_square
    mesh = symmetric_square(0.1, 0.02)
    v = np.random.default_rng(0).normal(size=2 * len(mesh.boundary))

    def work(nu):
        return v @ jsq.fem.compliance(mesh, jsq.Material(E=1e5, nu=nu, thickness=0.01), "dense").G @ v

    np.testing.assert_allclose(jax.grad(work)(0.3), jax.jacfwd(work)(0.3), rtol=1e-12)     # (README)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", ["rectangle", "annulus"])
def test_deform_matches_direct_elimination(name, method):
    mesh, op = mesh_of(name), op_of(name, method)
    K = dense_K(mesh)
    rng = np.random.default_rng(2)
    for s in (2, 3, 5):
        nodes, d = _random_case(mesh, s, rng)
        p = np.ravel([[2 * i, 2 * i + 1] for i in nodes])
        free = np.setdiff1d(np.arange(2 * mesh.n), p)
        u = np.zeros(2 * mesh.n)
        u[p] = d.ravel()
        u[free] = np.linalg.solve(K[np.ix_(free, free)], -K[np.ix_(free, p)] @ d.ravel())
        reaction = (K @ u)[p].reshape(-1, 2)
        sol = jsq.deform(op, nodes, d)
        assert rel_err(sol.forces, reaction) <= 1e-9
        assert rel_err(sol.displacement, u.reshape(-1, 2)) <= 1e-9


# ----------------------------------------------------------------------------- Theorem 3, Corollary 4
def _blocks(op, nodes):
    slots = bordered.boundary_slots(op, nodes)
    dofs = np.asarray(bordered.slot_dofs(jnp.asarray(slots)))
    return op.G[dofs][:, dofs], op.N[dofs]


@pytest.mark.parametrize("name", ["rectangle", "annulus"])
def test_theorem3_bordered_matrix_nonsingular_iff_two_nodes(name):
    mesh, op = mesh_of(name), op_of(name, "sparse")
    rng = np.random.default_rng(3)
    b = mesh.boundary
    cases = [b[[0, 1]], b[[0, len(b) // 2]]] + [rng.choice(b, s, replace=False) for s in (2, 2, 3, 3, 6, 6)]
    for nodes in cases:
        A, B = _blocks(op, nodes)
        M = np.asarray(bordered.bordered_matrix(A, B, jnp.ones(len(nodes), bool)))
        assert M.shape == (2 * len(nodes) + 3,) * 2
        assert np.abs(M - M.T).max() == 0
        sv = np.linalg.svd(M, compute_uv=False)
        assert sv[-1] > 1e-6 * sv[0], (nodes, sv[-1] / sv[0])
    for node in rng.choice(b, 4, replace=False):
        A, B = _blocks(op, [node])
        sv = np.linalg.svd(np.asarray(bordered.bordered_matrix(A, B, jnp.ones(1, bool))), compute_uv=False)
        assert sv[-1] <= 1e-13 * sv[0]                       # free to rotate about the node


def test_bordered_inactive_slots_are_inert():
    mesh, op = mesh_of("rectangle"), op_of("rectangle", "sparse")
    nodes = mesh.boundary[[0, 5, 11, 17]]
    d = 1e-3 * np.random.default_rng(4).standard_normal((4, 2))
    A, B = _blocks(op, nodes)
    active = jnp.array([True, False, True, False])
    M = np.asarray(bordered.bordered_matrix(A, B, active))
    assert np.linalg.svd(M, compute_uv=False)[-1] > 1e-8
    f, g = bordered.bordered_solve(A, B, jnp.asarray(d.ravel() / op.length), active)
    f = np.asarray(f).reshape(-1, 2)
    assert np.all(f[[1, 3]] == 0)
    ref = jsq.deform(op, nodes[[0, 2]], d[[0, 2]])
    np.testing.assert_allclose(f[[0, 2]] * float(op.force_scale), ref.forces, rtol=1e-10, atol=0)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", ["lshape", "annulus"])
def test_corollary4_rigid_displacement_gives_zero_force(name, method):
    mesh, op = mesh_of(name), op_of(name, method)
    rng = np.random.default_rng(5)
    t, theta = np.array([3e-3, -2e-3]), 1e-2
    for s in (2, 4, 6):
        nodes, d = _random_case(mesh, s, rng)
        p = mesh.points[nodes]
        rigid = t + theta * np.stack([-p[:, 1], p[:, 0]], axis=1)
        deforming = jsq.deform(op, nodes, rigid + d)
        sol = jsq.deform(op, nodes, rigid)
        assert np.abs(np.asarray(sol.forces)).max() <= 1e-10 * np.abs(np.asarray(deforming.forces)).max()
        # the points are centred, so g is exactly (t_x, t_y, theta)
        np.testing.assert_allclose(np.asarray(sol.g), [*t, theta], rtol=1e-9, atol=1e-15)
        field = t + theta * np.stack([-mesh.points[:, 1], mesh.points[:, 0]], axis=1)
        assert rel_err(sol.displacement, field) <= 1e-9


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", SHAPES)
def test_force_and_torque_equilibrium(name, method):
    mesh, op = mesh_of(name), op_of(name, method)
    rng = np.random.default_rng(6)
    for s in (2, 3, 6):
        nodes, d = _random_case(mesh, s, rng)
        f = np.asarray(jsq.deform(op, nodes, d).forces)
        fmax = np.abs(f).max()
        assert fmax > 0
        assert np.abs(f.sum(axis=0)).max() <= 1e-10 * fmax
        # torque about the centroid, and about any other point (total force is zero)
        L = fem.object_length(mesh)
        assert abs(cross(mesh.points[nodes], f).sum()) <= 1e-10 * fmax * L
        assert abs(cross(mesh.points[nodes] + mesh.offset, f).sum()) <= 1e-10 * fmax * (L + np.abs(mesh.offset).max())
        if s == 2:   # two-node forces are equal, opposite and along the line joining the nodes
            dp = mesh.points[nodes[1]] - mesh.points[nodes[0]]
            assert abs(cross(dp, f[0])) <= 1e-10 * fmax * np.linalg.norm(dp)


# ----------------------------------------------------------------------------- errors
def test_deform_errors():
    mesh, op = mesh_of("rectangle"), op_of("rectangle", "sparse")
    b = mesh.boundary
    with pytest.raises(ValueError, match=r"s >= 2"):
        jsq.deform(op, b[:1], np.zeros((1, 2)))
    with pytest.raises(ValueError, match=r"not on the boundary"):
        jsq.deform(op, [b[0], interior(mesh)[0]], np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"not on the boundary"):
        jsq.deform(op, [b[0], mesh.n + 5], np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"duplicates"):
        jsq.deform(op, [b[0], b[3], b[0]], np.zeros((3, 2)))
    with pytest.raises(ValueError, match=r"shape \(3, 2\)"):
        jsq.deform(op, b[:3], np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"shape \(2, 2\)"):
        jsq.deform(op, b[:2], np.zeros(4))
    with pytest.raises(ValueError, match=rf"node\(s\) \[{int(b[1])}\] are not finite"):
        jsq.deform(op, b[:2], np.array([[0.0, 0.0], [np.nan, 0.0]]))
    with pytest.raises(ValueError, match=r"method"):
        fem.compliance(mesh, MAT, "cholesky")
    # node 2.5 was read as node 2, a complex displacement lost its imaginary part with only
    # numpy's ComplexWarning, and a (1, 2) array of nodes was flattened
    with pytest.raises(ValueError, match=r"node indices must be integers, got \[.*2.5\] \(float64\)"):
        jsq.deform(op, [float(b[0]), 2.5], np.zeros((2, 2)))
    for bad in (np.zeros((2, 2)) + 1e-3j, [["a", "b"], ["c", "d"]], np.zeros((2, 2), bool)):
        with pytest.raises(ValueError, match=r"displacements must be real numbers \[m\]; got dtype"):
            jsq.deform(op, b[:2], bad)
    with pytest.raises(ValueError, match=r"flat list of s boundary node indices, got shape \(1, 2\)"):
        jsq.deform(op, [b[:2]], np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"flat list of s boundary node indices, got \[1, \[2, 3\]\]"):
        jsq.deform(op, [1, [2, 3]], np.zeros((2, 2)))


@pytest.mark.parametrize("kwargs, field", [
    (dict(E=0.0, nu=0.3, thickness=0.01), "E"),
    (dict(E=-1e6, nu=0.3, thickness=0.01), "E"),
    (dict(E=float("nan"), nu=0.3, thickness=0.01), "E"),
    (dict(E=1e6, nu=0.6, thickness=0.01), "nu"),
    (dict(E=1e6, nu=-1.0, thickness=0.01), "nu"),
    (dict(E=1e6, nu=0.3, thickness=0.0), "thickness"),
    (dict(E=1e6, nu=np.array([0.3, 0.6]), thickness=0.01), "nu"),     # raw numpy "truth value ambiguous"
])
def test_material_validation(kwargs, field):
    with pytest.raises(ValueError, match=rf"Material\.{field}="):
        Material(**kwargs)


@pytest.mark.parametrize("field, value, says", [
    ("E", "1e5", "= '1e5': expected one real number [Pa]"), ("E", True, "= True: expected one real number [Pa]"),
    ("nu", 0.3 + 0.1j, "= (0.3+0.1j): expected one real number [-]"), ("thickness", None, "= None: expected one real"),
    ("E", [1e5, 2e5], "has shape (2,): one material takes one number"),
    ("nu", [0.3, [0.2]], "= [0.3, [0.2]]: expected one real number [-]"),      # (NumPy's own ragged-list error)
])
def test_fem_functions_refuse_a_material_that_is_not_numbers(field, value, says):
    """A Material holds anything (JAX rebuilds pytrees with placeholders and masks), so the
    functions that compute with one check it: ``fem.stiffness`` read E="1e5" as 1e5 Pa and
    True as 1 Pa, ``element_stress`` returned complex stresses for a complex E, and the others
    failed with a TypeError from deep inside."""
    mesh = mesh_of("rectangle", 0.05)
    mat = Material(**{**dict(E=1e5, nu=0.3, thickness=0.01), field: value})
    for call in (lambda: fem.stiffness(mesh, mat), lambda: fem.compliance(mesh, mat),
                 lambda: fem.element_stress(mesh, mat, np.zeros((mesh.n, 2))),
                 lambda: jsq.scene.compliance_of(mesh, mat)):          # Scene.operator() (it read True as 1 Pa)
        with pytest.raises(ValueError, match=re.escape(f"Material.{field} {says}")):
            call()


def test_material_edge_values_accepted():
    """The edges of the ranges are materials (no error), also as a batch of values."""
    assert Material(E=1.0, nu=0.5, thickness=1e-6).nu == 0.5
    assert Material(E=1e9, nu=-0.99, thickness=1.0).nu == -0.99
    batch = Material(E=1e9, nu=np.array([-0.99, 0.0, 0.5]), thickness=1.0)
    assert batch.nu.shape == (3,)


# ----------------------------------------------------------------------------- units (DESIGN 2.3)
@pytest.mark.parametrize("method", ["sparse", "dense"])
def test_scaling_invariance(method):
    """Scaling every length by k (object and displacements, thickness kept) leaves strains and
    stresses unchanged; forces = stress x thickness x edge length grow by k. The scaled
    compliance G is identical."""
    k = 1000.0
    m1 = mesh_of("lshape")
    mk = jsq.Mesh.from_arrays(m1.points * k, m1.triangles)
    np.testing.assert_array_equal(mk.boundary, m1.boundary)
    op1, opk = fem.compliance(m1, MAT, method), fem.compliance(mk, MAT, method)
    assert float(opk.length) == pytest.approx(k * float(op1.length), rel=1e-14)
    np.testing.assert_allclose(np.asarray(opk.G), np.asarray(op1.G), rtol=0, atol=1e-12 * np.abs(op1.G).max())
    np.testing.assert_allclose(np.asarray(opk.points), np.asarray(op1.points), rtol=0, atol=1e-14)
    rng = np.random.default_rng(7)
    for s in (2, 5):
        nodes, d = _random_case(m1, s, rng)
        s1, sk = jsq.deform(op1, nodes, d), jsq.deform(opk, nodes, k * d)
        assert rel_err(sk.forces, k * np.asarray(s1.forces)) <= 1e-10
        assert rel_err(sk.displacement, k * np.asarray(s1.displacement)) <= 1e-10
        np.testing.assert_allclose(np.asarray(sk.g), np.asarray(s1.g) * [k, k, 1], rtol=1e-8,
                                   atol=1e-10 * k * np.abs(d).max())
    # E and thickness only scale forces (E h), never G or displacements
    mat2 = Material(E=3 * MAT.E, nu=MAT.nu, thickness=0.5 * MAT.thickness)
    op2 = fem.compliance(m1, mat2, method)
    np.testing.assert_array_equal(np.asarray(op2.G), np.asarray(op1.G))
    nodes, d = _random_case(m1, 3, rng)
    s1, s2 = jsq.deform(op1, nodes, d), jsq.deform(op2, nodes, d)
    assert rel_err(s2.forces, 1.5 * np.asarray(s1.forces)) <= 1e-12
    assert rel_err(s2.displacement, s1.displacement) <= 1e-12


# ----------------------------------------------------------------------------- tracing
def test_deform_does_not_retrace():
    mesh, op = mesh_of("rectangle"), op_of("rectangle", "sparse")
    rng = np.random.default_rng(8)
    b = mesh.boundary
    jsq.deform(op, b[[0, 7, 13]], 1e-3 * rng.standard_normal((3, 2)))
    size = bordered._deform._cache_size()
    traces = []

    def listener(event, duration, **kw):
        if event == "/jax/core/compile/jaxpr_trace_duration" and "_deform" in str(kw.get("fun_name", "")):
            traces.append(kw.get("fun_name"))

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        for _ in range(3):   # new values and new nodes (same s): no new trace or compile
            nodes = rng.choice(b, 3, replace=False)
            jsq.deform(op, nodes, 1e-3 * rng.standard_normal((3, 2)))
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert bordered._deform._cache_size() == size
    assert traces == []
    # sanity: a new s (used nowhere else) does trace, so the listener would see a retrace
    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        jsq.deform(op, b[:11], np.zeros((11, 2)))
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert bordered._deform._cache_size() == size + 1
    assert len(traces) >= 1


def test_field_displacement_eager_equals_traced():
    """Eagerly the full field is the host solve plus the rigid modes in numpy; under jit it
    goes through the callback. Same numbers."""
    from jaxsqueeze.mechanics.operator import field_displacement
    op = op_of("annulus", "sparse")
    rng = np.random.default_rng(5)
    f_hat = jnp.asarray(rng.standard_normal(2 * op.m))
    g = jnp.asarray(rng.standard_normal(3))
    eager = field_displacement(op, f_hat, g)
    traced = jax.jit(lambda f, gg: field_displacement(op, f, gg))(f_hat, g)
    assert eager.shape == (mesh_of("annulus").n, 2)
    np.testing.assert_allclose(eager, traced, rtol=0, atol=1e-13 * float(jnp.abs(traced).max()))


def test_operator_builds_compile_only_the_element_kernel():
    """Operators of objects of new sizes (a mesh and a band) compile at most the jitted element
    kernel (for a new triangle count): their host arrays reach the device as they are, not
    through ``jnp.asarray`` and eager ``jnp`` calls, which compiled a small program per shape
    (about a dozen, 0.3 s, on every first squeeze of an object of a new size)."""
    from jaxsqueeze.geometry import curves
    from jaxsqueeze.mechanics.band import Band, band_compliance
    with compiles() as compiled:
        op = fem.compliance(shapes.polygon(L_SHAPE, max_edge=0.0137), MAT, "sparse")   # sizes no other test builds
        band = band_compliance(Band.from_function(curves.circle(0.03), 37), 1e9)
    assert len(compiled) <= 1
    for o in (op, band):
        assert all(isinstance(a, jax.Array) for a in (o.points, o.normals, o.G, o.N, o.length, o.stiffness, o.nodes))
        assert o.G.dtype == o.N.dtype == o.points.dtype == o.length.dtype == jnp.float64 and o.nodes.dtype == jnp.int64
        np.testing.assert_array_equal(o.N, fem.rigid_modes(o.points))
    assert float(op.stiffness) == MAT.E * MAT.thickness


def test_stresses_of_a_new_mesh_compile_one_program_each():
    """fem.element_stress and fem.von_mises of a mesh of a new size (as the CLI's plots, export
    and summary call them on a host displacement) compile one program each: eagerly, the
    conversions, the scaling by E and von Mises's arithmetic compiled about a dozen small
    programs (0.2 s of every `jaxsqueeze run`). The values are those of the formulas."""
    mesh = shapes.polygon(L_SHAPE, max_edge=0.0173)          # a size no other test builds
    u = 1e-3 * np.stack([np.sin(7 * mesh.points[:, 1]), np.cos(5 * mesh.points[:, 0])], axis=1)
    with compiles() as compiled:
        sig = fem.element_stress(mesh, MAT, u)
        vm = np.asarray(fem.von_mises(np.asarray(sig)))
    assert len(compiled) == 2
    sxx, syy, txy = np.asarray(sig).T
    np.testing.assert_allclose(vm, np.sqrt(sxx ** 2 - sxx * syy + syy ** 2 + 3 * txy ** 2), rtol=1e-12)
    assert np.all(vm > 0)
