"""The interface γ of a Robin subproblem: the data space, the data load C, the trace map N and the γ mass matrix.

The Robin data g live in continuous vector P3 on γ — the normal-trace space of AW, so a trace σn is
exactly representable — as values (x, y) at the γ nodes (``points``: replicated, in one canonical order
shared by both subdomains).  d(g; τ) = ∫_γ g·(τn) ds = C g; σn at the γ nodes = N c + n0 (exact: σn is a P3
polynomial on each γ edge, continuous at vertices); ‖g‖²_γ = g·(M_γ g).  Each rank holds one block of the
canonical values (``interface_range``).
"""

import basix.ufl
import numpy as np
import scipy.sparse as sp
import ufl
from mpi4py import MPI
from scipy.spatial import cKDTree

from dolfinx import fem
from dolfinx import mesh as dmesh

from fenics_contact.errors import InputError
from fenics_contact.fem import forms_mixed
from fenics_contact.fem.distributed import DistributedMatrix, coo_matrix, gather_rows, layout
from fenics_contact.fem.mixed_assembly import assemble_petsc
from fenics_contact.fem.mixed_spaces import MixedSpaces
from fenics_contact.fem.mixed_traces import BoundaryFacets, reference_coordinates, stress_evaluation, traction_weights
from fenics_contact.problem.tags import Boundary

__all__ = ["InterfaceData"]


class InterfaceData:
    """Robin data on γ: ``gamma_points`` (the γ nodes), ``interface_range`` (this rank's block of the values),
    C (data → stress load), N (stress → σn at the nodes, with ``n0`` the lifting's share), the γ ``mass``
    matrix and ``gamma_normal`` (the outward normal at each node), all as distributed matrices.

    ``points``: the γ nodes in the order to use (the other subdomain's; default: this mesh's sorted by (y, x)).
    """

    def __init__(self, msh: dmesh.Mesh, facet_tags: dmesh.MeshTags, spaces: MixedSpaces, gamma: np.ndarray,
                 points: np.ndarray | None) -> None:
        comm = msh.comm
        ds = forms_mixed.boundary_measure(msh, facet_tags)
        t, n = ufl.TestFunction(spaces.dg), ufl.FacetNormal(msh)
        Lam = fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 3, shape=(2,)))
        tdim = msh.topology.dim
        msh.topology.create_connectivity(tdim - 1, tdim)
        blocks = fem.locate_dofs_topological(Lam, tdim - 1, gamma)
        coords = Lam.tabulate_dof_coordinates()[blocks, :2]
        gblocks = Lam.dofmap.index_map.local_to_global(blocks.astype(np.int32)).astype(np.int64)
        if comm.size > 1:
            parts = comm.allgather((gblocks, coords))
            all_g = np.concatenate([p[0] for p in parts])
            all_x = np.concatenate([p[1] for p in parts])
            all_g, first = np.unique(all_g, return_index=True)
            all_x = all_x[first]
        else:
            all_g, all_x = gblocks, coords
        order = np.lexsort((all_x[:, 0], all_x[:, 1]))
        all_g, all_x = all_g[order], all_x[order]
        if points is not None:  # use the given order (the other subdomain's γ nodes)
            points = np.asarray(points, dtype=np.float64)[:, :2]
            dist, perm = cKDTree(all_x).query(points)
            # matching nodes agree to the rounding of their coordinates: a tolerance relative to their size
            # (lengths in mm or in km alike)
            tol = 1e-10 * max(float(np.max(np.abs(all_x), initial=0.0)), float(np.max(np.abs(points), initial=0.0)))
            if points.shape != all_x.shape or np.max(dist, initial=0.0) > tol or np.unique(perm).size != perm.size:
                raise InputError("the interface nodes of Ω₁ and Ω₂ do not match (γ must be conforming)")
            all_g, all_x = all_g[perm], all_x[perm]
        self.gamma_points = all_x
        n_nodes = all_x.shape[0]
        n_g = 2 * n_nodes
        g0, g1 = layout(comm, n_g)
        #: (start, end) of this rank's block of the γ values (x, y per node, canonical order)
        self.interface_range = (g0, g1)
        sort = np.argsort(all_g)
        g_sorted = all_g[sort]

        def canonical_value(global_dof: np.ndarray) -> np.ndarray:
            blk, comp = global_dof // 2, global_dof % 2
            pos = np.minimum(np.searchsorted(g_sorted, blk), max(g_sorted.size - 1, 0))
            hit = g_sorted[pos] == blk if g_sorted.size else np.zeros(blk.size, dtype=bool)
            return np.where(hit, 2 * sort[pos] + comp, -1)

        # d(g; τ) = C g:  Pᵀ C_dg S, S the canonical γ values -> P3 functions on γ
        g = ufl.TrialFunction(Lam)
        Cdg = assemble_petsc(forms_mixed.robin_data_form(g, t, n, ds(Boundary.INTERFACE)))
        ci, cj, cv = Cdg.getValuesCSR()
        Cdg.destroy()
        rows = np.repeat(np.arange(ci.size - 1), np.diff(ci))
        cols = canonical_value(cj.astype(np.int64))
        keep = cols >= 0
        C_local = sp.csr_matrix((cv[keep], (rows[keep], cols[keep])), shape=(spaces.n_dg, n_g))
        P_gamma = spaces.space.prolongation_for_rows(np.flatnonzero(np.diff(C_local.indptr)))
        C_red = (P_gamma.T @ C_local).tocoo()  # local AW rows (owned, ghosts) × canonical γ values
        gi = spaces.space.global_indices
        #: d(g; τ) = C g for interface data g = values (x, y) at ``gamma_points`` (this rank's block)
        self.C = DistributedMatrix(coo_matrix(comm, gi[C_red.row], C_red.col, C_red.data,
                                              (spaces.n_sigma, spaces.space.num_dofs), (g1 - g0, n_g)))
        # L²(γ) mass matrix of the continuous P3 data, canonical values × canonical values (the γ norm of the
        # convergence certificate); the owned Lagrange rows of every rank, mapped like the columns
        w = ufl.TestFunction(Lam)
        Mg = assemble_petsc(ufl.inner(g, w) * ds(Boundary.INTERFACE))
        mi, mj, mv = Mg.getValuesCSR()
        m_rows = canonical_value(Mg.getOwnershipRange()[0] + np.repeat(np.arange(mi.size - 1), np.diff(mi)))
        Mg.destroy()
        m_cols = canonical_value(mj.astype(np.int64))
        keep = (m_rows >= 0) & (m_cols >= 0)
        self.mass = DistributedMatrix(coo_matrix(comm, m_rows[keep], m_cols[keep], mv[keep],
                                                 (g1 - g0, n_g), (g1 - g0, n_g)))
        # trace σn at the γ nodes (exact: σn is a P3 polynomial on each γ edge, continuous at vertices),
        # each node evaluated by the lowest rank holding one of its facets with an owned cell
        bf = BoundaryFacets(msh, gamma)
        found, idx = bf.locate(all_x)
        mine = np.where(found, comm.rank, comm.size).astype(np.int32)
        owner = np.empty_like(mine)
        comm.Allreduce(mine, owner, op=MPI.MIN)
        if np.any(owner >= comm.size):
            raise RuntimeError("a γ node does not lie on the γ facets")
        nodes = np.flatnonzero(owner == comm.rank)
        cells, normals = bf.cells[idx[nodes]], bf.normal[idx[nodes]]
        X = reference_coordinates(msh, cells, all_x[nodes])
        wx, wy = traction_weights(normals)
        E = sp.vstack([stress_evaluation(spaces.dg, cells, X, wx), stress_evaluation(spaces.dg, cells, X, wy)]).tocsr()
        value_rows = np.concatenate([2 * nodes, 2 * nodes + 1])  # canonical value of each row of E
        N_loc = (E @ spaces.space.prolongation_for_rows(np.unique(E.indices))).tocoo()
        #: σn (outward n of this mesh) at ``gamma_points``, (x, y) per node, this rank's block: N c (+ ``n0``)
        self.N = DistributedMatrix(coo_matrix(comm, value_rows[N_loc.row], gi[N_loc.col], N_loc.data,
                                              (g1 - g0, n_g), (spaces.n_sigma, spaces.space.num_dofs)))
        #: σ_t n on γ (the traction lifting's trace; zero without tractions), this rank's block
        self.n0 = gather_rows(comm, value_rows, E @ spaces.s0, n_g)[g0:g1]
        self.gamma_normal = gather_rows(comm, nodes, normals, n_nodes)

    def traction(self, c: np.ndarray) -> np.ndarray:
        """σn on γ (outward n of this mesh) at ``gamma_points``, (x, y) per node, this rank's block."""
        return self.N @ c + self.n0

    def destroy(self) -> None:
        """Free the PETSc matrices (collective)."""
        for op in (self.C, self.N, self.mass):
            op.destroy()
