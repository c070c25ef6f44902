"""A serial copy of a distributed subdomain mesh on every rank, and the data transfers to and from it.

The multiscale offline phase works on independent local problems of Ω₁ (cells,
patches) that need whole coarse neighbourhoods. Under MPI every rank therefore
builds the same serial (COMM_SELF) copy of Ω₁ from the distributed Ω₁ submesh
(owned cells, vertex coordinates, facet tags and the coarse index of every cell
are allgathered), assembles the Ω₁ operators on it, computes its share of the
local problems and receives the others' (``multiscale.work``). The Ω₂ strip and
the interface iteration stay on the distributed mesh, as in Algorithm 1.

Vertices are identified across ranks by the global index of the distributed
submesh's geometry node; a P1 function moves between the two meshes through it
(``gather`` to the copy: one Allgather of the owned values; ``scatter`` back:
local, every rank holds all values). Interface data (owned γ values, the
``InterfaceSpace`` ordering) reach the copy with one Allgather per call.

With one rank the copy is built the same way (a renumbered twin of Ω₁), so the
serial and parallel runs share one code path.
"""

import basix.ufl
import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError

__all__ = ["SerialReplica"]


def _allgather_rows(comm: MPI.Comm, a: np.ndarray) -> np.ndarray:
    """Concatenate (in rank order) the row blocks of every rank; columns must agree."""
    a = np.ascontiguousarray(a)
    if comm.size == 1:
        return a.copy()
    rows = np.array(comm.allgather(a.shape[0]), dtype=np.int64)
    tail = a.shape[1:]
    width = int(np.prod(tail)) if tail else 1
    out = np.empty((int(rows.sum()),) + tail, dtype=a.dtype)
    counts = rows * width
    displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
    mpi_type = MPI._typedict[a.dtype.char]
    comm.Allgatherv([a, mpi_type], [out, (counts, displs), mpi_type])
    return out


class SerialReplica:
    """The same serial copy of a distributed submesh on every rank, with P1 transfers and γ bookkeeping.

    ``mesh`` (COMM_SELF), ``facet_tags`` (every tagged facet of the submesh, same values),
    ``cell_data[name]`` (gathered per-cell arrays, e.g. the coarse index), ``V`` (P1 with the shape
    of ``V_sub``) and transfers ``gather`` (V_sub function → V array) and ``scatter`` (V array → V_sub).
    """

    def __init__(
        self, msh: dmesh.Mesh, facet_tags: dmesh.MeshTags, V_sub: fem.FunctionSpace, cell_data: dict[str, np.ndarray]
    ) -> None:
        comm = msh.comm
        self.comm = comm
        tdim = msh.topology.dim
        gdim = msh.geometry.dim
        n_owned = msh.topology.index_map(tdim).size_local
        geo_map = msh.geometry.index_map()
        gdofs = msh.geometry.dofmaps[0]
        if gdofs.shape[1] != tdim + 1:
            raise InputError("the serial copy of a subdomain needs an affine (P1) triangle or tetrahedron geometry")
        n_nodes = geo_map.size_local + geo_map.num_ghosts  # (none on a rank that holds no cell of the submesh)
        node_gid = np.asarray(geo_map.local_to_global(np.arange(n_nodes, dtype=np.int32)), dtype=np.int64)
        cells_gid = node_gid[gdofs[:n_owned]]
        all_cells = _allgather_rows(comm, cells_gid)
        # node coordinates (owned nodes only, each once)
        n_nodes_owned = geo_map.size_local
        owned_x = np.ascontiguousarray(msh.geometry.x[:n_nodes_owned, :gdim])
        all_gid = _allgather_rows(comm, node_gid[:n_nodes_owned])
        all_x = _allgather_rows(comm, owned_x)
        order = np.argsort(all_gid)
        self.node_gids = all_gid[order]  #: sorted global node ids = input index of the copy's nodes
        x = all_x[order]
        cells = np.searchsorted(self.node_gids, all_cells)
        if np.any(self.node_gids[cells] != all_cells):
            raise RuntimeError("serial copy: a cell vertex is owned by no rank")
        # a UFL domain of its own: sharing the subdomain's would point that domain at the copy (forms on the
        # distributed mesh would then be built on the copy)
        domain = ufl.Mesh(basix.ufl.element("Lagrange", msh.basix_cell(), 1, shape=(gdim,)))
        self.mesh = dmesh.create_mesh(MPI.COMM_SELF, cells.astype(np.int64), domain, x)
        self.cell_data = {}
        original = np.asarray(self.mesh.topology.original_cell_index, dtype=np.int64)
        for name, values in cell_data.items():
            self.cell_data[name] = _allgather_rows(comm, np.asarray(values)[:n_owned])[original]
        # facet tags: (sorted global node ids of its vertices, value) of every tagged local facet
        msh.topology.create_connectivity(tdim - 1, tdim)
        ftags = self._facet_keys(msh, node_gid, facet_tags.indices)
        vals = facet_tags.values.astype(np.int64)
        width = tdim  # vertices of a facet: 2 (edges of triangles), 3 (faces of tetrahedra)
        keyed = _allgather_rows(
            comm, np.column_stack([ftags, vals]) if ftags.size else np.zeros((0, width + 1), np.int64)
        )
        keyed = np.unique(keyed, axis=0)
        serial_gid = self.node_gids[np.asarray(self.mesh.geometry.input_global_indices, dtype=np.int64)]
        smsh = self.mesh
        smsh.topology.create_connectivity(tdim - 1, tdim)
        smsh.topology.create_connectivity(tdim - 1, 0)
        nf = smsh.topology.index_map(tdim - 1).size_local
        skeys = self._facet_keys(smsh, serial_gid, np.arange(nf, dtype=np.int32))
        # match the gathered keys among the copy's facets (the rows of sorted vertex ids, compared whole)
        rows, inverse = np.unique(np.vstack([skeys, keyed[:, :width]]), axis=0, return_inverse=True)
        inverse = inverse.ravel()
        facet_of_row = np.full(rows.shape[0], -1, dtype=np.int64)
        facet_of_row[inverse[: skeys.shape[0]]] = np.arange(skeys.shape[0])
        facets = facet_of_row[inverse[skeys.shape[0] :]]
        if np.any(facets < 0):
            raise RuntimeError("serial copy: a tagged facet of the subdomain was not found in its copy")
        forder = np.argsort(facets, kind="stable")
        self.facet_tags = dmesh.meshtags(
            smsh, tdim - 1, facets[forder].astype(np.int32), keyed[forder, width].astype(np.int32)
        )
        # P1 space of the same shape, and the block ↔ global node id maps on both sides
        shape = tuple(int(d) for d in V_sub.value_shape)
        self.V = fem.functionspace(smsh, basix.ufl.element("Lagrange", smsh.basix_cell(), 1, shape=shape))
        self.bs = self.V.dofmap.index_map_bs
        self.block_gid = np.empty(self.V.dofmap.index_map.size_local, dtype=np.int64)
        self.block_gid[self.V.dofmap.list.ravel()] = serial_gid[smsh.geometry.dofmaps[0].ravel()]
        self._block_order = np.argsort(self.block_gid)
        self.V_sub = V_sub
        sub_blocks = V_sub.dofmap.index_map.size_local + V_sub.dofmap.index_map.num_ghosts
        self.sub_gid = np.empty(sub_blocks, dtype=np.int64)
        self.sub_gid[V_sub.dofmap.list.ravel()] = node_gid[gdofs.ravel()]
        self.sub_block_in_copy = self._blocks_of(self.sub_gid)
        self._owned_sub = V_sub.dofmap.index_map.size_local

    @staticmethod
    def _facet_keys(msh: dmesh.Mesh, node_gid: np.ndarray, facets: np.ndarray) -> np.ndarray:
        """The sorted global node ids of the vertices of each facet (two in the plane, three in 3D)."""
        tdim = msh.topology.dim
        if facets.size == 0:
            return np.zeros((0, tdim), dtype=np.int64)
        nodes = dmesh.entities_to_geometry(msh, tdim - 1, np.asarray(facets, dtype=np.int32))
        g = node_gid[nodes]
        return np.sort(g, axis=1)

    def _blocks_of(self, gids: np.ndarray) -> np.ndarray:
        pos = np.searchsorted(self.block_gid[self._block_order], gids)
        return self._block_order[np.minimum(pos, self._block_order.size - 1)]

    def dofs(self, blocks: np.ndarray) -> np.ndarray:
        return (self.bs * np.asarray(blocks, dtype=np.int64)[:, None] + np.arange(self.bs)).ravel()

    def gather(self, u_sub: fem.Function) -> np.ndarray:
        """The values of a V_sub function on the copy (collective: one Allgather of the owned values)."""
        n = self._owned_sub
        vals = u_sub.x.array[: n * self.bs].reshape(n, self.bs)
        blocks = _allgather_rows(self.comm, self.sub_block_in_copy[:n])
        values = _allgather_rows(self.comm, np.ascontiguousarray(vals))
        out = np.zeros(self.V.dofmap.index_map.size_local * self.bs)
        out[self.dofs(blocks)] = values.ravel()
        return out

    def scatter(self, values: np.ndarray, u_sub: fem.Function) -> None:
        """u_sub ← the copy's values at its (owned and ghost) DOFs (local: every rank holds all values)."""
        u_sub.x.array[:] = values[self.dofs(self.sub_block_in_copy)]
