"""The catalogue of net types (Table 2 of the paper) as named presets of constraint families."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..io.parameters import OPTIONS
from .constraints import (
    CoherentOrientation,
    ConstantAngle,
    ConstantCurvature,
    ConstantMannheimRadius,
    Constraint,
    ContactNormals,
    MannheimTangency,
    NormalNormalization,
    PlanarFaces,
    PlaneNormalization,
    RulingAngle,
    SphereCondition,
    SphereNormalization,
)

__all__ = ["NetType", "NETS", "get_net", "net_constraints"]


@dataclass(frozen=True)
class NetType:
    """A named preset.

    Attributes
    ----------
    name : the name used on the command line.
    summary : the defining properties in one line.
    angle : "none" (unconstrained), "param" (prescribed with --angle, else a free common
        angle) or "right" (90 degrees).
    radius : "none", "param" (prescribed with --radius, else a free common radius) or
        "infinite" (planar vertex stars: an A-net).
    planar_faces : every quad planar.
    coherent : spheres kept on one side of the surface.
    dual : an S*-net: contact elements whose tangent planes touch Mannheim spheres; its
        angle is measured between cone rulings, its radius is the Mannheim radius and
        "zero" radius makes the five planes of a star pass through one point.
    """

    name: str
    summary: str
    angle: str = "none"
    radius: str = "none"
    planar_faces: bool = False
    coherent: bool = False
    dual: bool = False


NETS: dict[str, NetType] = {n.name: n for n in [
    NetType("snet", "general S-net: every regular vertex and its four neighbours on a sphere"),
    NetType("isogonal", "S-net with a constant intersection angle (--angle, or free)",
            angle="param"),
    NetType("orthogonal", "S-net whose families meet at 90 deg (bisecting the principal "
            "directions)", angle="right"),
    NetType("const-radius", "S-net whose Meusnier spheres share one radius (--radius, or free): "
            "both families of constant normal curvature", radius="param", coherent=False),
    NetType("cmc", "orthogonal S-net of constant radius: constant mean curvature 1/r",
            angle="right", radius="param"),
    NetType("linear-weingarten", "isogonal S-net of constant radius: a k1 + b k2 = c "
            "(affine linear Weingarten surface)", angle="param", radius="param"),
    NetType("anet", "A-net: infinite Meusnier radius, every vertex star planar (asymptotic "
            "lines; lamellas unroll straight)", radius="infinite"),
    NetType("minimal", "orthogonal A-net: a discrete minimal surface (H = 0)",
            angle="right", radius="infinite"),
    NetType("constant-ratio", "isogonal A-net (--angle, or free): k1/k2 constant and negative",
            angle="param", radius="infinite"),
    NetType("char-conjugate", "S-net with planar quads: a characteristic conjugate net "
            "(flat panels)", planar_faces=True),
    NetType("mean-curvature-spheres", "orthogonal S-net with free radii: each Meusnier sphere "
            "is the mean curvature sphere (radius 1/H)", angle="right"),
    NetType("sstar", "general S*-net: the five tangent planes of every star touch one "
            "oriented sphere (the Mannheim sphere)", dual=True),
    NetType("sstar-isogonal", "S*-net whose cone rulings (Eq. 5) meet at a constant angle "
            "(--angle, or free)", angle="param", dual=True),
    NetType("sstar-orthogonal", "S*-net with orthogonal cone rulings; its Mannheim spheres "
            "are the mid-curvature spheres", angle="right", dual=True),
    NetType("sstar-const-radius", "S*-net whose Mannheim spheres share one radius "
            "(--radius, or free)", radius="param", dual=True),
    NetType("harmonic-mean", "orthogonal S*-net of constant Mannheim radius: constant "
            "harmonic mean curvature, (1/k1 + 1/k2)/2 = r", angle="right", radius="param",
            dual=True),
    NetType("dual-anet", "S*-net of Mannheim radius 0: the five tangent planes of every "
            "star pass through one point", radius="zero", dual=True),
]}


def get_net(name: str) -> NetType:
    """The preset called `name`; a clear error lists the known ones."""
    try:
        return NETS[name]
    except KeyError:
        raise InputError(f"unknown net type {name!r}; known: {', '.join(NETS)}") from None


def check_angle(angle_deg: float | None) -> None:
    """Refuse an intersection angle outside its range (`fabplan.io.parameters.OPTIONS`)."""
    if angle_deg is not None:
        OPTIONS["--angle"].check(angle_deg)


def check_radius(radius: float | None) -> None:
    """Refuse a Meusnier radius outside its range (`fabplan.io.parameters.OPTIONS`)."""
    if radius is not None:
        OPTIONS["--radius"].check(radius)


def net_constraints(net: NetType, *, angle_deg: float | None = None,
                    radius: float | None = None, length_scale: float = 1.0,
                    curvature_sign: float = 1.0) -> list[Constraint]:
    """The hard constraint families of a preset.

    Parameters
    ----------
    angle_deg : prescribed intersection angle in degrees; an angle above 90 is the same
        net with the families swapped, so ``min(angle, 180 - angle)`` is used.
    radius : prescribed Meusnier radius in model units.
    length_scale : model units per normalized unit of the solver.
    curvature_sign : side of the spheres for a prescribed radius: the sign of the normal
        curvature (S-nets) or of the Mannheim radius (S*-nets) of the start.
    """
    check_angle(angle_deg)
    check_radius(radius)
    if angle_deg is not None and net.angle != "param":
        raise InputError(f"net type {net.name!r} takes no --angle")
    if radius is not None and net.radius != "param":
        raise InputError(f"net type {net.name!r} takes no --radius")
    families: list[Constraint]
    angle_family: type[RulingAngle] | type[ConstantAngle]
    if net.dual:   # planes touching Mannheim spheres; angles between cone rulings
        families = [ContactNormals(), NormalNormalization(), MannheimTangency()]
        angle_family = RulingAngle
    else:          # vertices on Meusnier spheres; angles between osculating tangents
        families = [SphereCondition(), SphereNormalization()]
        angle_family = ConstantAngle
    if net.angle == "right":
        families.append(angle_family(0.0))
    elif net.angle == "param":
        cosine = None
        if angle_deg is not None:
            cosine = math.cos(math.radians(min(angle_deg, 180.0 - angle_deg)))
        families.append(angle_family(cosine))
    side = float(np.sign(curvature_sign) or 1.0)
    if net.radius == "infinite":
        families.append(ConstantCurvature(0.0))
    elif net.radius == "zero":
        families.append(ConstantMannheimRadius(0.0))
    elif net.radius == "param" and net.dual:
        families.append(ConstantMannheimRadius(None if radius is None else side * radius / length_scale))
    elif net.radius == "param":
        families.append(ConstantCurvature(None if radius is None else side * length_scale / radius))
    if net.planar_faces:
        families += [PlanarFaces(), PlaneNormalization()]
    if net.coherent:
        families.append(CoherentOrientation())
    return families
