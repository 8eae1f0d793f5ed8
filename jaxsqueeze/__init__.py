"""jaxsqueeze: differentiable two-finger squeeze grasps of soft planar objects."""
from . import fem
from .bordered import Deformation, deform
from .material import Material
from .mesh import Mesh
from .operator import Compliance
from .status import Status

__all__ = ["Compliance", "Deformation", "Material", "Mesh", "Status", "deform", "fem"]
__version__ = "0.1.0"
