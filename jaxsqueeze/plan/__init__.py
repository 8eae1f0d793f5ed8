"""Planning layer: continuous finger placement, grasp quality, grasp maps and placement search
(DESIGN 2.9). Builds on :mod:`jaxsqueeze.simulation`; never imported by it."""
from ..simulation.scene import Adversary, Placement
from ..simulation.validate import PlacementResolutionWarning
from . import quality
from .search import GraspMap, Search, candidate_pairs, evaluate, grasp_map, optimize_placement, roles_symmetric

__all__ = ["Adversary", "GraspMap", "Placement", "PlacementResolutionWarning", "Search", "candidate_pairs", "evaluate",
           "grasp_map", "optimize_placement", "quality", "roles_symmetric"]
