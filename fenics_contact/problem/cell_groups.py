"""Named cell groups beyond Omega1/Omega2 (materials by physical group) and fields defined by group.

A user's gmsh file may carry surface groups of its own (``matrix``, ``fibres``; volume groups in a
file of tetrahedra) that overlay the Omega1/Omega2 partition.  DOLFINx reads every cell from one
physical group, so these overlay groups are read on rank 0 with gmsh (``read_cell_groups``: the
centroid of every cell of each group) and left out of the mesh
(``geometry.read_mesh(..., overlay_groups=...)``).
``CellGroups`` then tells, for cell midpoints, which overlay group and which of Omega1/Omega2
holds each one (k-d trees of the centroids; a midpoint matches a centroid within 1e-9 of the
mesh's extent), and ``CellGroups.field`` makes a scalar or vector field x ↦ the value of the
cell's group, an overlay group's value winning over its Omega group's.  Cells whose groups
give no value get ``default`` (NaN unless given); ``CellGroups.uncovered`` counts the cells
where a field is NaN (collective), so that the caller can refuse it with a message.

Fields are evaluated at cell midpoints only (``problem.fields.cell_function``: DG0
interpolation), on the mesh or its submeshes, whose cells are the same triangles.
"""

from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

import gmsh
import numpy as np
import scipy.spatial
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.geometry import ContactMesh, gmsh_session
from fenics_contact.problem.tags import PHYSICAL_NAMES, Subdomain

__all__ = ["SUBDOMAIN_NAMES", "read_cell_groups", "CellGroups", "bounding_box"]

#: the names of the two subdomain groups every mesh has
SUBDOMAIN_NAMES = (PHYSICAL_NAMES[Subdomain.OMEGA1], PHYSICAL_NAMES[Subdomain.OMEGA2])
_TRIANGLE = 2  #: gmsh element type of the 3-node triangle
_TETRAHEDRON = 4  #: gmsh element type of the 4-node tetrahedron


def read_cell_groups(
    path: str | Path, names: Iterable[str] = (), *, comm: MPI.Comm = MPI.COMM_WORLD
) -> dict[str, np.ndarray]:
    """Centroids (N, d) of the cells of every cell group of a gmsh file but Omega1/Omega2 (collective): the
    triangles of its surface groups (d = 2), or the tetrahedra of its volume groups in a file of tetrahedra (d = 3).

    ``names``: the groups the caller will use: MeshTagError if one is not a cell group of the
    file (the message lists those it has), or two of them share a cell (a cell would take
    two values); InputError if the file cannot be read.
    """
    names = sorted(set(names))
    result = None
    if comm.rank == 0:
        try:
            result = _read_on_rank_zero(Path(path), names)
        except (InputError, MeshTagError) as err:
            result = err
    result = comm.bcast(result, root=0)
    if isinstance(result, Exception):
        raise result
    return result


def _read_on_rank_zero(path: Path, names: list[str]) -> dict[str, np.ndarray]:
    with gmsh_session():
        gmsh.model.add("cell groups")
        try:
            gmsh.merge(str(path))
        except Exception as err:  # gmsh raises a bare Exception with its parser's message
            raise InputError(f"cannot read {path} as a gmsh mesh: {err}") from None
        tdim = 3 if len(gmsh.model.mesh.getElementTypes(3)) else 2
        kind, element, corners = ("volume", _TETRAHEDRON, 4) if tdim == 3 else ("surface", _TRIANGLE, 3)
        groups = {gmsh.model.getPhysicalName(dim, tag): tag for dim, tag in gmsh.model.getPhysicalGroups(tdim)}
        missing = [name for name in names if name not in groups or name in SUBDOMAIN_NAMES]
        if missing:
            raise MeshTagError(
                f"{path} has no {kind} group {missing[0]!r} (named in the case); its {kind} groups are {sorted(groups)}"
            )
        node_tags, coords, _ = gmsh.model.mesh.getNodes()
        coords = np.asarray(coords).reshape(-1, 3)[:, :tdim]
        index = np.zeros(int(np.max(node_tags, initial=0)) + 1, dtype=np.int64)
        index[np.asarray(node_tags, dtype=np.int64)] = np.arange(len(node_tags))
        centroids, members = {}, {}
        for name in sorted(set(groups) - set(SUBDOMAIN_NAMES)):
            elements, nodes = [np.zeros(0, dtype=np.int64)], [np.zeros((0, corners), dtype=np.int64)]
            for entity in gmsh.model.getEntitiesForPhysicalGroup(tdim, groups[name]):
                types, tags, node_lists = gmsh.model.mesh.getElements(tdim, entity)
                for t, e, n in zip(types, tags, node_lists):
                    if t == element:
                        elements.append(np.asarray(e, dtype=np.int64))
                        nodes.append(np.asarray(n, dtype=np.int64).reshape(-1, corners))
            cells = np.concatenate(nodes)
            members[name] = np.concatenate(elements)
            centroids[name] = coords[index[cells]].mean(axis=1) if cells.size else np.zeros((0, tdim))
            if not cells.size:
                raise MeshTagError(
                    f"the {kind} group {name!r} of {path} holds no {'tetrahedra' if tdim == 3 else 'triangles'}"
                )
        for i, a in enumerate(names):
            for b in names[i + 1 :]:
                shared = np.intersect1d(members[a], members[b]).size
                if shared:
                    raise MeshTagError(
                        f"the {kind} groups {a!r} and {b!r} of {path} share {shared} cells: a "
                        "cell takes its material from one group"
                    )
        gmsh.model.remove()
    return centroids


def bounding_box(msh: dmesh.Mesh) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) of the whole mesh (collective)."""
    x = msh.geometry.x[:, :2]
    lo = [msh.comm.allreduce(float(v), op=MPI.MIN) for v in np.min(x, axis=0, initial=np.inf)]
    hi = [msh.comm.allreduce(float(v), op=MPI.MAX) for v in np.max(x, axis=0, initial=-np.inf)]
    return lo[0], hi[0], lo[1], hi[1]


def _midpoints(msh: dmesh.Mesh, cells: np.ndarray) -> np.ndarray:
    """The midpoints (N, tdim) of ``cells``: in the plane of a triangle mesh, in space for tetrahedra."""
    return dmesh.compute_midpoints(msh, msh.topology.dim, cells.astype(np.int32))[:, : msh.topology.dim]


class CellGroups:
    """Which overlay group and which subdomain (Omega1/Omega2) hold each cell midpoint of a mesh.

    ``overlays``: {name: centroids (N, tdim)} (``read_cell_groups``). The subdomain centroids are
    gathered from ``cm.cell_tags`` on every rank (collective).
    """

    def __init__(self, cm: ContactMesh, overlays: Mapping[str, np.ndarray]) -> None:
        msh, comm = cm.mesh, cm.comm
        self.dim = msh.topology.dim
        x = msh.geometry.x[:, : self.dim]
        lo = np.array([comm.allreduce(float(v), op=MPI.MIN) for v in np.min(x, axis=0, initial=np.inf)])
        hi = np.array([comm.allreduce(float(v), op=MPI.MAX) for v in np.max(x, axis=0, initial=-np.inf)])
        self.tol = 1e-9 * float(np.linalg.norm(hi - lo))
        self.overlay_names = tuple(overlays)
        self._overlay = self._tree([np.asarray(overlays[name]) for name in self.overlay_names])
        owned = msh.topology.index_map(msh.topology.dim).size_local
        parts = []
        for tag in (Subdomain.OMEGA1, Subdomain.OMEGA2):
            cells = cm.cell_tags.find(tag)
            parts.append(np.concatenate(comm.allgather(_midpoints(msh, cells[cells < owned]))))
        self._subdomain = self._tree(parts)
        self.msh = msh

    def _tree(self, parts: list[np.ndarray]) -> tuple[scipy.spatial.cKDTree | None, np.ndarray]:
        labels = np.concatenate([np.full(len(p), k, dtype=np.int64) for k, p in enumerate(parts)] or [[]])
        points = np.concatenate(parts) if parts else np.zeros((0, self.dim))
        return (scipy.spatial.cKDTree(points) if len(points) else None), labels

    def _labels(self, tree_labels, points: np.ndarray) -> np.ndarray:
        tree, labels = tree_labels
        if tree is None:
            return np.full(len(points), -1, dtype=np.int64)
        distance, index = tree.query(points, distance_upper_bound=self.tol)
        found = np.isfinite(distance)
        out = np.full(len(points), -1, dtype=np.int64)
        out[found] = labels[index[found]]
        return out

    def field(
        self, values: Mapping[str, object], *, shape: tuple[int, ...] = (), default: float = np.nan
    ) -> Callable[[np.ndarray], np.ndarray]:
        """x (3, N) ↦ the value of each point's group (shape ``(N,)`` or ``(*shape, N)``); ``default`` elsewhere."""
        unknown = [name for name in values if name not in self.overlay_names and name not in SUBDOMAIN_NAMES]
        if unknown:
            raise MeshTagError(
                f"no cell group {unknown[0]!r}: the groups are {[*SUBDOMAIN_NAMES, *self.overlay_names]}"
            )
        table = {name: np.asarray(value, dtype=np.float64).reshape(shape) for name, value in values.items()}

        def evaluate(x: np.ndarray) -> np.ndarray:
            points = np.asarray(x, dtype=np.float64)[: self.dim].T
            out = np.full((*shape, len(points)), default, dtype=np.float64)
            for names, tree in ((SUBDOMAIN_NAMES, self._subdomain), (self.overlay_names, self._overlay)):
                label = self._labels(tree, points)
                for k, name in enumerate(names):  # overlays second: they win
                    if name in table:
                        out[..., label == k] = table[name][..., None]
            return out

        return evaluate

    def uncovered(self, fn: Callable[[np.ndarray], np.ndarray]) -> int:
        """Number of (owned) cells of the mesh where ``fn`` is NaN (collective)."""
        tdim = self.msh.topology.dim
        cells = np.arange(self.msh.topology.index_map(tdim).size_local, dtype=np.int32)
        x = np.zeros((3, cells.size))
        x[:tdim] = _midpoints(self.msh, cells).T
        values = np.asarray(fn(x)).reshape(-1, cells.size)
        return self.msh.comm.allreduce(int(np.count_nonzero(np.any(np.isnan(values), axis=0))), op=MPI.SUM)
