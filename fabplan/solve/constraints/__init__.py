"""Constraint families: each module holds one family's residuals and Jacobian side by side."""

from .angle import ConstantAngle
from .base import Constraint, NetState, VariableBlocks
from .closeness import BoundaryGliding, Closeness
from .collapse import EdgeCollapseBarrier, EdgeLengthRange
from .fairness import Fairness
from .guards import NormalCone, StarAngleRange
from .levels import FamilyLevels
from .mannheim import (
    ConstantMannheimRadius,
    ContactNormals,
    MannheimTangency,
    NormalNormalization,
    RulingAngle,
)
from .orientation import CoherentOrientation
from .planarity import PlanarFaces, PlaneNormalization
from .radius import ConstantCurvature
from .sphere import SphereCondition, SphereNormalization

__all__ = [
    "Constraint",
    "VariableBlocks",
    "NetState",
    "SphereCondition",
    "SphereNormalization",
    "ConstantAngle",
    "ConstantCurvature",
    "CoherentOrientation",
    "PlanarFaces",
    "PlaneNormalization",
    "Fairness",
    "NormalCone",
    "StarAngleRange",
    "EdgeCollapseBarrier",
    "EdgeLengthRange",
    "FamilyLevels",
    "ContactNormals",
    "NormalNormalization",
    "MannheimTangency",
    "ConstantMannheimRadius",
    "RulingAngle",
    "Closeness",
    "BoundaryGliding",
]
