"""The command line end to end: demo, run, outputs, and bad scene files (exit status 2)."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import warnings

import meshio
import numpy as np
import pytest

import jaxsqueeze as jsq
import physics
from jaxsqueeze.io import cli, scenefile
from jaxsqueeze.post import views

ROOT = physics.ROOT

# The demo is run on a coarse mesh; the `run` scene below builds the very same mesh (same
# max_edge, refine_edge and refine_radius), so both share one compiled squeeze.
COARSE = ["--max-edge", "0.02", "--refine-edge", "0.003"]

SCENE = """\
title = "coarse foam square"

[object]
shape = "rectangle"
width = 0.1
height = 0.1
max_edge = 0.02
refine_edge = 0.003
refine_radius = 0.012

[material]
E = 1.0e5
nu = 0.3
thickness = 0.0254

[fingers]
radius = 0.01

[grip]
points = [[-0.005, -0.05], [0.005, 0.05]]

[squeeze]
depth = 0.01
friction = 0.3

[accuracy]
capacity = 64
max_steps = 400
precision = "float64"
"""

OUTPUTS = ["summary.json", "deformed.png", "stress.png", "force_profile.png", "sliding_profile.png", "events.png",
           "squeeze.xdmf", "squeeze.h5", "final.vtu"]


@pytest.fixture(scope="module")
def demo_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "demo"
    rc = cli.main(["demo", "--out", str(out), "-q", *COARSE])
    assert rc == 0
    return out


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    base = tmp_path_factory.mktemp("run")
    path = base / "scene.toml"
    path.write_text(SCENE)
    out = base / "out"
    rc = cli.main(["run", str(path), "--out", str(out), "-q"])
    assert rc == 0
    return path, out


def _check_outputs(out):
    for name in OUTPUTS:
        p = out / name
        assert p.is_file(), f"missing {name}"
        assert p.stat().st_size > 0, f"empty {name}"
    for name in OUTPUTS:
        if name.endswith(".png"):
            assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_demo_writes_everything(demo_dir):
    _check_outputs(demo_dir)
    cli._check_out(str(demo_dir))       # a second run may replace it (stress.png was refused: make demo twice failed)
    s = json.loads((demo_dir / "summary.json").read_text())
    assert s["status"] == "SUCCESS"
    assert s["final_depth"] == pytest.approx(0.015)
    assert set(s["timings"]) >= {"meshing", "operator", "squeeze", "total"}
    assert s["n_events"] == len(s["events"]) and s["n_events"] > 0
    assert all(ev["phase"] == "squeeze" and ev["relative_depth"] > 0 for ev in s["events"])       # no adversary


def test_run_matches_python(run_dir):
    path, out = run_dir
    _check_outputs(out)
    cli._check_out(str(out))
    s = json.loads((out / "summary.json").read_text())
    spec = scenefile.load(path)
    res = jsq.squeeze(spec.scene)
    assert s["status"] == res.outcome.name
    assert s["final_depth"] == pytest.approx(res.final_depth, rel=1e-12)
    assert s["n_events"] == len(res.events)
    assert s["event_sequence"] == "".join(r[2] for r in res.events.rows())
    assert s["rows"] == len(res.depth)
    tf = res.total_force[-1]
    for f in (0, 1):
        np.testing.assert_allclose(s["total_force"][f"finger{f}"], tf[f], rtol=1e-9, atol=1e-12)
        reg = views.contact_regions(res)[f]
        assert s["contact_regions"][f"finger{f}"]["n_stick"] == sum(r["n_stick"] for r in reg)


def test_a_float32_scene_file_runs_in_float32_from_the_command_line(run_dir, tmp_path):
    """README: ``precision = "float32"`` in [accuracy], and the CLI sets JAX's precision from it
    (a fresh process, as a user runs it): the float64 run's squeeze to float32's accuracy,
    with the same events, and not the float64 numbers to the last digits. The process keeps
    its compiled squeeze in the persistent cache, on by default in the CLI
    (``$JAXSQUEEZE_CACHE``, here without the test run's shared cache)."""
    path = tmp_path / "scene32.toml"
    path.write_text(SCENE.replace('precision = "float64"', 'precision = "float32"'))
    out = tmp_path / "out32"
    env = {k: v for k, v in os.environ.items() if k not in ("JAX_ENABLE_X64", "JAXSQUEEZE_NO_CACHE",
                                                            "JAX_COMPILATION_CACHE_DIR", "JAX_COMPILATION_CACHE_MAX_SIZE")}
    env["JAXSQUEEZE_CACHE"] = str(tmp_path / "cache")
    r = subprocess.run([sys.executable, "-m", "jaxsqueeze", "run", str(path), "--out", str(out), "--no-plots", "-q"],
                       capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    assert any((tmp_path / "cache").iterdir()), "the CLI wrote nothing to its compilation cache"
    s32, s64 = (json.loads((o / "summary.json").read_text()) for o in (out, run_dir[1]))
    assert (s32["precision"], s64["precision"]) == ("float32", "float64")
    assert s32["status"] == s64["status"] == "SUCCESS" and s32["event_sequence"] == s64["event_sequence"]
    F32, F64 = (np.array([s["total_force"][f"finger{f}"] for f in (0, 1)]) for s in (s32, s64))
    scale = np.abs(F64).max()
    assert 1e-12 * scale < np.abs(F32 - F64).max() < 1e-4 * scale


def test_no_cache_keeps_the_command_line_off_the_compilation_cache(run_dir, tmp_path, monkeypatch):
    """``--no-cache`` (and ``JAXSQUEEZE_NO_CACHE``, which the tests set): the CLI does not turn
    the persistent compilation cache on; without either it does, once per command."""
    from jaxsqueeze import compile_cache
    calls = []
    monkeypatch.setattr(compile_cache, "enable", lambda *a, **kw: calls.append(a))
    monkeypatch.delenv("JAXSQUEEZE_NO_CACHE")
    args = ["run", str(run_dir[0]), "--out", str(tmp_path / "o"), "--no-plots", "-q"]
    assert cli.main(args + ["--no-cache"]) == 0 and calls == []
    assert cli.main(args) == 0 and calls == [()]
    monkeypatch.setenv("JAXSQUEEZE_NO_CACHE", "1")
    assert cli.main(args) == 0 and calls == [()]


def test_xdmf_reads_back(run_dir):
    path, out = run_dir
    spec = scenefile.load(path)
    mesh = spec.scene.mesh
    s = json.loads((out / "summary.json").read_text())
    with meshio.xdmf.TimeSeriesReader(str(out / "squeeze.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        assert points.shape == (mesh.n, 3)
        np.testing.assert_allclose(points[:, :2], mesh.points + mesh.offset)
        assert reader.num_steps == s["rows"]
        depths = []
        for k in range(reader.num_steps):
            t, pd, cd = reader.read_data(k)
            assert t == k
            # stresses per triangle: their strain energy is the work of the row's contact forces
            sig = np.c_[cd["stress_xx"][0], cd["stress_yy"][0], cd["stress_xy"][0]]
            assert sig.shape == (len(mesh.triangles), 3) and cd["von_mises"][0].shape == (len(mesh.triangles),)
            on = pd["mode"] > 0
            work = 0.5 * np.sum(pd["contact_force"][on] * pd["displacement"][on])
            assert abs(physics.stress_energy(mesh, spec.scene.material, sig) - work) <= 1e-9 * work + 1e-30
            for name in ("displacement", "boundary_displacement", "contact_force"):
                assert pd[name].shape == (mesh.n, 3)
                assert np.all(pd[name][:, 2] == 0)
            for name in ("mode", "finger", "full_field", "depth"):
                assert pd[name].shape == (mesh.n,)
            assert np.all(pd["full_field"] == 1)
            interior = np.setdiff1d(np.arange(mesh.n), mesh.boundary)
            assert np.all(pd["mode"][interior] == -1)
            # boundary nodes: the full field agrees with the recorded boundary displacement
            np.testing.assert_allclose(pd["displacement"][mesh.boundary], pd["boundary_displacement"][mesh.boundary],
                                       atol=1e-12)
            depths.append(pd["depth"][0])
        assert depths[-1] == pytest.approx(s["final_depth"])
        # the last step is the final state of the summary: forces sum to the totals
        F = pd["contact_force"]
        finger = pd["finger"]
        for f in (0, 1):
            np.testing.assert_allclose(F[finger == f, :2].sum(0), s["total_force"][f"finger{f}"], atol=1e-9)
    vtu = meshio.read(out / "final.vtu")
    assert vtu.point_data["displacement"].shape == (mesh.n, 3)
    # summary.json's largest von Mises stress is the final row's, where the file has it
    vm = vtu.cell_data["von_mises"][0]
    np.testing.assert_allclose(cd["von_mises"][0], vm, rtol=1e-12)
    assert s["stress"]["triangle"] == int(np.argmax(vm)) and s["stress"]["max_von_mises"] == pytest.approx(vm.max())
    np.testing.assert_allclose(s["stress"]["at"], (mesh.points + mesh.offset)[mesh.triangles[int(np.argmax(vm))]].mean(0))


def test_help_subprocess():
    r = subprocess.run([sys.executable, "-m", "jaxsqueeze", "--help"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0
    assert "jaxsqueeze run" in r.stdout and "examples:" in r.stdout


def test_version_is_one_number_everywhere(capsys):
    """`jaxsqueeze --version`, jaxsqueeze.__version__ and the installed package's metadata
    (pyproject.toml reads it from the package) agree; they said 0.2.0 and 0.1.0."""
    import importlib.metadata

    import jaxsqueeze
    with pytest.raises(SystemExit) as e:
        cli.main(["--version"])
    assert e.value.code == 0
    assert capsys.readouterr().out.strip() == f"jaxsqueeze {jaxsqueeze.__version__}"
    assert importlib.metadata.version("jaxsqueeze") == jaxsqueeze.__version__


def test_demo_scene_is_packaged(capsys):
    assert cli.main(["demo", "--print-scene"]) == 0
    text = capsys.readouterr().out
    assert "[material]" in text and "foam" in text


def test_scene_file_capacities_reach_the_settings():
    """[accuracy] capacity and sliding_capacity set Settings; left out, both are None (chosen
    and grown by an eager squeeze)."""
    base = SCENE.replace("refine_edge = 0.003\nrefine_radius = 0.012\n", "")
    s = scenefile.load_text(base.replace("capacity = 64", "capacity = 40\nsliding_capacity = 12")).scene.settings
    assert (s.capacity, s.sliding_capacity) == (40, 12)
    s = scenefile.load_text(base.replace("capacity = 64\n", "")).scene.settings
    assert (s.capacity, s.sliding_capacity, s.fused) == (None, None, False)
    assert scenefile.load_text(base.replace("capacity = 64", "capacity = 64\nfused = true")).scene.settings.fused


def test_scene_file_keys_reach_the_scene():
    """Each optional key of the schema (io/scenefile.py, README "Scene files") lands in the Scene
    it describes: fingertip rotation, friction model, contact model, compliance build, the disk
    and polygon-with-holes shapes, and a relative depth (ρ x the initial grip distance)."""
    base = SCENE.replace("refine_edge = 0.003\nrefine_radius = 0.012\n", "")
    sc = scenefile.load_text(base.replace("radius = 0.01", "radius = 0.01\nrotation = [[0.0, 0.0], [40.0, 0.0]]")
                             .replace("friction = 0.3", 'friction = 0.3\nfriction_model = "stick"\ncontact = "point"\n'
                                                        'method = "dense"')).scene
    assert [list(map(float, r)) for r in sc.fingers.rotation] == [[0.0, 0.0], [40.0, 0.0]]
    assert (sc.friction_model, sc.contact, sc.method) == ("stick", "point", "dense")
    opposite = base.replace("points = [[-0.005, -0.05], [0.005, 0.05]]", "points = [[-0.01, -0.05], [-0.01, 0.05]]")
    assert scenefile.load_text(opposite.replace("friction = 0.3", 'friction = 0.3\nfriction_model = "frictionless"')
                               ).scene.friction_model == "frictionless"
    disk = scenefile.load_text(base.replace('shape = "rectangle"\nwidth = 0.1\nheight = 0.1', 'shape = "disk"\nradius = 0.05')
                               ).scene.mesh
    r = np.linalg.norm(disk.points[disk.boundary] + disk.offset, axis=1)
    np.testing.assert_allclose(r, 0.05, rtol=1e-9)
    holed = base.replace('shape = "rectangle"\nwidth = 0.1\nheight = 0.1',
                         'shape = "polygon"\nvertices = [[-0.05, -0.05], [0.05, -0.05], [0.05, 0.05], [-0.05, 0.05]]\n'
                         'holes = [[[-0.01, -0.01], [0.01, -0.01], [0.01, 0.01], [-0.01, 0.01]]]')
    mesh = scenefile.load_text(holed).scene.mesh
    assert len(mesh.loops) == 2 and mesh.loops[1] > 0
    inner = mesh.points[mesh.boundary[mesh.loops[0]:]] + mesh.offset
    np.testing.assert_allclose(np.abs(inner).max(axis=1), 0.01, atol=1e-12)
    rel = scenefile.load_text(base.replace("depth = 0.01", "relative_depth = 0.1")).scene
    p = rel.mesh.points[list(rel.grip)]
    assert float(rel.depth) == pytest.approx(0.1 * np.linalg.norm(p[0] - p[1]), rel=1e-12)


def test_example_scene_reads_mesh_file():
    spec = scenefile.load(os.path.join(ROOT, "examples", "foam_disk.toml"))
    mesh = spec.scene.mesh
    assert mesh.n > 100 and len(mesh.loops) == 1
    p = mesh.points[list(spec.scene.grip)] + mesh.offset
    np.testing.assert_allclose(p, [[0.0, -0.04], [0.006946, 0.039392]], atol=1e-3)  # nearest nodes


def test_a_mesh_file_one_element_thick_somewhere_warns(tmp_path):
    """The built-in shapes' warning (test_mesh.py) now also covers mesh files: a ring one element
    across its wall, read from a file, is 3.3 times too stiff in bending (two across: 1.5)."""
    with pytest.warns(UserWarning, match="one element thick"):
        ring = jsq.shapes.annulus(0.042, 0.038, max_edge=0.004)
    jsq.write_mesh(tmp_path / "ring.vtu", ring)
    with pytest.warns(UserWarning, match=r"the mesh in .*ring.vtu is one element thick at 126 place\(s\) .* here "
                                         r"0.001 m") as said:
        jsq.read_mesh(tmp_path / "ring.vtu")
    assert len(said) == 1 and said[0].filename == __file__
    text = ('[object]\nmesh_file = "ring.vtu"\n[material]\nE = 1e5\nnu = 0.3\nthickness = 0.01\n'
            "[fingers]\nradius = 0.01\n[grip]\npoints = [[0.0, -0.042], [0.0, 0.042]]\n[squeeze]\ndepth = 0.002\n")
    said = scenefile.load_text(text, base=str(tmp_path)).warnings
    assert [w for w in said if "one element thick" in w][0].startswith("object.mesh_file: the mesh in "), said


def test_a_mesh_file_in_millimetres_warns(tmp_path):
    """Unit checks ran only on built-in shapes (sized before meshing): a mesh file written in
    mm (a 100-unit square) squeezed with SUCCESS and no word. They now run on the object as
    read, as they do on a band, with the words an eager squeeze would warn with."""
    mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=0.02)
    pts = 1000 * (mesh.points + mesh.offset)
    meshio.write(tmp_path / "mm.vtu", meshio.Mesh(np.c_[pts, np.zeros(len(pts))], [("triangle", mesh.triangles)]))
    text = ('[object]\nmesh_file = "mm.vtu"\n[material]\nE = 1e5\nnu = 0.3\nthickness = 25.4\n'
            "[fingers]\nradius = 0.01\n[grip]\npoints = [[0.0, -50.0], [0.0, 50.0]]\n[squeeze]\ndepth = 0.005\n")
    said = scenefile.load_text(text, base=str(tmp_path)).warnings
    assert any("the object is 100 m across; every length is in metres" in w for w in said), said
    assert any(w.startswith("the fingertip radius (0.01 m) and the object (100 m across) differ by a factor 1e+04")
               for w in said), said
    assert not scenefile.load(os.path.join(ROOT, "examples", "foam_disk.toml")).warnings


def test_a_grip_point_midway_between_two_nodes_warns():
    """(0, -0.05) on a square meshed at 8 mm lies midway between two boundary nodes: which one
    it snapped to was round-off (the same file in mm picked the other, a slanted grip). The
    shipped scenes put their points on nodes and say nothing."""
    text = ('[object]\nshape = "rectangle"\nwidth = 0.1\nheight = 0.1\nmax_edge = 0.008\n[material]\nE = 1e5\n'
            "nu = 0.3\nthickness = 0.0254\n[fingers]\nradius = 0.01\n[grip]\npoints = [[0.0, -0.05], [0.0, 0.05]]\n"
            "[squeeze]\ndepth = 0.005\n")
    said = scenefile.load_text(text).warnings
    assert len(said) == 2 and all(w.startswith("grip.points: point ") and "(a tie broken by round-off)" in w
                                  for w in said), said
    assert not scenefile.load_text(text.replace("0.008", "0.01")).warnings          # a node at x = 0
    for name in ("foam_square", "heart_band", "leaf_band"):
        assert not scenefile.load(os.path.join(ROOT, "jaxsqueeze", "scenes", f"{name}.toml")).warnings, name


def test_a_max_edge_larger_than_the_object_warns_under_its_key():
    """The shape's warning is the scene file's, under object.max_edge (the CLI prints it as a
    warning: line and writes it to summary.json), not a Python warning from the library."""
    text = ('[object]\nshape = "rectangle"\nwidth = 0.1\nheight = 0.1\nmax_edge = 1.0\n[material]\nE = 1e5\n'
            "nu = 0.3\nthickness = 0.0254\n[fingers]\nradius = 0.01\n[grip]\nnodes = [0, 2]\n"
            "[squeeze]\ndepth = 0.005\nfriction = 0.5\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        said = scenefile.load_text(text).warnings
    assert len(said) == 1 and said[0].startswith("object.max_edge: max_edge = 1 m exceeds the object"), said


@pytest.mark.filterwarnings("ignore:boundary nodes .* are equally near")     # either node will do here
def test_grip_nodes_of_a_mesh_file_with_unused_nodes_are_refused(tmp_path):
    """A mesh file whose node 0 is used by no triangle (gmsh writes a circle's centre): the
    reader drops it and renumbers the rest (``mesh.source`` maps back), so grip.nodes in the
    file's numbering named other nodes and squeezed a tilted grip with SUCCESS. It is now an
    error that says to use grip.points; points, and a file with unused nodes only at its end
    (nothing renumbered), work."""
    mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=0.02)
    pts = np.concatenate([[[0.0, 0.0]], mesh.points + mesh.offset])
    meshio.write(tmp_path / "first.vtu", meshio.Mesh(np.c_[pts, np.zeros(len(pts))], [("triangle", mesh.triangles + 1)]))
    with pytest.warns(UserWarning, match=r"used by no triangle \(0\)"):       # Python names the shift
        read = jsq.read_mesh(tmp_path / "first.vtu")
    np.testing.assert_array_equal(read.source, np.arange(1, mesh.n + 1))
    np.testing.assert_allclose(read.points + read.offset, pts[read.source], atol=1e-15)
    a, b = (int(jsq.scene.nearest_boundary_node(mesh, p)) for p in ((0.0, -0.05), (0.0, 0.05)))
    body = SCENE[SCENE.index("[material]"):].replace("[[-0.005, -0.05], [0.005, 0.05]]", "[[0.0, -0.05], [0.0, 0.05]]")
    (tmp_path / "nodes.toml").write_text('[object]\nmesh_file = "first.vtu"\n\n' + body.replace(
        "points = [[0.0, -0.05], [0.0, 0.05]]", f"nodes = [{a + 1}, {b + 1}]"))
    with pytest.raises(scenefile.SceneFileError, match="used by no triangle .file nodes 0.*give grip.points"):
        scenefile.load(tmp_path / "nodes.toml")
    (tmp_path / "points.toml").write_text('[object]\nmesh_file = "first.vtu"\n\n' + body)
    loaded = scenefile.load(tmp_path / "points.toml")
    assert loaded.scene.grip == (a, b) and not any("no triangle" in w for w in loaded.warnings)   # no numbers to shift
    # the outputs number nodes as the mesh does; the file's numbers travel with them (a ParaView
    # user comparing point ids with the file landed on other points)
    assert cli.main(["run", str(tmp_path / "points.toml"), "--out", str(tmp_path / "o"), "--no-plots", "-q"]) == 0
    vtu = meshio.read(tmp_path / "o" / "final.vtu")
    np.testing.assert_array_equal(vtu.point_data["source_node"], read.source)
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["grip_nodes_source"] == [a + 1, b + 1]
    np.testing.assert_array_equal(vtu.point_data["push"], 0.0)
    # a reader's own numpy warning (meshio's STL format sniffing: "overflow encountered in scalar
    # multiply") was printed as the scene's "warning: object.mesh_file: ..."
    meshio.write(tmp_path / "tris.stl", meshio.Mesh(np.c_[mesh.points + mesh.offset, np.zeros(mesh.n)],
                                                    [("triangle", mesh.triangles)]), binary=True)
    (tmp_path / "stl.toml").write_text('[object]\nmesh_file = "tris.stl"\n\n' + body)
    loaded = scenefile.load(tmp_path / "stl.toml")
    assert loaded.scene.mesh.n == mesh.n and all(w.startswith("grip.points: ") for w in loaded.warnings), loaded.warnings
    last = np.roll(pts, -1, axis=0)                        # the unused node at the end
    meshio.write(tmp_path / "last.vtu", meshio.Mesh(np.c_[last, np.zeros(len(pts))], [("triangle", mesh.triangles)]))
    assert jsq.read_mesh(tmp_path / "last.vtu").source is not None
    (tmp_path / "last.toml").write_text('[object]\nmesh_file = "last.vtu"\n\n' + body.replace(
        "points = [[0.0, -0.05], [0.0, 0.05]]", f"nodes = [{a}, {b}]"))
    assert scenefile.load(tmp_path / "last.toml").scene.grip == (a, b)


# ----------------------------------------------------------------------------- bad scene files
def _line_only_mesh(tmp_path):
    path = tmp_path / "lines.vtu"
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]], float)
    meshio.write(path, meshio.Mesh(pts, [("line", np.array([[0, 1], [1, 2]]))]))
    return path.name


def _interior_node():
    mesh = jsq.shapes.rectangle(0.1, 0.1, max_edge=0.02)   # the mesh of the unrefined scene below
    return int(np.setdiff1d(np.arange(mesh.n), mesh.boundary)[0])


BAD = {
    "unknown key": ("material.colour", lambda s: s.replace("nu = 0.3", "nu = 0.3\ncolour = 1")),
    "unknown table": ("output", lambda s: s + "\n[output]\nformat = 'png'\n"),
    "unknown top-level key": ("name", lambda s: "name = 'x'\n" + s),
    "nu out of range": ("material.nu", lambda s: s.replace("nu = 0.3", "nu = 0.7")),
    "E as a string": ("material.E", lambda s: s.replace("E = 1.0e5", 'E = "nan"')),
    "E nan": ("material.E", lambda s: s.replace("E = 1.0e5", "E = nan")),
    "negative radius": ("fingers.radius", lambda s: s.replace("radius = 0.01", "radius = -0.01")),
    "zero depth": ("squeeze.depth", lambda s: s.replace("depth = 0.01", "depth = 0")),
    "depth too large": ("squeeze.depth", lambda s: s.replace("depth = 0.01", "depth = 0.2")),
    "negative friction": ("squeeze.friction", lambda s: s.replace("friction = 0.3", "friction = -0.1")),
    "missing object": ("object", lambda s: s[:s.index("[object]")] + s[s.index("[material]"):]),
    "missing material key": ("material.thickness", lambda s: s.replace("thickness = 0.0254\n", "")),
    "unknown shape": ("object.shape", lambda s: s.replace('"rectangle"', '"hexagon"')),
    "missing shape size": ("object.height", lambda s: s.replace("height = 0.1\n", "")),
    "refine edge too big": ("object.refine_edge", lambda s: s.replace("refine_edge = 0.003", "refine_edge = 0.05")),
    "shape and mesh file": ("object", lambda s: s.replace("[object]", '[object]\nmesh_file = "x.msh"')),
    "grip node interior": ("grip.nodes", lambda s: s.replace(
        "points = [[-0.005, -0.05], [0.005, 0.05]]", f"nodes = [0, {_interior_node()}]").replace(
        "refine_edge = 0.003\nrefine_radius = 0.012\n", "")),
    "grip node missing": ("grip.nodes", lambda s: s.replace(
        "points = [[-0.005, -0.05], [0.005, 0.05]]", "nodes = [0, 99999]").replace(
        "refine_edge = 0.003\nrefine_radius = 0.012\n", "")),
    "grip outside cones": ("grip.points", lambda s: s.replace("[[-0.005, -0.05], [0.005, 0.05]]",
                                                                "[[-0.04, -0.05], [0.04, 0.05]]")),
    "grip bad shape": ("grip.points", lambda s: s.replace("[[-0.005, -0.05], [0.005, 0.05]]", "[[0.0, 0.05]]")),
    "both grip kinds": ("grip", lambda s: s.replace("[grip]", "[grip]\nnodes = [1, 2]")),
    "bad precision": ("accuracy.precision", lambda s: s.replace('"float64"', '"float16"')),
    "zero capacity": ("accuracy.capacity", lambda s: s.replace("capacity = 64", "capacity = 0")),
    "float capacity": ("accuracy.capacity", lambda s: s.replace("capacity = 64", "capacity = 6.4")),
    "zero sliding capacity": ("accuracy.sliding_capacity", lambda s: s.replace("capacity = 64", "capacity = 64\nsliding_capacity = 0")),
    "fused not a boolean": ("accuracy.fused", lambda s: s.replace("capacity = 64", 'capacity = 64\nfused = "yes"')),
    "bad friction model": ("squeeze.friction_model", lambda s: s.replace("friction = 0.3", 'friction = 0.3\nfriction_model = "viscous"')),
    "not toml": ("file", lambda s: s.replace("[material]", "[material")),
    "mesh file missing": ("object.mesh_file", lambda s: s.replace(
        s[s.index("[object]"):s.index("[material]")], '[object]\nmesh_file = "nope.msh"\n\n').replace(
        "[[-0.005, -0.05], [0.005, 0.05]]", "[[0, 0], [1, 1]]")),
    "mesh file without triangles": ("object.mesh_file", lambda s: s.replace(
        s[s.index("[object]"):s.index("[material]")], '[object]\nmesh_file = "lines.vtu"\n\n')),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_scene_file(case, tmp_path, capsys):
    key, edit = BAD[case]
    _line_only_mesh(tmp_path)
    text = edit(SCENE)
    assert text != SCENE
    path = tmp_path / "bad.toml"
    path.write_text(text)
    out = tmp_path / "out"
    rc = cli.main(["run", str(path), "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert err and any(line.startswith(f"error: {key}: ") for line in err), err
    assert not out.exists()


@pytest.mark.parametrize("argv, said", [(["run", "scene.toml", "--out", "OUT", "--bogus"], "unrecognized arguments: --bogus"),
                                        (["run", "scene.toml"], "required: --out"),
                                        (["runn"], "invalid choice: 'runn'"), ([], "required: COMMAND")])
def test_a_bad_command_line_exits_2_with_usage_and_writes_nothing(argv, said, tmp_path, capsys):
    """docs/errors.md: a bad command line exits 2 with argparse's usage line and one error line;
    nothing is run or written."""
    argv = [str(tmp_path / "out") if a == "OUT" else a for a in argv]
    with pytest.raises(SystemExit) as exit_:
        cli.main(argv)
    err = capsys.readouterr().err
    assert exit_.value.code == 2
    assert err.startswith("usage: jaxsqueeze") and re.search(r"^jaxsqueeze( run)?: error: .*" + re.escape(said), err, re.M), err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("center, said", [("0.0", "got 0.0"), ("[[0.0, 0.0]]", "got an array of 1 (nested)"),
                                          ("[0.0, 0.0, 0.0]", "got an array of 3")])
def test_a_centre_that_is_not_one_point_says_the_form_it_needs(center, said, tmp_path, capsys):
    """object.center = 0.0 said "expected 1 points [[x, y], ...], got an array" (a number was
    given, and the form it suggested is itself refused)."""
    path = tmp_path / "bad.toml"
    path.write_text(SCENE.replace("max_edge = 0.02", f"max_edge = 0.02\ncenter = {center}"))
    assert cli.main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: object.center: expected one point [x, y], {said}"), err


def test_bad_size_option(tmp_path, capsys):
    out = tmp_path / "out"
    assert cli.main(["demo", "--out", str(out), "--max-edge", "-1"]) == 2
    assert capsys.readouterr().err.startswith("error: --max-edge: ")
    assert not out.exists()


def test_post_consumers_honour_count_of_a_jit_result(tmp_path):
    """A result from jax.jit keeps its fixed capacity; every consumer trims it first."""
    import dataclasses

    from jaxsqueeze.post import export, plots
    from jaxsqueeze.simulation.result import EventLog

    spec = scenefile.load_text(SCENE.replace("refine_edge = 0.003\nrefine_radius = 0.012\n", "")
                               .replace("points = [[-0.005, -0.05], [0.005, 0.05]]",
                                        "points = [[-0.01, -0.05], [-0.01, 0.05]]"))
    scene = spec.scene.replace(depth=0.004)        # (the summary refuses a scene of another depth)
    eager = jsq.squeeze(scene)
    k, e = int(eager.count), int(eager.n_events)
    # pad it as a jit result is: rows repeat the last state, the event log is zero-filled
    pad = lambda a: np.concatenate([a, np.repeat(a[-1:], 60, axis=0)])  # noqa: E731
    res = dataclasses.replace(eager, **{f: pad(np.asarray(getattr(eager, f))) for f in (
        "depth", "modes", "finger", "theta", "forces", "boundary_displacement", "centres", "alpha")},
        events=EventLog(*(np.concatenate([np.asarray(a), np.zeros(60, np.asarray(a).dtype)]) for a in eager.events)))
    assert len(np.asarray(res.depth)) > k                       # padded
    s = views.summary(res, scene)
    assert s["rows"] == k and s["n_events"] == e == len(views.event_table(res))
    assert int(res.squeeze_events) == e and all(ev["phase"] == "squeeze" and ev["relative_depth"] > 0
                                                          for ev in s["events"])
    path = export.write_paraview(str(tmp_path), res, scene.mesh)
    with meshio.xdmf.TimeSeriesReader(path) as r:
        r.read_points_cells()
        assert r.num_steps == k
    assert os.getcwd() != str(tmp_path)
    plots.plot_events(res)


def test_the_report_of_a_summary_with_nulls_says_n_a():
    """docs/errors.md: summary.json writes null for non-finite numbers (NONFINITE); the printed
    report formatted them with ':.3f' and the run ended as an internal error (exit 3)."""
    regions = {"n_stick": 1, "n_slip": 0, "regions": [{"nodes": [3, 3], "theta_range": [None, None]}]}
    s = {"title": "t", "scene_file": "x.toml", "status": "NONFINITE", "advice": "check the grip",
         "final_depth": None, "target_depth": 0.004, "relative_depth": None, "grip_distance": None, "rows": 3,
         "event_sequence": "", "n_events": 0, "contact_regions": {"finger0": regions, "finger1": regions},
         "total_force": {"finger0": [None, None], "finger1": [1.0, None]}, "timings": {}, "outputs": {}}
    s["stress"] = {"max_von_mises": None, "triangle": None, "at": None}
    text = cli._report(s, None, "out", np)
    assert "stress       largest von Mises n/a Pa, in triangle n/a at (n/a, n/a) mm" in text
    assert [cli._stress(x) for x in (0.0, 0.5, 34840.45, 2.07e8, 2.1e11, 3e14)] == [
        "0 Pa", "0.5 Pa", "34.8 kPa", "207 MPa", "210 GPa", "3e+05 GPa"]
    assert "final depth  n/a mm of 4.000 mm (n/a % of the grip distance n/a mm)" in text
    assert "total force on the object (1.000, n/a) N, |F| = n/a N" in text and "polar angle n/a..n/a deg" in text
