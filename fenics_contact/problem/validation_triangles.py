"""The checks of a triangle mesh's tags (``problem.validation``): ``describe_contact_mesh`` gathers a distributed
``ContactMesh`` as plain arrays on rank 0 (``MeshDescription``), ``mesh_problems`` lists every contradiction
between its tags and the contact problem, one sentence each."""

from collections.abc import Iterable
from typing import NamedTuple

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
import scipy.spatial
from dolfinx import mesh as dmesh

from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, Subdomain
from fenics_contact.problem.validation_rules import (
    BOUNDARY_RULES,
    GAMMA,
    GAMMA_C,
    GAMMA_D,
    OMEGA1,
    OMEGA2,
    BoundaryRule,
)

__all__ = ["MeshDescription", "describe_contact_mesh", "mesh_problems"]

#: cell label codes in ``MeshDescription.label``
UNTAGGED, MULTIPLY_TAGGED = 0, -1


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


class Edges:
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


def _cracks(desc: MeshDescription, edges: Edges) -> np.ndarray:
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

    edges = Edges(desc)
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
