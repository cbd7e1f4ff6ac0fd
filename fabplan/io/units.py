"""Model units: the one table of them, and whether a size fits the units it is read in.

A net or design file holds numbers, not lengths: the same file is a 150 mm bowl or a
150 m stadium. Every command reads its geometry in the units the user states
(``--units``; a study's ``design.units``), or those the file's record states, and says
which it used. A size that does not fit its units (panels of 3 mm read in metres, a
whole facade of 0.11 m) gets a warning naming the likely unit, or with
``--strict-units`` a refusal.
"""

from __future__ import annotations

import math

from ..errors import InputError

__all__ = ["MM_PER_UNIT", "UNIT_WORDS", "DEFAULT_UNITS", "PLAUSIBLE_PANEL_MM",
           "PLAUSIBLE_DESIGN_MM", "check_units", "units_warning", "likely_design_units"]

#: millimetres per model unit, for every unit a command takes
MM_PER_UNIT = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4, "ft": 304.8}
#: the units in words
UNIT_WORDS = {"mm": "millimetres", "cm": "centimetres", "m": "metres", "in": "inches",
              "ft": "feet"}
#: model units when neither the user nor the file says
DEFAULT_UNITS = "m"

PLAUSIBLE_PANEL_MM = (10.0, 20_000.0)
"""Panel sizes (median edge length, mm) a fabrication plan can mean. Outside them a run
warns; a factor 10 further out (under 1 mm, over 200 m) it refuses: the units are wrong."""

PLAUSIBLE_DESIGN_MM = (1_000.0, 2_000_000.0)
"""Sizes of a whole design (its largest extent, mm) a building can have. The lower bound
is checked for designs read in the large units (metres, feet) only: a 150 mm part read in
millimetres is a milling job, read in metres it is likely a millimetre file."""

_LARGE_UNITS = ("m", "ft")


def check_units(units: str, option: str = "--units") -> str:
    """`units` when it is one of `MM_PER_UNIT`; else a one-line refusal naming them.

    Examples
    --------
    >>> check_units("cm")
    'cm'
    >>> check_units("km")
    Traceback (most recent call last):
    ...
    fabplan.errors.InputError: --units km: use mm, cm, m, in or ft
    """
    if units not in MM_PER_UNIT:
        names = list(MM_PER_UNIT)
        raise InputError(f"{option} {units}: use {', '.join(names[:-1])} or {names[-1]}")
    return units


def _likely(panel: float | None, extent: float | None, units: str) -> str | None:
    """The unit of the same system (metric or imperial) that puts the panel edge nearest
    1 m (given a panel; else the extent nearest 30 m), in the log, when that is not
    `units`."""
    size, target = (panel, 1000.0) if panel is not None else (extent, 30_000.0)
    if size is None or not (size > 0 and math.isfinite(size)):
        return None
    system = ("in", "ft") if units in ("in", "ft") else ("mm", "cm", "m")
    best = min(system, key=lambda u: abs(math.log(size * MM_PER_UNIT[u] / target)))
    return None if best == units else best


def likely_design_units(extent: float, units: str) -> str | None:
    """The unit a design `extent` (model units) across is likely drawn in, when read in
    `units` it lies outside `PLAUSIBLE_DESIGN_MM`; None when it fits.

    Examples
    --------
    >>> likely_design_units(24_000.0, "m")
    'mm'
    >>> likely_design_units(24.0, "m") is None
    True
    """
    return _likely(None, extent, units) if _implausible_design(extent, units) else None


def _implausible_design(extent: float, units: str) -> bool:
    """Whether a design `extent` (model units) across lies outside `PLAUSIBLE_DESIGN_MM`
    read in `units` (its lower bound checked in the large units only)."""
    low = PLAUSIBLE_DESIGN_MM[0] if units in _LARGE_UNITS else 0.0
    return not low <= extent * MM_PER_UNIT[units] <= PLAUSIBLE_DESIGN_MM[1]


def units_warning(name: str, units: str, *, panel: float | None = None,
                  extent: float | None = None, strict: bool = False) -> str | None:
    """A warning when a net's or design's size does not fit the units it is read in: a
    panel outside `PLAUSIBLE_PANEL_MM`, or a design outside `PLAUSIBLE_DESIGN_MM`.

    Parameters
    ----------
    name : the file, for the message.
    units : the units it is read in.
    panel : its typical panel edge (model units), if known.
    extent : its largest extent (model units), if known.
    strict : refuse instead of warning (``--strict-units``).

    Returns
    -------
    The warning, or None when the sizes fit.

    Raises
    ------
    InputError
        With `strict`, instead of the warning; and always for a panel a factor 10
        beyond `PLAUSIBLE_PANEL_MM` (no fabrication plan can mean it).

    Examples
    --------
    >>> units_warning("bowl.stl", "mm", panel=12.0, extent=150.0) is None
    True
    >>> print(units_warning("stadium.obj", "mm", panel=3.0, extent=111.0))
    stadium.obj: panels of 3 mm (median edge 3 mm) read in millimetres: implausible for a \
building; if the file is in metres, give --units m
    >>> print(units_warning("roof.obj", "m", extent=0.6))
    roof.obj: a design 600 mm across read in metres: implausible for a building; check --units
    """
    mm = MM_PER_UNIT[units]
    problems = []
    low, high = PLAUSIBLE_PANEL_MM
    if panel is not None:
        edge_mm = panel * mm
        said = f"{name}: panels of {edge_mm:.3g} mm (median edge {panel:.4g} {units})"
        if edge_mm < 0.1 * low or edge_mm > 10 * high:
            other = _likely(panel, extent, units) or ("mm" if edge_mm > high else "m")
            raise InputError(f"{said} cannot be meant for fabrication: is the model in "
                             f"{UNIT_WORDS[other]}? Give --units {other}")
        if not low <= edge_mm <= high:
            problems.append(said)
    if extent is not None and _implausible_design(extent, units):
        across = f"a design {extent * mm:.3g} mm across"
        problems.append(f"on {across}" if problems else f"{name}: {across}")
    if not problems:
        return None
    # the size that is out of place tells the unit
    panel_odd = panel is not None and not low <= panel * mm <= high
    likely = _likely(panel if panel_odd else None, extent, units)
    hint = (f"if the file is in {UNIT_WORDS[likely]}, give --units {likely}" if likely
            else "check --units")
    message = f"{' '.join(problems)} read in {UNIT_WORDS[units]}: implausible for a building; {hint}"
    if strict:
        raise InputError(message + " (--strict-units)")
    return message
