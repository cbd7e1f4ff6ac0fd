"""Error hierarchy: every failure fabplan reports to a user derives from `FabplanError`."""

__all__ = ["FabplanError", "InputError", "SolverError"]


class FabplanError(Exception):
    """Base of all errors fabplan raises on purpose; the CLI prints the message only."""


class InputError(FabplanError, ValueError):
    """Bad input: a missing or malformed file, an impossible parameter, unusable geometry."""


class SolverError(FabplanError, RuntimeError):
    """The optimization could not produce a result (divergence, impossible constraints)."""
