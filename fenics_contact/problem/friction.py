"""Friction laws on Γ_C: Tresca (a given threshold) and Coulomb (μ times the contact pressure), penalized.

With ν the contact direction at a Γ_C node and P = I − ν⊗ν the projection on its tangential plane (a line in
2D, a plane in 3D), the tangential traction t on the body is a return mapping of the tangential penalty,
quasi-static and incremental (the docs' theory page, 'Friction'):

    t_trial = t_old − (1/δ_t) P (u − u_old − Δm),      t = t_trial                   if |t_trial| ≤ τ   (stick)
                                                        t = τ t_trial / |t_trial|     otherwise          (slip)

u_old and t_old the node's displacement and traction at the previous converged load step, Δm the obstacle's
rigid motion since then, τ the threshold: Tresca τ = s on all of Γ_C (the given-friction law of the classical
Tresca problem: a convex energy), Coulomb τ = μ p with p = (1/δ)(u·ν − g)⁺ the normal penalty pressure.  The
stick stiffness 1/δ_t is ``stiffness_ratio`` times the normal penalty 1/δ (default 1: δ_t = δ = 1e-3·h/E_c,
a factor 1e3 above the element stiffness; the elastic stick slip it leaves is τ·δ_t, like the penetration p·δ).
The mixed methods write the same law on the traction (``fem.mixed_friction``): exact stick, and a slip penalty
ε_t = ε/``stiffness_ratio`` on the excess |t| − τ; both laws become the exact one as δ_t, ε_t → 0.
"""

import math
from dataclasses import dataclass

from fenics_contact.errors import InputError

__all__ = ["Friction", "FRICTION_LAWS", "friction_of"]

#: the friction laws by name
FRICTION_LAWS = ("coulomb", "tresca")


def _positive(value, what: str, *, zero: bool = False) -> float:
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        and not hasattr(value, "__float__")
        or not math.isfinite(float(value))
        or float(value) < 0.0
        or (float(value) == 0.0 and not zero)
    ):
        bound = ">= 0" if zero else "> 0"
        raise InputError(f"friction: {what} must be a finite number {bound}, got {value!r}")
    return float(value)


@dataclass(frozen=True, slots=True)
class Friction:
    """A penalized friction law on Γ_C: ``Friction(law="coulomb", mu=0.3)`` or ``Friction(law="tresca",
    threshold=s)``.

    ``mu``: the Coulomb coefficient (≥ 0); ``threshold``: the Tresca slip threshold s (a traction, ≥ 0);
    ``stiffness_ratio``: the stick stiffness 1/δ_t over the normal penalty 1/δ (default 1); the mixed methods' slip
    penalty is ε_t = ε/``stiffness_ratio``.
    """

    law: str
    mu: float | None = None
    threshold: float | None = None
    stiffness_ratio: float = 1.0

    def __post_init__(self) -> None:
        if self.law not in FRICTION_LAWS:
            raise InputError(f"unknown friction law {self.law!r}; choose one of {', '.join(FRICTION_LAWS)}")
        if self.law == "coulomb":
            if self.mu is None or self.threshold is not None:
                raise InputError(
                    "friction: the Coulomb law takes mu (and no threshold), e.g. Friction('coulomb', mu=0.3)"
                )
            object.__setattr__(self, "mu", _positive(self.mu, "the Coulomb coefficient mu", zero=True))
        else:
            if self.threshold is None or self.mu is not None:
                raise InputError(
                    "friction: the Tresca law takes threshold (and no mu), e.g. Friction('tresca', threshold=0.1)"
                )
            object.__setattr__(self, "threshold", _positive(self.threshold, "the Tresca threshold", zero=True))
        object.__setattr__(self, "stiffness_ratio", _positive(self.stiffness_ratio, "stiffness_ratio"))

    @property
    def name(self) -> str:
        """The law's name ("coulomb" or "tresca")."""
        return self.law

    @property
    def symmetric(self) -> bool:
        """Whether the generalized Jacobian is symmetric: Tresca yes, Coulomb no (its threshold follows the
        pressure, so a slipping node's traction depends on its normal displacement)."""
        return self.law == "tresca"

    def describe(self) -> str:
        """One line: the law and its parameter."""
        value = f"mu = {self.mu:g}" if self.law == "coulomb" else f"threshold = {self.threshold:g}"
        ratio = "" if self.stiffness_ratio == 1.0 else f", stick stiffness {self.stiffness_ratio:g}/δ"
        return f"{self.law} friction, {value}{ratio}"


def friction_of(law) -> Friction | None:
    """The friction law of a contact law (None when frictionless)."""
    return law if isinstance(law, Friction) else None
