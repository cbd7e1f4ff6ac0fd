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

import os
import shutil
import stat
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator, Mapping

from ..errors import InputError

__all__ = [
    "STAGING_MARKER",
    "existing_ancestor",
    "check_output_file",
    "check_output_folder",
    "atomic_path",
    "write_texts",
    "output_folder",
    "remove_stale_staging",
    "path_inside",
]

STAGING_MARKER = ".fabplan-staging"   # file in every staging folder: the owner's pid


def existing_ancestor(path: str | os.PathLike) -> Path:
    """The nearest folder at or above `path` that exists (the place a run may write first)."""
    probe = Path(os.path.abspath(path))
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    return probe


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

    Nothing is created. Devices, FIFOs and sockets are refused, so that an output never
    replaces ``/dev/null`` or a pipe with a regular file.

    Raises
    ------
    InputError
        When the path is a folder or a special file, or its folder cannot be made or
        written.
    """
    path = Path(path)
    kind = _special_kind(path)
    if kind:
        raise InputError(f"{path}: is {kind}, not a regular file; give a file path")
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not a file")
    _check_creatable(path)


def check_output_folder(folder: str | os.PathLike, *,
                        accept: Callable[[Path], bool] | None = None) -> None:
    """Make sure `folder` can receive a run's files, without creating anything.

    Parameters
    ----------
    folder : the output folder; it may not exist yet.
    accept : for a run that replaces the folder as a whole, tells whether an existing
        non-empty folder may be replaced (it holds an earlier result of the same kind).
        Without it, files are added to the folder.

    Raises
    ------
    InputError
        When the path is a file or a special file, a folder that may not be replaced, or
        not writable.
    """
    folder = Path(folder)
    kind = _special_kind(folder)
    if kind:
        raise InputError(f"{folder}: is {kind}, not a folder")
    if folder.exists():
        if not folder.is_dir():
            raise InputError(f"{folder}: exists and is not a folder")
        if accept is not None and any(_visible(folder)) and not accept(folder):
            raise InputError(f"{folder}: the folder is not empty and holds no earlier result "
                             "of this command (it would be replaced); choose another folder")
    _check_creatable(folder)


def _visible(folder: Path) -> Iterator[Path]:
    return (p for p in folder.iterdir() if not _is_staging(p))


def _is_staging(path: Path) -> bool:
    return path.is_dir() and (path / STAGING_MARKER).is_file()


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def remove_stale_staging(folder: str | os.PathLike) -> list[Path]:
    """Remove the staging folders in `folder` whose owning process is gone.

    Returns
    -------
    list of Path, the folders removed.
    """
    removed: list[Path] = []
    folder = Path(folder)
    if not folder.is_dir():
        return removed
    for entry in folder.iterdir():
        if not entry.name.startswith(".") or not _is_staging(entry):
            continue
        try:
            pid = int((entry / STAGING_MARKER).read_text().split()[0])
        except (OSError, ValueError, IndexError):
            pid = -1
        if pid != os.getpid() and (pid <= 0 or not _pid_alive(pid)):
            shutil.rmtree(entry, ignore_errors=True)
            removed.append(entry)
    return removed


def _new_staging(beside: Path, name: str) -> Path:
    """A new staging folder in the existing folder `beside`, marked with this process."""
    remove_stale_staging(beside)
    staging = beside / f".{name}.staging-{uuid.uuid4().hex[:12]}"
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
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex[:12]}.tmp"
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
            tmp = current.parent / f".{current.name}.{uuid.uuid4().hex[:12]}.tmp"
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


@contextmanager
def output_folder(folder: str | os.PathLike, *, replace: bool = False,
                  accept: Callable[[Path], bool] | None = None) -> Iterator[Path]:
    """Stage a run's output folder; move it into place only when the block succeeds.

    Parameters
    ----------
    folder : the output folder.
    replace : True: the folder is replaced as a whole (an earlier result is kept until
        the new one is complete, then removed). False: the staged files are moved into
        the folder one by one, each replacing a file of the same name.
    accept : with `replace`, tells whether an existing non-empty folder may be replaced
        (see `check_output_folder`).

    Yields
    ------
    Path of the staging folder: write every file there.

    Raises
    ------
    InputError
        When the folder cannot be written; nothing is left behind.
    """
    folder = Path(folder)
    check_output_folder(folder, accept=accept if replace else None)
    beside = existing_ancestor(folder.parent if replace else folder)
    created: list[Path] = []
    staging = _new_staging(beside, folder.name or "output")
    try:
        yield staging
        (staging / STAGING_MARKER).unlink()
        if replace:
            created = _make_parents(folder.parent)
            _swap_in(staging, folder)
        else:
            created = _make_parents(folder)
            for entry in staging.iterdir():
                target = folder / entry.name
                if entry.is_dir() and target.is_dir():
                    shutil.rmtree(target)
                os.replace(entry, target)
    except OSError as exc:
        _remove_created(created)
        raise InputError(f"{folder}: cannot write ({exc.strerror or exc})") from None
    except BaseException:
        _remove_created(created)
        raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _swap_in(staging: Path, folder: Path) -> None:
    """Replace `folder` (if any) by `staging`; the old folder is removed only afterwards."""
    if not folder.exists():
        os.replace(staging, folder)
        return
    old = _new_staging(folder.parent, f"{folder.name}.old")
    os.replace(folder, old / "previous")
    try:
        os.replace(staging, folder)
    except BaseException:
        os.replace(old / "previous", folder)
        raise
    finally:
        shutil.rmtree(old, ignore_errors=True)
