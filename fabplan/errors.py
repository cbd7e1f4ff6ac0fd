"""Error hierarchy: every failure fabplan reports to a user derives from `FabplanError`."""

__all__ = ["FabplanError", "InputError", "BrokenLayoutError", "SolverError", "CannotMakeError"]


class FabplanError(Exception):
    """Base of all errors fabplan raises on purpose; the CLI prints the message only."""


class InputError(FabplanError, ValueError):
    """Bad input: a missing or malformed file, an impossible parameter, unusable geometry."""


class BrokenLayoutError(InputError):
    """A design whose layout at the panel size asked does not hold together (umbilics,
    directions that turn within a panel): another panel size may
    (`fabplan.layout.surface_layout.holding_panel_size`)."""


class SolverError(FabplanError, RuntimeError):
    """The optimization could not produce a result (divergence, impossible constraints)."""


class CannotMakeError(FabplanError, RuntimeError):
    """Sound input from which what was asked cannot be made as it stands (a net milled in
    one piece whose lines break at irregular vertices, spheres on both sides of it): the
    CLI says why and exits 3, as for a result that misses its limits, not 2 (bad input)."""
