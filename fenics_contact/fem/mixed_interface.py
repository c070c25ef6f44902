"""The interface γ of a Robin subproblem: the data space, the data load C, the trace map N and the γ mass matrix.

The Robin data g live in the normal-trace space of AW on γ, so a trace σn is exactly representable: vector P3 on
each γ edge, continuous where γ is straight, one value per side where it bends (``GammaBends``: the two tractions
of one symmetric tensor there).  They are stored as values (x, y) at the γ nodes (``points``: replicated, in one
canonical order shared by both subdomains) and, at a bend, as 3 coefficients.  d(g; τ) = ∫_γ g·(τn) ds = C g;
σn at the γ nodes = N c + n0 (exact: σn is a P3 polynomial on each γ edge); ‖g‖²_γ = g·(M_γ g).  Each rank holds
one block of the canonical values (``interface_range``).
"""

import basix.ufl
import numpy as np
import scipy.sparse as sp
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI
from scipy.spatial import cKDTree

from fenics_contact.errors import InputError
from fenics_contact.fem import forms_mixed
from fenics_contact.fem.distributed import DistributedMatrix, coo_matrix, gather_rows, layout
from fenics_contact.fem.mixed_assembly import assemble_petsc
from fenics_contact.fem.mixed_spaces import MixedSpaces
from fenics_contact.fem.mixed_traces import BoundaryFacets, reference_coordinates, stress_evaluation, traction_weights
from fenics_contact.problem.tags import Boundary
from fenics_contact.problem.validation import BEND

__all__ = ["GammaBends", "InterfaceData"]


class GammaBends:
    """Where γ bends, and the Robin data space there (replicated, the same on every rank and in both subdomains).

    ``points`` are the γ nodes in the canonical order.  At a vertex v where two γ edges a, b meet at an angle
    (|e_a × e_b| > ``BEND``, e the unit edge directions away from v) the traction σn jumps with the normal, so the
    data hold one value per side there, restricted to the tractions of one symmetric tensor S:
    (g_a, g_b) = (S n_a, S n_b), i.e. r_b·g_a + r_a·g_b = 0 with r = e rotated by +90° (the same for either side's
    outward normals).  That space is 3-dimensional: node k of a bend stores the coefficients c (3) of
    (g_a, g_b) = V_k c in an orthonormal basis V_k (4 × 3) of it; every other node stores (x, y).  Side a is the
    edge whose midpoint comes first in (y, x).  ``basis`` maps the stored values to the *copy values*: (x, y) of
    every node (node k: 2k, 2k + 1), then of side b at every bend (bend j: 2n + 2j, 2n + 2j + 1).

    ``colour_tags`` (facet tags 0, 1, 2 on the γ facets of ``msh``; None where γ is straight) colour the γ
    facets so that the two edges of a bend differ: an integral over one colour class sees one side of each bend.
    """

    def __init__(self, msh: dmesh.Mesh, gamma: np.ndarray, points: np.ndarray) -> None:
        comm = msh.comm
        bf = BoundaryFacets(msh, gamma)
        ends = comm.allgather((bf.a, bf.b))  # every γ facet once (its cell's owner)
        a = np.concatenate([e[0] for e in ends]).reshape(-1, 2)
        b = np.concatenate([e[1] for e in ends]).reshape(-1, 2)
        mid = 0.5 * (a + b)
        order = np.lexsort((mid[:, 0], mid[:, 1]))
        a, b, mid = a[order], b[order], mid[order]
        n = points.shape[0]
        tree = cKDTree(points)
        scale = max(float(np.max(np.linalg.norm(b - a, axis=1), initial=0.0)), 1e-300)
        da, ia = tree.query(a)
        db, ib = tree.query(b)
        if max(np.max(da, initial=0.0), np.max(db, initial=0.0)) > 1e-10 * scale:
            raise RuntimeError("an end point of a γ facet is not a γ node")
        ends_at = np.stack([ia, ib], axis=1)  # (F, 2) node of each end
        degree = np.bincount(ends_at.ravel(), minlength=n)
        if np.any(degree > 2):
            x, y = points[np.flatnonzero(degree > 2)[0]]
            raise InputError(
                f"the interface γ branches at ({x:.6g}, {y:.6g}) (more than two γ facets meet there): "
                "the mixed methods need γ to be a chain of facets; change the strip Ω₂"
            )
        self.points = points
        # the two facets at each node of degree 2 (incidences sorted by node, then facet: side a first)
        inc_node, inc_facet = ends_at.ravel(), np.repeat(np.arange(ends_at.shape[0]), 2)
        inc_far = np.where(np.tile([True, False], ends_at.shape[0])[:, None], b[inc_facet], a[inc_facet])
        order = np.lexsort((inc_facet, inc_node))
        ks = np.flatnonzero(degree == 2)
        first = order[np.searchsorted(inc_node[order], ks)]
        second = order[np.searchsorted(inc_node[order], ks) + 1]
        e = [
            (inc_far[i] - points[ks]) / np.linalg.norm(inc_far[i] - points[ks], axis=1)[:, None]
            for i in (first, second)
        ]
        bent = np.abs(e[0][:, 0] * e[1][:, 1] - e[0][:, 1] * e[1][:, 0]) > BEND
        bend_nodes = ks[bent]
        sides = [
            (np.array([fa, fb]), np.stack([ea, eb]))
            for fa, fb, ea, eb in zip(inc_facet[first[bent]], inc_facet[second[bent]], e[0][bent], e[1][bent])
        ]
        #: the γ nodes where γ bends (indices into ``points``)
        self.nodes = np.asarray(bend_nodes, dtype=np.int64)
        #: the midpoints of the two γ facets at each bend (sides a, b): (n_bends, 2, 2)
        self.side_midpoints = np.array([mid[f] for f, _ in sides]).reshape(-1, 2, 2)
        counts = np.full(n, 2, dtype=np.int64)
        counts[self.nodes] = 3
        #: node k holds the values offsets[k]:offsets[k + 1]
        self.offsets = np.concatenate([[0], np.cumsum(counts)])
        self.num_values = int(self.offsets[-1])
        self.num_copy_values = 2 * n + 2 * self.nodes.size
        rows = [np.repeat(2 * np.arange(n), 2) + np.tile([0, 1], n)]
        cols = [np.repeat(self.offsets[:-1], 2) + np.tile([0, 1], n)]
        vals = [np.ones(2 * n)]
        keep = ~np.isin(rows[0] // 2, self.nodes)
        rows, cols, vals = [rows[0][keep]], [cols[0][keep]], [vals[0][keep]]
        self.V = np.zeros((self.nodes.size, 4, 3))
        for j, (k, (_, e)) in enumerate(zip(self.nodes, sides)):
            r = np.stack([-e[:, 1], e[:, 0]], axis=1)  # (2, 2): r_a, r_b
            w = np.concatenate([r[1], r[0]]) / np.sqrt(2.0)  # the constraint row on (g_a, g_b), unit
            i = int(np.argmax(np.abs(w)))
            u = w.copy()
            u[i] += np.copysign(1.0, w[i])
            H = np.eye(4) - 2.0 * np.outer(u, u) / (u @ u)  # Householder: H w = ∓e_i, its other columns ⊥ w
            self.V[j] = np.delete(H, i, axis=1)
            rows.append(np.repeat([2 * k, 2 * k + 1, 2 * n + 2 * j, 2 * n + 2 * j + 1], 3))
            cols.append(np.tile(self.offsets[k] + np.arange(3), 4))
            vals.append(self.V[j].ravel())
        #: stored values → copy values (``num_copy_values`` × ``num_values``)
        self.basis = sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
            shape=(self.num_copy_values, self.num_values),
        )
        self.colour_tags = None
        self.copy_of_colour = np.zeros((self.nodes.size, 3), dtype=np.int64)
        if self.nodes.size:
            self._colour(msh, gamma, mid, [f for f, _ in sides])

    @property
    def bent(self) -> bool:
        return self.nodes.size > 0

    def _colour(self, msh, gamma, mid, side_facets) -> None:
        """Greedy colouring of the γ facets (in their (y, x) midpoint order) so that the sides of a bend differ."""
        F = mid.shape[0]
        neighbours = [[] for _ in range(F)]
        for fa, fb in side_facets:
            neighbours[fa].append(fb)
            neighbours[fb].append(fa)
        colour = np.full(F, -1, dtype=np.int64)
        for f in range(F):
            used = {colour[g] for g in neighbours[f]}
            colour[f] = min(c for c in range(3) if c not in used)
        for j, (fa, fb) in enumerate(side_facets):
            self.copy_of_colour[j] = -1
            self.copy_of_colour[j, colour[fa]] = 0
            self.copy_of_colour[j, colour[fb]] = 1
        tdim = msh.topology.dim
        facets = np.unique(np.asarray(gamma, dtype=np.int32))
        local_mid = msh.geometry.x[dmesh.entities_to_geometry(msh, tdim - 1, facets)][:, :, :2].mean(axis=1)
        dist, which = cKDTree(mid).query(local_mid) if facets.size else (np.zeros(0), np.zeros(0, dtype=np.int64))
        if np.max(dist, initial=0.0) > 1e-10 * max(float(np.max(np.abs(mid), initial=0.0)), 1e-300):  # (relative)
            raise RuntimeError("a γ facet of this rank is not among the gathered γ facets")
        #: the colour class of each local γ facet (values 0, 1, 2)
        self.colour_tags = dmesh.meshtags(msh, tdim - 1, facets, colour[which].astype(np.int32))
        self.num_colours = int(colour.max()) + 1

    def copy_column(self, node: np.ndarray, comp: np.ndarray, colour: int | None) -> np.ndarray:
        """The copy value of component ``comp`` at γ node ``node`` seen from a facet of ``colour``."""
        col = 2 * node + comp
        if colour is None or not self.bent:
            return col
        j = np.searchsorted(self.nodes, node)
        j = np.minimum(j, self.nodes.size - 1)
        at_bend = self.nodes[j] == node
        side_b = at_bend & (self.copy_of_colour[j, colour] == 1)
        return np.where(side_b, 2 * self.points.shape[0] + 2 * j + comp, col)


class InterfaceData:
    """Robin data on γ: ``gamma_points`` (the γ nodes), ``interface_range`` (this rank's block of the values),
    C (data → stress load), N (stress → σn at the nodes, with ``n0`` the lifting's share), the γ ``mass``
    matrix and ``gamma_normal`` (the outward normal at each node), all as distributed matrices.

    ``points``: the γ nodes in the order to use (the other subdomain's; default: this mesh's sorted by (y, x)).
    """

    def __init__(
        self,
        msh: dmesh.Mesh,
        facet_tags: dmesh.MeshTags,
        spaces: MixedSpaces,
        gamma: np.ndarray,
        points: np.ndarray | None,
    ) -> None:
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
        #: where γ bends and the data space there (``GammaBends``)
        self.bends = bends = GammaBends(msh, gamma, all_x)
        n_g = bends.num_values
        #: the number of Robin data values (global): (x, y) per node, 3 coefficients at a bend
        self.num_values = n_g
        g0, g1 = layout(comm, n_g)
        #: (start, end) of this rank's block of the γ values (canonical order)
        self.interface_range = (g0, g1)
        sort = np.argsort(all_g)
        g_sorted = all_g[sort]

        def canonical_value(global_dof: np.ndarray, colour: int | None = None) -> np.ndarray:
            """Copy value (``GammaBends``; where γ is straight: the value) of Lagrange DOFs, −1 off γ."""
            blk, comp = global_dof // 2, global_dof % 2
            pos = np.minimum(np.searchsorted(g_sorted, blk), max(g_sorted.size - 1, 0))
            hit = g_sorted[pos] == blk if g_sorted.size else np.zeros(blk.size, dtype=bool)
            return np.where(hit, bends.copy_column(sort[pos], comp, colour), -1)

        # the γ integrals over each colour class of facets (one class where γ is straight): at a bend, each
        # class sees one side's value
        if bends.bent:
            dsc = forms_mixed.boundary_measure(msh, bends.colour_tags)
            measures = [(dsc(c), c) for c in range(bends.num_colours)]
        else:
            measures = [(ds(Boundary.INTERFACE), None)]
        n_copy = bends.num_copy_values
        # d(g; τ) = C g:  Pᵀ C_dg S, S the canonical γ values -> P3 functions on γ
        g = ufl.TrialFunction(Lam)
        C_local = None
        for measure, colour in measures:
            Cdg = assemble_petsc(forms_mixed.robin_data_form(g, t, n, measure))
            ci, cj, cv = Cdg.getValuesCSR()
            Cdg.destroy()
            rows = np.repeat(np.arange(ci.size - 1), np.diff(ci))
            cols = canonical_value(cj.astype(np.int64), colour)
            keep = cols >= 0
            part = sp.csr_matrix((cv[keep], (rows[keep], cols[keep])), shape=(spaces.n_dg, n_copy))
            C_local = part if C_local is None else C_local + part
        if bends.bent:
            C_local = (C_local @ bends.basis).tocsr()
        #: d(g; τ) on the DG P3 stresses: owned DG rows × canonical γ values (C = Pᵀ C_dg)
        self.C_dg = C_local
        P_gamma = spaces.space.prolongation_for_rows(np.flatnonzero(np.diff(C_local.indptr)))
        C_red = (P_gamma.T @ C_local).tocoo()  # local AW rows (owned, ghosts) × canonical γ values
        gi = spaces.space.global_indices
        #: d(g; τ) = C g for interface data g = values (x, y) at ``gamma_points`` (this rank's block)
        self.C = DistributedMatrix(
            coo_matrix(
                comm, gi[C_red.row], C_red.col, C_red.data, (spaces.n_sigma, spaces.space.num_dofs), (g1 - g0, n_g)
            )
        )
        # L²(γ) mass matrix of the data, canonical values × canonical values (the γ norm of the
        # convergence certificate); the owned Lagrange rows of every rank, mapped like the columns
        w = ufl.TestFunction(Lam)
        m_parts = []
        for measure, colour in measures:
            Mg = assemble_petsc(ufl.inner(g, w) * measure)
            mi, mj, mv = Mg.getValuesCSR()
            m_rows = canonical_value(Mg.getOwnershipRange()[0] + np.repeat(np.arange(mi.size - 1), np.diff(mi)), colour)
            Mg.destroy()
            m_cols = canonical_value(mj.astype(np.int64), colour)
            keep = (m_rows >= 0) & (m_cols >= 0)
            m_parts.append((m_rows[keep], m_cols[keep], mv[keep]))
        m_rows, m_cols, mv = (np.concatenate(x) for x in zip(*m_parts))
        if bends.bent:
            Mc = sp.csr_matrix((mv, (m_rows, m_cols)), shape=(n_copy, n_copy))
            Mc = (bends.basis.T @ Mc @ bends.basis).tocoo()
            m_rows, m_cols, mv = Mc.row, Mc.col, Mc.data
        self.mass = DistributedMatrix(coo_matrix(comm, m_rows, m_cols, mv, (g1 - g0, n_g), (g1 - g0, n_g)))
        # trace σn at the γ nodes (exact: σn is a P3 polynomial on each γ edge, continuous at straight vertices),
        # each node evaluated by the lowest rank holding one of its facets with an owned cell; at a bend each
        # side on its own facet
        bf = BoundaryFacets(msh, gamma)
        found, idx = bf.locate(all_x)
        found[bends.nodes] = False
        mine = np.where(found, comm.rank, comm.size).astype(np.int32)
        owner = np.empty_like(mine)
        comm.Allreduce(mine, owner, op=MPI.MIN)
        owner[bends.nodes] = comm.rank
        if np.any(owner >= comm.size):
            raise RuntimeError("a γ node does not lie on the γ facets")
        nodes = np.flatnonzero((owner == comm.rank) & ~np.isin(np.arange(n_nodes), bends.nodes))
        cells, normals = bf.cells[idx[nodes]], bf.normal[idx[nodes]]
        points = all_x[nodes]
        copy_rows = 2 * nodes
        normal_nodes = nodes
        if bends.bent:  # the sides of the bends whose facet this rank holds
            bmid = 0.5 * (bf.a + bf.b)
            extra = []
            for side in range(2):
                if bmid.shape[0] == 0:
                    break
                dist, facet = cKDTree(bmid).query(bends.side_midpoints[:, side])
                held = np.flatnonzero(dist <= 1e-10 * np.maximum(bf.length[facet], 1e-300))
                extra.append((held, facet[held], side))
            for held, facet, side in extra:
                k = bends.nodes[held]
                cells = np.concatenate([cells, bf.cells[facet]])
                normals = np.concatenate([normals, bf.normal[facet]])
                points = np.concatenate([points, all_x[k]])
                copy_rows = np.concatenate([copy_rows, 2 * k if side == 0 else 2 * n_nodes + 2 * held])
                if side == 0:
                    normal_nodes = np.concatenate([normal_nodes, k])
        X = reference_coordinates(msh, cells, points)
        wx, wy = traction_weights(normals)
        E = sp.vstack([stress_evaluation(spaces.dg, cells, X, wx), stress_evaluation(spaces.dg, cells, X, wy)]).tocsr()
        value_rows = np.concatenate([copy_rows, copy_rows + 1])  # canonical (copy) value of each row of E
        N_loc = (E @ spaces.space.prolongation_for_rows(np.unique(E.indices))).tocoo()
        if bends.bent:  # copy values -> stored values: the rows of Vᵀ (V orthonormal: the coefficients)
            R = bends.basis.T.tocsr()[:, value_rows]
            N_loc = (R @ N_loc).tocoo()
            n0 = comm.allreduce(R @ (E @ spaces.s0), op=MPI.SUM) if comm.size > 1 else R @ (E @ spaces.s0)
            rows_of = np.arange(n_g)
        else:
            rows_of = value_rows
        #: σn (outward n of this mesh) at ``gamma_points``, this rank's block: N c (+ ``n0``)
        self.N = DistributedMatrix(
            coo_matrix(
                comm,
                rows_of[N_loc.row],
                gi[N_loc.col],
                N_loc.data,
                (g1 - g0, n_g),
                (spaces.n_sigma, spaces.space.num_dofs),
            )
        )
        #: σ_t n on γ (the traction lifting's trace; zero without tractions), this rank's block
        self.n0 = (n0 if bends.bent else gather_rows(comm, value_rows, E @ spaces.s0, n_g))[g0:g1]
        #: outward unit normal at each γ node (at a bend: side a's)
        self.gamma_normal = gather_rows(comm, normal_nodes, normals[: normal_nodes.size], n_nodes)

    def traction(self, c: np.ndarray) -> np.ndarray:
        """σn on γ (outward n of this mesh) at ``gamma_points``, (x, y) per node, this rank's block."""
        return self.N @ c + self.n0

    def destroy(self) -> None:
        """Free the PETSc matrices (collective)."""
        for op in (self.C, self.N, self.mass):
            op.destroy()
