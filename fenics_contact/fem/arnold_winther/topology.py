"""The mesh entities the Arnold–Winther DOFs live on: local vertices, edges and owned cells of a triangle mesh.

Vertices and edges are the rank's local ones (owned, then ghosts), cells the owned ones.  Every edge is
oriented from its lower to its higher *global* vertex number, so that the two cells sharing an edge (on
one rank or two) agree on its tangent and normal, the edge moments' orientation.
"""

from __future__ import annotations

import dolfinx.mesh
import numpy as np

from fenics_contact.fem.arnold_winther.functionals import EDGE_VERTICES

__all__ = ["TriangleEntities"]


class TriangleEntities:
    """Connectivity, vertex coordinates, global numbers and edge orientation of a (distributed) triangle mesh.

    Attributes: ``c2v`` (n_c, 3) and ``c2e`` (n_c, 3) of the owned cells (basix local order: edge k opposite
    vertex k), ``c2v_all`` of every local cell, ``e2v`` (n_e, 2), ``vx`` (n_v, 2) vertex coordinates,
    ``vertex_gid`` / ``edge_gid`` global numbers, ``edge_start`` / ``edge_end`` the local vertices of each
    edge in its global orientation, ``edge_flip`` (n_c, 3) True where the cell's local edge runs the other way.
    """

    def __init__(self, mesh: dolfinx.mesh.Mesh) -> None:
        self.mesh = mesh
        top = mesh.topology
        for d0, d1 in ((2, 0), (2, 1), (1, 0), (1, 2)):
            top.create_connectivity(d0, d1)
        im0, im1, im2 = (top.index_map(d) for d in range(3))
        nc = im2.size_local
        nv = im0.size_local + im0.num_ghosts
        ne = im1.size_local + im1.num_ghosts
        c2v_all = top.connectivity(2, 0).array.reshape(-1, 3).astype(np.int64)
        c2v = c2v_all[:nc]
        c2e = top.connectivity(2, 1).array.reshape(-1, 3)[:nc].astype(np.int64)
        e2v = top.connectivity(1, 0).array.reshape(-1, 2).astype(np.int64)
        vx = np.zeros((nv, 2))
        vx[c2v_all.ravel()] = mesh.geometry.x[mesh.geometry.dofmaps[0].ravel(), :2]
        self.c2v, self.c2e, self.e2v, self.vx, self.c2v_all = c2v, c2e, e2v, vx, c2v_all
        self.num_cells, self.num_vertices, self.num_edges = nc, nv, ne
        self.vertex_gid = im0.local_to_global(np.arange(nv, dtype=np.int32)).astype(np.int64)
        self.edge_gid = im1.local_to_global(np.arange(ne, dtype=np.int32)).astype(np.int64)

        # sanity: local edge k is opposite local vertex k (basix numbering)
        loc = np.sort(c2v[:, EDGE_VERTICES], axis=-1)  # (nc, 3, 2)
        if not np.array_equal(loc, np.sort(e2v[c2e], axis=-1)):
            raise RuntimeError("Unexpected local edge numbering in the mesh topology.")
        gnum = self.vertex_gid
        self.edge_flip = gnum[c2v[:, EDGE_VERTICES[:, 0]]] > gnum[c2v[:, EDGE_VERTICES[:, 1]]]
        lower = gnum[e2v[:, 0]] < gnum[e2v[:, 1]]
        self.edge_start = np.where(lower, e2v[:, 0], e2v[:, 1])  # orientation from global vertex numbers
        self.edge_end = np.where(lower, e2v[:, 1], e2v[:, 0])

    @property
    def num_dofs_full(self) -> int:
        """Size of the full local numbering: 3 per vertex, 4 per edge, 3 per owned cell."""
        return 3 * self.num_vertices + 4 * self.num_edges + 3 * self.num_cells

    def outward_sign(self, facets: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """+1 where the edge normal n_e (global orientation) points out of the mesh, −1 where it points in."""
        f2c = self.mesh.topology.connectivity(1, 2)
        counts = np.diff(f2c.offsets)[facets]
        if np.any(counts < 1):
            raise ValueError("a traction facet does not belong to a cell")
        cells = f2c.array[f2c.offsets[facets]]
        mid = 0.5 * (self.vx[self.edge_start[facets]] + self.vx[self.edge_end[facets]])
        centre = self.vx[self.c2v_all[cells]].mean(axis=1)
        return np.where(np.sum(normals * (mid - centre), axis=1) > 0.0, 1.0, -1.0)
