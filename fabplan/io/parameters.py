"""The range of every numeric parameter: command-line options and built-in surface parameters.

One table states, for each number a user can give, its type, its bounds (inclusive or
not) and its unit. The command line checks its options with it as it parses them
(`fabplan.cli`), `fabplan.design.parametric` checks the parameters of a built-in surface
with it (``layout NAME:key=value``, ``--reference``, a study's ``[design] parameters``),
and the help text states the ranges from it. A value outside its range is refused in one
line naming the parameter, the value and the range, before any work and before any
number reaches numpy.

The bounds are those no real plan comes near: they keep NaN, infinities, 1e300 and
1e-300 out, not unusual designs. Bounds that depend on the input (a panel size larger
than the design) are checked where the input is read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from ..errors import InputError
from .inputs import MAX_COORDINATE

__all__ = ["Parameter", "OPTIONS", "SURFACE_PARAMETERS", "option_parameter", "surface_parameter"]


def _number_text(value: float, integer: bool = False) -> str:
    """A bound as a user reads it: ``0.001``, ``20000``, ``1e+07``; a count in digits."""
    return str(int(value)) if integer else f"{value:g}"


@dataclass(frozen=True)
class Parameter:
    """The range of one numeric parameter.

    Parameters
    ----------
    name : the parameter as the user writes it (``--panel-size``, ``width``).
    low, high : its bounds; None for none.
    low_open, high_open : whether the bound itself is refused (``(0, 180)``).
    integer : a whole number (a count), else a real number.
    units : what the number counts, for messages and help (``mm``, ``model units``,
        ``degrees``); "" for a pure number.
    signed : the bounds hold for the magnitude, either sign allowed (a signed radius).

    Examples
    --------
    >>> size = Parameter("--panel-size", 1e-6, 1e7, units="model units")
    >>> size.check("2.5")
    2.5
    >>> size.check("1e300")
    Traceback (most recent call last):
    ...
    fabplan.errors.InputError: --panel-size 1e300: must be at most 1e+07 model units (range [1e-06, 1e+07])
    >>> Parameter("--starts", 1, 5, integer=True).check("nan")
    Traceback (most recent call last):
    ...
    fabplan.errors.InputError: --starts nan: must be a whole number between 1 and 5
    """

    name: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    integer: bool = False
    units: str = ""
    signed: bool = False

    @property
    def allowed(self) -> str:
        """The range in words: ``between 1 and 5``, ``more than 0 and at most 180 degrees``."""
        low, high = self.low, self.high
        if low is not None and high is not None and not (self.low_open or self.high_open):
            text = f"between {self._text(low)} and {self._text(high)}"
        else:
            parts = []
            if low is not None:
                parts.append(f"{'more than' if self.low_open else 'at least'} {self._text(low)}")
            if high is not None:
                parts.append(f"{'less than' if self.high_open else 'at most'} {self._text(high)}")
            text = " and ".join(parts) or "any finite number"
        if self.units:
            text += f" {self.units}"
        return text + (" in size, of either sign" if self.signed else "")

    def _text(self, bound: float) -> str:
        return _number_text(bound, self.integer)

    @property
    def kind(self) -> str:
        return "a whole number" if self.integer else "a number"

    def check(self, value: object, *, where: str = "") -> float:
        """`value` (a number or its text) as a float, or an int for a whole number.

        Parameters
        ----------
        value : the number, or the text the user gave.
        where : what the parameter belongs to, put before its name in the message
            (``"hyperbolic-paraboloid: "``).

        Raises
        ------
        InputError
            For text that is no number, NaN, an infinity, a fraction where a whole number
            is due, or a value outside the range; one line naming the parameter, the
            value and the range.
        """
        number, reason = self._judged(value)
        if reason is not None or number is None:
            raise InputError(f"{where}{self.name} {_shown(value)}: {reason}")
        return number

    def reason(self, value: object) -> str | None:
        """Why `value` is refused (``must be at least 0.01 mm (range [0.01, 1000])``), or
        None when it is in range: for a caller that names the parameter its own way."""
        return self._judged(value)[1]

    def _judged(self, value: object) -> tuple[float | int | None, str | None]:
        """The number in `value` and why it is refused (None when it is not)."""
        number = self._number(value)
        if number is None or (isinstance(number, float) and not math.isfinite(number)):
            what = self.kind if number is None else f"a finite {self.kind[2:]}"
            return number, f"must be {what} {self.allowed}"
        size = abs(number) if self.signed else number
        if self.low is not None and (size < self.low or (self.low_open and size == self.low)):
            bound = f"{'more than' if self.low_open else 'at least'} {self._text(self.low)}"
            return number, f"must be {self._bound_words(bound)}"
        if self.high is not None and (size > self.high or (self.high_open and size == self.high)):
            bound = f"{'less than' if self.high_open else 'at most'} {self._text(self.high)}"
            return number, f"must be {self._bound_words(bound)}"
        return number, None

    @property
    def interval(self) -> str:
        """The range as an interval: ``[1e-06, 1e+07]``, ``(0, 180)``, ``[1, inf)``."""
        low = "-inf" if self.low is None else self._text(self.low)
        high = "inf" if self.high is None else self._text(self.high)
        return (f"{'(' if self.low_open or self.low is None else '['}{low}, "
                f"{high}{')' if self.high_open or self.high is None else ']'}")

    def _bound_words(self, bound: str) -> str:
        """The bound missed, with the whole range where there are two bounds."""
        text = bound + (f" {self.units}" if self.units else "") + (" in size" if self.signed else "")
        sign = "±" if self.signed else ""
        return text + (f" (range {sign}{self.interval})" if None not in (self.low, self.high) else "")

    def _number(self, value: object) -> float | int | None:
        """The number in `value`, or None when it holds none of the right kind."""
        if isinstance(value, bool):
            return None
        if isinstance(value, str):
            text = value.strip()
            if self.integer:
                try:
                    return int(text)
                except ValueError:
                    return None
            try:
                return float(text)
            except ValueError:
                return None
        if self.integer:
            if isinstance(value, int):
                return value
            if isinstance(value, float) and value.is_integer():
                return int(value)
            return None
        try:
            return float(value)     # type: ignore[arg-type]
        except (TypeError, ValueError, OverflowError):
            return None


def _shown(value: object) -> str:
    """A value for a message: the user's text as given (shortened, control characters
    escaped), a number as Python writes it."""
    text = value.strip() if isinstance(value, str) else repr(value)
    if isinstance(value, float):
        text = f"{value:g}"
    if not text.isprintable() or not text:
        text = repr(text)
    return text if len(text) <= 40 else text[:37] + "..."


# ---------------------------------------------------------------------------- the table
#: lengths in model units (a panel, a deviation): from a micrometre in metres to ten
#: kilometres in millimetres
MODEL_LENGTH = (1e-6, 1e7)
#: a whole design's sizes in model units (a millimetre in metres up)
DESIGN_SIZE = (1e-3, 1e7)
#: the largest part a sheet or a machine can hold, in mm (`fabplan.fabricate.strips`)
SHEET_MM = 20_000.0


def _length(name: str, *, low: float = MODEL_LENGTH[0], high: float = MODEL_LENGTH[1],
            units: str = "model units") -> Parameter:
    return Parameter(name, low, high, units=units)


def _mm(name: str, low: float, high: float) -> Parameter:
    return Parameter(name, low, high, units="mm")


def _count(name: str, low: int, high: int) -> Parameter:
    return Parameter(name, low, high, integer=True)


_OPTIONS = [
    # nets and their solve (layout, optimize, measure)
    Parameter("--angle", 1.0, 179.0, units="degrees"),
    _length("--radius", high=MAX_COORDINATE),
    _length("--max-deviation"),
    Parameter("--max-line-turn", 0.1, 180.0, units="degrees"),
    _count("--max-iter", 1, 100_000),
    # layout
    _length("--panel-size"),
    _count("--triangles", 100, 5_000_000),
    Parameter("--smoothing", 0.05, 20.0, units="panels"),
    _count("--starts", 1, 5),
    _count("--max-panels", 1, 1_000_000_000),
    # molds
    _mm("--tolerance-mm", 0.01, 1000.0),
    _mm("--max-mold-size", 1.0, 1e6),
    _mm("--step-limit", 0.001, 1000.0),
    _mm("--max-deviation-mm", 0.001, 1e7),
    # strips (millimetres)
    _mm("--height", 1.0, SHEET_MM),
    _mm("--thickness", 0.01, 1000.0),
    _mm("--spacing", 0.0, SHEET_MM),
    _mm("strips --margin", 0.0, SHEET_MM),
    _mm("--kerf", 0.0, 100.0),
    _mm("--clearance", 0.0, 100.0),
    _mm("--tolerance", 0.001, 10.0),
    _mm("--extension", 0.0, SHEET_MM),
    _mm("--boundary-member", 0.0, 10_000.0),
    _mm("--splice-length", 1.0, SHEET_MM),
    _mm("--label-height", 0.1, 1000.0),
    Parameter("--max-twist", 0.01, 36_000.0, units="deg/m"),
    # arcs
    Parameter("--max-arc-angle", 0.1, 360.0, units="degrees"),
    # mill
    _mm("mill --margin", 0.0, 1000.0),
    _mm("--scallop", 1e-5, 10.0),
    _mm("--sim-step", 0.01, 10.0),
    # edit: a TCP port (0, the default, is a free one: given by leaving the option out)
    _count("--port", 1, 65535),
]


#: option -> its range; ``"COMMAND --option"`` where the same option means different things
#: in different commands (``strips --margin`` on the sheet, ``mill --margin`` on the tool)
OPTIONS: dict[str, Parameter] = {p.name: replace(p, name=p.name.split()[-1]) for p in _OPTIONS}


def option_parameter(command: str, option: str) -> Parameter:
    """The range of `option` of `command` (``"layout"``, ``"--panel-size"``).

    Raises
    ------
    KeyError
        For an option the table does not hold (a new option must be added to it).
    """
    return OPTIONS.get(f"{command} {option}") or OPTIONS[option]


def _design(name: str, *, signed: bool = False, low: float = DESIGN_SIZE[0]) -> Parameter:
    return Parameter(name, low, DESIGN_SIZE[1], units="model units", signed=signed)


def _offset(name: str) -> Parameter:
    """A length either way from the design's plane: zero allowed (flat)."""
    return Parameter(name, -DESIGN_SIZE[1], DESIGN_SIZE[1], units="model units")


def _degrees(name: str, low: float, high: float, **kw: bool) -> Parameter:
    return Parameter(name, low, high, units="degrees", **kw)


def _ratio(name: str, low: float = 1e-3, high: float = 1e3) -> Parameter:
    return Parameter(name, low, high)


#: built-in surface -> parameter -> its range (`fabplan.design.parametric.SURFACES`; the
#: parameters that name files are checked by their readers). ``u_deg`` and ``v_deg`` are
#: ranges ``LO..HI``: each end is checked.
SURFACE_PARAMETERS: dict[str, dict[str, Parameter]] = {
    "hyperbolic-paraboloid": {"width": _design("width"), "depth": _design("depth"),
                              "rise": _offset("rise")},
    "paraboloid": {"radius_x": _design("radius_x", signed=True),
                   "radius_y": _design("radius_y", signed=True),
                   "width": _design("width"), "depth": _design("depth")},
    "torus": {"major": _design("major"), "minor": _design("minor"),
              "u_deg": _degrees("u_deg", -360.0, 360.0), "v_deg": _degrees("v_deg", -360.0, 360.0)},
    "revolution": {"height": _design("height"), "radius": _design("radius"),
                   "waist": _ratio("waist"),
                   "sweep_deg": _degrees("sweep_deg", 1.0, 360.0),
                   "aspect": _ratio("aspect"), "twist_deg": _degrees("twist_deg", -720.0, 720.0)},
    "tower-facade": {"width": _design("width"), "height": _design("height"),
                     "twist": _offset("twist"),
                     "plan": Parameter("plan", -1e3, 1e3, units="per model unit"),
                     "vertical": Parameter("vertical", -1e3, 1e3, units="per model unit")},
    "height-field": {"width": _design("width"), "depth": _design("depth")},
    "bspline": {"degree": _count("degree", 1, 5)},
}


def surface_parameter(surface: str, key: str) -> Parameter | None:
    """The range of parameter `key` of built-in surface `surface`; None for a parameter
    that is no number (a file, a callable, an array)."""
    return SURFACE_PARAMETERS.get(surface, {}).get(key)
