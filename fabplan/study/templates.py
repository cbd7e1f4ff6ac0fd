"""The bundled study templates (``templates/NAME.toml``): found, listed, summed up, and
copied with the files they refer to, to start a study of one's own.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from ..errors import InputError
from .spec import read_study
from .table import suggest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = ["templates_folder", "template_names", "template_path", "template_summary",
           "resolve_study", "copy_template"]


def templates_folder() -> Path:
    """The folder of the bundled study templates (``templates/`` of the project)."""
    from importlib.util import find_spec

    try:
        spec = find_spec("fabplan.templates")
    except ModuleNotFoundError:
        spec = None
    for location in (spec.submodule_search_locations or []) if spec else []:
        if Path(location).is_dir():
            return Path(location)
    return Path(__file__).resolve().parents[2] / "templates"


def template_names() -> list[str]:
    """Names of the bundled templates (``templates/NAME.toml``), sorted."""
    return sorted(p.stem for p in templates_folder().glob("*.toml"))


def template_path(name: str) -> Path:
    """The study file of a bundled template.

    Raises
    ------
    InputError
        For an unknown template name (the message lists the known ones).
    """
    path = templates_folder() / f"{name}.toml"
    if not path.is_file():
        names = template_names()
        raise InputError(f"unknown template {name!r}; templates: {', '.join(names)}"
                         + suggest(name, names))
    return path


def template_summary(name: str) -> str:
    """The one-line description of a template (its ``study.description``)."""
    data = tomllib.loads(template_path(name).read_text(encoding="utf-8"))
    text = str(data.get("study", {}).get("description", ""))
    return text.split(". ")[0].rstrip(".")


def resolve_study(source: str) -> Path:
    """A study file path from a path or a template name (a folder of the same name, such as
    an earlier study's output, does not hide the template)."""
    path = Path(source)
    if path.suffix.lower() == ".toml" or path.is_file():
        return path
    if path.is_dir() and source not in template_names():
        raise InputError(f"{source}: a folder, not a study file (a .toml file or a template "
                         f"name: {', '.join(template_names())})")
    return template_path(source)


def copy_template(name: str, destination: str | Path) -> list[Path]:
    """Copy a template (and the files it refers to beside it) to start a new study.

    Returns
    -------
    list of Path written. Refuses to overwrite an existing file.
    """
    from ..io.output import check_output_file, write_texts

    source = template_path(name)
    folder = str(destination).endswith(("/", os.sep)) or Path(destination).is_dir()
    destination = Path(destination)
    if not folder:
        check_output_file(destination)  # a device or FIFO is refused, not renamed .toml
    if folder:
        destination = destination / source.name
    elif destination.suffix.lower() != ".toml":
        destination = destination.with_suffix(".toml")
    study = read_study(source)
    files = {destination: source.read_text(encoding="utf-8")}
    referenced = [Path(study.design.source)] if Path(study.design.source).is_file() else []
    referenced += [Path(v.split("=", 1)[1]) for v in study.design.source.split(":", 1)[-1].split(",")
                   if "=" in v and Path(v.split("=", 1)[1]).is_file()]
    for path in referenced:
        files[destination.parent / path.name] = path.read_text(encoding="utf-8")
    for path in files:
        if path.exists():
            raise InputError(f"{path}: exists; refusing to overwrite it")
    write_texts(files)
    return list(files)
