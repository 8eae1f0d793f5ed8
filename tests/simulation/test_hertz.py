"""Physics oracle: a disk squeezed by two round tips against plane-stress Hertz line contact.

Johnson, Contact Mechanics, §5.6: a² = 4 P R* / (π E) with P the load per unit thickness,
1/R* = 1/R + 1/r (rigid tips), and the pressure p(x) = p0 √(1 − x²/a²), p0 = 2P/(πa).
Depth 1 mm on a 100 mm disk (1 % strain) keeps a/R* ≈ 0.13, where Hertz applies.
Away from the contacts the stress field is the Brazilian disk's (Timoshenko & Goodier, §41).
"""
import numpy as np
import pytest

import jaxsqueeze as jsq

R, r, E, h = 0.05, 0.02, 1e5, 0.0254


@pytest.fixture(scope="module")
def disk():
    return jsq.shapes.disk(R, 0.004, refine_near=[[0, -R], [0, R]], refine_edge=0.0003, refine_radius=0.008)


def squeeze(disk, model):
    nb = lambda xy: jsq.scene.nearest_boundary_node(disk, xy)  # noqa: E731
    scene = jsq.Scene(mesh=disk, material=jsq.Material(E, 0.3, h), fingers=jsq.Fingers(radius=r),
                      grip=(nb([0, -R]), nb([0, R])), friction=1.0, depth=0.001, friction_model=model,
                      settings=jsq.Settings(capacity=96, step=0.001 / 20))
    res = jsq.squeeze(scene)
    assert res.outcome == jsq.Status.SUCCESS
    return res


def contact_on_finger1(disk, res):
    F = np.asarray(res.forces[-1])
    on = (np.asarray(res.modes[-1]) > 0) & (np.asarray(res.finger[-1]) == 0)
    x = disk.points[disk.boundary][:, 0] + np.asarray(res.boundary_displacement[-1])[:, 0]
    P = F[on].sum(0)[1] / h                         # load per unit thickness [N/m]
    return F, on, x, P


@pytest.fixture(scope="module")
def frictionless(disk):
    return squeeze(disk, "frictionless")


def test_contact_width_matches_hertz(disk, frictionless):
    F, on, x, P = contact_on_finger1(disk, frictionless)
    a = np.sqrt(4 * P * (1 / (1 / R + 1 / r)) / (np.pi * E))
    bottom = disk.points[disk.boundary][:, 1] < 0
    inside = np.abs(x[on]).max()                               # outermost contact node
    outside = np.abs(x[bottom & ~on & (np.abs(x) < 4 * a)]).min()  # first free node
    print(f"Hertz half-width {a * 1e3:.4f} mm, contact bracket [{inside * 1e3:.4f}, {outside * 1e3:.4f}] mm")
    assert inside <= a <= outside
    assert outside - inside < 1.5 * np.diff(np.sort(x[on])).max()


def test_pressure_profile_is_semi_elliptic(disk, frictionless):
    F, on, x, P = contact_on_finger1(disk, frictionless)
    a = np.sqrt(4 * P * (1 / (1 / R + 1 / r)) / (np.pi * E))
    order = np.argsort(x[on])
    xs, f = x[on][order], np.linalg.norm(F[on], axis=1)[order]
    edges = np.concatenate([[xs[0] - (xs[1] - xs[0]) / 2], (xs[1:] + xs[:-1]) / 2, [xs[-1] + (xs[-1] - xs[-2]) / 2]])
    p = f / np.diff(edges) / h
    p0 = 2 * P / (np.pi * a)
    inner = np.abs(xs) < 0.7 * a
    err = np.abs(p[inner] - p0 * np.sqrt(1 - xs[inner] ** 2 / a**2)).max() / p0
    print(f"pressure vs semi-ellipse: max error {err:.3%} of p0 over |x| < 0.7a ({inner.sum()} nodes)")
    assert inner.sum() >= 7
    assert err < 0.08


def test_full_stick_changes_the_load_by_under_one_percent(disk, frictionless):
    P_free = contact_on_finger1(disk, frictionless)[3]
    P_stick = contact_on_finger1(disk, squeeze(disk, "stick"))[3]
    print(f"adhesive correction to the load: {P_stick / P_free - 1:.3%}")
    assert 0 < P_stick / P_free - 1 < 0.01


def brazilian_disk(p, P):
    """Plane stress (k, 2, 2) [Pa] at points p (k, 2) of a disk of radius R under two opposite
    point loads P [N/m] at (0, ∓R) (Timoshenko & Goodier, Theory of Elasticity, §41): the two
    Flamant radial fields σ_ρ = −2P cos θ / (π ρ) plus a uniform tension P / (π R) that frees
    the rim. At the centre σ_xx = 2P/(πD), σ_yy = −6P/(πD)."""
    out = np.broadcast_to(np.eye(2) * P / (np.pi * R), (len(p), 2, 2)).copy()
    for at, inward in (((0, -R), (0, 1)), ((0, R), (0, -1))):
        d = p - np.array(at)
        rho = np.linalg.norm(d, axis=1)
        e = d / rho[:, None]
        out += (-2 * P / np.pi * (e @ np.array(inward)) / rho)[:, None, None] * e[:, :, None] * e[:, None, :]
    return out


def test_stress_inside_is_the_brazilian_disks(disk, frictionless):
    """views.row_stress of the squeezed disk against the point-load solution, over the
    triangles within 0.4 R of the centre (the contacts, 2 mm wide, are 30 mm away; St Venant):
    area-weighted means of σ_xx, σ_yy, τ_xy within 1 % of the centre's σ0 = 6P/(πD), the rms
    error within 3 % and the largest within 12 % (linear triangles have constant stress, 4 mm
    edges here)."""
    from jaxsqueeze.post import views

    scene = jsq.Scene(mesh=disk, material=jsq.Material(E, 0.3, h), fingers=jsq.Fingers(radius=r),
                      grip=frictionless.grip, friction=1.0, depth=0.001, friction_model="frictionless")
    P = contact_on_finger1(disk, frictionless)[3]
    sig = views.row_stress(frictionless, scene)
    p = (disk.points + disk.offset)[disk.triangles]
    c = p.mean(axis=1)
    area = 0.5 * np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    ex = brazilian_disk(c, P)
    ex = np.c_[ex[:, 0, 0], ex[:, 1, 1], ex[:, 0, 1]]
    s0 = 6 * P / (np.pi * 2 * R)
    m = np.linalg.norm(c, axis=1) < 0.4 * R
    a = area[m] / area[m].sum()
    mean_err = np.abs(a @ (sig[m] - ex[m])).max() / s0
    rms = np.sqrt(a @ ((sig[m] - ex[m]) ** 2).mean(axis=1)) / s0
    worst = np.abs(sig[m] - ex[m]).max() / s0
    print(f"Brazilian disk, {m.sum()} triangles within 0.4 R: mean error {mean_err:.2%}, rms {rms:.2%}, "
          f"largest {worst:.2%} of 6P/(pi D) = {s0:.1f} Pa")
    assert m.sum() > 100 and mean_err < 0.01 and rms < 0.03 and worst < 0.12
