"""One table of a study file, read key by key: every value checked as it is asked for,
every problem one `InputError` naming the file and the key, and the keys nobody asked for
refused (a typo must not silently drop a limit).
"""

from __future__ import annotations

import difflib
import math
from typing import Any, Iterable, Literal, NoReturn, Sequence, overload

from ..errors import InputError
from ..io.parameters import OPTIONS

__all__ = ["Table", "suggest"]


class Table:
    """One TOML table and its path in the file, for messages that name the key."""

    def __init__(self, data: object, where: str, file: str) -> None:
        if not isinstance(data, dict):
            raise InputError(f"{file}: [{where}] must be a table")
        self.data: dict[str, Any] = data    # TOML values: whatever the file holds
        self.where, self.file = where, file
        self.used: set[str] = set()

    def _name(self, key: str) -> str:
        return f"{self.file}: {self.where}.{key}" if self.where else f"{self.file}: {key}"

    def fail(self, key: str, what: str) -> NoReturn:
        raise InputError(f"{self._name(key)} {what}")

    def within(self, key: str, value: float | None, option: str) -> None:
        """Refuse `value` of `key` outside the range of the command-line option it is
        given to (`fabplan.io.parameters.OPTIONS`), naming the key."""
        reason = None if value is None else OPTIONS[option].reason(value)
        if reason is not None:
            self.fail(key, reason)

    def missing(self, key: str, what: str) -> NoReturn:
        """A required key is absent: name a present key that looks like a typo of it."""
        close = difflib.get_close_matches(key, [k for k in self.data if k not in self.used], n=1)
        if close:
            self.fail(close[0], f"is not a known key (did you mean {key!r}?)")
        self.fail(key, f"is missing: {what}")

    def get(self, key: str, default: Any = None) -> Any:
        self.used.add(key)
        return self.data.get(key, default)

    def has(self, key: str) -> bool:
        return key in self.data

    # number and text return None only for an absent key without a default that is not
    # required, and number an int with integer=True: the overloads say so to the checker
    @overload
    def number(self, key: str, default: int, *, positive: bool = ..., integer: Literal[True],
               unit: str = ...) -> int: ...
    @overload
    def number(self, key: str, default: None = ..., *, positive: bool = ..., integer: Literal[True],
               unit: str = ...) -> int | None: ...
    @overload
    def number(self, key: str, default: float, *, positive: bool = ..., unit: str = ...) -> float: ...
    @overload
    def number(self, key: str, default: None = ..., *, positive: bool = ..., required: Literal[True],
               unit: str = ...) -> float: ...
    @overload
    def number(self, key: str, default: None = ..., *, positive: bool = ...,
               unit: str = ...) -> float | None: ...

    def number(self, key: str, default: float | None = None, *, positive: bool = True,
               required: bool = False, integer: bool = False, unit: str = "") -> float | None:
        """A number (an int with `integer`); `default` when absent, unless `required`."""
        value = self.get(key)
        if value is None:
            if required:
                self.missing(key, f"give a {'positive ' if positive else ''}number"
                             + (f" ({unit})" if unit else ""))
            return default
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        if ok and integer:
            ok = float(value).is_integer()
        if not ok or (positive and value <= 0):
            kind = "a positive " if positive else "a "
            kind += "whole number" if integer else "number"
            # as the file says it (TOML's true, not Python's True)
            shown = str(value).lower() if isinstance(value, bool) else repr(value)
            self.fail(key, f"must be {kind}{f' ({unit})' if unit else ''}, got {shown}")
        return int(value) if integer else float(value)

    @overload
    def text(self, key: str, default: str, *, choices: Sequence[str] | None = ...) -> str: ...
    @overload
    def text(self, key: str, default: None = ..., *, choices: Sequence[str] | None = ...,
             required: Literal[True]) -> str: ...
    @overload
    def text(self, key: str, default: None = ..., *,
             choices: Sequence[str] | None = ...) -> str | None: ...

    def text(self, key: str, default: str | None = None, *, choices: Sequence[str] | None = None,
             required: bool = False) -> str | None:
        """A string (one of `choices` if given); `default` when absent, unless `required`."""
        value = self.get(key)
        if value is None:
            if required:
                self.missing(key, "give a name")
            return default
        if not isinstance(value, str):
            self.fail(key, f"must be a string, got {value!r}")
        if choices is not None and value not in choices:
            self.fail(key, f"must be one of {', '.join(map(str, choices))}; got {value!r}"
                      + suggest(value, choices))
        return value

    def boolean(self, key: str, default: bool = False) -> bool:
        value = self.get(key)
        if value is None:
            return default
        if not isinstance(value, bool):
            self.fail(key, f"must be true or false, got {value!r}")
        return value

    def only(self, tables: Sequence[str]) -> None:
        """Refuse top-level tables other than `tables` before anything else is read, so
        that a misspelt table (``[panel]``) is named, not reported as missing keys."""
        for key in self.data:
            if key not in tables:
                header = {t: f"[[{t}]]" if t == "candidates" else f"[{t}]" for t in tables}
                close = difflib.get_close_matches(key, tables, n=1, cutoff=0.7)
                hint = f" (did you mean {header[close[0]]}?)" if close else \
                    f"; the tables are {', '.join(header.values())}"
                raise InputError(f"{self.file}: [{key}] is not a known table{hint}")

    def done(self) -> None:
        """Refuse keys nobody asked for (a typo must not silently drop a limit)."""
        for key in self.data:
            if key not in self.used:
                self.fail(key, "is not a known key" + suggest(key, self.used))


def suggest(word: object, options: Iterable[object]) -> str:
    """`` (did you mean 'x'?)`` for the option closest to `word`, or nothing."""
    close = difflib.get_close_matches(str(word), [str(o) for o in options], n=1, cutoff=0.7)
    return f" (did you mean {close[0]!r}?)" if close else ""
