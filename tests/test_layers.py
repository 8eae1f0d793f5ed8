"""The package's layers (README, "The package"; ``jaxsqueeze/__init__.py``): each layer imports
only from the layers before it, the modules that serve every layer (``tracing``, ``numbers``,
``compiler``) import from no layer, and no module imports another module's private names.
Read from the source (every ``from . import`` / ``from .. import``, inside functions too),
without importing it."""
import ast
import pathlib

LAYERS = ("geometry", "mechanics", "simulation", "plan", "post", "io")
SHARED = ("tracing", "numbers", "compiler")
ROOT = pathlib.Path(__file__).resolve().parents[1] / "jaxsqueeze"


def _imports(path: pathlib.Path, root: pathlib.Path):
    """(first package part, names, line) of every relative import in ``path``, resolved."""
    here = list(path.relative_to(root).parent.parts)
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.level > 0:
            base = here[: len(here) - (node.level - 1)]
            target = base + (node.module.split(".") if node.module else [])
            names = [a.name for a in node.names]
            yield (target[0] if target else None), target, names, node.lineno


def problems(root: pathlib.Path = ROOT) -> list[str]:
    out = []
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root).parts
        home = parts[0] if len(parts) > 1 else path.stem
        for first, target, names, line in _imports(path, root):
            where = f"{path.relative_to(root)}:{line}"
            # ``from .. import x`` names modules of the package itself
            for t in ([first] if first is not None else names):
                if home in LAYERS and t in LAYERS and LAYERS.index(t) > LAYERS.index(home):
                    out.append(f"{where}: layer {home} imports the later layer {t}")
                if home in SHARED and t in LAYERS:
                    out.append(f"{where}: {home}, which serves every layer, imports the layer {t}")
            if target:         # ``from .module import _private`` (the module's own package aside)
                out += [f"{where}: imports the private name {n} of {'.'.join(target)}" for n in names
                        if n.startswith("_") and not n.startswith("__")]
    return out


def test_layers_import_only_downward_and_no_private_names():
    assert problems() == []


def test_the_layer_check_finds_what_it_forbids(tmp_path):
    """The check itself: a copy of the package with an upward import, a private name and a
    shared module importing a layer gives exactly those three."""
    import shutil
    copy = tmp_path / "jaxsqueeze"
    shutil.copytree(ROOT, copy, ignore=shutil.ignore_patterns("__pycache__"))
    for rel, line in [("simulation/laws.py", "from ..plan import quality"),
                      ("post/views.py", "from ..simulation.engine import _log"),
                      ("tracing.py", "from .simulation import scene")]:
        with open(copy / rel, "a", encoding="utf-8") as f:
            f.write(f"\n{line}  # planted\n")
    found = problems(copy)
    assert len(found) == 3, found
    assert any("simulation/laws.py" in p and "later layer plan" in p for p in found)
    assert any("post/views.py" in p and "private name _log of simulation.engine" in p for p in found)
    assert any("tracing.py" in p and "imports the layer simulation" in p for p in found)
