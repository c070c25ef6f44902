"""The checks of a tetrahedral mesh's tags, on the distributed mesh (``problem.validation``; collective)."""

from collections.abc import Iterable

import numpy as np
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, Subdomain, is_neumann_name, neumann_tag
from fenics_contact.problem.validation_rules import BOUNDARY_RULES, GAMMA, OMEGA1, OMEGA2, BoundaryRule

__all__ = ["tetrahedral_mesh_problems"]


def tetrahedral_mesh_problems(cm, rules: Iterable[BoundaryRule] = BOUNDARY_RULES) -> list[str]:
    """The checks of a tetrahedral ContactMesh, on the distributed mesh (collective; the same list on every rank):
    every cell in exactly one of Omega1 and Omega2, no cell of zero volume, gamma non-empty and inside the mesh,
    each group of ``rules`` non-empty (when required) and on the outer boundary, of its subdomain, disjoint
    from and away from the groups its rule names; gamma the common boundary of Omega1 and Omega2."""
    msh, comm = cm.mesh, cm.comm
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    msh.topology.create_connectivity(tdim - 1, 0)
    n_cells = msh.topology.index_map(tdim).size_local
    problems: list[str] = []
    count = np.zeros(n_cells, dtype=np.int64)
    for sub in Subdomain:
        found = cm.cell_tags.find(sub)
        np.add.at(count, found[found < n_cells], 1)
    bad = comm.allreduce(int(np.count_nonzero(count != 1)), op=MPI.SUM)
    if bad:
        problems.append(f"{bad} tetrahedra are not in exactly one of {OMEGA1} and {OMEGA2}")
    x = msh.geometry.x[dmesh.entities_to_geometry(msh, tdim, np.arange(n_cells, dtype=np.int32))]
    volume = np.abs(np.linalg.det(x[:, 1:] - x[:, :1])) / 6.0
    scale = comm.allreduce(float(np.max(np.ptp(msh.geometry.x, axis=0), initial=0.0)), op=MPI.MAX)
    flat = comm.allreduce(int(np.count_nonzero(volume <= 1e-14 * scale**3)), op=MPI.SUM)
    if flat:
        problems.append(f"{flat} tetrahedra have zero volume")
    exterior = dmesh.exterior_facet_indices(msh.topology)
    by_name = {PHYSICAL_NAMES[t]: t for t in Boundary}
    facets = {name: cm.facet_tags.find(tag) for name, tag in by_name.items()}
    f2v = msh.topology.connectivity(tdim - 1, 0)
    vmap = msh.topology.index_map(0)

    def global_vertices(found: np.ndarray) -> set:
        local = np.unique(np.concatenate([f2v.links(f) for f in found] or [np.zeros(0, np.int32)])).astype(np.int32)
        return set().union(*comm.allgather(set(vmap.local_to_global(local).tolist())))

    gamma_total = comm.allreduce(int(facets[GAMMA].size), op=MPI.SUM)
    on_boundary = comm.allreduce(int(np.count_nonzero(np.isin(facets[GAMMA], exterior))), op=MPI.SUM)
    if gamma_total == 0:
        problems.append(f"the physical group {GAMMA!r} (the interface between Omega1 and Omega2) is missing or empty")
    elif on_boundary:
        problems.append(f"{on_boundary} of {gamma_total} facets of {GAMMA!r} lie on the outer boundary of the mesh")
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    problems += _tetrahedral_interface_problems(cm, facets[GAMMA])
    for rule in rules:
        if rule.name not in facets:
            facets[rule.name] = cm.facet_tags.find(neumann_tag(rule.name) if is_neumann_name(rule.name) else -1)
        found = facets[rule.name]
        total = comm.allreduce(int(found.size), op=MPI.SUM)
        if total == 0:
            if rule.required:
                problems.append(f"the physical group {rule.name!r} is missing or empty")
            continue
        interior = comm.allreduce(int(np.count_nonzero(~np.isin(found, exterior))), op=MPI.SUM)
        if interior:
            problems.append(f"{interior} of {total} facets of {rule.name!r} are not on the outer boundary")
        if rule.subdomain is not None:
            cells = np.array([f2c.links(f)[0] for f in found], dtype=np.int32)
            sub = next(t for t in Subdomain if PHYSICAL_NAMES[t] == rule.subdomain)
            inside = np.isin(cells, cm.cell_tags.find(sub))
            wrong = comm.allreduce(int(np.count_nonzero(~np.asarray(inside, dtype=bool))), op=MPI.SUM)
            if wrong:
                problems.append(
                    f"{wrong} of {total} facets of {rule.name!r} are not on the boundary of {rule.subdomain}"
                )
        for other in rule.disjoint_from:
            common = comm.allreduce(
                int(np.intersect1d(found, facets.get(other, np.zeros(0, np.int32))).size), op=MPI.SUM
            )
            if common:
                problems.append(f"{rule.name!r} and {other!r} share {common} facets: they must be disjoint")
        for other in rule.away_from:
            common = global_vertices(found) & global_vertices(facets.get(other, np.zeros(0, np.int32)))
            if common:
                problems.append(
                    f"{rule.name!r} touches {other!r} at {len(common)} nodes: {rule.name} must lie away from {other}"
                )
    return problems


def _tetrahedral_interface_problems(cm, gamma: np.ndarray) -> list[str]:
    """gamma is the common boundary of Omega1 and Omega2: every gamma facet lies between an Omega1 and an Omega2
    cell, and every facet between an Omega1 and an Omega2 cell is tagged gamma (owned facets whose two cells
    this rank holds; collective)."""
    msh, comm = cm.mesh, cm.comm
    tdim = msh.topology.dim
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    imap = msh.topology.index_map(tdim)
    label = np.zeros(imap.size_local + imap.num_ghosts, dtype=np.int64)
    for sub in Subdomain:
        label[cm.cell_tags.find(sub)] = int(sub)
    owned = np.arange(msh.topology.index_map(tdim - 1).size_local, dtype=np.int32)
    two = owned[np.diff(f2c.offsets)[owned] == 2]
    first, second = label[f2c.array[f2c.offsets[two]]], label[f2c.array[f2c.offsets[two] + 1]]
    across = two[np.minimum(first, second) * np.maximum(first, second) == int(Subdomain.OMEGA1) * int(Subdomain.OMEGA2)]
    tagged = np.isin(two, gamma)
    inside = np.isin(across, gamma, invert=True)
    counts = comm.allreduce(
        np.array([np.count_nonzero(tagged & ~np.isin(two, across)), np.count_nonzero(inside)]), op=MPI.SUM
    )
    problems = []
    if counts[0]:
        problems.append(f"{counts[0]} facets of {GAMMA!r} do not lie between an {OMEGA1} and an {OMEGA2} cell")
    if counts[1]:
        problems.append(
            f"{counts[1]} facets between an {OMEGA1} and an {OMEGA2} cell are not tagged {GAMMA!r} (gamma must be "
            "the whole common boundary of Omega1 and Omega2)"
        )
    return problems
