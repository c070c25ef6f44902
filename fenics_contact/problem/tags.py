"""Named tags for the subdomains and boundaries of a contact model.

The built-in meshes and any user gmsh model must carry physical groups with
these names; the integers are what the gmsh builders in this package assign.

Traction (Neumann) boundaries are any number of facet groups whose names start
with ``Gamma_N`` (``Gamma_N``, ``Gamma_N_top``, ``Gamma_N_2``, ...); each gets
the integer ``neumann_tag(name)``, a pure function of its name, so that a
submesh, a subproblem and a case file all find a group by its name alone.
Every exterior facet in none of the groups is traction free.
"""

import re
import zlib
from enum import IntEnum

from fenics_contact.errors import InputError

__all__ = ["Subdomain", "Boundary", "PHYSICAL_NAMES", "NEUMANN_PREFIX", "is_neumann_name", "neumann_tag"]


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

#: Name prefix of the traction (Neumann) facet groups.
NEUMANN_PREFIX = "Gamma_N"
_NEUMANN_NAME = re.compile(r"^Gamma_N(_?[A-Za-z0-9_]+)?$")
_NEUMANN_BASE = 1000
_NEUMANN_RANGE = 1_000_000


def is_neumann_name(name: str) -> bool:
    """True for ``Gamma_N`` and ``Gamma_N<label>`` (label: letters, digits, underscores)."""
    return bool(_NEUMANN_NAME.match(name))


def neumann_tag(name: str) -> int:
    """The facet-tag integer of the traction group ``name`` (1000 + CRC-32 of the name mod 10⁶)."""
    if not is_neumann_name(name):
        raise InputError(
            f"{name!r} is not a traction group name: use 'Gamma_N' or 'Gamma_N_<label>' (letters, digits, underscores)"
        )
    return _NEUMANN_BASE + zlib.crc32(name.encode()) % _NEUMANN_RANGE
