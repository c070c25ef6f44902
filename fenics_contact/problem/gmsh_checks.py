"""What a gmsh mesh file must hold, checked on its gmsh model before the mesh is built (``geometry.read_mesh``).

Planar (z = 0) 3-node triangles or 4-node tetrahedra; the physical groups of ``tags.PHYSICAL_NAMES`` by name and
of the right dimension; every cell in exactly one group of cells, Omega1 or Omega2 (or, in a file that tags none of
Omega1, Omega2 and gamma, any group: the strip is then built, ``problem.strip``); no facet in two facet groups.
Each check returns (error class, message) or None, so that rank 0 decides and every rank raises the same error.
"""

from pathlib import Path

import gmsh
import numpy as np

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, Subdomain

__all__ = ["STRIP_NAMES", "gmsh_model_problem", "needs_strip"]

#: gmsh element types of the 3-node triangle and the 4-node tetrahedron
_TRIANGLE, _TETRAHEDRON = 2, 4
#: the groups built by the automatic strip when a file has none of them
STRIP_NAMES = frozenset(PHYSICAL_NAMES[t] for t in (Subdomain.OMEGA1, Subdomain.OMEGA2, Boundary.INTERFACE))


def gmsh_model_problem(path: Path, *, auto_strip: bool = False) -> tuple[type, str] | None:
    """(error class, message) if the current gmsh model is not a planar triangle mesh with the named groups."""

    def names_of(types) -> list[str]:
        return [gmsh.model.mesh.getElementProperties(t)[0] for t in types]

    solid = list(gmsh.model.mesh.getElementTypes(3))
    if solid:
        if solid != [_TETRAHEDRON]:
            other = names_of(t for t in solid if t != _TETRAHEDRON)
            return InputError, (
                f"{path} has {other} elements; a 3D mesh must be of 4-node tetrahedra only "
                "(no hexahedra, prisms, pyramids, no second-order elements)"
            )
        return _groups_problem(path, 3, auto_strip)
    surface = list(gmsh.model.mesh.getElementTypes(2))
    if not surface:
        return InputError, (
            f"{path} holds no triangles (no 2D mesh elements): is it a mesh? A .geo model must be "
            "meshed first (gmsh -2 model.geo -o model.msh)"
        )
    if surface != [_TRIANGLE]:
        other = names_of(t for t in surface if t != _TRIANGLE)
        return InputError, (
            f"{path} has {other} elements; fenics-contact needs 3-node triangles only "
            "(no quadrangles, no second-order elements)"
        )
    _, coords, _ = gmsh.model.mesh.getNodes()
    z = np.abs(np.asarray(coords).reshape(-1, 3)[:, 2])
    if np.any(z > 0.0):
        return InputError, (
            f"{path}: {np.count_nonzero(z > 0)} nodes have z ≠ 0 (largest |z| = {z.max():.3g}); "
            "the mesh must lie in the plane z = 0 (it is not projected)"
        )
    return _groups_problem(path, 2, auto_strip)


def _groups_problem(path: Path, tdim: int, auto_strip: bool) -> tuple[type, str] | None:
    """(error class, message) if the physical groups of the current gmsh model of cells of dimension ``tdim``
    lack a name or have the wrong dimension, or if the cells or facets are in the wrong groups."""
    dims: dict[str, set[int]] = {}
    for dim, tag in gmsh.model.getPhysicalGroups():
        dims.setdefault(gmsh.model.getPhysicalName(dim, tag), set()).add(dim)
    wrong = []
    for tag, name in PHYSICAL_NAMES.items():
        want = tdim if isinstance(tag, Subdomain) else tdim - 1
        if name in dims and want not in dims[name]:
            kinds = {0: "a point", 1: "a curve", 2: "a surface", 3: "a volume"}
            got = " and ".join(kinds[d] for d in sorted(dims[name]))
            wrong.append(
                f"{name!r} is {got} group (dimension {sorted(dims[name])}); it must be {kinds[want]} "
                f"group (dimension {want})"
            )
    if wrong:
        return MeshTagError, f"{path}: " + "; ".join(wrong)
    missing = [name for name in PHYSICAL_NAMES.values() if name not in dims]
    if auto_strip:
        missing = [name for name in missing if name not in STRIP_NAMES]
    if missing:
        return MeshTagError, (
            f"{path} lacks the physical group(s) {missing}; it has {sorted(dims)}. "
            f"Required names: {list(PHYSICAL_NAMES.values())}"
            + (
                ""
                if auto_strip
                else f" (or none of {sorted(STRIP_NAMES)}: Omega2 is then built along Gamma_C from the coarse cells)"
            )
        )
    return _surface_groups_problem(path, auto_strip=auto_strip, tdim=tdim) or _curve_groups_problem(path, tdim - 1)


def needs_strip(tdim: int = 2) -> bool:
    """True if the current gmsh model tags none of Omega1/Omega2/gamma but has a group of cells (dimension tdim)."""
    names = {gmsh.model.getPhysicalName(d, t) for d, t in gmsh.model.getPhysicalGroups()}
    return not (names & STRIP_NAMES) and len(gmsh.model.getPhysicalGroups(tdim)) > 0


def _curve_groups_problem(path: Path, fdim: int = 1) -> tuple[type, str] | None:
    """No facet (segment; triangle of a 3D mesh, ``fdim`` = 2) may be in two facet groups: a mesh facet carries
    one tag (dolfinx would keep one of them)."""
    keys, owner, names = [], [], []
    k = fdim + 1  # vertices of a facet; its gmsh element type is 1 (segment) or 2 (triangle), i.e. fdim
    for dim, tag in gmsh.model.getPhysicalGroups(fdim):
        names.append(gmsh.model.getPhysicalName(dim, tag))
        segments = [np.zeros((0, k), dtype=np.int64)]
        for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
            types, _, nodes = gmsh.model.mesh.getElements(fdim, entity)
            segments += [np.asarray(n, dtype=np.int64).reshape(-1, k) for t, n in zip(types, nodes) if t == fdim]
        segments = np.unique(np.sort(np.concatenate(segments), axis=1), axis=0)
        keys.append(segments)
        owner.append(np.full(segments.shape[0], len(names) - 1))
    if not keys:
        return None
    keys, owner = np.concatenate(keys), np.concatenate(owner)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    shared = counts[inverse.reshape(-1)] > 1
    if not np.any(shared):
        return None
    pairs: dict[tuple[str, str], int] = {}
    groups_of: dict[int, list[int]] = {}
    for segment, group in zip(inverse.reshape(-1)[shared], owner[shared]):
        groups_of.setdefault(int(segment), []).append(int(group))
    for groups in groups_of.values():
        for a in range(len(groups)):
            for b in range(a + 1, len(groups)):
                pair = tuple(sorted((names[groups[a]], names[groups[b]])))
                pairs[pair] = pairs.get(pair, 0) + 1
    text = "; ".join(f"{a!r} and {b!r} share {n} segments" for (a, b), n in pairs.items())
    return MeshTagError, (
        f"{path} does not describe the contact problem: {text}: they must be disjoint (a mesh facet carries one tag)"
    )


def _surface_groups_problem(path: Path, *, auto_strip: bool = False, tdim: int = 2) -> tuple[type, str] | None:
    """Every triangle (tetrahedron in 3D) must be in exactly one surface (volume) group, and that group Omega1
    or Omega2 (with ``auto_strip``: any such group, the coarse cells or the material regions of the user)."""
    _, element_tags, _ = gmsh.model.mesh.getElements(tdim)
    triangles = np.concatenate([np.asarray(t, dtype=np.int64) for t in element_tags])
    count = np.zeros(triangles.size, dtype=np.int64)
    known = np.zeros(triangles.size, dtype=bool)
    order = np.argsort(triangles)
    others = []
    for dim, tag in gmsh.model.getPhysicalGroups(tdim):
        name = gmsh.model.getPhysicalName(dim, tag)
        members = [np.zeros(0, dtype=np.int64)]
        for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
            members += [np.asarray(t, dtype=np.int64) for t in gmsh.model.mesh.getElements(tdim, entity)[1]]
        members = np.unique(np.concatenate(members))
        pos = order[np.searchsorted(triangles, members, sorter=order)]
        np.add.at(count, pos, 1)
        if auto_strip or name in (PHYSICAL_NAMES[Subdomain.OMEGA1], PHYSICAL_NAMES[Subdomain.OMEGA2]):
            known[pos] = True
        elif members.size:
            others.append(name)
    problems = []
    if np.any(~known):
        where = "no surface group" if auto_strip else "neither Omega1 nor Omega2"
        problems.append(f"{np.count_nonzero(~known)} of {triangles.size} triangles are in {where}")
    if np.any(count > 1):
        problems.append(
            f"{np.count_nonzero(count > 1)} triangles are in more than one surface group (of Omega1, "
            f"Omega2 and {others}); every triangle must be in exactly one"
        )
    if problems:
        return MeshTagError, f"{path} does not describe the contact problem: " + "; ".join(problems)
    return None
