"""jaxsqueeze: differentiable two-finger squeeze grasps of soft planar objects.

Layers, each importing only from the ones above it in this list:

* :mod:`jaxsqueeze.geometry`   mesh, shapes, curves, boundary
* :mod:`jaxsqueeze.mechanics`  material, fem, operator, band, bordered, linalg
* :mod:`jaxsqueeze.simulation` scene, laws, validate, engine, result, status, api (``squeeze``)
* :mod:`jaxsqueeze.plan`       quality, search (placement, grasp maps, optax search)
* :mod:`jaxsqueeze.post`       views, cones, plots, export
* :mod:`jaxsqueeze.io`         scenefile, cli

``jaxsqueeze.tracing`` (is a value a tracer), ``jaxsqueeze.numbers`` (is an input made of real
numbers) and ``jaxsqueeze.compiler`` (how the library's programs are compiled: options, one-kernel
regions, full-precision products) serve every layer and import from none
(``tests/test_layers.py``).

The main names are imported here. The module names of version 0.1 (``jaxsqueeze.fem``,
``jaxsqueeze.scene``, ``jaxsqueeze.views``, ...) keep working as aliases of their new homes;
the heavier ones (plots, export, cones, scenefile, cli) load on first use.
"""
__version__ = "0.2.0"      # the one place it is written: pyproject.toml reads it

import importlib
import importlib.abc
import importlib.util
import sys

from .geometry import mesh as _mesh_mod  # noqa: F401
from .geometry import shapes
from .geometry.mesh import Mesh, read_mesh, write_mesh
from .mechanics import fem
from .mechanics.bordered import Deformation, deform
from .mechanics.material import Material
from .mechanics.operator import Compliance
from .simulation import scene
from .simulation.api import squeeze
from .simulation.result import EventLog, SqueezeResult
from .simulation.scene import Adversary, Fingers, Placement, Scene, Settings
from .simulation.status import Status

#: old flat module name -> its home in the layered package
MODULES = {
    "mesh": "geometry.mesh", "shapes": "geometry.shapes", "curves": "geometry.curves",
    "boundary": "geometry.boundary",
    "material": "mechanics.material", "fem": "mechanics.fem", "operator": "mechanics.operator",
    "band": "mechanics.band", "bordered": "mechanics.bordered", "linalg": "mechanics.linalg",
    "status": "simulation.status", "scene": "simulation.scene", "engine": "simulation.engine",
    "grasp": "simulation.api", "result": "simulation.result", "laws": "simulation.laws",
    "views": "post.views", "cones": "post.cones", "plots": "post.plots", "export": "post.export",
    "scenefile": "io.scenefile", "cli": "io.cli",
}

__all__ = ["Adversary", "Compliance", "Deformation", "EventLog", "Fingers", "Material", "Mesh", "Placement", "Scene",
           "Settings", "SqueezeResult", "Status", "deform", "fem", "grasp_map", "optimize_placement", "plan", "quality",
           "read_mesh", "scene", "shapes", "squeeze", "write_mesh"]


def __getattr__(name):
    if name in MODULES:
        return importlib.import_module(f"{__name__}.{MODULES[name]}")
    if name in ("plan", "quality", "grasp_map", "optimize_placement", "candidate_pairs"):
        plan = importlib.import_module(f"{__name__}.plan")
        return plan if name == "plan" else getattr(plan, name)
    raise AttributeError(f"module 'jaxsqueeze' has no attribute {name!r}")


class _AliasFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """``import jaxsqueeze.fem`` (an old flat name) imports ``jaxsqueeze.mechanics.fem``."""

    def find_spec(self, fullname, path=None, target=None):
        head, _, tail = fullname.partition(".")
        if head == __name__ and tail in MODULES:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):
        module = importlib.import_module(f"{__name__}.{MODULES[spec.name.partition('.')[2]]}")
        spec.loader_state = module.__spec__      # importlib overwrites __spec__; put it back below
        return module

    def exec_module(self, module):
        module.__spec__ = module.__spec__.loader_state


if not any(isinstance(f, _AliasFinder) for f in sys.meta_path):
    sys.meta_path.append(_AliasFinder())
