"""The rules a tagged mesh obeys, shared by the triangle and the tetrahedral checks (``problem.validation``): the
names of the subdomains and of the built-in groups, and a ``BoundaryRule`` per boundary group."""

from dataclasses import dataclass

from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, Subdomain

__all__ = ["BoundaryRule", "BOUNDARY_RULES"]

OMEGA1, OMEGA2 = PHYSICAL_NAMES[Subdomain.OMEGA1], PHYSICAL_NAMES[Subdomain.OMEGA2]
GAMMA_D, GAMMA_C, GAMMA = (PHYSICAL_NAMES[b] for b in (Boundary.GAMMA_D, Boundary.GAMMA_C, Boundary.INTERFACE))


@dataclass(frozen=True, slots=True)
class BoundaryRule:
    """What a tagged boundary group must satisfy: on the outer boundary (of ``subdomain``, if given),
    no segment in common with the groups ``disjoint_from``, no node in common with ``away_from``."""

    name: str
    required: bool = True
    subdomain: str | None = None
    disjoint_from: tuple[str, ...] = ()
    away_from: tuple[str, ...] = ()


#: The rules of the built-in boundary groups (the interface ``gamma`` has its own check).
BOUNDARY_RULES: tuple[BoundaryRule, ...] = (
    BoundaryRule(GAMMA_D, disjoint_from=(GAMMA_C,)),
    BoundaryRule(GAMMA_C, subdomain=OMEGA2, away_from=(GAMMA,)),
)
