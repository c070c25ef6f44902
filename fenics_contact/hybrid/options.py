"""Options of the hybrid iteration and of its interface Newton: frozen, validated dataclasses.

``IterationOptions`` is the stopping rule and the update of the interface data (``hybrid.iteration``);
``InterfaceNewtonOptions`` the strategy and step caps of the interface Newton
(``hybrid.interface_newton``), which ``IterationOptions.newton`` carries.  They live apart from both
so that the loop and the Newton method read the same options without importing each other.
"""

from dataclasses import dataclass, replace

import numpy as np

from fenics_contact.errors import InputError

__all__ = ["default_accel", "interface_options", "ACCELERATIONS", "InterfaceNewtonOptions", "IterationOptions"]


#: The updates of the interface data: the paper's plain update, Anderson acceleration, interface Newton.
ACCELERATIONS = ("none", "anderson", "newton")


@dataclass(frozen=True, slots=True)
class InterfaceNewtonOptions:
    """Interface Newton (``hybrid.interface_newton``): strategy and step caps.

    ``strategy``: ``"condensed"`` (Ω₁'s affine interface response and the contact-free Ω₂
    condensed offline onto γ and Γ_C; online a semismooth Newton on the Γ_C unknowns, then one
    application of T to certify) or ``"interface"`` (Newton on F(g) = g − T(g), Ω₂'s generalized
    Jacobian by back-solves with its current factorization at every step).
    ``max_steps`` caps the contact Newton, ``max_corrections`` the Newton steps on F(g) that
    follow it (or, for ``"interface"``, all steps).  ``front_window`` (default 8; 0: off): the condensed
    contact Newton resolves every front of its next active set locally, on the ``front_window`` Γ_C
    unknowns on either side of it (on a 3D contact surface: within ``front_window`` − 1 rings of neighbours)
    with the forces elsewhere held (``hybrid.fronts.LocalFronts``; the same
    fixed point; 3–5 steps instead of 8–11 where a near-rigid body rests on Γ_C at contrast 1e6: README,
    "Interface Newton").
    ``krylov_layers`` and ``krylov_coarse`` (an Ω₁ solved by AMG: its matrix-free Newton–GMRES,
    ``hybrid.krylov_newton``): GMRES preconditioned by the Robin response of the band of Ω₁ within
    ``krylov_layers`` cells of γ and, beyond it, the coarse functions ``krylov_coarse`` levels below the finest of
    Ω₁'s AMG (0: none); ``krylov_layers`` None: no preconditioner (``hybrid.krylov_band``).
    """

    strategy: str = "condensed"
    max_steps: int = 50
    max_corrections: int = 8
    chunk: int = 128  #: right-hand sides per multi-RHS back-solve of the offline condensation
    front_window: int = 8
    krylov_layers: int | None = 2
    krylov_coarse: int = 1

    def __post_init__(self) -> None:
        if (
            isinstance(self.front_window, bool)
            or not isinstance(self.front_window, (int, np.integer))
            or self.front_window < 0
        ):
            raise InputError(
                f"interface Newton: front_window must be an integer >= 0 (0: off), got {self.front_window!r}"
            )
        for name in ("krylov_layers", "krylov_coarse"):
            value = getattr(self, name)
            if (value is not None or name == "krylov_coarse") and (
                isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0
            ):
                raise InputError(f"interface Newton: {name} must be an integer >= 0, got {value!r}")
        if self.krylov_layers == 0 and self.krylov_coarse == 0:
            raise InputError(
                "interface Newton: krylov_layers and krylov_coarse are both 0 (no Ω₁ model); "
                "krylov_layers=None turns the preconditioner off"
            )
        if self.strategy not in ("condensed", "interface"):
            raise InputError(f"unknown interface Newton strategy {self.strategy!r}; choose 'condensed' or 'interface'")
        if self.max_steps < 1 or self.max_corrections < 0 or self.chunk < 1:
            raise InputError("interface Newton: max_steps and chunk must be >= 1, max_corrections >= 0")


@dataclass(frozen=True, slots=True)
class IterationOptions:
    """Stopping rule: transmission residual < tol (``hybrid.certificate``), at most max_iterations.

    ``accel`` is the update: ``"none"`` (the paper's), ``"anderson"`` (depth ``depth``) or
    ``"newton"`` (``hybrid.interface_newton``, options ``newton``); None: ``default_accel`` of the step (the
    interface Newton, measured the fastest on every tested model, serially and under MPI).
    """

    tol: float = 1.0e-6
    max_iterations: int = 2000
    accel: str | None = None
    depth: int = 10
    newton: InterfaceNewtonOptions = InterfaceNewtonOptions()

    def __post_init__(self) -> None:
        if not (isinstance(self.tol, (int, float, np.number)) and 0 < self.tol < 1):
            raise InputError(f"the relative tolerance must lie in (0, 1), got {self.tol!r}")
        if not isinstance(self.max_iterations, (int, np.integer)) or self.max_iterations < 1:
            raise InputError(f"max_iterations must be an integer >= 1, got {self.max_iterations!r}")
        if self.accel is not None and self.accel not in ACCELERATIONS:
            raise InputError(f"unknown acceleration {self.accel!r}; choose one of {', '.join(ACCELERATIONS)}")
        if not isinstance(self.depth, (int, np.integer)) or self.depth < 1:
            raise InputError(f"the Anderson depth must be an integer >= 1, got {self.depth!r}")


def default_accel(step, comm) -> str:
    """The update when none is given: the interface Newton, for every step (a hybrid step or its class) on any
    number of ranks ``comm`` (with an Ω₁ solved by AMG its matrix-free Newton–GMRES, ``hybrid.krylov_newton``:
    measured faster than Anderson with the same Ω₁, and converging at contrast 1e6 where Anderson does not)."""
    return "newton"


def interface_options(
    options: InterfaceNewtonOptions, friction, *, frictional_condensation: bool
) -> InterfaceNewtonOptions:
    """The interface Newton options a step runs: with friction on Γ_C (``friction`` not None) and no frictional
    condensation (``hybrid.friction``: Algorithm 1) the ``"interface"`` strategy (Newton on
    F(g) = g − T(g) with Ω₂'s frictional Jacobian) instead of the normal-only condensation."""
    if friction is not None and options.strategy == "condensed" and not frictional_condensation:
        return replace(options, strategy="interface")
    return options
