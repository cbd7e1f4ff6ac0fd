"""Resource guards: refuse a run up front when it would need more memory than there is.

A layout, strip plan or study on a panel size far too small for the design (or a design
in millimetres read as metres) needs memory in proportion to its panel count, and used
to end in a `MemoryError` after a minute and several gigabytes. The commands estimate the
count first, from the design's area or the net's faces, and refuse beyond a limit with
the count and what to change. The default limit follows the memory this process may use;
``--max-panels`` raises (or lowers) it.

`molds` and `mill` estimate their peak from the net's faces, a triangulation (``--triangles``,
a study's ``design.triangles``, a design or reference mesh file) from its triangles, each
with a `MemoryModel` fitted to measured peaks (``benchmarks/bench_memory.py``, figures in
``benchmarks/README.md``), and refuse in one line naming the option and the largest size
that fits.
"""

from __future__ import annotations

import math
import os
import resource
from dataclasses import dataclass

from ..errors import InputError

__all__ = ["BYTES_PER_PANEL", "MIN_MAX_PANELS", "available_memory", "default_max_panels",
           "check_panel_count", "worker_count", "MemoryModel", "MOLDS_MEMORY", "MILL_MEMORY",
           "DESIGN_MEMORY", "REFERENCE_MEMORY", "SIMULATION_MEMORY", "STUDY_BYTES_PER_PANEL", "memory_limit",
           "memory_reason", "check_memory"]

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


def default_max_panels(bytes_per_panel: float = BYTES_PER_PANEL) -> int:
    """The panel limit when none is given: half the available memory at `bytes_per_panel`
    (at least `MIN_MAX_PANELS`)."""
    return max(MIN_MAX_PANELS, int(memory_limit() / bytes_per_panel))


def memory_limit() -> float:
    """Bytes a run may plan to use: half the `available_memory`, the rest left to the
    system and to other work."""
    return _MEMORY_SHARE * available_memory()


def check_panel_count(count: float, *, what: str, fix: str,
                      max_panels: int | None = None,
                      bytes_per_panel: float = BYTES_PER_PANEL) -> None:
    """Refuse `count` panels beyond the limit, naming the count, the memory and the fix.

    Parameters
    ----------
    count : the estimated panel count (may be huge or infinite).
    what : what the count is of, e.g. ``"layout of hyperbolic-paraboloid at panel size
        0.05"``.
    fix : what to change, e.g. ``"a --panel-size of 0.2 gives about 10,000 panels"``.
    max_panels : the limit; None for `default_max_panels`.
    bytes_per_panel : peak memory per panel of the work, bytes (`BYTES_PER_PANEL` for a
        layout, `STUDY_BYTES_PER_PANEL` for a study).

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
    limit = default_max_panels(bytes_per_panel) if max_panels is None else max_panels
    if count <= limit:
        return
    raise InputError(f"{what}: about {_count_text(count)} panels (about "
                     f"{_bytes_text(count * bytes_per_panel)} of memory), more than the "
                     f"limit of {limit:,}: {fix}, or raise the limit with --max-panels")


def _count_text(count: float) -> str:
    return f"{count:,.0f}" if count < 1e15 else f"{count:.1e}"


def _bytes_text(size: float) -> str:
    """``12 GB``, ``3.4 GB``, ``250 MB``."""
    gigabytes = size / 1e9
    return (f"{gigabytes:,.0f} GB" if gigabytes >= 10 else f"{gigabytes:.1f} GB"
            if gigabytes >= 0.1 else f"{1000 * gigabytes:.0f} MB")


@dataclass(frozen=True)
class MemoryModel:
    """Peak memory of one kind of work against its size: ``base_bytes + bytes_per_unit *
    size``, a straight line fitted to peaks measured at three sizes.

    Parameters
    ----------
    work : the work in words, for messages (``"molds of"``, ``"a triangulation of"``).
    unit : what the size counts (``"faces"``, ``"triangles"``).
    base_bytes : the peak of the process at size 0 (Python, numpy, the libraries), bytes.
    bytes_per_unit : the peak's growth per unit of size, bytes.
    seconds_per_unit : the time per unit of size on the machine measured, seconds (0 for
        not measured).

    Examples
    --------
    >>> model = MemoryModel("molds of", "faces", 100e6, 50e3)
    >>> model.peak_bytes(10_000)
    600000000.0
    >>> model.largest_fitting(1.1e9)
    20000
    """

    work: str
    unit: str
    base_bytes: float
    bytes_per_unit: float
    seconds_per_unit: float = 0.0

    def peak_bytes(self, size: float) -> float:
        """The estimated peak memory of work of `size` units, bytes."""
        return self.base_bytes + self.bytes_per_unit * size

    def largest_fitting(self, memory_bytes: float) -> int:
        """The largest size whose estimated peak is within `memory_bytes` (0 if none)."""
        return max(0, math.floor((memory_bytes - self.base_bytes) / self.bytes_per_unit))


# Fitted to peaks measured by benchmarks/bench_memory.py (figures and command in
# benchmarks/README.md), rounded up a little: each line lies at or above every measured peak.
#: molds of a net, per face (`plan_molds` and its report): 221, 572 (574) and 1,949 MiB at
#: 2,500, 10,000 and 40,000 faces (4, 10 and 31 s)
MOLDS_MEMORY = MemoryModel("molds of", "faces", 120e6, 48_500, 0.0008)
#: milling paths of a net, per face (the plan and its files, no simulation): 265, 473 and
#: 1,626 MiB at 2,500, 10,000 and 40,000 faces (4, 8 and 30 s)
MILL_MEMORY = MemoryModel("milling paths of", "faces", 185e6, 39_000, 0.00075)
#: the milling simulation, per cell of its grid (the adaptive and the conventional path
#: simulated), on top of MILL_MEMORY: 420 and 1,203 MiB at 250,000 and 1 million cells
#: against 265 MiB without (28 s, and 2 to 4 minutes on the shared machine)
SIMULATION_MEMORY = MemoryModel("a milling simulation of", "cells", 0.0, 1_100, 0.00026)
#: a design triangulated and laid out, per triangle (`fabplan layout --triangles`, a
#: study's ``design.triangles``, `molds --design`, a design mesh file): 484, 1,738 and
#: 6,845 MiB at 100,000, 400,000 and 1,600,000 triangles (12 s, 53 s and 9 min)
DESIGN_MEMORY = MemoryModel("a design of", "triangles", 60e6, 4_500, 0.0003)
#: a reference mesh of an optimization, per triangle (read, its closest-point tree and
#: the solve of a small net): 146, 370 and 1,212 MiB at 100,000, 400,000 and 1,600,000
#: triangles (1, 2 and 8 s)
REFERENCE_MEMORY = MemoryModel("a reference of", "triangles", 90e6, 750, 0.000005)
#: a study's candidates, per panel: a layout and then molds of its net, one after the other
STUDY_BYTES_PER_PANEL = max(BYTES_PER_PANEL, MOLDS_MEMORY.bytes_per_unit)


def memory_reason(model: MemoryModel, size: float, *, beside_bytes: float = 0.0) -> str | None:
    """Why work of `size` units is refused for the memory it needs, or None when it fits
    `memory_limit`: for a caller that names the option or key (``--triangles 5000000: ``).

    Parameters
    ----------
    model : the work's memory model.
    size : its size, in the model's units.
    beside_bytes : memory the rest of the run needs at the same time, bytes.

    Examples
    --------
    >>> model = MemoryModel("molds of", "faces", 100e6, 50e3)
    >>> memory_reason(model, 10, ) is None
    True
    >>> memory_reason(model, 1e9).split(":")[0]
    'molds of 1,000,000,000 faces would need about 50,000 GB of memory, more than the \
limit of half the available memory'
    """
    limit = memory_limit()
    need = model.peak_bytes(size) + beside_bytes
    if need <= limit:
        return None
    fitting = model.largest_fitting(limit - beside_bytes)
    minutes = model.seconds_per_unit * size / 60
    took = f" and about {minutes:,.0f} minutes" if minutes >= 1 else ""
    rest = f" (the rest of the run {_bytes_text(beside_bytes)} of it)" if beside_bytes else ""
    return (f"{model.work} {_count_text(size)} {model.unit} would need about {_bytes_text(need)} of "
            f"memory{rest}{took}, more than the limit of half the available memory: "
            f"{_bytes_text(limit)} holds at most {fitting:,} {model.unit}"
            + (" beside the rest" if beside_bytes else ""))


def check_memory(model: MemoryModel, size: float, *, where: str, fix: str,
                 beside_bytes: float = 0.0) -> None:
    """Refuse work of `size` units that needs more memory than `memory_limit`, in one
    line: `where` (the option, key or file), the estimate, the largest size that fits
    and `fix` (`beside_bytes`: what the rest of the run needs at the same time).

    Raises
    ------
    InputError
        When the estimated peak exceeds the limit.
    """
    reason = memory_reason(model, size, beside_bytes=beside_bytes)
    if reason is not None:
        raise InputError(f"{where}: {reason}; {fix}")


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
