"""Fabrication limits: how far a part may go before a shop cannot make it as drawn.

Each limit has a name (the key a study uses for the same limit, `fabplan.study.checks`),
words and a unit, a default a fabricator accepts, and the option that changes it. A
command measures its parts against the limits that apply (`limit_check`), writes the
checks into its JSON (``limits``), shows them in its report or summary, and ends in exit
code 3 when a part exceeds one. The defaults and where they come from are in
``docs/fabrication-limits.md``.

- ``max_twist_deg_per_m``: the largest rotation of a lamella strip's normals about its
  edges per metre (`fabplan.fabricate.strips.Strip.twist_deg_per_m`), ``strips --max-twist``.
- ``max_arc_angle_deg``: the largest central angle of an arc of a circular arc structure
  (`fabplan.fabricate.arcs.ArcStructure.angle`), ``arcs --max-arc-angle``.
- ``congruence_tolerance_mm``: on a net that claims a constant radius (or an infinite one),
  the largest difference of a strip part from the common arc (`fabplan.fabricate.strips.nesting.
  congruence`), ``strips --tolerance`` (the cutting tolerance, as in a study).
- ``max_scallop_mm``: the largest height of material a milling plan leaves between
  neighbouring passes: simulated, else predicted (`fabplan.fabricate.milling`),
  ``mill --scallop``.
- ``max_deviation_mm``: the largest distance of a net vertex from its design or reference,
  ``optimize --max-deviation`` (model units, also held in the solve), ``molds
  --max-deviation-mm`` and ``strips --max-deviation-mm`` (with ``--design``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FabricationLimit", "LimitCheck", "LIMITS", "limit_check", "limits_record",
           "exceeded_text", "limit_row_label", "limit_row_text", "DEFAULT_MAX_TWIST_DEG_PER_M",
           "DEFAULT_MAX_ARC_ANGLE_DEG", "DEFAULT_MAX_DEVIATION_MM"]

DEFAULT_MAX_TWIST_DEG_PER_M = 30.0
"""A conservative shop default: at 30 deg/m the edges of a 100 mm lamella lengthen by
0.034 % over its mid-line, a third of the elastic strain of structural steel S235
(235 / 210000 = 0.11 %): the strip takes its twist elastically as it is assembled."""

DEFAULT_MAX_ARC_ANGLE_DEG = 90.0
"""A conservative shop default: a quarter circle; an arc beyond it rises more than 0.29 of
its radius over its chord, while the arcs of a fair net span a few degrees."""

DEFAULT_MAX_DEVIATION_MM = 20.0
"""The flatness tolerance DIN 18202:2019-07, Table 3, row 6 gives finished walls and wall
claddings at measuring points 10 m apart, taken as the largest distance of a net vertex
from its design."""


@dataclass(frozen=True)
class FabricationLimit:
    """One limit: what it bounds, in words and unit, its default and its option.

    Attributes
    ----------
    name : the key (``max_twist_deg_per_m``), the same as a study's for the same limit.
    words : what it bounds, in words (``largest twist of a lamella strip``).
    unit : the unit of its values (``deg/m``, ``deg``, ``mm``).
    default : the default bound, in `unit`.
    option : the option that changes it.
    """

    name: str
    words: str
    unit: str
    default: float
    option: str


#: every fabrication limit a command checks, by name
LIMITS: dict[str, FabricationLimit] = {limit.name: limit for limit in (
    FabricationLimit("max_twist_deg_per_m", "largest twist of a lamella strip", "deg/m",
                     DEFAULT_MAX_TWIST_DEG_PER_M, "--max-twist"),
    FabricationLimit("max_arc_angle_deg", "largest central angle of an arc", "deg",
                     DEFAULT_MAX_ARC_ANGLE_DEG, "--max-arc-angle"),
    FabricationLimit("congruence_tolerance_mm", "largest difference of a strip from the common "
                     "arc", "mm", 0.1, "--tolerance"),
    FabricationLimit("max_deviation_mm", "largest deviation from the design", "mm",
                     DEFAULT_MAX_DEVIATION_MM, "--max-deviation-mm"),
    FabricationLimit("max_scallop_mm", "largest scallop between milling passes", "mm", 0.01,
                     "--scallop"),
)}


@dataclass(frozen=True)
class LimitCheck:
    """Parts measured against one limit.

    Attributes
    ----------
    limit : the limit's name (a key of `LIMITS`).
    bound : the bound the parts were held to, in the limit's unit.
    parts : what was counted, plural (``strips``, ``arcs``, ``strip parts``, ``vertices``).
    measured : how many parts were measured.
    over : how many exceed the bound.
    worst : the largest value measured (None when no part was measured).
    option : the option that changes the bound (``--max-twist``).
    where : the worst part in words (``edge 12 between vertices 4 and 5, at (x, y, z)``),
        or None.
    """

    limit: str
    bound: float
    parts: str
    measured: int
    over: int
    worst: float | None
    option: str
    where: str | None = None

    @property
    def exceeded(self) -> bool:
        """Whether a part exceeds the bound."""
        return self.over > 0

    @property
    def unit(self) -> str:
        return LIMITS[self.limit].unit

    def to_json(self) -> dict:
        """The check as the command's JSON holds it (``limits.NAME``)."""
        return {"limit": self.bound, "unit": self.unit, "parts": self.parts,
                "measured": self.measured, "over": self.over, "worst": self.worst,
                "worst_at": self.where, "exceeded": self.exceeded, "option": self.option,
                "words": LIMITS[self.limit].words}

    def text(self) -> str:
        """The check in one sentence, with the figures of `to_json`.

        Examples
        --------
        >>> print(LimitCheck("max_arc_angle_deg", 90.0, "arcs", 40, 2, 179.0,
        ...                  "--max-arc-angle").text())  # doctest: +NORMALIZE_WHITESPACE
        2 of 40 arcs exceed the largest central angle of an arc of 90 deg: up to 179 deg,
        89 deg over (--max-arc-angle)
        >>> LimitCheck("max_arc_angle_deg", 90.0, "arcs", 40, 0, 12.5, "--max-arc-angle").text()
        'all 40 arcs within the largest central angle of an arc of 90 deg (up to 12.5 deg)'
        """
        words = f"the {LIMITS[self.limit].words} of {self.bound:g} {self.unit}"
        if not self.exceeded:
            worst = "" if self.worst is None else f" (up to {_figure(self.worst)} {self.unit})"
            return f"all {self.measured} {self.parts} within {words}{worst}"
        assert self.worst is not None
        at = f" at {self.where}" if self.where else ""
        return (f"{self.over} of {self.measured} {self.parts} exceed {words}: up to "
                f"{_figure(self.worst)} {self.unit}{at}, {_figure(self.worst - self.bound)} "
                f"{self.unit} over ({self.option})")


def _figure(value: float) -> str:
    """A figure as the summaries print it: three significant digits, at least one decimal
    below 100 (``179``, ``12.5``, ``0.0123``)."""
    return f"{value:.3g}" if abs(value) < 1e5 else f"{value:.0f}"


def limit_check(limit: str, values: np.ndarray, bound: float, *, parts: str,
                option: str | None = None) -> LimitCheck:
    """Measure parts against a limit.

    Parameters
    ----------
    limit : the limit's name (a key of `LIMITS`).
    values : (n,) float, each part's value in the limit's unit; NaN for a part it does not
        apply to (left out of the count).
    bound : the bound, in the limit's unit.
    parts : what the values belong to, plural (``strips``).
    option : the option that changes the bound (default: the limit's own).

    Returns
    -------
    LimitCheck

    Examples
    --------
    >>> check = limit_check("max_twist_deg_per_m", np.array([12.0, 45.0, np.nan]), 30.0,
    ...                     parts="strips")
    >>> check.measured, check.over, check.worst, check.exceeded
    (2, 1, 45.0, True)
    >>> limit_check("max_twist_deg_per_m", np.zeros(0), 30.0, parts="strips").worst is None
    True
    """
    if limit not in LIMITS:
        raise KeyError(f"no fabrication limit {limit!r}: one of {', '.join(LIMITS)}")
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[~np.isnan(v)]
    worst = float(v.max()) if v.size else None
    return LimitCheck(limit=limit, bound=float(bound), parts=parts, measured=int(v.size),
                      over=int(np.count_nonzero(v > bound)), worst=worst,
                      option=option or LIMITS[limit].option)


def limits_record(checks: list[LimitCheck]) -> dict:
    """``{name: check.to_json()}``: the ``limits`` a command's JSON holds."""
    return {c.limit: c.to_json() for c in checks}


def exceeded_text(checks: list[LimitCheck]) -> str | None:
    """The exceeded limits in one line for the warning a command ends with; None when
    every part is within its limits."""
    over = [c.text() for c in checks if c.exceeded]
    return "; ".join(over) if over else None


def limit_row_label(check: dict) -> str:
    """A check as the JSON holds it (`LimitCheck.to_json`), named for a report's row: its
    words, bound, unit and option.

    Examples
    --------
    >>> limit_row_label(LimitCheck("max_scallop_mm", 0.01, "pass nodes", 3, 0, 0.004,
    ...                            "--scallop").to_json())
    'largest scallop between milling passes (limit 0.01 mm, --scallop)'
    """
    return f"{check['words']} (limit {check['limit']:g} {check['unit']}, {check['option']})"


def limit_row_text(check: dict) -> str:
    """A check as the JSON holds it (`LimitCheck.to_json`), in the words of a report's row:
    the count over the limit and the largest value, figures as the JSON has them to four
    significant digits.

    Examples
    --------
    >>> limit_row_text(LimitCheck("max_deviation_mm", 20.0, "vertices", 30, 4, 31.25,
    ...                           "--max-deviation-mm").to_json())
    '4 of 30 vertices over the limit; largest 31.25 mm'
    >>> limit_row_text(limit_check("max_deviation_mm", np.zeros(0), 20.0, parts="vertices").to_json())
    '0 of 0 vertices over the limit'
    """
    text = f"{check['over']} of {check['measured']} {check['parts']} over the limit"
    if check["worst"] is None:
        return text
    return text + f"; largest {check['worst']:.4g} {check['unit']}"
