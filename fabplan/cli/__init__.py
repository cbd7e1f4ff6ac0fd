"""The `fabplan` command: thin wrappers over the API, one module per command.

Each command's module (`nets`, `measure`, `optimize`, `molds`, `layout`, `strips`, `arcs`,
`mill`, `study`, `templates`, `edit`) holds its arguments, its checks, its run and the
summary it prints, and registers itself (`registry`). What several commands share: the
parser and the shared options (`arguments`), how a command runs and ends (`running`: exit
codes, one-line errors, signals, warnings), the files it reads and writes (`files`), the
record beside a net (`records`), the solve (`solving`), memory checks (`memory`), the
fabrication limits (`limits`) and the cladding's shortfalls (`cladding`). `command_line`
builds the parser from the registry and runs `main`.

May import: every stage below it (`fabplan.edit`, `.study`, `.fabricate`, `.layout`,
`.design`, `.solve`, `.net`, `.report`, `.io`, `.errors`).
"""

from __future__ import annotations

from .arguments import InRange
from .cladding import boundary_text, boundary_warnings
from .command_line import build_parser, command_parser, main
from .layout import LINE_TURN_WARNING_DEG, layout_warnings
from .limits import deviation_check, limits_exit
from .registry import COMMANDS, Command, register
from .running import EXIT_BAD_INPUT, EXIT_NOT_CONVERGED, stopped_by_signals

__all__ = ["COMMANDS", "Command", "EXIT_BAD_INPUT", "EXIT_NOT_CONVERGED", "InRange",
           "LINE_TURN_WARNING_DEG", "boundary_text", "boundary_warnings", "build_parser",
           "command_parser",
           "deviation_check", "layout_warnings", "limits_exit", "main", "register",
           "stopped_by_signals"]
