"""The candidates of a study file: its ``[[candidates]]`` tables read and expanded into
every candidate it runs (``net = "auto"``, lists and sweeps of angles and radii, the
sweeps of panel size and mold tolerance) and the searches it makes, each named with a
safe folder name.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from typing import Literal, Sequence, overload

from ..errors import InputError
from ..io.parameters import OPTIONS
from ..solve.net_types import NETS, NetType, get_net
from .definition import SEARCH_BUDGET, Candidate, Search, candidate_name
from .table import Table

__all__ = ["AUTO_CANDIDATES", "MAX_SWEEP_VALUES", "MAX_CANDIDATES", "SAFE_NAME", "swept_values",
           "search_range", "read_candidates", "sweep_candidates"]

#: The candidates ``net = "auto"`` stands for (the baseline is always added).
AUTO_CANDIDATES = (
    ("isogonal", None, None),
    ("linear-weingarten", None, None),
    ("const-radius", None, None),
    ("char-conjugate", None, None),
    ("cmc", None, None),
)

#: Most values one swept key may take.
MAX_SWEEP_VALUES = 50


@overload
def swept_values(t: Table, key: str, unit: str, *, free: Literal[False]) -> list[float]: ...
@overload
def swept_values(t: Table, key: str, unit: str, *, free: bool = ...) -> list[float | None]: ...
def swept_values(t: Table, key: str, unit: str, *, free: bool = True) -> Sequence[float | None]:
    """A parameter as a list of values: a number, ``"free"`` (with `free`), a list, or a
    sweep ``{from, to, step}`` or ``{from, to, count}`` (both ends included)."""
    value = t.get(key)
    if free and (value is None or value == "free"):
        return [None]
    if isinstance(value, dict):
        sweep = Table(value, f"{t.where}.{key}", t.file)
        lo = sweep.number("from", required=True, unit=unit)
        hi = sweep.number("to", required=True, unit=unit)
        if sweep.has("step") == sweep.has("count"):
            t.fail(key, "is a sweep: give either 'step' or 'count' with 'from' and 'to'")
        if hi < lo:
            t.fail(key, f"sweeps from {lo:g} down to {hi:g}: 'to' must not be below 'from'")
        if sweep.has("count"):
            count = sweep.number("count", 1, integer=True)
            if count == 1 and hi > lo:
                t.fail(key, "is a sweep of count 1: 'from' and 'to' must then be equal")
            step = (hi - lo) / max(count - 1, 1)
        else:
            step = sweep.number("step", required=True, unit=unit)
            count = int(math.floor((hi - lo) / step + 1e-9)) + 1
        sweep.done()
        if count > MAX_SWEEP_VALUES:
            t.fail(key, f"sweep has {count} values; at most {MAX_SWEEP_VALUES}")
        # rounded, so that names and cache keys read 1.25, not 1.2500000000000002
        return [round(lo + i * step, 9) for i in range(count)]
    items = value if isinstance(value, list) else [value]
    if not items:
        t.fail(key, "is an empty list")
    if len(items) > MAX_SWEEP_VALUES:
        t.fail(key, f"lists {len(items)} values; at most {MAX_SWEEP_VALUES}")
    out: list[float | None] = []
    for v in items:
        if free and v == "free":
            out.append(None)
        elif isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0:
            out.append(float(v))
        elif not free and not isinstance(value, list):
            t.fail(key, f"must be a positive number ({unit}), got {v!r}")
        else:
            t.fail(key, f"must be {chr(34) + 'free' + chr(34) + ', ' if free else ''}a positive "
                   f"number ({unit}), a list of them or {{ from = .., to = .., step = .. }} "
                   f"(or count = .. instead of step); got {v!r}")
    if len(set(out)) < len(out):
        t.fail(key, f"lists a value twice: {items!r}")
    return out


def search_range(t: Table, key: str, unit: str) -> tuple[float, float, int] | None:
    """``{ search = [low, high], budget = N }`` of `key`, or None when it is no search."""
    value = t.get(key)
    if not (isinstance(value, dict) and "search" in value):
        return None
    table = Table(value, f"{t.where}.{key}", t.file)
    bounds = table.get("search")
    if not (isinstance(bounds, list) and len(bounds) == 2 and all(
            isinstance(b, (int, float)) and not isinstance(b, bool) and math.isfinite(b) and b > 0
            for b in bounds) and bounds[0] < bounds[1]):
        table.fail("search", f"must be [low, high], two positive numbers ({unit}) with low < "
                   f"high; got {bounds!r}")
    low, high, default = SEARCH_BUDGET
    budget = table.number("budget", default, integer=True)
    if not low <= budget <= high:
        table.fail("budget", f"must lie between {low} and {high} solves, got {budget}")
    table.done()
    return float(bounds[0]), float(bounds[1]), int(budget)


@dataclass
class _Entry:
    """One ``[[candidates]]`` table as read: its net type, the parameters it searches
    (``{parameter: (low, high, budget)}``), lists or sweeps, and name and start angle."""

    table: Table
    net: str
    preset: NetType
    searched: dict[str, tuple[float, float, int]]
    angles: list[float | None]
    radii: list[float | None]
    label: str | None
    start: float | None


def read_candidates(value: object, file: str) -> tuple[tuple[Candidate, ...], tuple[Search, ...]]:
    """The candidates (the baseline first) and searches of a study file's ``candidates``
    (``"auto"`` or its ``[[candidates]]`` tables), their names checked.

    Raises
    ------
    InputError
        A malformed table, a net type that cannot be studied, a parameter that does not
        apply to its net type or lies out of range, an unsafe or repeated name.
    """
    baseline = Candidate("baseline", "snet", baseline=True)
    searches: list[Search] = []
    if value == "auto":
        value = [{"net": "auto"}]
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise InputError(f"{file}: candidates must be \"auto\" or a list of [[candidates]] tables")
    out: list[Candidate] = [baseline]
    for i, entry in enumerate(value):
        t = Table(entry, f"candidates[{i}]", file)
        net = t.text("net", required=True, choices=(*NETS, "auto"))
        if net == "auto":
            t.done()
            out += [Candidate(candidate_name(n, a, r), n, a, r) for n, a, r in AUTO_CANDIDATES]
            continue
        read = _read_entry(t, net)
        _check_applies(read)
        if read.searched:
            searches.append(_entry_search(read))
            continue
        out += _entry_candidates(read)
    _check_names(out, searches, file)
    return tuple(out), tuple(searches)


def _read_entry(t: Table, net: str) -> _Entry:
    """Every key of one ``[[candidates]]`` table of net type `net`, read in turn."""
    preset = get_net(net)
    if preset.dual:
        t.fail("net", f"is the S*-net type {net!r}: studies lay out S-nets on the design; "
               "optimize an S*-net from a study's net with `fabplan optimize`")
    searched = {key: found for key, unit in (("angle", "degrees"), ("radius", "model units"))
                if (found := search_range(t, key, unit)) is not None}
    if len(searched) > 1:
        t.fail("radius", "is searched with the angle: search one of them at a time")
    angles = [None] if "angle" in searched else swept_values(t, "angle", "degrees")
    radii = [None] if "radius" in searched else swept_values(t, "radius", "model units")
    label = t.text("name")
    if label is not None and not SAFE_NAME.fullmatch(label):
        t.fail("name", f"is {label!r}, {_SAFE_NAME_RULE}")
    start = t.number("start_angle", unit="degrees")
    if start is not None and not 0 < start < 180:
        t.fail("start_angle", f"must lie strictly between 0 and 180 degrees, got {start:g}")
    t.done()
    return _Entry(t, net, preset, searched, list(angles), list(radii), label, start)


def _lowest_angle() -> float:
    """The solver's smallest angle (degrees): the low end of ``--angle``."""
    return float(OPTIONS["--angle"].low or 0)


def _check_applies(read: _Entry) -> None:
    """Refuse an angle or radius, given or searched, that the net type does not have, and
    a searched angle out of the solver's range."""
    t, net, preset, searched = read.table, read.net, read.preset, read.searched
    if read.angles != [None] and preset.angle != "param":
        t.fail("angle", f"does not apply to net type {net!r} (its angle is "
               f"{'90 degrees' if preset.angle == 'right' else 'not constrained'})")
    if read.radii != [None] and preset.radius != "param":
        t.fail("radius", f"does not apply to net type {net!r}")
    if "angle" in searched and preset.angle != "param":
        t.fail("angle", f"does not apply to net type {net!r}: there is no angle to search")
    if "radius" in searched and preset.radius != "param":
        t.fail("radius", f"does not apply to net type {net!r}: there is no radius to search")
    lowest = _lowest_angle()
    if "angle" in searched and not lowest <= searched["angle"][0] <= searched["angle"][1] <= 90:
        t.fail("angle", f"search must lie in [{lowest:g}, 90] degrees, got "
               f"{searched['angle'][0]:g} to {searched['angle'][1]:g}")


def _entry_search(read: _Entry) -> Search:
    """The search of a table that searches its angle or radius, the other one fixed or free."""
    angles, radii = read.angles, read.radii
    if len(angles) * len(radii) > 1:
        read.table.fail("angle" if len(angles) > 1 else "radius", "sweeps while the other is "
                        "searched: search one parameter, the other fixed or free")
    (parameter, (low, high, budget)), = read.searched.items()
    return Search(read.label or read.net, read.net, parameter, low, high, budget,
                  angle=angles[0], radius=radii[0], start_angle=read.start)


def _entry_candidates(read: _Entry) -> list[Candidate]:
    """The candidates of a table: one per angle and radius of its lists or sweeps, named
    after them (its own name then begins theirs)."""
    t, net, label, angles, radii = read.table, read.net, read.label, read.angles, read.radii
    lowest = _lowest_angle()
    for a in angles:
        if a is not None and not lowest <= a <= 90:
            t.fail("angle", f"must lie in [{lowest:g}, 90] degrees, got {a:g}: an isogonal "
                   f"net of angle a is the same net as one of 180 - a with the families "
                   f"swapped (ask for {180 - a:g})" if 90 < a < 180 else
                   f"must lie in [{lowest:g}, 90] degrees, got {a:g}")
    for r in radii:
        t.within("radius", r, "--radius")
    sweep = len(angles) * len(radii) > 1
    out = []
    for a in angles:
        for r in radii:
            name = candidate_name(net, a, r) if (label is None or sweep) else label
            if label is not None and sweep:
                name = label + name[len(net):]
            out.append(Candidate(name, net, a, r, start_angle=read.start))
    return out


def _check_names(out: list[Candidate], searches: list[Search], file: str) -> None:
    """Refuse a candidate or search name that is not a safe folder name or is given twice."""
    names = [c.name for c in out]
    for c in out:
        if not SAFE_NAME.fullmatch(c.name):
            raise InputError(f"{file}: candidate name {c.name!r} {_SAFE_NAME_RULE}")
    for c in out:
        if names.count(c.name) > 1:
            raise InputError(f"{file}: two candidates are both called {c.name!r}; give them "
                             "different names (candidates[].name)")
    labels = [s.name for s in searches]
    for s in searches:
        if labels.count(s.name) > 1 or not SAFE_NAME.fullmatch(s.name):
            raise InputError(f"{file}: two searches are both called {s.name!r}, or the name is "
                             "not a safe folder name; give them names (candidates[].name)")


def sweep_candidates(candidates: tuple[Candidate, ...], sizes: list[float], tolerances: list[float],
           file: str) -> tuple[Candidate, ...]:
    """Every candidate (the baseline included) at every swept panel size and mold
    tolerance, named with the swept values (``isogonal-60-p1.5-t2``); unswept studies
    keep their candidates as they are."""
    if len(sizes) == 1 and len(tolerances) == 1:
        return candidates
    out = []
    for c in candidates:
        for size in sizes:
            for tolerance in tolerances:
                name = c.name
                if len(sizes) > 1:
                    name += f"-p{size:g}"
                if len(tolerances) > 1:
                    name += f"-t{tolerance:g}"
                out.append(replace(c, name=name,
                                   panel_size=size if len(sizes) > 1 else None,
                                   mold_tolerance_mm=tolerance if len(tolerances) > 1 else None))
    if len(out) > MAX_CANDIDATES:
        raise InputError(f"{file}: the sweep makes {len(out)} candidates "
                         f"({len(candidates)} nets x {len(sizes)} panel sizes x "
                         f"{len(tolerances)} mold tolerances); at most {MAX_CANDIDATES}")
    for c in out:
        if not SAFE_NAME.fullmatch(c.name):
            raise InputError(f"{file}: candidate name {c.name!r} {_SAFE_NAME_RULE}")
    names = [c.name for c in out]
    twice = next((n for n in names if names.count(n) > 1), None)
    if twice is not None:
        raise InputError(f"{file}: two candidates of the sweep are both called {twice!r}; "
                         "give the candidates different names (candidates[].name)")
    return tuple(out)


#: Most candidates a study may expand into (a sweep of sweeps grows fast).
MAX_CANDIDATES = 1000


SAFE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9._+-]{0,63}")
"""A candidate name: it becomes a folder inside the study folder, so no separators, no
leading dot (no '..', no hidden folder) and nothing a shell or a file system mangles."""
_SAFE_NAME_RULE = ("which is not a safe folder name: use up to 64 letters, digits, '.', '_', "
                   "'+' and '-', starting with a letter, digit or '_' (no '/', '..' or spaces)")
