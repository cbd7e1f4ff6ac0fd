"""The one way fabplan writes its outputs: all of it, or nothing.

A run builds its files in a hidden staging place beside the destination and moves them
into place only when everything is written and checked. A failed or interrupted run
therefore leaves neither a half-written file nor an empty folder, and an earlier result
stays intact until the new one is complete. Staging folders carry a marker naming the
process that owns them, so that a later run removes those of a process that is gone
(killed with ``kill -9``, say).

Permissions: files are created with mode 0o666 and folders with 0o777, so the process
umask applies as it does for any program; the umask is never read or changed.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import stat
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterable, Iterator, Mapping

from ..errors import InputError

__all__ = [
    "STAGING_MARKER",
    "MANIFEST",
    "existing_ancestor",
    "output_argument",
    "check_output_file",
    "check_output_folder",
    "check_apart",
    "temporary_path",
    "atomic_path",
    "write_texts",
    "output_folder",
    "read_manifest",
    "remove_stale_staging",
    "path_inside",
]

STAGING_MARKER = ".fabplan-staging"   # file in every staging folder: the owner's pid
#: in a folder that a run replaces (a study's): the files that run wrote there, one
#: relative path per JSON list entry; a later run removes those and nothing else
MANIFEST = ".fabplan-files"
#: a manifest listing more entries than this is not read (no run writes that many files)
MAX_MANIFEST_ENTRIES = 100_000
# hidden names of files and folders being written: ``.fabplan-PID-HEX.tmp`` (or
# ``.staging``, ``.old``), short whatever the output's name, naming the process that
# owns them so that a later run can remove them once it is gone
_TEMPORARY = re.compile(r"^\.fabplan-(\d+)-[0-9a-f]{12}\.(tmp|staging|old)$")
_NAME_MAX = 255
_PATH_MAX = 4095


def existing_ancestor(path: str | os.PathLike) -> Path:
    """The nearest folder at or above `path` that exists (the place a run may write first)."""
    probe = Path(os.path.abspath(path))
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    return probe


def temporary_path(folder: str | os.PathLike, kind: str = "tmp") -> Path:
    """A new hidden name in `folder` for a file (`kind` "tmp") or folder ("staging",
    "old") being written: ``.fabplan-PID-HEX.KIND``."""
    return Path(folder) / f".fabplan-{os.getpid()}-{uuid.uuid4().hex[:12]}.{kind}"


def output_argument(text: str, *, folder: bool = False, option: str = "-o") -> Path:
    """The path a user gave for an output, refused before any work when it cannot be one.

    Parameters
    ----------
    text : the path as given (a trailing ``/`` still on it).
    folder : the output is a folder (else a file).
    option : the option named in the messages.

    Raises
    ------
    InputError
        For an empty path, a file path ending in ``/``, a name or path longer than the
        file system takes, or ``..`` out of a folder that does not exist (which the run
        would create first and then fail in).

    Examples
    --------
    >>> output_argument("out/net.obj").as_posix()
    'out/net.obj'
    >>> output_argument("")
    Traceback (most recent call last):
    ...
    fabplan.errors.InputError: -o is empty: name the output file
    >>> output_argument("net.json/")
    Traceback (most recent call last):
    ...
    fabplan.errors.InputError: net.json/: ends in '/', which names a folder; -o takes a file
    """
    what = "folder" if folder else "file"
    if not text or not text.strip():
        raise InputError(f"{option} is empty: name the output {what}")
    if "\0" in text:
        raise InputError(f"{option} {text!r}: a path cannot hold a NUL character")
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        raise InputError(f"{option} {text!r}: the name is not valid UTF-8 text (the files "
                         "record their names); rename it") from None
    if not folder and text.endswith(("/", os.sep)):
        raise InputError(f"{text}: ends in '/', which names a folder; {option} takes a file")
    path = Path(text)
    probe = Path(path.anchor)
    for part in path.parts[1 if path.anchor else 0:]:
        if part == ".." and not probe.is_dir():
            raise InputError(f"{text}: goes up (..) out of {probe}, which is not an existing "
                             "folder; give the path without it")
        probe = probe / part
    check_path_length(path)
    return path


def check_path_length(path: str | os.PathLike) -> None:
    """Refuse a path whose name or whole length the file system would refuse."""
    absolute = os.path.abspath(path)
    for part in Path(absolute).parts:
        if len(os.fsencode(part)) > _NAME_MAX:
            raise InputError(f"{path}: the name {part[:40]}... is {len(os.fsencode(part))} bytes "
                             f"long; file names take at most {_NAME_MAX}")
    if len(os.fsencode(absolute)) > _PATH_MAX:
        raise InputError(f"{path}: the path is {len(os.fsencode(absolute))} bytes long; "
                         f"paths take at most {_PATH_MAX}")


def check_apart(outputs: Iterable[str | os.PathLike],
                inputs: Mapping[Path, str] | Iterable[str | os.PathLike]) -> None:
    """Refuse any output that is one of `inputs`: the same path, or the same file through
    a link or a hard link.

    Parameters
    ----------
    outputs : every path a run will write.
    inputs : every file it reads (or that the next command reads back with them), with
        what it is ("the layout record of lay.obj") where a mapping is given.

    Raises
    ------
    InputError
        Naming the output and the input it would overwrite.

    Examples
    --------
    >>> check_apart(["a/net.obj"], {Path("a/../a/net.obj"): "the input net"})
    Traceback (most recent call last):
    ...
    fabplan.errors.InputError: a/net.obj: is the input net (a/../a/net.obj); refusing to \
overwrite the input: choose another output
    """
    known = _input_keys(inputs)
    for out in outputs:
        hit = _input_at(out, known)
        if hit is not None:
            raise InputError(f"{out}: is {hit[1]} ({hit[0]}); refusing to overwrite the input: "
                             "choose another output")


def path_inside(folder: str | os.PathLike, *parts: str) -> Path:
    """`folder` joined with `parts`, refused unless it resolves to a path inside `folder`.

    For output paths built from names a user gave (a study's candidate names): an
    absolute name, ``..`` or a symbolic link must not lead a run to write elsewhere.

    Raises
    ------
    InputError
        When the joined path leaves `folder`.

    Examples
    --------
    >>> path_inside("/tmp/study", "candidates", "snet").as_posix()
    '/tmp/study/candidates/snet'
    >>> path_inside("/tmp/study", "candidates", "../../etc")
    Traceback (most recent call last):
    ...
    fabplan.errors.InputError: candidates/../../etc: leaves the output folder /tmp/study; \
refusing to write there
    """
    root = Path(os.path.realpath(folder))
    path = root.joinpath(*parts)
    if not Path(os.path.realpath(path)).is_relative_to(root) or path == root:
        raise InputError(f"{'/'.join(parts)}: leaves the output folder {folder}; "
                         "refusing to write there")
    return path


def _input_keys(inputs: Mapping[Path, str] | Iterable[str | os.PathLike]
                ) -> dict[object, tuple[str, str]]:
    """Every input by its resolved path and by its file (device, inode): what
    `_input_at` looks a path up in."""
    described = inputs if isinstance(inputs, Mapping) else {Path(p): "an input" for p in inputs}
    known: dict[object, tuple[str, str]] = {}
    for path, what in described.items():
        if not path:
            continue
        try:
            known[os.path.realpath(path)] = (str(path), what)
            info = os.stat(path)
        except (OSError, ValueError):
            # no file by that name (a NUL byte in it, say): nothing an output can replace;
            # the command refuses the input where it reads it
            continue
        known[(info.st_dev, info.st_ino)] = (str(path), what)
    return known


def _input_at(path: str | os.PathLike, known: dict[object, tuple[str, str]]
              ) -> tuple[str, str] | None:
    """The input (its path and what it is) that `path` is, through links, or None."""
    try:
        hit = known.get(os.path.realpath(path))
        if hit is None:
            info = os.stat(path)
            hit = known.get((info.st_dev, info.st_ino))
    except (OSError, ValueError):
        return None         # no such file yet, or no name of a file (a NUL byte in it)
    return hit


def _special_kind(path: Path) -> str | None:
    """'a device', 'a FIFO', ... when `path` exists and is neither a file nor a folder."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    for test, name in ((stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return None


def _check_creatable(path: Path) -> None:
    """Refuse `path` when the folder a run would write it into is not a writable folder."""
    path = Path(os.path.abspath(path))
    if path.exists():
        folder = path if path.is_dir() else path.parent
    else:
        folder = existing_ancestor(path)
        if not folder.is_dir():
            raise InputError(f"{path}: cannot write there ({folder} is not a folder)")
    if not os.access(folder, os.W_OK):
        raise InputError(f"{path}: cannot write there ({folder} is not writable)")


def check_output_file(path: str | os.PathLike) -> None:
    """Make sure `path` can be written as a regular file, before any long work.

    Nothing is created; the staging of runs that died (killed) beside it is removed.
    Devices, FIFOs and sockets are refused, so that an output never replaces
    ``/dev/null`` or a pipe with a regular file.

    Raises
    ------
    InputError
        When the path is a folder or a special file, too long, or its folder cannot be
        made or written.
    """
    path = Path(path)
    check_path_length(path)
    kind = _special_kind(path)
    if kind:
        raise InputError(f"{path}: is {kind}, not a regular file; give a file path")
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not a file")
    _check_creatable(path)
    remove_stale_staging(existing_ancestor(path.parent))


def check_output_folder(folder: str | os.PathLike, *,
                        owned: Callable[[Path], set[str] | None] | None = None) -> None:
    """Make sure `folder` can receive a run's files, without creating anything (the
    staging of runs that died beside and in it is removed).

    Parameters
    ----------
    folder : the output folder; it may not exist yet.
    owned : for a run that replaces what an earlier run wrote (see `output_folder`):
        the files an earlier run of the same kind wrote in an existing folder, or None
        when it holds none; such a folder must then be empty. Without it, files are
        added to the folder.

    Raises
    ------
    InputError
        When the path is a file or a special file, a folder of other files that may not
        be replaced, or not writable.
    """
    folder = Path(folder)
    check_path_length(folder)
    kind = _special_kind(folder)
    if kind:
        raise InputError(f"{folder}: is {kind}, not a folder")
    if folder.exists():
        if not folder.is_dir():
            raise InputError(f"{folder}: exists and is not a folder")
        if owned is not None and owned(folder) is None and any(_visible(folder)):
            raise InputError(f"{folder}: the folder is not empty and holds no earlier result "
                             "of this command; choose another folder")
    _check_creatable(folder)
    remove_stale_staging(existing_ancestor(folder.parent))
    if folder.is_dir():
        remove_stale_staging(folder)


def _visible(folder: Path) -> Iterator[Path]:
    return (p for p in folder.iterdir() if not _is_staging(p))


def _is_staging(path: Path) -> bool:
    return path.is_dir() and not path.is_symlink() and (path / STAGING_MARKER).is_file()


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def remove_stale_staging(folder: str | os.PathLike) -> list[Path]:
    """Remove the staging folders and temporary files in `folder` whose process is gone.

    Returns
    -------
    list of Path, what was removed.
    """
    removed: list[Path] = []
    folder = Path(folder)
    try:
        entries = list(folder.iterdir())
    except OSError:
        return removed
    for entry in entries:
        if not entry.name.startswith("."):
            continue
        match = _TEMPORARY.match(entry.name)
        if match is not None and entry.is_file() and not entry.is_symlink():
            pid = int(match.group(1))
        elif _is_staging(entry):
            try:
                pid = int((entry / STAGING_MARKER).read_text().split()[0])
            except (OSError, ValueError, IndexError):
                pid = -1
        else:
            continue
        if pid == os.getpid() or (pid > 0 and _pid_alive(pid)):
            continue
        if entry.is_dir():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)
        removed.append(entry)
    return removed


def _new_staging(beside: Path, kind: str = "staging") -> Path:
    """A new staging folder in the existing folder `beside`, marked with this process."""
    staging = temporary_path(beside, kind)
    os.mkdir(staging, 0o777)
    try:
        (staging / STAGING_MARKER).write_text(f"{os.getpid()}\n", encoding="utf-8")
    except BaseException:     # disk full at the first byte: leave no unmarked folder
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return staging


def _make_parents(folder: Path) -> list[Path]:
    """Create `folder` and its missing parents; return the ones created (outermost first)."""
    created = []
    probe = folder
    while not probe.exists():
        created.append(probe)
        probe = probe.parent
    for path in reversed(created):
        os.mkdir(path, 0o777)
    return list(reversed(created))


def _remove_created(created: list[Path]) -> None:
    for path in reversed(created):
        try:
            path.rmdir()
        except OSError:
            pass


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside `path`; rename it onto `path` only if the block succeeds.

    The folder of `path` is created when needed and removed again on failure. A failed
    run therefore never leaves a half-written file, nor an empty folder, behind.
    """
    path = Path(path)
    check_output_file(path)
    created = _make_parents(path.parent)
    tmp = temporary_path(path.parent)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        _remove_created(created)
        raise


def write_texts(files: Mapping[Path, str] | Mapping[str, str]) -> None:
    """Write several text files as one step: all of them, or none.

    Every file goes to a temporary file beside it first; the renames happen only after
    all writes succeeded. On failure the temporary files and any folder made for them
    are removed.

    Raises
    ------
    InputError
        When a file cannot be written (the message names it).
    """
    temporary: dict[Path, Path] = {}
    created: list[Path] = []
    current: Path | None = None
    try:
        for target in files:
            check_output_file(target)
        for target, text in files.items():
            current = Path(target)
            created += _make_parents(current.parent)
            tmp = temporary_path(current.parent)
            temporary[current] = tmp
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            with os.fdopen(fd, "w", encoding="utf-8") as handle:
                handle.write(text)
        for current, tmp in temporary.items():
            os.replace(tmp, current)
    except BaseException as exc:
        for tmp in temporary.values():
            tmp.unlink(missing_ok=True)
        _remove_created(created)
        if isinstance(exc, OSError):
            raise InputError(f"{current}: cannot write ({exc.strerror or exc})") from None
        raise


def read_manifest(folder: str | os.PathLike) -> set[str] | None:
    """The files an earlier run listed in ``folder/.fabplan-files`` (`MANIFEST`) as its
    own, or None when there is no such list. Entries that could lead out of the folder
    (absolute, ``..``, through a link) are left out: the list is data from a folder
    someone may have shared, and it never makes a run remove anything elsewhere."""
    path = Path(folder) / MANIFEST
    try:
        if path.is_symlink() or not path.is_file():
            return None
        listed = json.loads(path.read_text(encoding="utf-8")).get("files")
    except (OSError, ValueError, AttributeError, RecursionError):
        return None
    if not isinstance(listed, list) or len(listed) > MAX_MANIFEST_ENTRIES:
        return None
    return {name for name in listed if isinstance(name, str) and len(name) <= 1024
            and _plain_relative(folder, name)}


def _plain_relative(folder: str | os.PathLike, name: str) -> bool:
    """`name` is a relative path to a place inside `folder`, through no link."""
    parts = name.split("/")
    if not name or name.startswith("/") or any(p in ("", ".", "..") or "\0" in p for p in parts):
        return False
    try:
        path_inside(folder, *parts)
    except (InputError, ValueError, OSError):
        return False
    probe = Path(folder)
    for part in parts[:-1]:
        probe = probe / part
        if probe.is_symlink():
            return False
    return True


def _staged_files(staging: Path) -> list[str]:
    """Every file in `staging` (the marker left out), as relative POSIX paths."""
    return sorted(p.relative_to(staging).as_posix() for p in staging.rglob("*")
                  if not p.is_dir() and p.name != STAGING_MARKER)


def _move_in(staging: Path, folder: Path, *, owned: set[str] | None,
             protect: Mapping[Path, str]) -> None:
    """Move every staged file into `folder`, replacing files of the same name; with
    `owned` (a run that replaces an earlier one) also take away the files of `owned`
    that this run does not write, and refuse to replace any file not among them.

    The files replaced or taken away go to a folder beside first and are removed only
    when everything is in place: on failure every move is undone.
    """
    new = _staged_files(staging)
    targets = [folder / name for name in new]
    check_apart(targets, protect)
    for name, target in zip(new, targets, strict=True):
        for parent in [*reversed(Path(name).parents[:-1])]:
            place = folder / parent
            if place.is_symlink() or (place.exists() and not place.is_dir()):
                raise InputError(f"{place}: is in the way of {target} (not a folder)")
        if owned is not None and os.path.lexists(target) and name not in owned:
            raise InputError(f"{target}: exists and no earlier run wrote it; refusing to "
                             "replace it (move it away or choose another folder)")
        if os.path.isdir(target) and not os.path.islink(target):
            raise InputError(f"{target}: is a folder in the way of a file")
    # an input of the run is never taken away, whatever an earlier run's list says
    inputs = _input_keys(protect)
    leaving = set(new) if owned is None else set(new) | {
        name for name in owned if _plain_relative(folder, name)
        and _input_at(folder / name, inputs) is None}
    trash = _new_staging(folder.parent if folder.parent.exists() else folder, "old")
    moved: list[tuple[Path, Path]] = []
    created: list[Path] = []
    try:
        for name in sorted(leaving):
            old = folder / name
            if os.path.lexists(old) and not (old.is_dir() and not old.is_symlink()):
                kept = trash / "files" / name
                kept.parent.mkdir(parents=True, exist_ok=True)
                os.replace(old, kept)
                moved.append((old, kept))
        for name, target in zip(new, targets, strict=True):
            created += _make_parents(target.parent)
            os.replace(staging / name, target)
            moved.append((staging / name, target))
    except BaseException:
        for source, destination in reversed(moved):
            try:
                os.replace(destination, source)
            except OSError:
                pass
        _remove_created(created)
        shutil.rmtree(trash, ignore_errors=True)
        raise
    shutil.rmtree(trash, ignore_errors=True)
    # folders that only the earlier run's files filled
    emptied = {folder / p for name in leaving - set(new) for p in Path(name).parents[:-1]}
    for place in sorted(emptied, key=lambda p: len(p.parts), reverse=True):
        try:
            place.rmdir()
        except OSError:
            pass


@contextmanager
def output_folder(folder: str | os.PathLike, *, replace: bool = False,
                  owned: Callable[[Path], set[str] | None] | None = None,
                  protect: Mapping[Path, str] | None = None) -> Iterator[Path]:
    """Stage a run's output folder; move it into place only when the block succeeds.

    Parameters
    ----------
    folder : the output folder.
    replace : True: the run replaces what an earlier run of its kind wrote there (the
        files `owned` names; by default those of its `MANIFEST`) and writes a new
        manifest; every other file in the folder stays, and one in the way of a new
        file is refused. False: the staged files are added to the folder, each
        replacing a file of the same name.
    owned : with `replace`, the files an earlier run wrote in an existing folder, or
        None when it holds no earlier result (the folder must then be empty); default
        `read_manifest`.
    protect : the run's inputs (path -> what it is), which no output may replace
        (`check_apart`).

    Yields
    ------
    Path of the staging folder: write every file there.

    Raises
    ------
    InputError
        When the folder cannot be written; nothing is left behind.
    """
    folder = Path(folder)
    earlier = (owned or read_manifest) if replace else None
    check_output_folder(folder, owned=earlier)
    beside = existing_ancestor(folder.parent if replace else folder)
    created: list[Path] = []
    staging = _new_staging(beside)
    try:
        yield staging
        # the marker stays until the files are in place: a run killed while moving them
        # leaves staging that the next run knows as stale
        if replace:
            files = {"files": _staged_files(staging) + [MANIFEST]}
            (staging / MANIFEST).write_text(json.dumps(files, indent=1) + "\n", encoding="utf-8")
        if replace and not folder.exists():
            check_apart([folder / name for name in _staged_files(staging)], protect or {})
            created = _make_parents(folder.parent)
            (staging / STAGING_MARKER).unlink()
            os.replace(staging, folder)
        else:
            created = _make_parents(folder)
            previous = None if earlier is None else earlier(folder)
            _move_in(staging, folder, owned=None if not replace else (previous or set()) | {MANIFEST},
                     protect=protect or {})
    except OSError as exc:
        _remove_created(created)
        raise InputError(f"{folder}: cannot write ({exc.strerror or exc})") from None
    except BaseException:
        _remove_created(created)
        raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
