"""Checks that a tagged mesh describes the problem the methods solve, before any solve.

A mesh whose tags contradict the method is refused with a ``MeshTagError`` that
names the group and what is wrong (a solve on it would "converge" to the answer
of another problem). The rules, on the triangles and the tagged boundary
segments:

* **cells** — every triangle lies in exactly one of ``Omega1`` and ``Omega2``;
  no triangle has zero area;
* **conforming** — a boundary edge of the triangulation lies on the outer
  boundary of the domain, never inside it (two parts meshed separately, with
  duplicate or hanging nodes, leave such a crack);
* **gamma** — exactly the common boundary of ``Omega1`` and ``Omega2``: every
  segment is an edge shared by an ``Omega1`` and an ``Omega2`` triangle, and
  every such edge is tagged ``gamma``;
* **boundary groups** (``BoundaryRule``, one per group: ``Gamma_D``,
  ``Gamma_C``, and whatever the caller adds, e.g. a ``Gamma_N`` disjoint from
  ``Gamma_D`` and ``Gamma_C``) — segments on the outer boundary, optionally of
  one subdomain (``Gamma_C`` on ``Omega2``), sharing no segment with some groups
  and no node with others (``Gamma_C`` away from ``gamma``);
* every connected part of the mesh touches ``Gamma_D`` (else a rigid motion is free).

Physical groups this module does not know are ignored. ``validate_contact_mesh``
checks a distributed ``ContactMesh`` (gathered on rank 0; collective);
``check_mesh_description`` checks plain arrays (``MeshDescription``).

The rules are in ``validation_rules``, the triangle checks in ``validation_triangles``, the
tetrahedral ones in ``validation_tetrahedra``, the open ends of Gamma_C and the bends of gamma in
``validation_curves``; this module raises on their findings and checks a method against the
mesh's dimension.
"""

from collections.abc import Iterable

import numpy as np
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, Subdomain
from fenics_contact.problem.validation_curves import (
    BEND,
    contact_open_ends,
    interface_bends,
    interface_bends_of,
    open_ends,
)
from fenics_contact.problem.validation_rules import BOUNDARY_RULES, GAMMA, GAMMA_C, GAMMA_D, BoundaryRule
from fenics_contact.problem.validation_tetrahedra import tetrahedral_mesh_problems
from fenics_contact.problem.validation_triangles import MeshDescription, describe_contact_mesh, mesh_problems

__all__ = [
    "BoundaryRule",
    "BOUNDARY_RULES",
    "MeshDescription",
    "check_mesh_description",
    "contact_open_ends",
    "interface_bends",
    "interface_bends_of",
    "describe_contact_mesh",
    "open_ends",
    "mesh_problems",
    "require_facet_groups",
    "require_tag_counts",
    "tetrahedral_mesh_problems",
    "validate_contact_mesh",
    "METHODS_3D",
    "require_method_dimension",
    "BEND",
]


def check_mesh_description(
    desc: MeshDescription, rules: Iterable[BoundaryRule] = BOUNDARY_RULES, *, source: str = "the mesh"
) -> None:
    """Raise MeshTagError listing every problem of ``mesh_problems``."""
    problems = mesh_problems(desc, rules)
    if problems:
        raise MeshTagError(_message(source, problems))


def _message(source: str, problems: list[str]) -> str:
    return f"{source} does not describe the contact problem: " + "; ".join(problems)


def validate_contact_mesh(cm, rules: Iterable[BoundaryRule] = BOUNDARY_RULES, *, source: str = "the mesh") -> None:
    """Raise MeshTagError (on every rank) unless the tags of ``cm`` describe the contact problem; collective.
    A tetrahedral mesh is checked with ``tetrahedral_mesh_problems``."""
    rules = tuple(rules)
    if cm.mesh.topology.dim == 3:
        problems = tetrahedral_mesh_problems(cm, rules)
        if problems:
            raise MeshTagError(_message(source, problems))
        return
    names = (
        {GAMMA_D, GAMMA_C, GAMMA} | {r.name for r in rules} | {o for r in rules for o in r.disjoint_from + r.away_from}
    )
    desc = describe_contact_mesh(cm, names)
    problems = mesh_problems(desc, rules) if cm.comm.rank == 0 else None
    problems = cm.comm.bcast(problems, root=0)
    if problems:
        raise MeshTagError(_message(source, problems))


def require_tag_counts(cm) -> None:
    """Cheap collective check for meshes built by hand: every cell in Omega1 or Omega2, every group non-empty."""
    comm = cm.comm
    tdim = cm.mesh.topology.dim
    n_cells = cm.mesh.topology.index_map(tdim).size_local
    tagged = np.zeros(n_cells, dtype=np.int64)
    counts = []
    for sub in Subdomain:
        found = cm.cell_tags.find(sub)
        np.add.at(tagged, found[found < n_cells], 1)
        counts.append(found.size)
    for tag in Boundary:
        counts.append(cm.facet_tags.find(tag).size)
    counts = comm.allreduce(np.array(counts + [int(np.count_nonzero(tagged != 1))]), op=MPI.SUM)
    names = [PHYSICAL_NAMES[t] for t in (*Subdomain, *Boundary)]
    empty = [name for name, c in zip(names, counts[:-1]) if c == 0]
    if empty:
        raise MeshTagError(
            f"the mesh has no cells/facets tagged {empty}: tag them "
            f"(physical groups {list(PHYSICAL_NAMES.values())}) or build it with geometry.read_mesh"
        )
    if counts[-1]:
        raise MeshTagError(f"{counts[-1]} cells are not tagged exactly once as Omega1 or Omega2")


#: the methods that solve 3D (tetrahedral) problems and take rollers (symmetry planes): the primal monolithic
#: solve, Algorithm 1 (its strip Ω₂ and interface γ are built or read in 3D as in 2D) and Algorithm 3 (its
#: coarse grid of cubes, ``ContactMesh.coarse_cell``)
METHODS_3D = ("primal-monolithic", "primal", "primal-ms")


def require_method_dimension(method: str, msh, boundary=None) -> None:
    """InputError unless the method ``method`` (a name of ``methods.METHODS``) solves a problem on ``msh`` with
    ``boundary``: the methods other than ``METHODS_3D`` solve plane (triangle) problems without rollers."""
    if method in METHODS_3D:
        return
    works = " or ".join(repr(m) for m in METHODS_3D)
    if msh.topology.dim != 2:
        raise InputError(
            f"the method {method!r} solves plane problems (triangles) only; this mesh is "
            f"{msh.topology.dim}D: a 3D problem runs with the method {works} "
            "(fem.primal.solve_primal_monolithic, hybrid.primal.solve_primal_hybrid, "
            "multiscale.primal.solve_primal_ms_hybrid)"
        )
    if boundary is not None and getattr(boundary, "rollers", ()):
        raise InputError(f"the method {method!r} takes no rollers (symmetry planes); the methods {works} do")


def require_facet_groups(msh, facet_tags, groups: Iterable[Boundary]) -> None:
    """Collective: MeshTagError unless ``facet_tags`` are facet tags of ``msh`` with facets in every group."""
    if not isinstance(facet_tags, dmesh.MeshTags) or facet_tags.dim != msh.topology.dim - 1:
        got = type(facet_tags).__name__
        if isinstance(facet_tags, dmesh.MeshTags):
            got += f" of dimension {facet_tags.dim}"
        raise MeshTagError(
            f"facet_tags must be the facet MeshTags of the mesh (dimension {msh.topology.dim - 1}), got {got}"
        )
    groups = list(groups)
    counts = msh.comm.allreduce(np.array([facet_tags.find(g).size for g in groups], dtype=np.int64), op=MPI.SUM)
    empty = [PHYSICAL_NAMES[g] for g, c in zip(groups, counts) if c == 0]
    if empty:
        raise MeshTagError(
            f"the mesh has no facets tagged {empty} (tag values {[int(g) for g in groups]}): "
            "a solve without them would be another problem"
        )
