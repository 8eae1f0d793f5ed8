"""Property-based squeezes: random star-shaped polygons (convex or not), materials, grips, friction.

Every outcome either holds the per-state invariants or carries a non-success status with
advice, and a NaN never escapes: a SUCCESS result is finite everywhere. All examples share
one mesh size class (exactly ``M`` boundary nodes, no boundary Steiner points) and one static
configuration, so the squeeze compiles once for the whole run.

``JAXSQUEEZE_HYPOTHESIS_EXAMPLES`` sets the number of examples (default 60: about 3 s more than 5,
the compile is shared; 300 pass too).
"""
from __future__ import annotations

import os

import numpy as np
import pytest
import triangle
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import jaxsqueeze as jsq
from jaxsqueeze.simulation import api as grasp_mod
from jaxsqueeze.simulation.laws import CONE_SLACK
from physics import check_states

M = 40                      # boundary nodes of every random polygon
EXAMPLES = int(os.environ.get("JAXSQUEEZE_HYPOTHESIS_EXAMPLES", "60"))
SETTINGS = dict(capacity=M, max_steps=120, max_events=128)
HYP = settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
               suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def star_polygon(size, aspect, amps, phases, jitter):
    """M vertices at sorted angles with radius r(θ) = 1 + Σ a_k cos(kθ + φ_k), k = 2.. (simple:
    every ray from the origin meets the outline once), stretched by ``aspect`` and scaled to ``size``."""
    t = 2 * np.pi * (np.arange(M) + 0.45 * np.asarray(jitter)) / M
    r = 1 + sum(a * np.cos((k + 2) * t + p) for k, (a, p) in enumerate(zip(amps, phases)))
    return size * np.c_[aspect * r * np.cos(t), r * np.sin(t)] / 2


def mesh_of(outline):
    seg = np.c_[np.arange(M), (np.arange(M) + 1) % M]
    L = np.ptp(outline, axis=0).max()
    edge = np.linalg.norm(np.roll(outline, -1, 0) - outline, axis=1).mean()
    area = 1.5 * np.sqrt(3) / 4 * (edge / L) ** 2
    tri = triangle.triangulate(dict(vertices=outline / L, segments=seg), f"pq30a{area:.10f}YQ")
    mesh = jsq.Mesh.from_arrays(tri["vertices"] * L, tri["triangles"])
    assert mesh.m == M, "Triangle added boundary points"
    return mesh


shapes = st.builds(
    star_polygon,
    size=st.floats(0.02, 0.3),
    aspect=st.floats(0.6, 1.6),
    amps=st.lists(st.floats(0.0, 0.12), min_size=3, max_size=3),
    phases=st.lists(st.floats(0.0, 2 * np.pi), min_size=3, max_size=3),
    jitter=st.lists(st.floats(-1.0, 1.0), min_size=M, max_size=M),
)
materials = st.builds(jsq.Material, E=st.floats(3.0, 11.3).map(lambda x: 10.0**x),
                      nu=st.floats(-0.95, 0.5), thickness=st.floats(1e-3, 0.05))


def cone_angles(mesh, grip):
    pos = {int(v): k for k, v in enumerate(mesh.boundary)}
    i, j = grip
    seg = (mesh.points[j] - mesh.points[i]) / np.linalg.norm(mesh.points[j] - mesh.points[i])
    return np.arccos(np.clip([-mesh.normals[pos[i]] @ seg, mesh.normals[pos[j]] @ seg], -1, 1))


def judge(res, mesh, mu):
    """The property: invariants, or a non-success status with advice; never a silent NaN."""
    status = res.outcome
    assert status.advice
    arrays = [np.asarray(getattr(res, f)) for f in ("depth", "forces", "boundary_displacement", "theta", "g")]
    finite = all(np.all(np.isfinite(a)) for a in arrays)
    if status == jsq.Status.NONFINITE:
        return
    assert finite, f"{status.name} with non-finite values"
    if status == jsq.Status.SUCCESS:
        assert np.all(np.isfinite(np.asarray(res.displacement)))
    scale = np.abs(np.asarray(res.forces)).max()
    if status in (jsq.Status.NEWTON_FAILURE,) or scale == 0 or int(res.count) == 1:
        return      # a state the engine reports as unconverged, or only the force-free touch
    check_states(res, mesh, mu)


@HYP
@given(outline=shapes, material=materials, start=st.integers(0, M - 1), offset=st.integers(-3, 3),
       mu=st.floats(0.0, 1.5), radius=st.floats(0.05, 0.4), depth=st.floats(0.01, 0.12))
def test_random_squeezes_hold_invariants_or_say_why(outline, material, start, offset, mu, radius, depth):
    mesh = mesh_of(outline)
    L = np.ptp(mesh.points, axis=0).max()
    b = mesh.boundary
    grip = (int(b[start]), int(b[(start + M // 2 + offset) % M]))
    gap = np.linalg.norm(mesh.points[grip[0]] - mesh.points[grip[1]])
    scene = jsq.Scene(mesh=mesh, material=material, fingers=jsq.Fingers(radius=radius * L), grip=grip,
                      friction=mu, depth=depth * gap, settings=jsq.Settings(**SETTINGS))
    if np.any(cone_angles(mesh, grip) > np.arctan(mu) + CONE_SLACK):
        before = grasp_mod._run._cache_size()
        with pytest.raises(ValueError, match="friction cones"):
            jsq.squeeze(scene)
        assert grasp_mod._run._cache_size() == before
        print("property example: grip outside the friction cones (ValueError)")
        return
    try:
        res = jsq.squeeze(scene)
    except ValueError as e:      # a large fingertip at a concave stretch of the outline: refused, and why
        assert "grip.overlap" in str(e) and "smaller fingertip radius" in str(e), str(e)
        print("property example: the fingertip would overlap the outline (ValueError)")
        return
    print(f"property example: {res.outcome.name} at {res.final_depth / scene.depth:.0%} of the depth, "
          f"{len(res.events)} events")
    judge(res, mesh, mu)
    # forces are linear in E at fixed geometry, whatever the outcome
    twice = jsq.squeeze(scene.replace(material=jsq.Material(E=2 * material.E, nu=material.nu,
                                                             thickness=material.thickness)))
    assert twice.outcome == res.outcome and int(twice.count) == int(res.count)
    if res.outcome != jsq.Status.NONFINITE:
        np.testing.assert_allclose(np.asarray(twice.forces), 2 * np.asarray(res.forces), rtol=1e-8,
                                   atol=1e-10 * np.abs(np.asarray(res.forces)).max())


def test_one_compile_for_all_polygons():
    """Two different random polygons with M boundary nodes reuse one compiled squeeze."""
    rng = np.random.default_rng(3)
    runs = []
    for _ in range(2):
        mesh = mesh_of(star_polygon(0.1, 1.2, rng.uniform(0, 0.1, 3), rng.uniform(0, 6, 3), rng.uniform(-1, 1, M)))
        b = mesh.boundary
        scene = jsq.Scene(mesh=mesh, material=jsq.Material(1e5, 0.3, 0.01), fingers=jsq.Fingers(radius=0.01),
                          grip=(int(b[0]), int(b[M // 2])), friction=1.0, depth=0.005,
                          settings=jsq.Settings(**SETTINGS))
        runs.append(jsq.squeeze(scene))
        if len(runs) == 1:
            size = grasp_mod._run._cache_size()
    assert grasp_mod._run._cache_size() == size
