"""Resource guards: refuse a run up front when it would need more memory than there is.

A layout, strip plan or study on a panel size far too small for the design (or a design
in millimetres read as metres) needs memory in proportion to its panel count, and used
to end in a `MemoryError` after a minute and several gigabytes. The commands estimate the
count first, from the design's area or the net's faces, and refuse beyond a limit with
the count and what to change. The default limit follows the memory this process may use;
``--max-panels`` raises (or lowers) it.
"""

from __future__ import annotations

import os
import resource

from ..errors import InputError

__all__ = ["BYTES_PER_PANEL", "MIN_MAX_PANELS", "available_memory", "default_max_panels",
           "check_panel_count", "worker_count"]

BYTES_PER_PANEL = 40_000
"""Peak memory per panel of a layout with its gliding solve, in bytes: 0.31 GB for 6,500
panels and 0.98 GB for 26,000 (hyperbolic paraboloid, snet); rounded up because the
factorization's fill-in grows a little faster than the panel count."""

MIN_MAX_PANELS = 20_000
"""The default limit never falls below this, however little memory is free now."""

_MEMORY_SHARE = 0.5   # of the memory available: leave the rest to the system and others


def available_memory() -> int:
    """Bytes this process may still allocate: the least of the system's available memory,
    the cgroup limit and the address-space limit (whichever are known)."""
    candidates = []
    try:
        with open("/proc/meminfo", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    candidates.append(int(line.split()[1]) * 1024)
    except (OSError, ValueError, IndexError):
        pass
    try:
        with open("/sys/fs/cgroup/memory.max", encoding="ascii") as handle:
            text = handle.read().strip()
        if text.isdigit():
            candidates.append(int(text))
    except OSError:
        pass
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft not in (resource.RLIM_INFINITY, -1) and soft > 0:
        candidates.append(int(soft))
    if not candidates:
        try:
            candidates.append(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
        except (ValueError, OSError, AttributeError):
            candidates.append(8 * 2**30)
    return min(candidates)


def default_max_panels() -> int:
    """The panel limit when none is given: half the available memory at `BYTES_PER_PANEL`
    (at least `MIN_MAX_PANELS`)."""
    return max(MIN_MAX_PANELS, int(_MEMORY_SHARE * available_memory() / BYTES_PER_PANEL))


def check_panel_count(count: float, *, what: str, fix: str,
                      max_panels: int | None = None) -> None:
    """Refuse `count` panels beyond the limit, naming the count, the memory and the fix.

    Parameters
    ----------
    count : the estimated panel count (may be huge or infinite).
    what : what the count is of, e.g. ``"layout of hyperbolic-paraboloid at panel size
        0.05"``.
    fix : what to change, e.g. ``"a --panel-size of 0.2 gives about 10,000 panels"``.
    max_panels : the limit; None for `default_max_panels`.

    Raises
    ------
    InputError
        When `count` exceeds the limit.

    Examples
    --------
    >>> check_panel_count(5e6, what="layout of wall.stl at panel size 0.01",
    ...                   fix="use a larger --panel-size", max_panels=100_000)
    Traceback (most recent call last):
    ...
    fabplan.errors.InputError: layout of wall.stl at panel size 0.01: about 5,000,000 panels \
(about 200 GB of memory), more than the limit of 100,000: use a larger --panel-size, or \
raise the limit with --max-panels
    """
    limit = default_max_panels() if max_panels is None else max_panels
    if count <= limit:
        return
    gigabytes = count * BYTES_PER_PANEL / 1e9
    size = f"{count:,.0f}" if count < 1e15 else f"{count:.1e}"
    memory = (f"{gigabytes:,.0f} GB" if gigabytes >= 10 else f"{gigabytes:.1f} GB"
              if gigabytes >= 0.1 else f"{1000 * gigabytes:.0f} MB")
    raise InputError(f"{what}: about {size} panels (about {memory} of memory), more than the "
                     f"limit of {limit:,}: {fix}, or raise the limit with --max-panels")


def worker_count(spec: str | int) -> int:
    """The number of local worker processes for ``--workers`` (``auto``: the cores)."""
    if spec == "auto":
        return max(1, os.cpu_count() or 1)
    try:
        n = int(spec)
    except ValueError:
        raise InputError(f"--workers must be a number or 'auto', got {spec!r}") from None
    if not 1 <= n <= 512:
        raise InputError(f"--workers must lie between 1 and 512, got {n}")
    return n
