"""``jaxsqueeze plan SCENE.toml --out DIR``: map, search, best grasp, summary; [plan] errors."""
import json

import jax
import pytest

from jaxsqueeze.io import cli

SCENE = """\
title = "coarse ellipse plan"

[object]
shape = "ellipse"
a = 0.06
b = 0.04
max_edge = 0.012

[material]
E = 1.0e5
nu = 0.3
thickness = 0.0254

[fingers]
radius = 0.01

[grip]
points = [[0.06, 0.0], [-0.06, 0.0]]

[squeeze]
depth = 0.004
friction = 0.5

[plan]
spacing = 0.03
starts = 2
steps = 3
learning_rate = 0.02
push = 0.002
"""


def test_plan_writes_map_search_and_best_grasp(tmp_path, capsys, monkeypatch):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE)
    out = tmp_path / "plan"
    from jaxsqueeze import compiler
    started, ahead = [], compiler.TopLevelJit.compile_ahead
    monkeypatch.setattr(compiler.TopLevelJit, "compile_ahead",
                        lambda self, *a, **kw: started.append(self.__name__) or ahead(self, *a, **kw))
    with jax.transfer_guard("disallow"):    # (JAX_TRANSFER_GUARD=disallow: every transfer is the program's own)
        code = cli.main(["plan", str(path), "--out", str(out), "-q"])
    assert code == 0, capsys.readouterr().err
    # the search's program compiles while the map runs, the best grasp's while the search runs
    assert started == ["_value_and_grad", "_run"]
    s = json.loads((out / "summary.json").read_text())
    assert s["quality"] == "adversary_work" and s["best"]["status"] == "SUCCESS"
    assert s["best"]["adversary_work_J"] > 0
    assert abs(sum(s["best"]["finger_work_J"]) - s["best"]["adversary_work_J"]) < 1e-9 * s["best"]["adversary_work_J"]
    assert s["map"]["squeezes"] > 0 and len(s["search"]["paths"]) >= 1
    assert (out / "map.png").stat().st_size > 0 and (out / "best.png").stat().st_size > 0
    cli._check_out(str(out))            # a second plan may replace what this one wrote
    # 12 mm boundary edges under 10 mm fingertips: placements between nodes may leave the cones (mu = 0.5)
    assert any(w.startswith("boundary edges 0.0117 m long under fingertips of radius 0.01 m") for w in s["warnings"])
    assert "warning: boundary edges" not in capsys.readouterr().err            # -q
    # --no-plots (a smaller plan, on the compiled programs of this one): no figures
    small = tmp_path / "small.toml"
    small.write_text(SCENE.replace("starts = 2", "starts = 1").replace("steps = 3", "steps = 1"))
    bare = tmp_path / "bare"
    assert cli.main(["plan", str(small), "--out", str(bare), "-q", "--no-plots"]) == 0
    assert sorted(p.name for p in bare.iterdir()) == ["summary.json"]
    assert json.loads((bare / "summary.json").read_text())["files"] == {}


def test_a_map_without_a_feasible_grasp_is_an_input_error_that_says_why(tmp_path, capsys):
    """No feasible cell on the map (three positions, none nearly opposite, μ = 0.2): the search ran a
    coarse map of its own, which found nothing either, and said "no feasible placement on the
    coarse map ... pass a finer coarse_spacing". Now exit 2 after the map, with its statuses."""
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.replace("spacing = 0.03", "spacing = 0.1").replace("friction = 0.5", "friction = 0.2"))
    code = cli.main(["plan", str(path), "--out", str(tmp_path / "o"), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: no feasible grasp on the map of 3 positions"), err
    assert "(ordered pairs: INFEASIBLE_GRIP 6)" in err and "use a finer plan.spacing" in err, err
    assert not (tmp_path / "o").exists()


def test_plan_table_errors_name_the_key(tmp_path, capsys):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.replace("starts = 2", "starts = 0\nbogus = 1").replace("steps = 3", 'steps = "x"'))
    code = cli.main(["plan", str(path), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and "plan.bogus" in err and not (tmp_path / "o").exists()


def test_plan_optimizer_that_is_not_an_optimizer_factory_is_an_input_error(tmp_path, capsys):
    """plan.optimizer names an optax function that is not an optimizer (apply_updates): exit 2
    with the key named, before any squeeze (it was exit 3 from inside optax)."""
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.replace("learning_rate = 0.02", 'learning_rate = 0.02\noptimizer = "apply_updates"'))
    code = cli.main(["plan", str(path), "--out", str(tmp_path / "o"), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and "plan.optimizer='apply_updates' is not an optax optimizer" in err, err
    path.write_text(SCENE.replace("learning_rate = 0.02", 'learning_rate = 0.02\noptimizer = "lbfgs"'))
    code = cli.main(["plan", str(path), "--out", str(tmp_path / "o"), "-q"])    # exit 3 from inside optax
    err = capsys.readouterr().err
    assert code == 2 and "plan.optimizer='lbfgs': the optimizer cannot take a step" in err, err
    assert not (tmp_path / "o").exists()


def test_plan_push_longer_than_the_object_is_an_input_error(tmp_path, capsys):
    """plan.push of 5 m on a 0.12 m ellipse: exit 2 naming plan.push before any squeeze (every
    cell of the map was INVALID_INPUT and the search said "no feasible placement")."""
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.replace("push = 0.002", "push = 5.0"))
    code = cli.main(["plan", str(path), "--out", str(tmp_path / "o"), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and "error: plan.push: expected a push [m] shorter than the object" in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("edit, said", [
    ("push = 0.002\npush_angle = 2.0", "error: plan.push_angle: expected an angle from the inward normal below pi/2"),
    ("push = 0.002\noptimizer = \"scale\"", "along the gradient, so the search would walk downhill"),
    ("push = 0.002\noptimizer = \"freeze\"", "its step from a unit gradient is zero, so the search would never move"),
    # named "adversary = [1e300, 0]" after 25 s (the map's compile started first)
    ("push = 0.002\npush_at = 1e300", "error: plan.push_at: expected an arc length [m] within 1,000 object sizes")])
def test_plan_a_pusher_that_cannot_push_or_an_optimizer_that_descends_names_its_key(tmp_path, capsys, edit, said):
    """push_angle = 2 rad (the pusher moves away from the surface): every cell INFEASIBLE_GRIP
    and "no feasible placement on the coarse map: refine coarse_spacing", a key [plan] does not
    have. optimizer = "scale" (optax.scale(learning_rate): no minus sign) climbed down and ended
    with exit 0. Both: exit 2 before any squeeze."""
    path = tmp_path / "scene.toml"
    assert "push = 0.002" in SCENE
    path.write_text(SCENE.replace("push = 0.002", edit))
    code = cli.main(["plan", str(path), "--out", str(tmp_path / "o"), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and said in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("spacing, said", [("1e-7", "more than 10 per boundary node"),
                                           ("1e-310", "more than 10 per boundary node"), ("100.0", "at least 3")])
def test_plan_spacing_too_fine_or_too_coarse_names_its_key(tmp_path, capsys, spacing, said):
    """plan.spacing of 1e-7 m said "error: spacing=..." without its key; 100 m was cut to 3
    positions quietly (no feasible pair, exit 0). Both: exit 2 naming plan.spacing, no work."""
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.replace("spacing = 0.03", f"spacing = {spacing}"))
    code = cli.main(["plan", str(path), "--out", str(tmp_path / "o"), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: plan.spacing: spacing=") and said in err, err
    assert not (tmp_path / "o").exists()


def test_plan_errors_of_a_hole_grip_and_a_band_push_name_their_key(tmp_path, capsys):
    """A wall pinch on an annulus (one grip point on the hole) said "node(s) [40, 77] are not on
    the outer boundary loop" (40 is on it) with no key; a push on a band (point contacts) said
    the Adversary's error with no key. Both now name the key and only the offending node."""
    annulus = SCENE.replace('shape = "ellipse"\na = 0.06\nb = 0.04', 'shape = "annulus"\nr_outer = 0.05\nr_inner = 0.03')
    (tmp_path / "ring.toml").write_text(annulus.replace("[[0.06, 0.0], [-0.06, 0.0]]", "[[0.0, -0.05], [0.0, -0.03]]"))
    assert cli.main(["plan", str(tmp_path / "ring.toml"), "--out", str(tmp_path / "o"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: grip: planning places both fingers along the outer boundary"), err
    assert "grip node(s) [" in err and "] lie on a hole's boundary" in err and "," not in err.split("node(s) [")[1][:8]
    band = ('[object]\nband = "circle"\nsize = 0.08\nnodes = 32\n[material]\nE = 2.0e9\n[fingers]\nradius = 0.005\n'
            "[grip]\npoints = [[-0.04, 0.0], [0.04, 0.0]]\n[squeeze]\nrelative_depth = 0.1\nfriction = 0.26\n"
            "[plan]\npush = 0.002\n")
    (tmp_path / "band.toml").write_text(band)
    assert cli.main(["plan", str(tmp_path / "band.toml"), "--out", str(tmp_path / "o"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: plan.push: an Adversary needs contact='segment'"), err
    assert not (tmp_path / "o").exists()


def test_plan_push_settings_without_a_push_and_a_quality_that_needs_one_name_their_keys(tmp_path, capsys):
    """push_at and push_angle without push were ignored (exit 0, a plan with no adversary);
    quality = "adversary_work" without push said the quality's error without its key."""
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.replace("push = 0.002", "push_at = 0.1\npush_angle = 0.3"))
    assert cli.main(["plan", str(path), "--out", str(tmp_path / "o"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "error: plan.push_at: sets the adversary's push, which needs plan.push > 0 [m]" in err, err
    assert "plan.push_angle: sets the adversary's push" in err, err
    path.write_text(SCENE.replace("push = 0.002", 'quality = "adversary_work"'))
    assert cli.main(["plan", str(path), "--out", str(tmp_path / "o"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: plan.quality: ") and "Adversary" in err, err
    assert not (tmp_path / "o").exists()


def test_feasible_pairs_count_either_order():
    """summary.json's map.feasible_pairs counted ok.sum() // 2, half the feasible cells: right for
    a mirrored map, too few for a map of unlike fingers (only one order of a pair may hold)."""
    import numpy as np
    from jaxsqueeze.io.planning import feasible_pairs
    ok = np.zeros((4, 4), bool)
    ok[0, 1] = ok[1, 0] = True          # both orders: one pair
    ok[0, 2] = True                     # one order only: one pair
    ok[3, 1] = True
    assert feasible_pairs(ok) == 3 and feasible_pairs(ok | ok.T) == 3


def test_plan_starts_beyond_eight_take_as_many_map_cells(tmp_path, capsys, monkeypatch):
    """[plan] starts = 12 ran 8 starts: the map kept its default 8 best cells."""
    from jaxsqueeze.plan import search
    seen = {}

    def spy(*args, **kw):
        seen.update(kw)
        raise ValueError("stopped by the test")
    monkeypatch.setattr(search, "grasp_map", spy)
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.replace("starts = 2", "starts = 12"))
    assert cli.main(["plan", str(path), "--out", str(tmp_path / "o"), "-q"]) == 2
    assert "stopped by the test" in capsys.readouterr().err and seen["keep"] == 12
