"""The candidates a study has computed, kept in its output folder for `--resume`.

With ``fabplan study STUDY -o DIR --resume`` a study writes every finished candidate (its
net, molds, strips and measurements) to ``DIR/.fabplan-cache/KEY.pkl`` as soon as it is
done, and takes the candidates already there instead of computing them: a run that was
interrupted (Ctrl-C, a lost machine) or a sweep that grows computes only what is missing.
Without ``--resume`` nothing is kept: a failed run leaves nothing behind. The key hashes
everything a candidate's result depends on: the fabplan version, the design (and the
bytes of every file it reads), the panel size, the limits, the strip options, the
iteration cap, the layout starts and the candidate itself. The cost weights are not in it: ranking is
recomputed from the measured candidates. A cache entry that does not load is ignored and
computed again.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .. import __version__

if TYPE_CHECKING:
    from .run import CandidateResult
    from .spec import Candidate, Study

__all__ = ["CACHE_FOLDER", "CandidateCache"]

CACHE_FOLDER = ".fabplan-cache"


def _file_digests(study: Study) -> dict[str, str]:
    """sha256 of every existing file the design names (its mesh, a profile, a grid)."""
    names = [study.design.source, *(str(v) for v in study.design.parameters.values())]
    names += [part.split("=", 1)[-1] for part in study.design.source.replace(":", ",").split(",")]
    digests = {}
    for name in names:
        path = Path(name)
        try:
            if path.is_file():
                digests[str(path)] = hashlib.sha256(path.read_bytes()).hexdigest()
        except OSError:
            continue
    return digests


class CandidateCache:
    """Finished candidates of a study, in ``out_dir/.fabplan-cache``.

    Parameters
    ----------
    out_dir : the study's output folder.
    study : the study; its candidates are looked up by `key`.
    """

    def __init__(self, out_dir: str | os.PathLike, study: Study) -> None:
        import cloudpickle  # what Dask sends tasks with: it also pickles parametric designs

        self._pickle = cloudpickle
        self.folder = Path(out_dir) / CACHE_FOLDER
        self._study = study
        record = study.record()
        self._common = json.dumps({
            "fabplan": __version__, "design": record["design"], "files": _file_digests(study),
            "strips": record["strips"], "max_iterations": record["max_iterations"],
            "layout_starts": record["layout_starts"],
        }, sort_keys=True, default=str)

    def key(self, candidate: Candidate) -> str:
        # the candidate's own panel size and limits, so that a sweep that grows keeps
        # the candidates it had
        own = {"candidate": asdict(candidate), "panel_size": self._study.panel_size_of(candidate),
               "limits": asdict(self._study.limits_of(candidate))}
        text = self._common + json.dumps(own, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:32]

    def load(self, candidate: Candidate) -> CandidateResult | None:
        """The cached result of `candidate`, or None."""
        path = self.folder / f"{self.key(candidate)}.pkl"
        try:
            with path.open("rb") as handle:
                result: Any = self._pickle.load(handle)
        except (OSError, EOFError, ValueError, TypeError, AttributeError, ImportError,
                ModuleNotFoundError, self._pickle.pickle.UnpicklingError):
            return None
        return result if getattr(result, "candidate", None) == candidate else None

    def store(self, result: CandidateResult) -> None:
        """Keep a finished candidate (written atomically; failed candidates are not kept:
        a resumed run tries them again)."""
        if result.failed:
            return
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / f"{self.key(result.candidate)}.pkl"
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        with tmp.open("wb") as handle:
            self._pickle.dump(result, handle)
        os.replace(tmp, path)
