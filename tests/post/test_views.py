"""Views rebuild rows from what the engine recorded (issue 9: the rigid part g of every row is in
the result, so no view refits it)."""
import os

import numpy as np
import pytest

import jaxsqueeze as jsq
from jaxsqueeze.post import views
from physics import contact_work, nearest, stress_energy, symmetric_square


@pytest.fixture(scope="module")
def offset():
    """An off-centre grip on the square (the object turns), squeezed once."""
    mesh = symmetric_square(0.1, 0.01)
    scene = jsq.Scene(mesh=mesh, material=jsq.Material(E=1e5, nu=0.3, thickness=0.0254),
                      fingers=jsq.Fingers(radius=0.01), grip=(nearest(mesh, (-0.01, -0.05)), nearest(mesh, (0.01, 0.05))),
                      friction=0.5, depth=0.01)
    op = scene.operator()
    return scene, op, jsq.squeeze(scene, op, throw=True)


def test_row_displacement_uses_the_recorded_rigid_part(offset):
    """The full field rebuilt at the final row equals the engine's own final field, on an
    off-centre grip (a real rigid rotation)."""
    scene, op, res = offset
    assert abs(float(res.rigid[-1][2])) > 1e-4                 # the object turned
    u = views.row_displacement(res, op, -1)
    ref = np.asarray(res.displacement)
    np.testing.assert_allclose(u, ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    # an earlier row: its boundary part is the recorded boundary displacement
    k = len(res.depth) // 2
    uk = views.row_displacement(res, op, k)
    bd = np.asarray(res.boundary_displacement[k])
    np.testing.assert_allclose(uk[np.asarray(res.nodes)], bd, rtol=0, atol=1e-10 * np.abs(bd).max())


def test_stress_energy_is_the_work_of_the_contact_forces_in_views_exports_and_plots(offset, tmp_path):
    """views.row_stress at the final row and at a middle one (rebuilt through the operator):
    the strain energy of the stresses (physics.stress_energy, textbook compliance) equals
    ½ Σ F·u of the row's contact forces (at the final row also jsq.quality.squeeze_work).
    The exports carry the same stresses as cell data, only when given the scene (its material):
    at every row with ``op``, NaN where the full field is unknown without it, and in the final
    VTU. plot_deformed(stress=...) adds a colour bar; a mesh (no material) and an unknown name
    are refused."""
    import matplotlib
    import meshio
    matplotlib.use("Agg")
    from jaxsqueeze.mechanics import fem
    from jaxsqueeze.post import export, plots

    scene, op, res = offset
    k = len(res.depth) // 2
    for row in (-1, k):
        sig = views.row_stress(res, scene, row)
        assert abs(stress_energy(scene.mesh, scene.material, sig) - contact_work(res, row)) <= 1e-9 * contact_work(res, row)
    last = views.row_stress(res, scene)
    assert abs(stress_energy(scene.mesh, scene.material, last) - float(jsq.quality.squeeze_work(res))) <= 1e-9 * np.abs(
        float(jsq.quality.squeeze_work(res)))
    vm = np.asarray(fem.von_mises(views.row_stress(res, scene, k)))
    with meshio.xdmf.TimeSeriesReader(export.write_paraview(tmp_path / "op", res, scene, op)) as r:
        r.read_points_cells()
        cells = [r.read_data(i)[2] for i in range(r.num_steps)]
    assert all(np.all(np.isfinite(c["von_mises"][0])) for c in cells)
    np.testing.assert_allclose(cells[k]["von_mises"][0], vm, rtol=1e-12, atol=0)
    with meshio.xdmf.TimeSeriesReader(export.write_paraview(tmp_path / "no_op", res, scene)) as r:
        r.read_points_cells()
        cells = [r.read_data(i)[2] for i in range(r.num_steps)]
    assert all(np.all(np.isnan(c["stress_xx"][0])) for c in cells[:-1])
    np.testing.assert_allclose(cells[-1]["stress_xx"][0], last[:, 0], rtol=1e-12, atol=0)
    vtu = meshio.read(export.write_final_vtu(tmp_path / "final.vtu", res, scene))
    np.testing.assert_allclose(vtu.cell_data["stress_xy"][0], last[:, 2], rtol=1e-12, atol=0)
    assert not meshio.read(export.write_final_vtu(tmp_path / "mesh.vtu", res, scene.mesh)).cell_data
    for row in (-1, k):
        fig = plots.plot_deformed(res, scene, row, stress="von_mises", details=False)
        assert [a.get_ylabel() for a in fig.axes][-1] == "von Mises stress [Pa]"
        assert fig.axes[0].get_title().startswith("von Mises stress at d = ")
    with pytest.raises(TypeError, match="stress= needs its material"):
        plots.plot_deformed(res, scene.mesh, stress="xx")
    with pytest.raises(ValueError, match="expected one of"):
        plots.plot_deformed(res, scene, stress="mises")


def test_exports_and_summary_refuse_or_survive_what_a_hostile_caller_passes(tmp_path):
    """Output paths that are not paths ('' wrote into the working directory, None/3/bytes failed
    inside os), a VTU name meshio cannot read the format of, an XDMF name with a folder in it,
    and a mesh or scene of another object (it failed in numpy broadcasting): errors that say
    what was wrong. A result whose first row has no finite contact angle (a squeeze refused at
    its first solve) has no grip distance of its own (null in valid JSON); given the scene, the
    summary takes the grip nodes' distance on the object."""
    import dataclasses
    import json

    import matplotlib
    import pytest
    matplotlib.use("Agg")
    from jaxsqueeze.post import export, plots

    mesh = symmetric_square(0.1, 0.01)
    scene = jsq.Scene(mesh=mesh, material=jsq.Material(E=1e5, nu=0.3, thickness=0.0254),
                      fingers=jsq.Fingers(radius=0.01), grip=(nearest(mesh, (0, -0.05)), nearest(mesh, (0, 0.05))),
                      friction=0.5, depth=0.01)
    res = jsq.squeeze(scene)
    for bad in ("", None, 3, b"x"):
        with pytest.raises(TypeError, match="expected a non-empty path"):
            export.write_paraview(bad, res, mesh)
        with pytest.raises(TypeError, match="expected a non-empty path"):
            plots.save_all(res, scene, bad)
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="cannot be created"):
        export.write_paraview(tmp_path / "file" / "sub", res, mesh)
    for name in ("final", "final.xyz", str(tmp_path)):
        with pytest.raises(ValueError, match="expected a file name ending in .vtu"):
            export.write_final_vtu(tmp_path / name, res, mesh)
    with pytest.raises(ValueError, match="name = 'a/b': expected a file name without a folder"):
        export.write_paraview(tmp_path, res, mesh, name="a/b")
    other = jsq.shapes.rectangle(0.1, 0.1, max_edge=0.02)
    with pytest.raises(ValueError, match="the mesh has 20 boundary nodes but the result"):
        export.write_paraview(tmp_path, res, other)
    with pytest.raises(ValueError, match="the scene has 20 boundary nodes"):
        plots.save_all(res, scene.replace(mesh=other, grip=(0, 5)), tmp_path / "p")
    assert export.write_final_vtu(tmp_path / "f.vtu", res, mesh).endswith("f.vtu")
    assert export.write_final_vtu(tmp_path / "s.vtu", res, scene).endswith("s.vtu")      # the scene's mesh
    assert export.write_paraview(tmp_path / "pv", res, scene).endswith("squeeze.xdmf")
    for bad in (-1.0, 0.0, float("nan"), "0.1"):          # (a negative one gave negative relative depths)
        with pytest.raises(ValueError, match="grip_distance_m must be"):
            views.event_table(res, grip_distance_m=bad)
    assert views.event_table(res, grip_distance_m=0.2) == [dict(e, relative_depth=e["depth"] / 0.2)
                                                           for e in views.event_table(res)]
    blind = dataclasses.replace(res, theta=np.full_like(res.theta, np.nan))
    s = views.summary(blind)
    assert s["grip_distance"] is None and s["relative_depth"] is None
    json.dumps(s, allow_nan=False)
    s = views.summary(blind, scene)             # with the scene: the grip nodes' distance on the object
    assert s["grip_distance"] == pytest.approx(0.1, rel=1e-12) and s["relative_depth"] is not None
    json.dumps(s, allow_nan=False)


def test_views_read_the_grip_and_fingers_from_the_result(offset):
    """The grip distance is that of the grip nodes before the squeeze, also for a
    ``history=False`` result (whose first row is the end of the squeeze: it read 0.0911 m there
    instead of 0.1005 m); the summary names the grip the squeeze used (a placement's first
    contacts; it read scene.grip, None for a placed scene); fingers are 0 and 1 in its JSON
    keys, as in the arrays (event tables: test_symmetric_push_is_resisted_equally_by_both_fingers)."""
    scene, op, res = offset
    P = np.asarray(scene.mesh.points)
    D0 = float(np.linalg.norm(P[scene.grip[1]] - P[scene.grip[0]]))
    assert views.grip_distance(res) == pytest.approx(D0, rel=1e-12)
    short = jsq.squeeze(scene, op, history=False)
    assert float(short.depth[0]) > 0                              # row 0 is not the first touch
    np.testing.assert_allclose(views.grip_positions(short), views.grip_positions(res), rtol=0, atol=1e-12)
    assert views.summary(short)["relative_depth"] == pytest.approx(0.01 / D0, rel=1e-12)
    placed = scene.replace(grip=None, placement=jsq.Placement(s=scene.arc_length(scene.grip)))
    s = views.summary(res, placed)
    assert s["grip_nodes"] == [int(g) for g in scene.grip]
    assert set(s["total_force"]) == set(s["contact_regions"]) == {"finger0", "finger1"}
    np.testing.assert_allclose(s["total_force"]["finger1"], np.asarray(res.total_force)[-1, 1], rtol=1e-12)


def test_a_placed_finger_that_cannot_touch_is_summarised_plotted_and_exported(offset, tmp_path):
    """Placed 10 mm apart along one edge, a finger cannot touch (INFEASIBLE_GRIP, margin −π);
    row 0 records where the tips were placed, not a touch. The grip positions read from it put
    a grip node 31 mm from its place, so save_all, summary(res, scene) and the exports refused
    the result with its own scene, and summary(res) said a grip distance of 29 mm (the nodes
    are 90 mm apart). No position is read from such a result now (NaN; the summary with its
    scene takes the nodes' distance)."""
    from jaxsqueeze.post import export, plots
    scene, op, _ = offset
    placed = scene.replace(grip=None, placement=jsq.Placement(s=(0.0, 0.01)))
    res = jsq.squeeze(placed, op)
    assert res.status == jsq.Status.INFEASIBLE_GRIP and float(res.margin) == pytest.approx(-np.pi)
    assert np.all(np.isnan(views.grip_positions(res))) and views.summary(res)["grip_distance"] is None
    # no node is in contact (row 0 listed both placed nodes as sticking, and the plot drew them);
    # without a force the cones have no margin (it read atan μ, a force on the cone axis)
    assert not np.any(np.asarray(res.modes) > 0) and views.contact_regions(res) == [[], []]
    from jaxsqueeze.post import cones
    with pytest.raises(ValueError, match="no contact with a finite force"):
        cones.grasp_stability(res, placed)
    P = np.asarray(scene.mesh.points)
    s = views.summary(res, placed)
    assert s["status"] == "INFEASIBLE_GRIP"
    assert s["grip_distance"] == pytest.approx(float(np.linalg.norm(np.subtract(*P[np.asarray(res.grip)]))), rel=1e-12)
    assert s["stress"]["max_von_mises"] == 0.0                # nothing touched: no deformation, no stress
    written = plots.save_all(res, placed, tmp_path / "plots")
    assert len(written) == 5 and all(os.path.getsize(p) > 0 for p in written.values())
    # its depths in mm, not "nan %" of a grip distance it never had; empty panels say why
    title = plots.plot_deformed(res, placed.mesh).axes[0].get_title()
    assert "nan" not in title and title.startswith("Deformed object at d = 0.00 mm")
    fig = plots.plot_force_profile(res, mesh=placed.mesh)
    assert [t.get_text() for t in fig.legends[0].get_texts()][0] == "d = 0.00 mm"
    assert sum(t.get_text() == "no contact" for ax in fig.axes for t in ax.texts) == 4
    export.write_final_vtu(tmp_path / "final.vtu", res, placed)
    export.write_paraview(tmp_path, res, placed, op)
    assert os.path.getsize(tmp_path / "final.vtu") > 0 and os.path.getsize(tmp_path / "squeeze.h5") > 0


def test_cones_of_a_grip_outside_its_cones_and_of_a_short_history_are_refused(offset):
    """A grip outside its cones (INFEASIBLE_GRIP, margin −5.6°) carries no force in any row:
    grasp_stability called it "neutral" with cone margins of +atan μ (the zero force read as
    along the axis). A ``history=False`` result, whose first row is the end of the squeeze,
    gave rotations and margin changes measured from there ("neutral", toward 0)."""
    from jaxsqueeze.post import cones
    scene, op, res = offset
    placed = scene.replace(grip=None, placement=jsq.Placement(s=scene.arc_length(scene.grip)), friction=0.1)
    bad = jsq.squeeze(placed, op)
    assert bad.status == jsq.Status.INFEASIBLE_GRIP and -0.2 < float(bad.margin) < 0
    assert np.all(np.isnan(cones.cone_axes(bad, placed).margin))
    with pytest.raises(ValueError, match="no contact with a finite force"):
        cones.grasp_stability(bad, placed)
    assert cones.grasp_stability(res, scene).label in ("stabilizing", "breaking", "neutral")
    short = jsq.squeeze(scene, op, history=False)
    with pytest.raises(ValueError, match=r"first row is at depth 0.01 m, not the touch .* history=False"):
        cones.grasp_stability(short, scene)


def test_plots_and_summary_say_what_a_result_cannot(offset):
    """A frictionless scene's sliding contacts are all labelled slip+ (their direction is not
    tracked): plot_deformed drew a slip arrow at each, all one way. An INVALID_INPUT result's
    summary said "result.invalid names it" and named nothing."""
    import dataclasses
    from jaxsqueeze.post import plots
    from jaxsqueeze.simulation.validate import RULES
    scene, op, res = offset
    modes = np.asarray(res.modes).copy()
    modes[-1][modes[-1] > 0] = 2                        # its two contacts, sliding
    res = dataclasses.replace(res, modes=modes)

    def quivers(obj):
        ax = plots.plot_deformed(res, obj, details=False).axes[0]
        return [c for c in ax.collections if type(c).__name__ == "Quiver"], ax.get_legend_handles_labels()[1]
    assert quivers(scene)[0] and quivers(scene.mesh)[0]
    q, labels = quivers(scene.replace(friction_model="frictionless"))
    assert not q and any(t.endswith("frictionless") for t in labels)
    bad = dataclasses.replace(res, status=np.asarray(jsq.Status.INVALID_INPUT), invalid=np.asarray(4))
    s = views.summary(bad)
    assert s["invalid"] == dict(index=4, field=RULES[4].field, expected=RULES[4].requirement, fix=RULES[4].fix)
    assert "invalid" not in views.summary(res)


def test_views_plots_and_exports_refuse_another_object_of_the_same_node_counts(offset, tmp_path):
    """A result drawn on another mesh with the same node counts (the square scaled 2x) gave a
    picture of fingertips inside the object and no error; plot_deformed, the force profiles,
    the summary and row_displacement failed on a mesh of other counts with numpy's broadcast
    or index errors. Every one now compares the grip nodes with the result's (plot_deformed
    takes a scene, as save_all does)."""
    import matplotlib
    matplotlib.use("Agg")
    from jaxsqueeze.post import export, plots

    scene, op, res = offset
    big = scene.replace(mesh=symmetric_square(0.2, 0.02))
    assert big.mesh.n == scene.mesh.n and big.mesh.m == scene.mesh.m
    disk = scene.replace(mesh=jsq.shapes.disk(0.05, 0.01), grip=(0, 5))
    said = r"grip nodes \[\d+, \d+\] lie 0.05\d* m from where the result had them: pass the"
    for call in (lambda o: plots.plot_deformed(res, o), lambda o: plots.plot_force_profile(res, mesh=o.mesh),
                 lambda o: views.force_profile(res, mesh=o.mesh), lambda o: views.summary(res, o),
                 lambda o: export.write_paraview(tmp_path, res, o.mesh), lambda o: plots.save_all(res, o, tmp_path)):
        with pytest.raises(ValueError, match=said):
            call(big)
        with pytest.raises(ValueError, match="boundary nodes but the result"):
            call(disk)
    with pytest.raises(ValueError, match=r"operator's grip nodes .* lie"):
        views.row_displacement(res, big.operator(), -1)
    assert plots.plot_deformed(res, scene) is not None                  # a scene gives its mesh
    for row in (5.7, "1", True):                                         # row 5.7 drew row 5
        with pytest.raises(TypeError, match="expected an integer row index"):
            plots.plot_deformed(res, scene, row=row)
    assert views.row_index(res, np.int64(-1)) == len(res.depth) - 1
    assert views.summary(res, scene)["status"] == "SUCCESS"
    # a zoom of the wrong form failed with "'int' object is not subscriptable", a NaN one drew
    # nothing; a displacement of the wrong shape failed in numpy's broadcasting; rows=[] drew
    # an empty figure; default_rows(res, 0) returned no rows
    for zoom in (-1, float("nan"), ((0, 1), (2, 1)), ((0, 0), -0.01), ((0, float("nan")), 0.01), "ab", (1, 2, 3)):
        with pytest.raises(ValueError, match="expected .*xmin, xmax.* with min < max, or a centre"):
            plots.plot_deformed(res, scene, zoom=zoom)
    x, y = np.asarray(res.centres[-1][0], float) + np.asarray(scene.mesh.offset)
    for zoom in (((x - 0.02) * 1e3, (x + 0.02) * 1e3), ((y - 0.02) * 1e3, (y + 0.02) * 1e3)), ((x, y), 0.02):
        ax = plots.plot_deformed(res, scene, zoom=zoom).axes[0]
        np.testing.assert_allclose(ax.get_xlim(), [(x - 0.02) * 1e3, (x + 0.02) * 1e3])
    for u in (np.zeros((3, 2)), np.full(np.shape(scene.mesh.points), np.nan)):
        with pytest.raises(ValueError, match=r"displacement must be finite \(n, 2\)"):
            plots.plot_deformed(res, scene, displacement=u)
    with pytest.raises(ValueError, match=r"displacement must be real numbers \[m\]; got dtype complex128"):
        plots.plot_deformed(res, scene, displacement=np.zeros(np.shape(scene.mesh.points)) + 1e-3j)
    b0 = int(scene.mesh.boundary[0])
    with pytest.raises(ValueError, match=r"node indices must be integers, got 0.5 \(float64\)"):
        scene.arc_length(0.5)                                           # it was read as node 0
    assert float(scene.arc_length(b0)) == float(scene.arc_length(np.int32(b0)))
    with pytest.raises(ValueError, match="rows is empty"):
        plots.plot_force_profile(res, rows=[])
    for count in (0, -3, 1.5, True):
        with pytest.raises(ValueError, match="expected an integer >= 1"):
            plots.default_rows(res, count)
    assert plots.default_rows(res, 1) == [len(res.depth) - 1]


def test_cone_axes_refuse_a_friction_no_scene_could_have(offset):
    """cone_axes(friction=-1) or NaN gave margins arctan(-1) - angle without a word; a given
    friction replaces the scene's in the margins and nowhere else."""
    from jaxsqueeze.post import cones
    scene, op, res = offset
    for bad in (-1, float("nan"), float("inf"), "0.5", 0.5 + 1j, [0.5], True):
        with pytest.raises(ValueError, match="friction"):
            cones.cone_axes(res, scene, friction=bad)
    own, given = cones.cone_axes(res, scene), cones.cone_axes(res, scene, friction=0.3)
    ok = np.isfinite(own.margin)
    assert ok.sum() > 0
    np.testing.assert_allclose((own.margin - given.margin)[ok], np.arctan(0.5) - np.arctan(0.3), rtol=1e-12)
    np.testing.assert_array_equal(own.axis, given.axis)


def test_views_refuse_a_scene_operator_or_loops_the_result_was_not_computed_with(offset):
    """A scene of the same mesh and grip but another fingertip radius or depth was summarised
    as SUCCESS at 10 mm beside a target of 30 mm, with the scene's radius; an operator of the
    same object built for another E or ν rebuilt rows 0.4–4.4 mm off and exported them as exact
    fields; loops that do not add up to the boundary dropped or split contact regions."""
    scene, op, res = offset
    for other, match in ((scene.replace(fingers=jsq.Fingers(radius=0.002)), "fingertip radius is 0.002 m but"),
                         (scene.replace(depth=0.03), r"reached depth 0.01 m \(SUCCESS\) but the scene asks for 0.03")):
        with pytest.raises(ValueError, match=match):
            views.summary(res, other)
    assert views.summary(res, scene)["status"] == "SUCCESS"
    for mat in (jsq.Material(E=2e5, nu=0.3, thickness=0.0254), jsq.Material(E=1e5, nu=0.45, thickness=0.0254)):
        with pytest.raises(ValueError, match="built for another material"):
            views.row_displacement(res, scene.replace(material=mat).operator(), len(res.depth) // 2)
    m = np.shape(res.modes)[-1]
    for loops in ((10,), (m // 2, m - m // 2 + 1), (500,)):
        with pytest.raises(ValueError, match="adding up to the result's"):
            views.contact_regions(res, loops=loops)


def test_cones_under_full_stick_have_half_angle_pi_over_2(offset):
    """Full stick needs only pushing: the cones are half-planes (laws.grip_half_angle). The
    margins were taken with μ = 0 (every contact outside its cone, "breaking", slip at depth 0)."""
    from jaxsqueeze.post import cones
    scene, _, _ = offset
    stick = scene.replace(friction_model="stick")
    res = jsq.squeeze(stick)
    c = cones.cone_axes(res, stick)
    F, a = np.asarray(c.force[-1]), np.asarray(c.axis[-1])
    angle = np.arctan2(np.abs(F[:, 0] * a[:, 1] - F[:, 1] * a[:, 0]), np.sum(F * a, -1))
    np.testing.assert_allclose(c.margin[-1], np.pi / 2 - angle, rtol=0, atol=1e-12)
    assert np.all(c.margin[-1] > 1.0)
    assert cones.grasp_stability(res, stick).surface_slip_depth is None


def test_post_functions_name_a_wrong_kind_of_argument(offset, tmp_path):
    """A mesh where the scene belongs, arguments swapped or None, a scene where the operator
    belongs, an operator where the mesh belongs: each raised an AttributeError from inside
    ('Mesh' object has no attribute 'mesh', ...); now a TypeError that names what was expected.
    A name ending in .xdmf wrote x.xdmf.xdmf; one row given as an int failed in iteration."""
    import matplotlib
    matplotlib.use("Agg")
    from jaxsqueeze.post import cones, export, plots
    scene, op, res = offset
    for call, match in [
            (lambda: plots.save_all(res, scene.mesh, tmp_path), r"the scene .* \(the jsq.Scene\), got Mesh"),
            (lambda: views.summary(res, scene.mesh), r"\(the jsq.Scene\), got Mesh"),
            (lambda: plots.save_all(scene, res, tmp_path), "expected a squeeze result .* got Scene"),
            (lambda: views.summary(None), "expected a squeeze result .* got NoneType"),
            (lambda: views.row_displacement(res, scene), r"compliance operator \(scene.operator\(\)\)\), got Scene"),
            (lambda: export.write_paraview(tmp_path, res, scene, op=scene), "got Scene"),
            (lambda: plots.plot_deformed(res, op), "got Compliance"),
            (lambda: cones.cone_axes(res, None), "got NoneType"),
            # a switch given as text ("False" is true to Python) is refused, not read by truthiness
            (lambda: plots.plot_force_profile(res, rows=-1, degrees="False"), "degrees='False' must be True or False"),
            (lambda: plots.plot_force_profile(res, rows=-1, smooth="no"), "smooth='no' must be True or False"),
            (lambda: plots.plot_sliding_profile(res, degrees="rad"), "degrees='rad' must be True or False"),
            (lambda: plots.plot_deformed(res, scene, show_nodes="off"), "show_nodes='off' must be True or False"),
            (lambda: plots.plot_deformed(res, scene, forces=1), "forces=1 must be True or False")]:
        with pytest.raises(TypeError, match=match):
            call()
    path = export.write_paraview(tmp_path, res, scene, name="run.xdmf")
    assert path.endswith(os.sep + "run.xdmf") and os.path.exists(path)
    assert export.write_paraview(tmp_path, res, scene, name="Big.XDMF").endswith(os.sep + "Big.xdmf")
    with pytest.raises(ValueError, match="expected a file name"):
        export.write_paraview(tmp_path, res, scene, name=" ")
    assert len(plots.plot_force_profile(res, rows=-1).axes[0].lines) >= 1
    if os.path.isdir("/proc"):       # a folder that exists and takes no files, even for root
        for call in (lambda: plots.save_all(res, scene, "/proc"), lambda: export.write_paraview("/proc", res, scene)):
            with pytest.raises(ValueError, match="output folder '/proc' takes no files"):
                call()
    for call in (lambda: views.sliding_profile(res, True), lambda: views.force_profile(res, finger=True),
                 lambda: cones.grasp_stability(res, scene, tol=-1.0), lambda: cones.grasp_stability(res, scene, tol="a")):
        with pytest.raises(ValueError, match="finger must be 0|tol="):
            call()


def test_plot_options_draw_what_they_say(offset):
    """plot_force_profile(degrees=False, smooth=False) draws the nodal directions in radians
    joined by straight lines (smooth: a spline through them, the same values in degrees);
    plot_sliding_profile(degrees=False) the polar angles in radians; plot_deformed(show_nodes=False)
    leaves out the stick and slip markers."""
    import matplotlib
    matplotlib.use("Agg")
    from jaxsqueeze.post import plots
    scene, op, _ = offset
    wide = scene.replace(fingers=jsq.Fingers(radius=0.1))       # wide tips: 5 nodes each, the same program
    res = jsq.squeeze(wide, op)
    p = views.force_profile(res, -1, 0)
    assert len(p.s) >= 3
    raw = plots.plot_force_profile(res, rows=-1, degrees=False, smooth=False).axes[2].lines[0]
    np.testing.assert_allclose(raw.get_xdata(), p.s * 1e3)
    np.testing.assert_allclose(raw.get_ydata(), p.angle)
    assert plots.plot_force_profile(res, rows=-1, degrees=False).axes[2].get_ylabel() == "force direction [rad]"
    smooth = plots.plot_force_profile(res, rows=-1).axes[2].lines[0]
    xs, ys = smooth.get_xdata(), smooth.get_ydata()
    assert len(xs) > len(p.s)
    np.testing.assert_allclose(np.interp(p.s * 1e3, xs, ys), np.degrees(p.angle), atol=0.05)   # through the nodes
    sliding = [plots.plot_sliding_profile(res, degrees=d).axes[0] for d in (True, False)]
    assert sliding[1].get_ylabel() == "polar angle [rad]"
    deg, rad = (np.concatenate([c.get_segments()[0] for c in ax.collections]) for ax in sliding)
    np.testing.assert_allclose(deg[:, 1], np.degrees(rad[:, 1]))
    marked = lambda fig: [ln.get_label() for ln in fig.axes[0].lines if ln.get_label().startswith(("stick", "slip"))]  # noqa: E731
    assert marked(plots.plot_deformed(res, wide)) and not marked(plots.plot_deformed(res, wide, show_nodes=False))
