"""Panel materials: what a sheet takes without a mold, with the published source of every number.

A `Material` is a sheet of a given thickness with three limits that decide how its panels
are made (`fabplan.fabricate.molds.panel_classes`):

- the **cold-bend limit** ``max_bend_stress_mpa``: the largest permanent surface stress the
  sheet takes when it is bent flat-to-shape onto its supports on site;
- the **roll-bend limit** ``min_roll_radius_mm``: the smallest radius a sheet is rolled to
  (None: the material is not rolled; a glass cylinder is hot-bent);
- the **flatness tolerance** ``flatness_mm_per_m``: the bow its product standard allows a
  flat pane, per metre of the panel's diagonal (None: the mold tolerance alone decides).

The stress of a bent plate (`bending_stress_mpa`, `membrane_stress_mpa`) follows the model
stated in ``docs/materials.md``, where every preset number is given with its source.

Presets are named ``glass-annealed``, ``glass-heat-strengthened``, ``glass-tempered``,
``glass-laminated`` (heat-strengthened plies), ``glass-laminated-tempered``, ``aluminium``
and ``steel``; `parse_material` reads ``NAME[:THICKNESS]`` (``glass-tempered:8mm``,
``glass-laminated:2x8mm``, ``aluminium:3mm``).
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass

import numpy as np

from ...errors import InputError

__all__ = [
    "Material",
    "MaterialPreset",
    "PRESETS",
    "material_preset",
    "parse_material",
    "material_from_table",
    "bending_stress_mpa",
    "membrane_stress_mpa",
]


@dataclass(frozen=True)
class Material:
    """A sheet material of a given thickness and the limits that decide its panels' class.

    Attributes
    ----------
    name : the preset's name (``glass-tempered``).
    label : the material in words (``tempered glass (EN 12150-1), 8 mm``).
    thickness_mm : thickness of one sheet or ply (mm).
    plies : sheets laminated together (1: monolithic).
    youngs_modulus_mpa : E (MPa).
    poisson : Poisson's ratio.
    max_bend_stress_mpa : the largest permanent surface stress of a cold-bent sheet (MPa).
    min_roll_radius_mm : the smallest radius a sheet is rolled to (mm); None: not rolled.
    flatness_mm_per_m : the overall bow its product standard allows a flat pane (mm per m
        of the panel's diagonal); None: a panel is flat within the mold tolerance.
    sources : the keys of its numbers' sources in ``docs/materials.md``.
    """

    name: str
    label: str
    thickness_mm: float
    plies: int
    youngs_modulus_mpa: float
    poisson: float
    max_bend_stress_mpa: float
    min_roll_radius_mm: float | None
    flatness_mm_per_m: float | None
    sources: tuple[str, ...] = ()

    @property
    def stress_thickness_mm(self) -> float:
        """The thickness the bending stress is computed with: for a laminate the plies'
        sum (full shear coupling through the interlayer, the larger stress; see
        ``docs/materials.md``)."""
        return self.thickness_mm * self.plies

    @property
    def plate_modulus_mpa_mm(self) -> float:
        """``E t / (2 (1 - nu^2))`` (MPa mm): surface stress per unit curvature (1/mm)."""
        return (self.youngs_modulus_mpa * self.stress_thickness_mm
                / (2.0 * (1.0 - self.poisson ** 2)))

    @property
    def spec(self) -> str:
        """The ``--material`` text that gives this material back (`parse_material`)."""
        t = f"{self.thickness_mm:g}mm"
        return f"{self.name}:{self.plies}x{t}" if self.plies > 1 else f"{self.name}:{t}"

    def record(self) -> dict:
        """The material as JSON (``molds.json`` ``material``)."""
        out = asdict(self)
        out["sources"] = list(self.sources)
        out["spec"] = self.spec
        out["stress_thickness_mm"] = self.stress_thickness_mm
        return out


def bending_stress_mpa(material: Material, k1: np.ndarray, k2: np.ndarray) -> np.ndarray:
    """Largest surface bending stress of a plate bent to principal curvatures ``k1, k2``.

    Kirchhoff plate: the moments of the curvature state are ``m_i = D (k_i + nu k_j)``, and
    the surface stress ``6 m / t^2 = E t / (2 (1 - nu^2)) (k_i + nu k_j)``; the larger in
    magnitude of the two governs. Pure twist ``w_xy`` (``k1 = -k2 = |w_xy|``) gives
    ``E t |w_xy| / (2 (1 + nu))``.

    Parameters
    ----------
    material : the sheet.
    k1, k2 : (p,) float, principal curvatures (1/mm).

    Returns
    -------
    (p,) float, MPa.

    Examples
    --------
    >>> m = material_preset("glass-tempered", 8.0)
    >>> round(float(bending_stress_mpa(m, np.array([1e-4]), np.array([-1e-4]))[0]), 6)  # twist 0.1 1/m
    23.333333
    """
    k1, k2 = np.asarray(k1, float), np.asarray(k2, float)
    nu = material.poisson
    return material.plate_modulus_mpa_mm * np.maximum(np.abs(k1 + nu * k2), np.abs(k2 + nu * k1))


def membrane_stress_mpa(material: Material, gauss: np.ndarray, radius_mm: np.ndarray) -> np.ndarray:
    """In-plane stress of a flat sheet held to a surface of Gaussian curvature ``K``.

    A flat disk of radius ``rho`` forced onto a surface of constant Gaussian curvature ``K``
    (Foeppl - von Karman compatibility ``lap^2 phi = -E K``, free edge) carries the
    hoop stress ``E K (rho^2 - 3 r^2) / 16``: ``E |K| rho^2 / 8`` at its edge, the largest.
    A panel is taken as the disk around it (`radius_mm`: its farthest point from its
    centre), an upper bound for the panel inside it.

    Parameters
    ----------
    gauss : (p,) float, ``k1 k2`` (1/mm^2); radius_mm : (p,) float.

    Returns
    -------
    (p,) float, MPa.

    Examples
    --------
    >>> m = material_preset("glass-tempered", 8.0)
    >>> float(membrane_stress_mpa(m, np.array([-1e-8]), np.array([1000.0]))[0])
    87.5
    """
    return (material.youngs_modulus_mpa * np.abs(np.asarray(gauss, float))
            * np.asarray(radius_mm, float) ** 2 / 8.0)


# ----------------------------------------------------------------------------- presets
@dataclass(frozen=True)
class MaterialPreset:
    """A named material: its constants, its limits per thickness, and their sources.

    Attributes
    ----------
    name, words : preset name and what it is.
    thickness_mm : default thickness (mm) of a sheet or ply; thickness_range_mm : (lo, hi).
    plies : default plies (1: monolithic; laminates 2).
    youngs_modulus_mpa, poisson, max_bend_stress_mpa : as `Material`.
    min_roll_radius_t : smallest roll radius in sheet thicknesses (None: not rolled).
    flatness_mm_per_m : as `Material`.
    sources : keys into ``docs/materials.md``.
    """

    name: str
    words: str
    thickness_mm: float
    thickness_range_mm: tuple[float, float]
    plies: int
    youngs_modulus_mpa: float
    poisson: float
    max_bend_stress_mpa: float
    min_roll_radius_t: float | None
    flatness_mm_per_m: float | None
    sources: tuple[str, ...]

    def material(self, thickness_mm: float | None = None, plies: int | None = None) -> Material:
        """The material at a thickness (mm, of one ply) and number of plies."""
        t = self.thickness_mm if thickness_mm is None else float(thickness_mm)
        n = self.plies if plies is None else int(plies)
        lo, hi = self.thickness_range_mm
        if not (math.isfinite(t) and lo <= t <= hi):
            raise InputError(f"material {self.name}: a thickness of {t:g} mm lies outside the "
                             f"{lo:g} .. {hi:g} mm its sources cover")
        if self.plies == 1 and n != 1:
            raise InputError(f"material {self.name} is a single sheet: give one thickness "
                             f"({self.name}:{t:g}mm), or a glass-laminated preset for plies")
        if not 1 <= n <= 4:
            raise InputError(f"material {self.name}: {n} plies; a laminate here has 2 to 4")
        thick = f"{n} x {t:g} mm" if n > 1 else f"{t:g} mm"
        roll = None if self.min_roll_radius_t is None else self.min_roll_radius_t * t * n
        return Material(name=self.name, label=f"{self.words}, {thick}", thickness_mm=t, plies=n,
                        youngs_modulus_mpa=self.youngs_modulus_mpa, poisson=self.poisson,
                        max_bend_stress_mpa=self.max_bend_stress_mpa, min_roll_radius_mm=roll,
                        flatness_mm_per_m=self.flatness_mm_per_m, sources=self.sources)


def _glass(name: str, words: str, thickness_mm: float, plies: int, stress_mpa: float,
           flatness_mm_per_m: float | None, sources: tuple[str, ...]) -> MaterialPreset:
    """A glass preset: E = 70000 MPa, nu = 0.2 (EN 572-1), 3 to 25 mm, not rolled."""
    return MaterialPreset(name, words, thickness_mm, (3.0, 25.0), plies=plies,
                          youngs_modulus_mpa=70000.0, poisson=0.2,
                          max_bend_stress_mpa=stress_mpa, min_roll_radius_t=None,
                          flatness_mm_per_m=flatness_mm_per_m, sources=sources)


PRESETS: dict[str, MaterialPreset] = {p.name: p for p in (
    # annealed: DIN 18008-1 R_d = k_mod k_c f_k / gamma_M = 0.25 * 1.0 * 45 / 1.8 (permanent)
    _glass("glass-annealed", "annealed float glass (EN 572-1)", 8.0, 1, 0.25 * 45.0 / 1.8,
           None, ("EN 572-1", "DIN 18008-1", "E-glass")),
    # heat-strengthened: R_d = k_c f_k / gamma_M = 70 / 1.5
    _glass("glass-heat-strengthened", "heat-strengthened glass (EN 1863-1)", 8.0, 1, 70.0 / 1.5,
           3.0, ("EN 1863-1", "DIN 18008-1", "E-glass", "ASTM C1048")),
    # tempered: R_d = 120 / 1.5
    _glass("glass-tempered", "thermally toughened (tempered) glass (EN 12150-1)", 8.0, 1,
           120.0 / 1.5, 3.0, ("EN 12150-1", "DIN 18008-1", "E-glass", "ASTM C1048")),
    _glass("glass-laminated", "laminated heat-strengthened glass (EN 14449)", 6.0, 2,
           70.0 / 1.5, 3.0, ("EN 1863-1", "DIN 18008-1", "E-glass", "laminate")),
    _glass("glass-laminated-tempered", "laminated tempered glass (EN 14449)", 6.0, 2,
           120.0 / 1.5, 3.0, ("EN 12150-1", "DIN 18008-1", "E-glass", "laminate")),
    # EN AW-5754 H22: R_p0.2 >= 130 MPa (EN 485-2), gamma_M1 = 1.1 (EN 1999-1-1)
    MaterialPreset("aluminium", "aluminium sheet EN AW-5754 H22 (EN 485-2, EN 573-3)", 3.0,
                   (0.5, 10.0), plies=1, youngs_modulus_mpa=70000.0, poisson=0.3,
                   max_bend_stress_mpa=130.0 / 1.1, min_roll_radius_t=1.5,
                   flatness_mm_per_m=None, sources=("EN 485-2", "EN 1999-1-1", "bend-guide")),
    # S235: f_y = 235 MPa for t <= 16 mm (EN 10025-2), gamma_M0 = 1.0 (EN 1993-1-1)
    MaterialPreset("steel", "structural steel sheet S235 (EN 10025-2)", 2.0, (0.5, 16.0),
                   plies=1, youngs_modulus_mpa=210000.0, poisson=0.3,
                   max_bend_stress_mpa=235.0, min_roll_radius_t=1.5, flatness_mm_per_m=None,
                   sources=("EN 10025-2", "EN 1993-1-1", "bend-guide")),
)}


def material_preset(name: str, thickness_mm: float | None = None,
                    plies: int | None = None) -> Material:
    """The material of a preset at a thickness (mm of one ply) and plies.

    Examples
    --------
    >>> material_preset("glass-tempered", 10).label
    'thermally toughened (tempered) glass (EN 12150-1), 10 mm'
    """
    if name not in PRESETS:
        raise InputError(f"unknown material {name!r}: use one of {', '.join(PRESETS)}")
    return PRESETS[name].material(thickness_mm, plies)


_SPEC = re.compile(r"^(?P<name>[a-z-]+)(?::(?:(?P<plies>\d+)\s*x\s*)?(?P<t>\d+(?:\.\d+)?)\s*(?:mm)?)?$")


def parse_material(text: str) -> Material:
    """A material from ``NAME[:THICKNESS]``: ``glass-tempered:8mm``, ``glass-laminated:2x8mm``
    (two 8 mm plies), ``aluminium:3`` (millimetres; the unit may be left out), ``steel``
    (its preset thickness).

    Examples
    --------
    >>> parse_material("glass-laminated:2x8mm").stress_thickness_mm
    16.0
    >>> parse_material("glass-tempered:10mm").thickness_mm
    10.0
    """
    match = _SPEC.match(text.strip().lower())
    if match is None:
        raise InputError(f"--material {text!r}: write NAME[:THICKNESS], e.g. glass-tempered:8mm "
                         "or glass-laminated:2x8mm (materials: " + ", ".join(PRESETS) + ")")
    t = match.group("t")
    plies = match.group("plies")
    return material_preset(match.group("name"), None if t is None else float(t),
                           None if plies is None else int(plies))


def material_from_table(table: dict, where: str = "material") -> Material:
    """A material from a study's ``[material]`` table: ``preset`` (required), ``thickness_mm``
    (of one ply) and ``plies`` (laminates).

    Raises
    ------
    InputError
        Naming the key (``where.key``) of a wrong or unknown entry.
    """
    known = ("preset", "thickness_mm", "plies")
    for key in table:
        if key not in known:
            raise InputError(f"{where}.{key} is not a known key (keys: {', '.join(known)})")
    name = table.get("preset")
    if not isinstance(name, str):
        raise InputError(f"{where}.preset is missing: name one of {', '.join(PRESETS)}")
    t = table.get("thickness_mm")
    if t is not None and (isinstance(t, bool) or not isinstance(t, (int, float))):
        raise InputError(f"{where}.thickness_mm must be a number of millimetres, got {t!r}")
    n = table.get("plies")
    if n is not None and (isinstance(n, bool) or not isinstance(n, int)):
        raise InputError(f"{where}.plies must be a whole number, got {n!r}")
    try:
        return material_preset(name, t, n)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None

