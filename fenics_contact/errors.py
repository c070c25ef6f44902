"""Exception classes: every failure of the package is one of these."""

__all__ = ["FenicsContactError", "InputError", "MeshTagError", "ConvergenceError", "OutputError"]


class FenicsContactError(Exception):
    """Base class of all errors raised by fenics-contact."""


class InputError(FenicsContactError, ValueError):
    """A parameter is outside its admissible range (ν, E, h, H, α, ...)."""


class MeshTagError(FenicsContactError, ValueError):
    """A mesh lacks a tag (physical group) that the method needs."""


class ConvergenceError(FenicsContactError, RuntimeError):
    """A nonlinear or linear solver did not converge."""


class OutputError(FenicsContactError, OSError):
    """The results cannot be written: too little space for them, a write that failed (a full disk)."""
