"""The candidates a study has computed, kept in its output folder for `--resume`.

With ``fabplan study STUDY -o DIR --resume`` a study keeps every finished candidate (its
net, molds, strips and measurements) in ``DIR/.fabplan-cache`` as soon as it is done, and
takes the candidates already there instead of computing them: a run that was interrupted
(Ctrl-C, a lost machine) or a sweep that grows computes only what is missing. Without
``--resume`` nothing is kept: a failed run leaves nothing behind.

A kept candidate is data, never code: ``KEY.json`` (the candidate's objects as a typed
JSON tree, `fabplan.io.typed_data`) and ``KEY.npz`` (its arrays, read with
``allow_pickle=False``). Only the result types listed in `CACHED_TYPES` can be read back,
so a crafted file in a shared study folder can at worst be ignored. The JSON holds the
format version, the key and the SHA-256 of its ``.npz``. The key hashes everything a
candidate's result depends on: the fabplan version, the design (and the bytes of every
file it reads), the panel size, the limits, the strip options, the iteration cap, the
layout starts, the panel material and the candidate itself. The cost weights are not in it: ranking is
recomputed from the measured candidates. An entry that does not match (another version,
a damaged or foreign file, a link or a FIFO in its place) is ignored with a note and
computed again.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import stat
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from .. import __version__
from ..errors import InputError
from ..io.output import remove_stale_staging, temporary_path
from ..io.typed_data import decode, encode, packed_bytes

if TYPE_CHECKING:
    from .definition import Candidate, Study
    from .result import CandidateResult

__all__ = ["CACHE_FOLDER", "CACHE_FORMAT", "CandidateCache", "cached_types"]

CACHE_FOLDER = ".fabplan-cache"
#: what a kept candidate's JSON says it is, and the version of its layout
CACHE_FORMAT = {"format": "fabplan-candidate", "version": 3}
#: largest kept file read back (a crafted huge file is ignored, not read)
MAX_ENTRY_BYTES = 2**29
#: room for the header of every array in a kept .npz beyond its values
_NPY_HEADER = 4096


def cached_types() -> dict[str, type]:
    """The only classes a kept candidate may hold: a study candidate's results."""
    from ..fabricate.limits import LimitCheck
    from ..fabricate.molds.boundary_molds import BoundaryMolds, BoundarySides
    from ..fabricate.molds.materials import Material
    from ..fabricate.molds.mold_plan import MoldPlan
    from ..fabricate.molds.mold_shapes import MoldSettings
    from ..fabricate.molds.panel_classes import PanelClasses
    from ..fabricate.molds.panel_meshes import PanelMesh
    from ..fabricate.strips.nesting import Label, Nesting, Part, Placement, Sheet
    from ..fabricate.strips.strip_plan import StripPlan
    from ..fabricate.strips.strip_set import Crossing, ReferenceCurve, Strip, StripSet, StripSettings
    from ..fabricate.strips.unrolling import ArcRun
    from ..layout.boundary_panels import BoundaryPanels
    from ..net.mesh import QuadMesh
    from ..solve.optimize import OptimizationResult
    from .definition import Candidate
    from .result import CandidateResult

    classes: list[type] = [
        CandidateResult, Candidate, OptimizationResult, QuadMesh, BoundaryPanels, MoldPlan,
        MoldSettings, BoundaryMolds, BoundarySides, StripPlan, StripSet, Strip, StripSettings, ReferenceCurve,
        ArcRun, Crossing, Part, Label, Placement, Sheet, Nesting, Material, PanelClasses,
        PanelMesh, LimitCheck]
    return {cls.__name__: cls for cls in classes}


def _file_digests(study: Study) -> dict[str, str]:
    """sha256 of every file the design reads (its mesh, a profile, a grid)."""
    digests = {}
    for path in study.design.files():
        try:
            digests[str(path)] = hashlib.sha256(path.read_bytes()).hexdigest()
        except OSError:
            continue
    return digests


def _arrays(data: bytes, expected: list[int]) -> list[np.ndarray]:
    """The packed arrays of a kept ``.npz``, each checked against the bytes its JSON
    expects before it is unpacked (a small file must not unpack into gigabytes)."""
    import zipfile

    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        members = {info.filename: info for info in archive.infolist()}
    names = [f"arr_{k}.npy" for k in range(len(expected))]
    if sorted(members) != sorted(names):
        raise ValueError("its arrays are not the ones it lists")
    for name, size in zip(names, expected, strict=True):
        if members[name].file_size > size + _NPY_HEADER:
            raise ValueError(f"{name} unpacks to {members[name].file_size} bytes, more than the "
                             f"{size} it lists")
    with np.load(io.BytesIO(data), allow_pickle=False) as stored:
        return [stored[f"arr_{k}"] for k in range(len(expected))]


def _read_regular(path: Path) -> bytes:
    """The bytes of `path`, which must be a regular file and not a link (a FIFO would
    block a plain read forever)."""
    fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise ValueError("not a regular file")
        if info.st_size > MAX_ENTRY_BYTES:
            raise ValueError(f"larger than {MAX_ENTRY_BYTES} bytes")
        with os.fdopen(fd, "rb", closefd=False) as handle:
            return handle.read()
    finally:
        os.close(fd)


class CandidateCache:
    """Finished candidates of a study, in ``out_dir/.fabplan-cache``.

    Parameters
    ----------
    out_dir : the study's output folder.
    study : the study; its candidates are looked up by `key`.
    note : called with a line for every kept entry that is ignored, and every candidate
        that cannot be kept.

    Raises
    ------
    InputError
        When ``.fabplan-cache`` exists and is not a folder of its own (a link, a file):
        a study writes nothing through it.
    """

    def __init__(self, out_dir: str | os.PathLike, study: Study, *,
                 note: Callable[[str], None] | None = None) -> None:
        self.folder = Path(out_dir) / CACHE_FOLDER
        if os.path.lexists(self.folder) and (self.folder.is_symlink() or not self.folder.is_dir()):
            raise InputError(f"{self.folder}: is not a folder of its own (a link or a file); "
                             "remove it to resume")
        remove_stale_staging(self.folder)      # what a killed run was writing
        self._study = study
        self._note = note or (lambda message: None)
        self._types = cached_types()
        record = study.record()
        self._common = json.dumps({
            "fabplan": __version__, "design": record["design"], "files": _file_digests(study),
            "strips": record["strips"], "max_iterations": record["max_iterations"],
            "layout_starts": record["layout_starts"], "material": record["material"],
            "smoothing": record["smoothing"],
        }, sort_keys=True, default=str)

    def under(self, study: Study) -> CandidateCache:
        """The same folder for the candidates of `study` (another study's limits: the runs
        of a relaxation, `fabplan.study.relaxation_check`)."""
        return CandidateCache(self.folder.parent, study, note=self._note)

    def key(self, candidate: Candidate) -> str:
        # the candidate's own panel size and limits, so that a sweep that grows keeps
        # the candidates it had
        own = {"candidate": asdict(candidate), "panel_size": self._study.panel_size_of(candidate),
               "limits": asdict(self._study.limits_of(candidate))}
        text = self._common + json.dumps(own, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:32]

    def load(self, candidate: Candidate) -> CandidateResult | None:
        """The kept result of `candidate`, or None (nothing kept, or an entry that does
        not match, which is ignored with a note)."""
        key = self.key(candidate)
        path = self.folder / f"{key}.json"
        if not os.path.lexists(path):
            return None
        try:
            header = json.loads(_read_regular(path))
            if not isinstance(header, dict) or {k: header.get(k) for k in CACHE_FORMAT} != CACHE_FORMAT:
                raise ValueError("not a kept candidate of this fabplan version")
            if header.get("key") != key or header.get("fabplan") != __version__:
                raise ValueError("kept for other inputs or another fabplan version")
            data = _read_regular(path.with_suffix(".npz"))
            if hashlib.sha256(data).hexdigest() != header.get("arrays_sha256"):
                raise ValueError("its arrays do not match it")
            arrays = _arrays(data, packed_bytes(header["data"]))
            result = decode(header["data"], arrays, self._types)
            if type(result).__name__ != "CandidateResult" or result.candidate != candidate:
                raise ValueError("another candidate")
            self._check(result)
        # the entry is data from a folder someone may have shared: whatever is wrong
        # with it (a broken zip, numbers out of range, fields that do not fit), it is
        # ignored and the candidate computed again
        except Exception as exc:
            what = str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__
            self._note(f"    {CACHE_FOLDER}/{path.name} ignored ({what}): {candidate.name} is "
                       "computed again")
            return None
        return result

    def _check(self, result: CandidateResult) -> None:
        """Raise unless a kept result holds together: its arrays sized to its net, and its
        metrics judged and written as a fresh candidate's are."""
        from ..io.records import json_text
        from .verdict import candidate_cost, verdict

        net, molds, deviation = result.net, result.molds, result.deviation_mm
        if net is None or molds is None or not isinstance(result.metrics, dict):
            raise ValueError("a kept candidate without its net, molds or metrics")
        vertices = net.mesh.vertex_count
        if deviation is not None and deviation.shape != (vertices,):
            raise ValueError(f"{deviation.shape[0] if deviation.ndim else 0} deviations for "
                             f"{vertices} vertices")
        if molds.mold.shape != (len(net.mesh.face_sizes),) and result.boundary_molds is None:
            raise ValueError("molds for another number of panels")
        verdict(result.metrics, self._study.limits_of(result.candidate),
                panel_size=self._study.panel_size_of(result.candidate),
                units=self._study.design.units)
        candidate_cost(result.metrics, self._study.cost)
        json_text({"metrics": result.metrics, "checks": result.checks})

    def store(self, result: CandidateResult) -> None:
        """Keep a finished candidate (written atomically, its arrays first; failed
        candidates are not kept: a resumed run tries them again)."""
        if result.failed:
            return
        try:
            tree, arrays = encode(result, self._types)
        except TypeError as exc:
            self._note(f"    {result.name} is not kept for --resume ({exc})")
            return
        buffer = io.BytesIO()
        np.savez(buffer, *arrays)
        data = buffer.getvalue()
        header = {**CACHE_FORMAT, "fabplan": __version__, "key": self.key(result.candidate),
                  "candidate": result.name, "arrays_sha256": hashlib.sha256(data).hexdigest(),
                  "data": tree}
        text = json.dumps(header, separators=(",", ":"))
        stem = self.folder / self.key(result.candidate)
        try:
            os.makedirs(self.folder, exist_ok=True)
            for path, content in ((stem.with_suffix(".npz"), data),
                                  (stem.with_suffix(".json"), text.encode())):
                if os.path.lexists(path) and (path.is_symlink() or not path.is_file()):
                    raise OSError(f"{path.name} is in the way (not a file)")
                tmp = temporary_path(self.folder)
                try:
                    with open(tmp, "xb") as handle:
                        handle.write(content)
                    os.replace(tmp, path)
                finally:
                    tmp.unlink(missing_ok=True)
        except OSError as exc:      # the study goes on; the candidate is computed again later
            self._note(f"    {result.name} is not kept for --resume "
                       f"({exc.strerror or exc})")
