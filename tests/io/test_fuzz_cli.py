"""Adversarial scene files through the CLI (issue 12): never a traceback, never minutes,
never SUCCESS for bad input. The corpus is tests/data/fuzz/cases.toml (expected exit status
and message fragments per case); most run in-process, a few need a subprocess."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import physics
from jaxsqueeze.io import cli
from jaxsqueeze.post import views

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib

ROOT = physics.ROOT
FUZZ = os.path.join(ROOT, "tests", "data", "fuzz")
BASE = Path(FUZZ, "base.toml").read_text(encoding="utf-8")
with open(os.path.join(FUZZ, "cases.toml"), "rb") as fh:
    CASES = tomllib.load(fh)


def _text(case: dict) -> str:
    s = BASE
    pairs = list(case.get("edits", []))
    if "old" in case:
        pairs.append([case["old"], case["new"]])
    for old, new in pairs:
        assert old in s, old
        s = s.replace(old, new)
    return s + case.get("append", "")


def _run(tmp_path, text, capsys, *extra):
    path = tmp_path / "scene.toml"
    path.write_text(text, encoding="utf-8")
    out = tmp_path / "out"
    t = time.perf_counter()
    rc = cli.main(["run", str(path), "--out", str(out), "--no-plots", "-q", *extra])
    cap = capsys.readouterr()
    return rc, cap.err, out, time.perf_counter() - t


@pytest.mark.parametrize("name", sorted(CASES))
def test_corpus(name, tmp_path, capsys):
    case = CASES[name]
    rc, err, out, dt = _run(tmp_path, _text(case), capsys)
    assert rc == case["exit"], err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert lines and all(ln.startswith("error: ") for ln in lines), err
    for frag in case["expect"]:
        assert frag in err, (frag, err)
    assert not out.exists()
    assert dt < 5.0


def _write(path, text):
    path.write_text(text, encoding="utf-8")
    return path


def test_scene_path_is_a_folder_or_not_utf8_or_missing(tmp_path, capsys):
    assert cli.main(["run", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err.strip() == f"error: file: {tmp_path} is a folder, not a scene file"
    bad = tmp_path / "latin1.toml"
    bad.write_bytes(BASE.replace("fuzz base", "fu\xdf").encode("latin-1"))
    assert cli.main(["run", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not UTF-8" in err[0]
    assert cli.main(["run", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "o")]) == 2
    assert "no such scene file" in capsys.readouterr().err
    # a UTF-8 byte-order mark (Windows editors) said "Invalid statement (at line 1, column 1)"
    from jaxsqueeze.io import scenefile
    bom = tmp_path / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbf" + BASE.encode("utf-8"))
    assert scenefile.load(bom).title == scenefile.load(_write(tmp_path / "plain.toml", BASE)).title
    # object.mesh_file naming a folder said "no such file"
    (tmp_path / "meshes").mkdir()
    text = BASE.split("[object]")[0] + '[object]\nmesh_file = "meshes"\n' + "[material]" + BASE.split("[material]")[1]
    with pytest.raises(scenefile.SceneFileError, match="object.mesh_file: .*meshes is a folder, not a mesh file"):
        scenefile.load_text(text, base=str(tmp_path))


def test_out_below_a_file_or_not_writable_is_refused_before_work(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text(BASE)
    f = tmp_path / "afile"
    f.write_text("x")
    t = time.perf_counter()
    assert cli.main(["run", str(scene), "--out", str(f / "sub" / "out")]) == 2
    assert "which is a file" in capsys.readouterr().err
    assert cli.main(["run", str(scene), "--out", str(f)]) == 2
    assert "is not a folder" in capsys.readouterr().err
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        try:
            assert cli.main(["run", str(scene), "--out", str(ro / "out")]) == 2
            assert "permission denied" in capsys.readouterr().err
        finally:
            ro.chmod(0o700)
    if os.path.isdir("/proc"):           # writable by its permissions, even for root, yet not a place for files
        assert cli.main(["run", str(scene), "--out", "/proc/jaxsqueeze-out"]) == 2
        assert "error: --out: cannot write into /proc" in capsys.readouterr().err
    assert time.perf_counter() - t < 2.0                     # no squeeze ran


def test_out_through_a_link_replaces_the_linked_folder_with_the_users_permissions(tmp_path, capsys):
    """--out a symlink to an earlier output folder: that folder is replaced and the link kept
    (the link became a real folder, the old outputs left behind with a stray .old link), and
    the new folder has the permissions of the umask (it was mkdtemp's 0700)."""
    rc, err, target, _ = _run(tmp_path, BASE, capsys)
    assert rc == 0, err
    first = target.stat().st_ino
    (tmp_path / "link").symlink_to("out")
    umask = os.umask(0o022)
    try:
        rc = cli.main(["run", str(tmp_path / "scene.toml"), "--out", str(tmp_path / "link"), "--no-plots", "-q"])
    finally:
        os.umask(umask)
    assert rc == 0, capsys.readouterr().err
    assert (tmp_path / "link").is_symlink() and os.readlink(tmp_path / "link") == "out"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "out", "scene.toml"]
    assert target.stat().st_ino != first and (target / "summary.json").is_file()    # a new folder, in place
    assert target.stat().st_mode & 0o777 == 0o755


def test_mesh_file_text_empty_png_exit_2(tmp_path, capsys):
    for name, content in (("text.vtu", b"hello\n"), ("empty.vtu", b""),
                          ("png.vtu", b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4)):
        (tmp_path / name).write_bytes(content)
        text = BASE.replace(BASE[BASE.index("[object]"):BASE.index("[material]")],
                            f'[object]\nmesh_file = "{name}"\n\n')
        rc, err, out, _ = _run(tmp_path, text, capsys)
        assert rc == 2 and err.startswith("error: object.mesh_file: ") and name in err, err
        assert len(err.strip().splitlines()) == 1


def test_internal_error_is_exit_3_with_traceback_file(tmp_path, capsys, monkeypatch):
    from jaxsqueeze.io import scenefile

    def boom(*a, **k):
        raise RuntimeError("simulated bug")

    monkeypatch.setattr(scenefile, "load", boom)
    rc, err, out, _ = _run(tmp_path, BASE, capsys)
    assert rc == 3 and "internal error" in err and "simulated bug" in err and "Traceback" not in err
    tb = err.split("the full traceback is in ")[1].split(" ")[0]
    text = Path(tb).read_text()
    assert "RuntimeError: simulated bug" in text and "scene.toml" in text
    os.remove(tb)


def test_keyboard_interrupt_is_exit_130_and_leaves_old_outputs(tmp_path, capsys, monkeypatch):
    from jaxsqueeze.io import scenefile

    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text("{}")

    def stop(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(scenefile, "load", stop)
    rc, err, _, _ = _run(tmp_path, BASE, capsys)
    assert rc == 130 and len(err.strip().splitlines()) == 1 and "interrupted" in err
    assert os.listdir(out) == ["summary.json"]
    assert not [p for p in os.listdir(tmp_path) if ".tmp-" in p]


def test_json_safe_writes_null_for_nan_and_inf():
    s = views.json_ready({"a": float("nan"), "b": [np.float64("inf"), 1.0], "c": np.array([1.0, -np.inf])})
    assert json.dumps(s, allow_nan=False) == '{"a": null, "b": [null, 1.0], "c": [1.0, null]}'


def test_good_run_is_atomic_and_no_plots_replaces_old_pictures(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "deformed.png").write_bytes(b"old picture")
    (out / "summary.json").write_text('{"old": true}')
    rc, err, _, _ = _run(tmp_path, BASE.replace("E = 1.0e5", "E = 1e308"), capsys)   # forces would overflow
    assert rc == 2 and "force scale E * thickness * size" in err, err
    assert (out / "deformed.png").read_bytes() == b"old picture"    # a refused scene writes nothing
    rc, err, _, _ = _run(tmp_path, BASE.replace("E = 1.0e5", "E = 1e150"), capsys)    # extreme, still representable
    assert rc in (0, 1), err
    assert "deformed.png" not in os.listdir(out)                # no old picture beside the new summary
    text = (out / "summary.json").read_text()
    summ = json.loads(text)                                     # strict JSON: no NaN / Infinity
    assert "NaN" not in text and "Infinity" not in text
    assert summ["status"] in ("SUCCESS", "NONFINITE") and "old" not in summ
    assert not [p for p in os.listdir(tmp_path) if ".tmp-" in p]


def test_sigterm_leaves_previous_outputs(tmp_path):
    """SIGTERM while a second run is working: the first run's folder is left whole."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text('{"run": "A"}')
    scene = tmp_path / "s.toml"
    scene.write_text(BASE)
    env = dict(os.environ, PYTHONPATH=ROOT, MPLBACKEND="Agg")
    p = subprocess.Popen([sys.executable, "-m", "jaxsqueeze", "run", str(scene), "--out", str(out), "-v"],
                         stderr=subprocess.PIPE, stdout=subprocess.PIPE, env=env, text=True)
    t0 = time.time()
    line = ""
    while "compliance operator" not in line and time.time() - t0 < 60:   # working
        line = p.stderr.readline()
        if not line and p.poll() is not None:
            break
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    if p.returncode == 0:                                       # it finished first: outputs replaced whole
        assert json.loads((out / "summary.json").read_text()).get("status")
    else:
        assert p.returncode == 130, err
        assert "interrupted" in err and "Traceback" not in err
        assert os.listdir(out) == ["summary.json"] and "A" in (out / "summary.json").read_text()
    assert not [q for q in os.listdir(tmp_path) if ".tmp-" in q]


@pytest.mark.parametrize("command", ["run", "plan", "demo"])
def test_out_never_replaces_a_folder_of_the_users(tmp_path, capsys, monkeypatch, command):
    """A run replaces its --out folder whole. `--out ""` (the current folder) replaced a whole
    source tree, .git included, and exit 0; `--out .` or any folder with files a run does not
    write would have too. Each is now exit 2 before any work, and the folder is untouched."""
    home = tmp_path / "project"
    (home / ".git").mkdir(parents=True)
    (home / "notes.txt").write_text("mine")
    (home / "summary.json").write_text("{}")
    scene = tmp_path / "scene.toml"
    scene.write_text(BASE, encoding="utf-8")
    monkeypatch.chdir(home)
    args = ([command] if command == "demo" else [command, str(scene)]) + ["--no-plots", "-q"]
    for out in ("", " ", ".", str(home), str(tmp_path)):
        rc = cli.main(args + ["--out", out])
        err = capsys.readouterr().err
        assert rc == 2 and "--out" in err, (out, err)
        assert ("empty path" in err) if not out.strip() else ("did not write" in err), err
        assert sorted(os.listdir(home)) == [".git", "notes.txt", "summary.json"]
        assert (home / "notes.txt").read_text() == "mine"


def test_out_is_never_the_current_folder_a_link_loop_or_an_overlong_name(tmp_path, capsys, monkeypatch):
    """`--out .` run from inside an earlier output folder, or from an empty folder, replaced the
    current folder (exit 0, the shell left in a deleted folder); a loop of links and a 250-byte
    name (its staging folder's name then passes 255 bytes) ran the whole squeeze and ended with
    exit 3. Each is now exit 2 before any work (the long name is taken), and nothing is touched."""
    scene = tmp_path / "scene.toml"
    scene.write_text(BASE, encoding="utf-8")
    args = ["run", str(scene), "--no-plots", "-q", "--out"]
    earlier, empty = tmp_path / "earlier", tmp_path / "empty"
    earlier.mkdir()
    (earlier / "summary.json").write_text("{}")
    empty.mkdir()
    for here, out in ((earlier, "."), (empty, "."), (empty, str(empty))):
        monkeypatch.chdir(here)
        assert cli.main(args + [out]) == 2
        assert "is the current folder or holds it" in capsys.readouterr().err
        assert os.listdir(earlier) == ["summary.json"] and os.listdir(empty) == []
    monkeypatch.chdir(tmp_path)
    os.symlink("loop_b", "loop_a")
    os.symlink("loop_a", "loop_b")
    assert cli.main(args + ["loop_a"]) == 2 and "a loop of links" in capsys.readouterr().err
    assert cli.main(args + ["b" * 256]) == 2 and "256 bytes long" in capsys.readouterr().err
    from jaxsqueeze.io.cli import _staging
    tmp = _staging(str(tmp_path / ("a" * 250)))               # a legal name: its staging name is too
    assert len(os.path.basename(tmp)) < 100 and os.path.isdir(tmp)


def test_a_scene_file_reports_its_problems_in_stages():
    """docs/errors.md: every problem of the first stage that has any, one line each: a bad ν and
    a bad radius together; a bad ν hides a bad friction (a later stage) until it is fixed."""
    from jaxsqueeze.io import scenefile

    def keys(edits):
        d = tomllib.loads(BASE)
        for (table, key), value in edits.items():
            d[table][key] = value
        with pytest.raises(scenefile.SceneFileError) as e:
            scenefile.from_dict(d)
        return [line.split(":")[0] for line in str(e.value).splitlines()]

    nu, radius, mu = ("material", "nu"), ("fingers", "radius"), ("squeeze", "friction")
    assert keys({nu: 0.7, radius: -0.01}) == ["material.nu", "fingers.radius"]
    assert keys({nu: 0.7, mu: -0.1}) == ["material.nu"]
    assert keys({mu: -0.1}) == ["squeeze.friction"]


def test_a_squeeze_that_stops_short_exits_1_with_its_outputs(tmp_path, capsys):
    """README and docs/errors.md: exit 1 when the squeeze ran but did not succeed, with every
    output written and the status and its advice in summary.json; an existing empty --out
    folder is taken."""
    (tmp_path / "out").mkdir()
    rc, err, out, _ = _run(tmp_path, BASE + "max_steps = 1\n", capsys)
    assert rc == 1, err
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "MAX_STEPS" and "max_steps" in s["advice"] and s["rows"] == 2
    assert set(s["outputs"].values()) <= {p.name for p in out.iterdir()}
