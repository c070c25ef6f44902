"""Named tags for the subdomains and boundaries of a contact model.

The built-in meshes and any user gmsh model must carry physical groups with
these names; the integers are what the gmsh builders in this package assign.
"""

from enum import IntEnum

__all__ = ["Subdomain", "Boundary", "PHYSICAL_NAMES"]


class Subdomain(IntEnum):
    """Cell tags: Ω₁ (large, heterogeneous, linear) and Ω₂ (contact strip)."""

    OMEGA1 = 1
    OMEGA2 = 2


class Boundary(IntEnum):
    """Facet tags: Dirichlet boundary Γ_D, contact boundary Γ_C, interface γ."""

    GAMMA_D = 11
    GAMMA_C = 12
    INTERFACE = 13


#: gmsh physical-group names, one per tag.
PHYSICAL_NAMES: dict[IntEnum, str] = {
    Subdomain.OMEGA1: "Omega1",
    Subdomain.OMEGA2: "Omega2",
    Boundary.GAMMA_D: "Gamma_D",
    Boundary.GAMMA_C: "Gamma_C",
    Boundary.INTERFACE: "gamma",
}
