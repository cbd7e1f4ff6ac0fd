"""Constraint families: each module holds one family's residuals and Jacobian side by side."""

from .angle import ConstantAngle
from .base import Constraint, NetState, VariableBlocks
from .closeness import BoundaryGliding, Closeness
from .collapse import EdgeCollapseBarrier, EdgeLengthRange
from .deviation import DeviationBound
from .fairness import DisplacementFairness, Fairness
from .guards import ConvexQuads, NormalCone, StarAngleRange
from .levels import FamilyLevels
from .mannheim import (
    ConstantMannheimRadius,
    ContactNormals,
    MannheimTangency,
    NormalNormalization,
    RulingAngle,
)
from .orientation import CoherentOrientation
from .planarity import PlanarFaces, PlanarityBound, PlaneNormalization
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
    "PlanarityBound",
    "PlaneNormalization",
    "Fairness",
    "DisplacementFairness",
    "NormalCone",
    "StarAngleRange",
    "ConvexQuads",
    "DeviationBound",
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
