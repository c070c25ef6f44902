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
"""

from collections.abc import Iterable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
import scipy.spatial
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, Subdomain, is_neumann_name, neumann_tag

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
]

OMEGA1, OMEGA2 = PHYSICAL_NAMES[Subdomain.OMEGA1], PHYSICAL_NAMES[Subdomain.OMEGA2]
GAMMA_D, GAMMA_C, GAMMA = (PHYSICAL_NAMES[b] for b in (Boundary.GAMMA_D, Boundary.GAMMA_C, Boundary.INTERFACE))

#: cell label codes in ``MeshDescription.label``
UNTAGGED, MULTIPLY_TAGGED = 0, -1


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


class MeshDescription(NamedTuple):
    """A triangle mesh as plain arrays (global numbering), the input of the checks."""

    points: np.ndarray  #: (n, 2) node coordinates
    triangles: np.ndarray  #: (m, 3) node indices
    label: np.ndarray  #: (m,) 1 = Omega1, 2 = Omega2, 0 untagged, -1 in both
    facets: dict[str, np.ndarray]  #: group name -> (k, 2) node indices of its segments


def _where(points: np.ndarray, segments: np.ndarray) -> str:
    """' (first at (x, y))' for the midpoint of the first segment."""
    if segments.size == 0:
        return ""
    x, y = points[segments[0]].mean(axis=0)
    return f" (first at ({x:.6g}, {y:.6g}))"


class _Edges:
    """The edges of a triangulation: unique keys, how many triangles share each, their labels."""

    def __init__(self, desc: MeshDescription) -> None:
        tri = np.asarray(desc.triangles, dtype=np.int64)
        self.n_points = max(int(desc.points.shape[0]), int(tri.max(initial=-1)) + 1, 1)
        local = np.stack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]], axis=1).reshape(-1, 2)
        keys = self.keys(local)
        self.unique, inverse, self.count = np.unique(keys, return_inverse=True, return_counts=True)
        owner = np.repeat(np.arange(tri.shape[0]), 3)
        order = np.argsort(inverse, kind="stable")
        start = np.concatenate([[0], np.cumsum(self.count)[:-1]]).astype(np.int64)
        self.tri1 = owner[order[start]]
        self.tri2 = np.where(self.count >= 2, owner[order[np.minimum(start + 1, order.size - 1)]], -1)
        self.nodes = np.stack([self.unique // self.n_points, self.unique % self.n_points], axis=1)
        label = np.asarray(desc.label)
        self.label1 = label[self.tri1] if self.tri1.size else np.zeros(0, dtype=label.dtype)
        self.label2 = (
            np.where(self.tri2 >= 0, label[np.maximum(self.tri2, 0)], UNTAGGED) if self.tri2.size else self.label1
        )

    def keys(self, segments: np.ndarray) -> np.ndarray:
        s = np.sort(np.asarray(segments, dtype=np.int64).reshape(-1, 2), axis=1)
        return s[:, 0] * self.n_points + s[:, 1]

    def find(self, segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(edge index, found) of each segment."""
        keys = self.keys(segments)
        pos = np.clip(np.searchsorted(self.unique, keys), 0, max(self.unique.size - 1, 0))
        found = self.unique[pos] == keys if self.unique.size else np.zeros(keys.size, dtype=bool)
        return pos, found

    @property
    def exterior(self) -> np.ndarray:
        return self.count == 1

    @property
    def interface(self) -> np.ndarray:
        pair = np.sort(np.stack([self.label1, self.label2], axis=1), axis=1)
        return (self.count == 2) & (pair[:, 0] == 1) & (pair[:, 1] == 2)


def _cracks(desc: MeshDescription, edges: _Edges) -> np.ndarray:
    """Boundary edges whose outer side is inside another triangle (non-conforming parts): their indices."""
    ext = np.flatnonzero(edges.exterior)
    if ext.size == 0 or desc.triangles.shape[0] < 2:
        return np.zeros(0, dtype=np.int64)
    pts = np.asarray(desc.points, dtype=np.float64)
    tri = np.asarray(desc.triangles, dtype=np.int64)
    a, b = pts[edges.nodes[ext, 0]], pts[edges.nodes[ext, 1]]
    t = tri[edges.tri1[ext]]
    opposite = pts[t].sum(axis=1) - a - b  # the third vertex of the owning triangle
    d = b - a
    n = np.stack([d[:, 1], -d[:, 0]], axis=1)
    n *= np.where(np.sum(n * (opposite - a), axis=1) > 0, -1.0, 1.0)[:, None]  # outward
    probe = 0.5 * (a + b) + 1e-4 * n  # |n| = |b − a|: a step of 1e-4 edge lengths outwards
    centres = pts[tri].mean(axis=1)
    k = min(16, tri.shape[0])
    _, near = scipy.spatial.cKDTree(centres).query(probe, k=k)
    near = near.reshape(probe.shape[0], k)
    inside = np.zeros(probe.shape[0], dtype=bool)
    for j in range(k):
        p0, p1, p2 = (pts[tri[near[:, j], i]] for i in range(3))
        det = (p1[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1]) - (p2[:, 0] - p0[:, 0]) * (p1[:, 1] - p0[:, 1])
        r = probe - p0
        with np.errstate(divide="ignore", invalid="ignore"):
            l1 = (r[:, 0] * (p2[:, 1] - p0[:, 1]) - (p2[:, 0] - p0[:, 0]) * r[:, 1]) / det
            l2 = ((p1[:, 0] - p0[:, 0]) * r[:, 1] - r[:, 0] * (p1[:, 1] - p0[:, 1])) / det
        inside |= (det != 0) & (l1 > 0) & (l2 > 0) & (l1 + l2 < 1)
    return ext[inside]


def mesh_problems(desc: MeshDescription, rules: Iterable[BoundaryRule] = BOUNDARY_RULES) -> list[str]:
    """Every contradiction between the tags and the contact problem, one sentence each (empty: valid)."""
    rules = tuple(rules)
    pts = np.asarray(desc.points, dtype=np.float64)
    tri = np.asarray(desc.triangles, dtype=np.int64)
    label = np.asarray(desc.label)
    problems: list[str] = []
    if tri.shape[0] == 0:
        return ["the mesh has no triangles"]

    # cells
    for code, name in ((1, OMEGA1), (2, OMEGA2)):
        if not np.any(label == code):
            problems.append(f"the physical group {name!r} has no triangles")
    for code, what in (
        (UNTAGGED, "belong to neither Omega1 nor Omega2"),
        (MULTIPLY_TAGGED, "are in both Omega1 and Omega2"),
    ):
        bad = np.flatnonzero(label == code)
        if bad.size:
            x, y = pts[tri[bad[0]]].mean(axis=0)
            problems.append(
                f"{bad.size} of {tri.shape[0]} triangles {what} (first at ({x:.6g}, {y:.6g})): "
                "every triangle must lie in exactly one of them"
            )
    p = pts[tri]
    area2 = (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (
        p[:, 1, 1] - p[:, 0, 1]
    )
    scale = max(float(np.ptp(pts[:, 0])), float(np.ptp(pts[:, 1])), 1e-300)
    flat = np.flatnonzero(np.abs(area2) <= 1e-14 * scale**2)
    if flat.size:
        x, y = p[flat[0]].mean(axis=0)
        problems.append(f"{flat.size} triangles have zero area (first at ({x:.6g}, {y:.6g}))")

    edges = _Edges(desc)
    if np.any(edges.count > 2):
        bad = np.flatnonzero(edges.count > 2)
        problems.append(
            f"{bad.size} edges are shared by more than two triangles (overlapping triangles)"
            + _where(pts, edges.nodes[bad])
        )
    cracks = _cracks(desc, edges)
    if cracks.size:
        problems.append(
            f"{cracks.size} boundary edges of the triangles lie inside the domain{_where(pts, edges.nodes[cracks])}: "
            "the mesh is not conforming there (parts meshed separately, with duplicate or hanging nodes; "
            "in gmsh build the surfaces on shared curves, e.g. with fragment, or remove duplicate nodes)"
        )

    groups = {name: np.asarray(seg, dtype=np.int64).reshape(-1, 2) for name, seg in desc.facets.items()}
    located: dict[str, np.ndarray] = {}
    for name, seg in groups.items():
        idx, found = edges.find(seg)
        if not np.all(found):
            problems.append(
                f"{np.count_nonzero(~found)} of {seg.shape[0]} segments of {name!r} are not edges of "
                f"the triangles{_where(pts, seg[~found])}: the curve must be meshed as part of the surfaces"
            )
        located[name] = np.unique(idx[found])

    # the interface gamma: exactly the common boundary of Omega1 and Omega2
    gamma = located.get(GAMMA)
    interface = np.flatnonzero(edges.interface)
    if gamma is None or gamma.size == 0:
        problems.append(f"the physical group {GAMMA!r} (the interface between Omega1 and Omega2) is missing or empty")
    else:
        on_boundary = gamma[edges.exterior[gamma]]
        if on_boundary.size:
            problems.append(
                f"{on_boundary.size} of {gamma.size} segments of {GAMMA!r} lie on the outer boundary of the mesh"
                f"{_where(pts, edges.nodes[on_boundary])}: gamma must be the common boundary of Omega1 and Omega2, "
                "its nodes shared by both (tagged on the wrong curve, or a non-conforming interface?)"
            )
        for code, name in ((1, OMEGA1), (2, OMEGA2)):
            inner = gamma[(edges.count[gamma] == 2) & (edges.label1[gamma] == code) & (edges.label2[gamma] == code)]
            if inner.size:
                problems.append(
                    f"{inner.size} segments of {GAMMA!r} lie inside {name} (both neighbours are {name} "
                    f"triangles){_where(pts, edges.nodes[inner])}: gamma must separate Omega1 from Omega2"
                )
        untagged = np.setdiff1d(interface, gamma)
        if untagged.size:
            problems.append(
                f"{untagged.size} edges between Omega1 and Omega2 are not tagged {GAMMA!r}"
                f"{_where(pts, edges.nodes[untagged])}: gamma must be the whole common boundary"
            )
    if interface.size == 0 and np.any(label == 1) and np.any(label == 2):
        problems.append("Omega1 and Omega2 share no edge: they are not joined (a non-conforming interface?)")

    # boundary groups
    gamma_nodes = np.unique(edges.nodes[gamma]) if gamma is not None else np.zeros(0, dtype=np.int64)
    node_sets = {name: np.unique(edges.nodes[idx]) for name, idx in located.items()}
    node_sets[GAMMA] = gamma_nodes
    for rule in rules:
        idx = located.get(rule.name)
        if idx is None or idx.size == 0:
            if rule.required:
                problems.append(f"the physical group {rule.name!r} is missing or empty")
            continue
        interior = idx[~edges.exterior[idx]]
        if interior.size:
            problems.append(
                f"{interior.size} of {idx.size} segments of {rule.name!r} are not on the outer boundary "
                f"(shared by two triangles){_where(pts, edges.nodes[interior])}"
            )
        if rule.subdomain is not None:
            code = 1 if rule.subdomain == OMEGA1 else 2
            wrong = idx[(edges.label1[idx] != code) & (edges.label2[idx] != code)]
            if wrong.size:
                problems.append(
                    f"{wrong.size} of {idx.size} segments of {rule.name!r} are not on the boundary of "
                    f"{rule.subdomain}{_where(pts, edges.nodes[wrong])}"
                )
        for other in rule.disjoint_from:
            common = np.intersect1d(idx, located.get(other, np.zeros(0, dtype=np.int64)))
            if common.size:
                problems.append(
                    f"{rule.name!r} and {other!r} share {common.size} segments"
                    f"{_where(pts, edges.nodes[common])}: they must be disjoint"
                )
        for other in rule.away_from:
            common = np.intersect1d(node_sets[rule.name], node_sets.get(other, np.zeros(0, dtype=np.int64)))
            if common.size:
                x, y = pts[common[0]]
                hint = (
                    "; the contact must lie inside the strip Omega2: extend Omega2 past the ends of Gamma_C, or "
                    "leave out Omega1, Omega2 and gamma and the strip is built along Gamma_C"
                    if (rule.name, other) == (GAMMA_C, GAMMA)
                    else ""
                )
                problems.append(
                    f"{rule.name!r} touches {other!r} at {common.size} nodes (first at ({x:.6g}, {y:.6g})): "
                    f"{rule.name} must lie away from {other}{hint}"
                )

    # every connected part is held by Gamma_D
    inner = np.flatnonzero(edges.count == 2)
    graph = scipy.sparse.coo_matrix(
        (np.ones(inner.size), (edges.tri1[inner], edges.tri2[inner])), shape=(tri.shape[0], tri.shape[0])
    )
    n_parts, part = scipy.sparse.csgraph.connected_components(graph, directed=False)
    clamped = located.get(GAMMA_D)
    if n_parts > 1 and clamped is not None and clamped.size:
        held = np.zeros(n_parts, dtype=bool)
        held[part[edges.tri1[clamped]]] = True
        free = np.flatnonzero(~held)
        if free.size:
            cells = np.flatnonzero(np.isin(part, free))
            x, y = p[cells[0]].mean(axis=0)
            problems.append(
                f"{free.size} of {n_parts} connected parts of the mesh ({cells.size} triangles, first at "
                f"({x:.6g}, {y:.6g})) do not touch {GAMMA_D!r}: their rigid motions would be free"
            )
    return problems


def check_mesh_description(
    desc: MeshDescription, rules: Iterable[BoundaryRule] = BOUNDARY_RULES, *, source: str = "the mesh"
) -> None:
    """Raise MeshTagError listing every problem of ``mesh_problems``."""
    problems = mesh_problems(desc, rules)
    if problems:
        raise MeshTagError(_message(source, problems))


def _message(source: str, problems: list[str]) -> str:
    return f"{source} does not describe the contact problem: " + "; ".join(problems)


def describe_contact_mesh(cm, names: Iterable[str] | None = None) -> MeshDescription | None:
    """The whole mesh of a ContactMesh as plain arrays on rank 0 (None elsewhere); collective.

    ``names`` (default: the boundary tags of ``tags.Boundary``) selects the facet groups, matched to
    their integers through ``PHYSICAL_NAMES``.
    """
    msh = cm.mesh
    comm = msh.comm
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim, 0)
    msh.topology.create_connectivity(tdim - 1, 0)
    msh.topology.create_connectivity(0, tdim)
    vmap = msh.topology.index_map(0)
    n_cells = msh.topology.index_map(tdim).size_local
    n_vertices = vmap.size_local + vmap.num_ghosts
    to_global = vmap.local_to_global(np.arange(n_vertices, dtype=np.int32)).astype(np.int64)
    c2v = msh.topology.connectivity(tdim, 0)
    cells = np.asarray(c2v.array, dtype=np.int64).reshape(-1, 3)[:n_cells] if n_cells else np.zeros((0, 3), np.int64)
    label = np.zeros(n_cells, dtype=np.int64)
    for sub in Subdomain:
        found = cm.cell_tags.find(sub)
        found = found[found < n_cells]
        label[found] = np.where(label[found] == UNTAGGED, int(sub), MULTIPLY_TAGGED)
    owned = np.arange(vmap.size_local, dtype=np.int32)
    geo = dmesh.entities_to_geometry(msh, 0, owned).reshape(-1)
    xy = msh.geometry.x[geo, :2]
    by_name = {name: tag for tag, name in PHYSICAL_NAMES.items() if isinstance(tag, Boundary)}
    wanted = list(by_name) if names is None else [n for n in names if n in by_name]
    f2v = msh.topology.connectivity(tdim - 1, 0)
    facets = {}
    for name in wanted:
        found = cm.facet_tags.find(by_name[name])
        seg = np.asarray(f2v.array, dtype=np.int64).reshape(-1, 2)[found] if found.size else np.zeros((0, 2), np.int64)
        facets[name] = to_global[seg]
    gathered = comm.gather((to_global[cells], label, to_global[owned], xy, facets), root=0)
    if comm.rank != 0:
        return None
    n_global = vmap.size_global
    points = np.zeros((n_global, 2))
    for _, _, index, coords, _ in gathered:
        points[index] = coords
    triangles = np.concatenate([g[0] for g in gathered]).reshape(-1, 3)
    labels = np.concatenate([g[1] for g in gathered])
    groups = {
        name: np.unique(np.sort(np.concatenate([g[4][name] for g in gathered]).reshape(-1, 2), axis=1), axis=0)
        for name in wanted
    }
    return MeshDescription(points, triangles, labels, groups)


#: Γ_C "ends openly" where the boundary goes on within this angle of Γ_C's own direction (degrees)
OPEN_END_ANGLE = 30.0


def open_ends(desc: MeshDescription, group: str = GAMMA_C, angle: float = OPEN_END_ANGLE) -> np.ndarray:
    """(k, 3): x, y of each end point of the facet group where the boundary continues nearly straight (within
    ``angle``), and the length of the group's facet that ends there.

    An end of Γ_C at a corner of the body (the bar's wall side) is a true end of the possible contact zone; an
    end where the boundary goes on straight (Γ_C a part of one side, as in a Hertz block) is not: a contact zone
    that reaches it is cut short by the tags, not by the mechanics.
    """
    seg = np.asarray(desc.facets.get(group, np.zeros((0, 2), np.int64)), dtype=np.int64).reshape(-1, 2)
    pts = np.asarray(desc.points, dtype=np.float64)
    if seg.shape[0] == 0:
        return np.zeros((0, 3))
    degree = np.bincount(seg.ravel(), minlength=pts.shape[0])
    edges = _Edges(desc)
    outer = edges.nodes[edges.exterior]
    others = outer[~np.isin(edges.keys(outer), edges.keys(seg))]  # exterior edges not in the group
    cos_max = np.cos(np.radians(angle))
    found = []
    for e in np.flatnonzero(degree == 1):
        own = seg[np.any(seg == e, axis=1)][0]
        d1 = pts[e] - pts[own[0] if own[1] == e else own[1]]  # along Γ_C, out of its end
        for q in others[np.any(others == e, axis=1)]:
            d2 = pts[q[0] if q[1] == e else q[1]] - pts[e]
            if d1 @ d2 > cos_max * np.linalg.norm(d1) * np.linalg.norm(d2):
                found.append([pts[e][0], pts[e][1], np.linalg.norm(d1)])
                break
    return np.array(found, dtype=np.float64).reshape(-1, 3)


def contact_open_ends(cm) -> np.ndarray:
    """``open_ends`` of Γ_C on every rank (collective: the mesh is described on rank 0); none on a tetrahedral
    mesh (the ends of a contact curve: a contact surface is not checked)."""
    if cm.mesh.topology.dim == 3:
        return np.zeros((0, 3))
    desc = describe_contact_mesh(cm, [GAMMA_C])
    ends = open_ends(desc) if cm.comm.rank == 0 else None
    return cm.comm.bcast(ends, root=0)


#: sin of the angle between two γ facets at a common vertex above which γ bends there
BEND = 1e-8


def interface_bends(desc: MeshDescription) -> np.ndarray:
    """(k, 2): the vertices where the interface γ bends (two γ facets meet at an angle) or branches."""
    seg = np.asarray(desc.facets.get(GAMMA, np.zeros((0, 2), np.int64)), dtype=np.int64).reshape(-1, 2)
    pts = np.asarray(desc.points, dtype=np.float64)
    if seg.shape[0] == 0:
        return np.zeros((0, 2))
    degree = np.bincount(seg.ravel(), minlength=pts.shape[0])
    found = [pts[v, :2] for v in np.flatnonzero(degree > 2)]
    d = pts[seg[:, 1], :2] - pts[seg[:, 0], :2]
    d /= np.linalg.norm(d, axis=1)[:, None]
    for v in np.flatnonzero(degree == 2):
        a, b = np.flatnonzero(np.any(seg == v, axis=1))
        if abs(d[a, 0] * d[b, 1] - d[a, 1] * d[b, 0]) > BEND:
            found.append(pts[v, :2])
    return np.array(found, dtype=np.float64).reshape(-1, 2)


def interface_bends_of(cm) -> np.ndarray:
    """``interface_bends`` of γ on every rank (collective: the mesh is described on rank 0); none on a tetrahedral
    mesh (the bends of an interface curve, which the mixed methods need to know: they are planar)."""
    if cm.mesh.topology.dim == 3:
        return np.zeros((0, 2))
    desc = describe_contact_mesh(cm, [GAMMA])
    bends = interface_bends(desc) if cm.comm.rank == 0 else None
    return cm.comm.bcast(bends, root=0)


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
