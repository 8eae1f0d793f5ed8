"""jaxsqueeze: differentiable two-finger squeeze grasps of soft planar objects."""
from . import fem, shapes
from .material import Material
from .mesh import Mesh, read_mesh, write_mesh
from .operator import Compliance
from .status import Status

__all__ = ["Compliance", "Material", "Mesh", "Status", "fem", "read_mesh", "shapes", "write_mesh"]
__version__ = "0.1.0"
