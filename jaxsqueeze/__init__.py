"""jaxsqueeze: differentiable two-finger squeeze grasps of soft planar objects."""
from . import fem, shapes
from .bordered import Deformation, deform
from .grasp import EventLog, SqueezeResult, squeeze
from .material import Material
from .mesh import Mesh, read_mesh, write_mesh
from .operator import Compliance
from .scene import Fingers, Scene, Settings
from .status import Status

__all__ = ["Compliance", "Deformation", "EventLog", "Fingers", "Material", "Mesh", "Scene", "Settings",
           "SqueezeResult", "Status", "deform", "fem", "read_mesh", "shapes", "squeeze", "write_mesh"]
__version__ = "0.1.0"
