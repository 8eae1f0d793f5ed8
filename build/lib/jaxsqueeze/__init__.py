"""jaxsqueeze: differentiable two-finger squeeze grasps of soft planar objects.

The main names are imported here; the heavier submodules (``plots``, ``export``, ``views``,
``band``, ``curves``, ``cones``, ``scenefile``) load on first use.
"""
import importlib

from . import fem, scene, shapes
from .bordered import Deformation, deform
from .grasp import EventLog, SqueezeResult, squeeze
from .material import Material
from .mesh import Mesh, read_mesh, write_mesh
from .operator import Compliance
from .scene import Fingers, Scene, Settings
from .status import Status

_LAZY = ("band", "cones", "curves", "export", "plots", "scenefile", "views")

__all__ = ["Compliance", "Deformation", "EventLog", "Fingers", "Material", "Mesh", "Scene", "Settings",
           "SqueezeResult", "Status", "deform", "fem", "read_mesh", "scene", "shapes", "squeeze", "write_mesh",
           *_LAZY]
__version__ = "0.1.0"


def __getattr__(name):
    if name in _LAZY:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'jaxsqueeze' has no attribute {name!r}")
