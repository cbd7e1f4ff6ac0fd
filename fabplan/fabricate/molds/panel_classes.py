"""Panel classes: flat, cold-bent, roll-bent or molded, each checked on the dense samples.

A mold is the dear way to make a curved panel. Every panel goes to the cheapest class whose
check it passes (`classify_panels`), for a sheet `fabplan.fabricate.molds.materials.Material`,
on the same densely sampled panel surfaces the mold plan verifies (`fabplan.fabricate.molds`):

``flat``
    a plane fits the samples within the flatness tolerance: the mold tolerance, or less
    where the material's product standard allows a flat pane only a smaller bow
    (``flatness_mm_per_m`` times the panel's span).
``cold_bent``
    a flat sheet bent onto its supports takes a shape of the family of a plate under edge
    moments and corner forces: ``z = (a x^2 + 2 b x y + c y^2) / 2`` (a hyperbolic
    paraboloid ``z = b x y``, the pure twist corner forces give, plus the cylindrical
    components of edge moments; every quadratic solves the plate equation). The best such
    shape (least squares, with tilt and offset) must fit the samples within the mold
    tolerance, and the stress of that shape, bending (`materials.bending_stress_mpa`) plus
    the membrane stress of its Gaussian curvature (`materials.membrane_stress_mpa`), must
    stay within the material's cold-bend limit.
``roll_bent``
    a cone (a cylinder when its taper is nil) fitted to the samples (Levenberg-Marquardt on
    the distance to the cone) within the mold tolerance, its smallest radius of curvature
    at least the material's smallest roll radius.
``molded``
    the rest: only these need a mold.

The order flat, cold-bent, roll-bent, molded is the default order of cost; a study whose
``[cost]`` makes roll bending the cheaper tries it before cold bending (`class_order`).

Coordinates in model units in, every figure out in millimetres, MPa and 1/mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .materials import Material, bending_stress_mpa, membrane_stress_mpa

__all__ = [
    "CLASSES",
    "DEFAULT_ORDER",
    "PanelClasses",
    "class_order",
    "classify_panels",
    "bent_shape_fits",
    "plane_fits",
    "cone_fits",
]

CLASSES = ("flat", "cold_bent", "roll_bent", "molded")
"""The panel classes, cheapest first by default; indices of `PanelClasses.panel_class`."""

DEFAULT_ORDER = ("flat", "cold_bent", "roll_bent", "molded")

CLASS_WORDS = {"flat": "flat", "cold_bent": "cold-bent", "roll_bent": "roll-bent",
               "molded": "molded"}
"""The classes in words, for reports."""


def class_order(cold_bent_cost: float, roll_bent_cost: float) -> tuple[str, ...]:
    """The order the classes are tried in: flat first, molded last, cold and roll bending by
    their cost (cold bending first on a tie).

    Examples
    --------
    >>> class_order(1.5, 2.0), class_order(3.0, 2.0)[1]
    (('flat', 'cold_bent', 'roll_bent', 'molded'), 'roll_bent')
    """
    middle = ("roll_bent", "cold_bent") if roll_bent_cost < cold_bent_cost else ("cold_bent", "roll_bent")
    return ("flat", *middle, "molded")


# ----------------------------------------------------------------------------- fits
def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def _local(points_mm: np.ndarray, origin_mm: np.ndarray, frame: np.ndarray) -> np.ndarray:
    """(p, s, 3) coordinates of points (p, s, 3) in frames (p, 3, 3) (rows x, y, n) at origins."""
    return np.einsum("pij,psj->psi", frame, points_mm - origin_mm[:, None, :])


def _gap(residual: np.ndarray) -> np.ndarray:
    """Half the spread of residuals (p, s): the largest gap once shifted to even it out."""
    return 0.5 * (residual.max(axis=1) - residual.min(axis=1))


def plane_fits(q: np.ndarray) -> np.ndarray:
    """Gap (mm) of the least-squares plane ``z = c0 + c1 x + c2 y`` to local points q (p, s, 3) mm,
    shifted along z to even out the gap.

    Examples
    --------
    >>> q = np.zeros((1, 4, 3)); q[0, :, :2] = [[0, 0], [1, 0], [0, 1], [1, 1]]; q[0, 3, 2] = 2.0
    >>> plane_fits(q)
    array([0.5])
    """
    A = np.concatenate([np.ones_like(q[..., :1]), q[..., :2]], axis=2)
    c = _solve_least_squares(A, q[..., 2])
    return _gap(q[..., 2] - np.einsum("psk,pk->ps", A, c))


def _solve_least_squares(A: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Per-panel least squares ``A c = z`` for A (p, s, k), z (p, s): c (p, k), columns
    scaled for conditioning."""
    scale = np.maximum(np.abs(A).max(axis=1), 1e-300)            # (p, k)
    As = A / scale[:, None, :]
    lhs = np.einsum("psi,psj->pij", As, As) + 1e-12 * np.eye(A.shape[2])
    rhs = np.einsum("psi,ps->pi", As, z)
    return np.linalg.solve(lhs, rhs[..., None])[..., 0] / scale


def bent_shape_fits(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The best bent shape ``z = c0 + c1 x + c2 y + (a x^2 + 2 b x y + c y^2) / 2`` of local
    points q (p, s, 3) (mm), by least squares.

    Returns
    -------
    curvature : (p, 3) float, ``(a, c, b)`` = ``(k_xx, k_yy, k_xy)`` (1/mm): the curvature
        tensor of the shape in the local frame, ``k_xy`` its twist ``w_xy``.
    gap : (p,) float, mm, its largest gap to the points once shifted along z.

    Examples
    --------
    >>> x, y = np.meshgrid(np.linspace(-500, 500, 5), np.linspace(-400, 400, 5))
    >>> q = np.stack([x.ravel(), y.ravel(), 2e-5 * (x * y).ravel()], -1)[None]
    >>> k, gap = bent_shape_fits(q)
    >>> np.round(k / 1e-5, 9).tolist(), float(np.round(gap, 9)[0])
    ([[0.0, 0.0, 2.0]], 0.0)
    """
    x, y = q[..., 0], q[..., 1]
    A = np.stack([np.ones_like(x), x, y, 0.5 * x * x, x * y, 0.5 * y * y], axis=2)
    c = _solve_least_squares(A, q[..., 2])
    gap = _gap(q[..., 2] - np.einsum("psk,pk->ps", A, c))
    return np.stack([c[:, 3], c[:, 5], c[:, 4]], axis=1), gap


def principal_curvatures(curvature: np.ndarray) -> np.ndarray:
    """(p, 2) ``k1 >= k2`` of curvature tensors ``(k_xx, k_yy, k_xy)`` (p, 3)."""
    mean = 0.5 * (curvature[:, 0] + curvature[:, 1])
    half = np.hypot(0.5 * (curvature[:, 0] - curvature[:, 1]), curvature[:, 2])
    return np.stack([mean + half, mean - half], axis=1)


def _cone_residuals(P: np.ndarray, C: np.ndarray, d: np.ndarray, r0: np.ndarray,
                    t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distances (p, s) of points P (p, s, 3) from cones (apex side aside) with axis
    through C (p, 3) along unit d (p, 3), radius ``r0 + t s`` at axial coordinate s; and s."""
    v = P - C[:, None, :]
    s = np.einsum("psi,pi->ps", v, d)
    rho = np.linalg.norm(v - s[..., None] * d[:, None, :], axis=2)
    return (rho - r0[:, None] - t[:, None] * s) / np.sqrt(1.0 + t * t)[:, None], s


def cone_fits(P: np.ndarray, C: np.ndarray, d: np.ndarray, r0: np.ndarray,
              iterations: int = 30, fit_samples: int = 150) -> dict[str, np.ndarray]:
    """Fit cones (cylinders with taper 0) to points, from a start cylinder.

    Levenberg-Marquardt on the points' distances to the cone: six unknowns per panel, the
    axis turned in the two directions across it, moved in the two directions across it,
    the radius at the foot of the panel's centre and the taper ``dr / ds``; finite-difference
    Jacobians for every panel at once.

    Parameters
    ----------
    P : (p, s, 3) float, mm; C : (p, 3) start axis point; d : (p, 3) start axis direction;
    r0 : (p,) start radius (mm).
    iterations : cap on the Levenberg-Marquardt steps (they stop when no panel improves).
    fit_samples : the cone is fitted to about this many of each panel's samples (evenly
        strided); its gap is measured on all of them.

    Returns
    -------
    dict of (p, ...) arrays: ``point`` (axis point nearest the samples' centre, mm),
    ``direction`` (unit), ``radius_mm`` (at ``point``), ``taper``, ``gap_mm`` (largest
    distance once the radius evens out the gap), ``min_radius_mm`` (the smallest radius of
    curvature over the samples: ``(r0 + t s) sqrt(1 + t^2)``).
    """
    p = len(P)
    centre = P.mean(axis=1)
    d = _unit(d)
    every = P
    P = P[:, ::max(1, P.shape[1] // fit_samples)]

    def frame(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        helper = np.where(np.abs(d[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
        u = _unit(np.cross(d, helper))
        return u, np.cross(d, u)

    def state(C: np.ndarray, d: np.ndarray, r0: np.ndarray, t: np.ndarray, th: np.ndarray):
        u, v = frame(d)
        d2 = _unit(d + th[:, :1] * u + th[:, 1:2] * v)
        C2 = C + th[:, 2:3] * u + th[:, 3:4] * v
        return C2, d2, r0 + th[:, 4], t + th[:, 5]

    t = np.zeros(p)
    scale = np.maximum(np.abs(r0), 1.0)
    # steps: angles, lengths (mm), radius (mm), taper
    h = np.stack([np.full(p, 1e-7), np.full(p, 1e-7), 1e-7 * scale, 1e-7 * scale,
                  1e-7 * scale, np.full(p, 1e-7)], axis=1)
    lam = np.full(p, 1e-3)

    def cost(C, d, r0, t):
        f, _ = _cone_residuals(P, C, d, r0, t)
        return f, np.einsum("ps,ps->p", f, f)

    f, current = cost(C, d, r0, t)
    for _ in range(iterations):
        J = np.empty(f.shape + (6,))
        for k in range(6):
            step = np.zeros((p, 6))
            step[:, k] = h[:, k]
            fk, _ = cost(*state(C, d, r0, t, step))
            J[..., k] = (fk - f) / h[:, k:k + 1]
        JtJ = np.einsum("psi,psj->pij", J, J)
        g = np.einsum("psi,ps->pi", J, f)
        diag = np.einsum("pii->pi", JtJ) + 1e-30
        lhs = JtJ + (lam[:, None] * diag)[:, :, None] * np.eye(6)
        delta = -np.linalg.solve(lhs, g[..., None])[..., 0]
        C2, d2, r2, t2 = state(C, d, r0, t, delta)
        f2, trial = cost(C2, d2, r2, t2)
        better = trial < current
        # settled: the step gains nothing measurable, or the damping has grown huge
        settled = ~better & (lam >= 1e6) | better & (current - trial <= 1e-12 * current)
        C = np.where(better[:, None], C2, C)
        d = np.where(better[:, None], d2, d)
        r0, t = np.where(better, r2, r0), np.where(better, t2, t)
        f = np.where(better[:, None], f2, f)
        current = np.where(better, trial, current)
        lam = np.where(better, lam * 0.3, lam * 10.0)
        lam = np.clip(lam, 1e-12, 1e12)
        if settled.all():
            break
    P = every
    # the axis point nearest the centre, its radius, and the radius evening out the gap
    s_c = np.einsum("pi,pi->p", centre - C, d)
    C = C + s_c[:, None] * d
    r0 = r0 + t * s_c
    f, s = _cone_residuals(P, C, d, r0, t)
    shift = 0.5 * (f.max(axis=1) + f.min(axis=1)) * np.sqrt(1.0 + t * t)
    r0 = r0 + shift
    f, s = _cone_residuals(P, C, d, r0, t)
    return {"point": C, "direction": d, "radius_mm": r0, "taper": t, "gap_mm": _gap(f),
            "min_radius_mm": (r0[:, None] + t[:, None] * s).min(axis=1) * np.sqrt(1.0 + t * t)}


# ----------------------------------------------------------------------------- classes
@dataclass
class PanelClasses:
    """Every panel's class and the figures its checks measured.

    Attributes
    ----------
    material : the sheet.
    tolerance_mm : the mold tolerance every bent or rolled shape must fit within.
    order : the classes in the order they were tried.
    panel_class : (p,) int, index into `CLASSES`.
    origin : (p, 3) float, the centre of every panel's samples (model units).
    frame : (p, 3, 3) float, rows: x (along the panel's first edge, in its tangent plane),
        y, and the unit normal of its surface: the frame of its bent shape.
    span_mm : (p,) float, twice the farthest sample from the centre (the diagonal of a
        rectangle), mm.
    plane_gap_mm, flat_limit_mm : (p,) float, the plane's gap and the flatness tolerance.
    curvature : (p, 3) float, ``(k_xx, k_yy, k_xy)`` of the best bent shape in `frame`
        (1/mm); ``k_xy`` is its twist.
    principal : (p, 2) float, its principal curvatures ``k1 >= k2`` (1/mm).
    bent_gap_mm : (p,) float, the bent shape's gap to the samples.
    bending_stress_mpa, membrane_stress_mpa, stress_mpa : (p,) float, its stresses (the
        sum governs).
    roll : dict of (p, ...) arrays from `cone_fits` (NaN where no cone was fitted: the
        material is not rolled, or a cheaper class took the panel first).
    """

    material: Material
    tolerance_mm: float
    order: tuple[str, ...]
    panel_class: np.ndarray
    origin: np.ndarray
    frame: np.ndarray
    span_mm: np.ndarray
    plane_gap_mm: np.ndarray
    flat_limit_mm: np.ndarray
    curvature: np.ndarray
    principal: np.ndarray
    bent_gap_mm: np.ndarray
    bending_stress_mpa: np.ndarray
    membrane_stress_mpa: np.ndarray
    stress_mpa: np.ndarray
    roll: dict[str, np.ndarray]

    @property
    def counts(self) -> dict[str, int]:
        """Panels of every class."""
        return {c: int(np.sum(self.panel_class == i)) for i, c in enumerate(CLASSES)}

    @property
    def molded(self) -> np.ndarray:
        """(p,) bool, the panels that need a mold."""
        return self.panel_class == CLASSES.index("molded")

    def passes(self) -> dict[str, np.ndarray]:
        """(p,) bool per class: the panels whose check for it passes (molded: all)."""
        m, tol = self.material, self.tolerance_mm
        roll = (np.isfinite(self.roll["gap_mm"]) & (self.roll["gap_mm"] <= tol)
                & (self.roll["min_radius_mm"] >= (m.min_roll_radius_mm or math.inf)))
        return {"flat": self.plane_gap_mm <= self.flat_limit_mm,
                "cold_bent": (self.bent_gap_mm <= tol) & (self.stress_mpa <= m.max_bend_stress_mpa),
                "roll_bent": roll,
                "molded": np.ones(len(self.panel_class), bool)}

    def figure(self) -> tuple[np.ndarray, np.ndarray, list[str]]:
        """Every panel's governing figure, its limit and their unit: the plane's gap (mm)
        against the flatness tolerance for a flat panel, the stress (MPa) against the
        cold-bend limit for a cold-bent or a molded one, the smallest radius (mm) against
        the smallest roll radius for a roll-bent one."""
        n = len(self.panel_class)
        value = self.stress_mpa.copy()
        limit = np.full(n, self.material.max_bend_stress_mpa)
        unit = ["MPa"] * n
        flat = self.panel_class == CLASSES.index("flat")
        value[flat], limit[flat] = self.plane_gap_mm[flat], self.flat_limit_mm[flat]
        roll = self.panel_class == CLASSES.index("roll_bent")
        value[roll] = self.roll["min_radius_mm"][roll]
        limit[roll] = self.material.min_roll_radius_mm or math.inf
        for i in np.flatnonzero(flat | roll):
            unit[i] = "mm"
        return value, limit, unit

    def reason(self, i: int) -> str:
        """Why panel `i` is of its class, in words with its figures."""
        m, tol = self.material, self.tolerance_mm
        c = CLASSES[self.panel_class[i]]
        if c == "flat":
            return (f"flat: within {self.plane_gap_mm[i]:.2f} mm of a plane "
                    f"(flatness tolerance {self.flat_limit_mm[i]:.2f} mm)")
        cold = (f"bent shape within {self.bent_gap_mm[i]:.2f} mm, stress "
                f"{self.stress_mpa[i]:.1f} MPa (bending {self.bending_stress_mpa[i]:.1f}, "
                f"membrane {self.membrane_stress_mpa[i]:.1f}; limit {m.max_bend_stress_mpa:.3g} MPa)")
        if c == "cold_bent":
            return "cold-bent: " + cold
        if c == "roll_bent":
            return (f"roll-bent: {'cone' if self.roll_kind()[i] == 'cone' else 'cylinder'} within "
                    f"{self.roll['gap_mm'][i]:.2f} mm, smallest radius "
                    f"{self.roll['min_radius_mm'][i]:.0f} mm (limit {m.min_roll_radius_mm:.3g} mm)")
        why = []
        if self.bent_gap_mm[i] > tol:
            why.append(f"no bent shape within {tol:g} mm (best {self.bent_gap_mm[i]:.2f} mm)")
        elif self.stress_mpa[i] > m.max_bend_stress_mpa:
            why.append(f"cold bending stresses it to {self.stress_mpa[i]:.1f} MPa (limit "
                       f"{m.max_bend_stress_mpa:.3g} MPa)")
        if m.min_roll_radius_mm is None:
            why.append(f"{m.name} is not roll-bent")
        elif np.isfinite(self.roll["gap_mm"][i]):
            if self.roll["gap_mm"][i] > tol:
                why.append(f"no cone within {tol:g} mm (best {self.roll['gap_mm'][i]:.2f} mm)")
            else:
                why.append(f"its radius {self.roll['min_radius_mm'][i]:.0f} mm is below the "
                           f"smallest roll radius {m.min_roll_radius_mm:.3g} mm")
        return "molded: " + "; ".join(why)

    def roll_kind(self) -> list[str]:
        """``"cylinder"``, ``"cone"`` or ``""`` (no cone fitted) per panel: a cone whose
        radius changes by less than the tolerance over the panel's span is a cylinder."""
        t, span = self.roll["taper"], self.span_mm
        return ["" if not np.isfinite(t[i]) else
                ("cylinder" if abs(t[i]) * span[i] <= self.tolerance_mm else "cone")
                for i in range(len(t))]

    def record(self, mm_per_unit: float) -> dict:
        """The classes as JSON: the material, counts, and per panel its class, figure,
        limit, bent shape and cone (``molds.json`` ``panel_classes``; schema in
        ``docs/molds-schema.md``)."""
        value, limit, unit = self.figure()
        kinds = self.roll_kind()
        panels = []
        for i in range(len(self.panel_class)):
            entry: dict = {
                "face": i,
                "class": CLASSES[self.panel_class[i]],
                "figure": float(value[i]), "limit": float(limit[i]), "unit": unit[i],
                "reason": self.reason(i),
                "plane_gap_mm": float(self.plane_gap_mm[i]),
                "flat_limit_mm": float(self.flat_limit_mm[i]),
                "bent_shape": {
                    "origin": self.origin[i].tolist(),
                    "x_axis": self.frame[i, 0].tolist(), "y_axis": self.frame[i, 1].tolist(),
                    "normal": self.frame[i, 2].tolist(),
                    "curvature_per_mm": self.curvature[i].tolist(),
                    "twist_per_mm": float(self.curvature[i, 2]),
                    "principal_per_mm": self.principal[i].tolist(),
                    "gap_mm": float(self.bent_gap_mm[i]),
                    "span_mm": float(self.span_mm[i]),
                    "bending_stress_mpa": float(self.bending_stress_mpa[i]),
                    "membrane_stress_mpa": float(self.membrane_stress_mpa[i]),
                    "stress_mpa": float(self.stress_mpa[i]),
                },
            }
            if kinds[i]:
                entry["roll"] = {
                    "kind": kinds[i],
                    "axis_point": (self.roll["point"][i] / mm_per_unit).tolist(),
                    "axis_direction": self.roll["direction"][i].tolist(),
                    "radius_mm": float(self.roll["radius_mm"][i]),
                    "taper": float(self.roll["taper"][i]),
                    "min_radius_mm": float(self.roll["min_radius_mm"][i]),
                    "gap_mm": float(self.roll["gap_mm"][i]),
                }
            panels.append(entry)
        m = self.material
        return {
            "material": m.record(),
            "tolerance_mm": self.tolerance_mm,
            "order": list(self.order),
            "counts": self.counts,
            "max_stress_mpa": float(self.stress_mpa[self.panel_class == 1].max())
            if np.any(self.panel_class == 1) else None,
            "panels": panels,
        }


def classify_panels(mesh, dense: np.ndarray, normal: np.ndarray, material: Material,
                    tolerance_mm: float, mm_per_unit: float,
                    order: tuple[str, ...] = DEFAULT_ORDER) -> PanelClasses:
    """The class of every panel (see the module notes), checked on its dense samples.

    Parameters
    ----------
    mesh : the net (`fabplan.net.mesh.QuadMesh`): its faces' first edges orient the frames.
    dense : (p, s, 3) float, the panels' dense samples (model units), as the mold plan
        verifies them (`fabplan.fabricate.molds.panels.panel_samples` and its kin).
    normal : (p, 3) float, the unit normal of every panel surface at its centre.
    material : the sheet; tolerance_mm : the mold tolerance; mm_per_unit : mm per model unit.
    order : the classes in the order they are tried (`class_order`); flat first, molded last.

    Returns
    -------
    PanelClasses
    """
    if order[0] != "flat" or order[-1] != "molded" or sorted(order) != sorted(CLASSES):
        raise ValueError(f"class order {order}: flat first, molded last, each class once")
    P = dense * mm_per_unit
    origin = P.mean(axis=1)
    X = mesh.vertices * mm_per_unit
    first = mesh.face_indices[mesh.face_indptr[:-1]]
    second = mesh.face_indices[mesh.face_indptr[:-1] + 1]
    n = _unit(normal)
    edge = X[second] - X[first]
    x = _unit(edge - np.sum(edge * n, axis=1, keepdims=True) * n)
    frame = np.stack([x, np.cross(n, x), n], axis=1)
    q = _local(P, origin, frame)
    radius = np.linalg.norm(q[..., :2], axis=2).max(axis=1)
    span = 2.0 * radius

    plane_gap = plane_fits(q)
    flat_limit = np.full(len(P), float(tolerance_mm))
    if material.flatness_mm_per_m is not None:
        flat_limit = np.minimum(flat_limit, material.flatness_mm_per_m * span / 1000.0)
    curvature, bent_gap = bent_shape_fits(q)
    principal = principal_curvatures(curvature)
    bending = bending_stress_mpa(material, principal[:, 0], principal[:, 1])
    membrane = membrane_stress_mpa(material, principal[:, 0] * principal[:, 1], radius)
    stress = bending + membrane

    nan3 = np.full((len(P), 3), np.nan)
    roll = {"point": nan3.copy(), "direction": nan3.copy(), **{
        k: np.full(len(P), np.nan) for k in ("radius_mm", "taper", "gap_mm", "min_radius_mm")}}
    classes = PanelClasses(material=material, tolerance_mm=float(tolerance_mm), order=tuple(order),
                           panel_class=np.full(len(P), CLASSES.index("molded")), origin=origin / mm_per_unit,
                           frame=frame, span_mm=span, plane_gap_mm=plane_gap,
                           flat_limit_mm=flat_limit, curvature=curvature, principal=principal,
                           bent_gap_mm=bent_gap, bending_stress_mpa=bending,
                           membrane_stress_mpa=membrane, stress_mpa=stress, roll=roll)
    passes = classes.passes()
    decided = np.zeros(len(P), bool)
    for name in order:
        if name == "roll_bent" and material.min_roll_radius_mm is not None:
            # cones only for the panels no cheaper class took, with a curved direction
            todo = np.flatnonzero(~decided & (np.abs(principal).max(axis=1) > 1e-12))
            if todo.size:
                _fit_rolls(classes, q, todo, origin, frame)
                passes = classes.passes()
        take = ~decided & passes[name]
        classes.panel_class[take] = CLASSES.index(name)
        decided |= take
    return classes


#: panels per block of cone fits (the Jacobian's temporaries stay small)
_CONE_BLOCK = 256


def _fit_rolls(classes: PanelClasses, q: np.ndarray, todo: np.ndarray, origin: np.ndarray,
               frame: np.ndarray) -> None:
    """Fit cones to the panels `todo`, from the cylinder of their larger principal curvature
    in magnitude, into ``classes.roll`` (mm, model coordinates scaled to mm)."""
    k = classes.curvature[todo]
    # principal direction of the larger |k| in the local frame: the cylinder bends along it
    angle = 0.5 * np.arctan2(2.0 * k[:, 2], k[:, 0] - k[:, 1])
    kk = classes.principal[todo]
    big = np.where(np.abs(kk[:, 0]) >= np.abs(kk[:, 1]), kk[:, 0], kk[:, 1])
    across = np.where((np.abs(kk[:, 0]) >= np.abs(kk[:, 1]))[:, None],
                      np.stack([np.cos(angle), np.sin(angle)], 1),
                      np.stack([-np.sin(angle), np.cos(angle)], 1))
    axis_local = np.stack([-across[:, 1], across[:, 0], np.zeros(len(todo))], axis=1)
    for b in range(0, len(todo), _CONE_BLOCK):
        rows = slice(b, b + _CONE_BLOCK)
        faces = todo[rows]
        F = frame[faces]
        C_local = np.zeros((len(faces), 3))
        C_local[:, 2] = 1.0 / big[rows]
        fit = cone_fits(q[faces], C_local, axis_local[rows], np.abs(1.0 / big[rows]))
        # back to model-aligned coordinates (mm): local rows (x, y, n) of the frame
        classes.roll["point"][faces] = origin[faces] + np.einsum("pji,pj->pi", F, fit["point"])
        classes.roll["direction"][faces] = np.einsum("pji,pj->pi", F, fit["direction"])
        for key in ("radius_mm", "taper", "gap_mm", "min_radius_mm"):
            classes.roll[key][faces] = fit[key]
