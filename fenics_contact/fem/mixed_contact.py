"""The contact boundary Γ_C of the mixed subproblem: its Gauss–Lobatto nodes, the map Q to σ_c, the penalty.

**Contact quadrature.**  The penalty is integrated with the 4-point Gauss–Lobatto rule per Γ_C edge
(``forms_mixed.contact_measure``).  Its nodes (3 per edge, vertices shared) are a Lagrange basis of the σ_c
trace space (continuous P3 on Γ_C), so the penalty acts on nodal values of σ_c with a diagonal weight, as
the primal method's vertex quadrature does for u_c.  Newton works with the sparse matrix Q of nodal values
σ_c(x_q) (a DG P3 evaluation times the prolongation P): it gives the active set, the penalty residual
(1/ε) Qᵀ W (Qσ)⁺, its generalized Jacobian (1/ε) Qᵀ W H(Qσ) Q and the energy.  The same term assembled from
the UFL form ``forms_mixed.contact_penalty`` agrees to round-off (tested).  (With 4 Gauss–Legendre points
per edge — more points than trace DOFs — full semismooth Newton steps wander for 50+ steps at h = 1/64 and
the line search creeps one point per step; with the nodal rule full steps converge in about 5.)

**Penalty.**  The natural boundary term says u_c = −(σ_c)⁺/ε on Γ_C: where the body presses on the obstacle
(σ_c ≤ 0) u_c = 0 exactly; where it separates, a small tensile stress σ_c = ε|u_c| remains
(``MixedContactProfile.max_tensile``).

**MPI.**  The node data (σ_c, weights, gap, the active set) are small and replicated: every rank holds all
of them in the same (``profile_order``) order; Q has this rank's block of rows.
"""

import numpy as np
import scipy.sparse as sp
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.fem.contact import ContactProfile, profile_order
from fenics_contact.fem.contact_boundary import obstacle_at_nodes
from fenics_contact.fem.distributed import DistributedMatrix, coo_matrix, gather_rows, layout
from fenics_contact.fem.mixed_spaces import MixedSpaces
from fenics_contact.fem.mixed_traces import (
    BoundaryFacets,
    normal_weights,
    reference_coordinates,
    stress_evaluation,
    tangential_weights,
)
from fenics_contact.problem.obstacles import Obstacle
from fenics_contact.problem.tags import Boundary

__all__ = ["ContactNodes", "MixedContactProfile", "merge_contact_nodes"]


class MixedContactProfile(ContactProfile):
    """σ_c and u_c = −(σ_c)⁺/ε along Γ_C (sorted by y) for the mixed penalty.

    The mixed penalty allows no penetration (u_c ≤ 0 everywhere); a point is in
    contact where the normal stress is compressive, σ_c < 0 (there u_c = 0).  ``max_tensile`` is the penalty error:
    the tensile stress left
    where the body separates (= ε·max|u_c|).
    """

    __slots__ = ()

    @property
    def active(self) -> np.ndarray:
        """Points in contact: σ_c < 0 (compressive: the penalty is inactive and u_c = g).

        (σ_c = 0 exactly where an essential condition fixes it, e.g. at a Γ_C end next to a traction-free
        side in line with Γ_C (``_drop_fixed_rows``): not contact; values within 1e−12 of max |σ_c| of 0
        count as 0.)
        """
        scale = float(np.max(np.abs(self.sigma_c), initial=0.0))
        return self.sigma_c < -1e-12 * scale

    @property
    def max_tensile(self) -> float:
        """max (σ_c)⁺: the tensile contact stress the penalty leaves."""
        return float(np.max(np.maximum(self.sigma_c, 0.0), initial=0.0))


def merge_contact_nodes(comm, pts, wts, normals, vertex):
    """Gauss–Lobatto nodes of all ranks, copies of a vertex shared by two edges with the same normal merged.

    Returns the replicated, canonically ordered (``profile_order``) points, weights, normals and vertex
    numbers, and for this rank (local node index, canonical index) of the copies it evaluates
    (the first copy of each merged node in rank order).
    """
    local_n = pts.shape[0]
    if comm.size > 1:
        parts = comm.allgather((pts, wts, normals, vertex))
        start = int(sum(p[0].shape[0] for p in parts[: comm.rank]))
        pts, wts, normals, vertex = (np.concatenate([p[i] for p in parts]) for i in range(4))
    else:
        start = 0
    key = np.where(vertex >= 0, vertex, -1 - np.arange(vertex.size))
    nkey = np.round(normals * 1e8).astype(np.int64)
    _, first, inverse = np.unique(
        np.stack([key, nkey[:, 0], nkey[:, 1]], axis=1), axis=0, return_index=True, return_inverse=True
    )
    merged_w = np.zeros(first.size)
    np.add.at(merged_w, inverse.ravel(), wts)
    order = profile_order(pts[first])
    first = first[order]
    mine = (first >= start) & (first < start + local_n)
    mine_rows = np.flatnonzero(mine)
    return (pts[first], merged_w[order], normals[first], vertex[first], first[mine] - start, mine_rows)


#: a row of an evaluation matrix whose entries are all below this share of the largest entry is round-off
FIXED_ROW_TOL = 1e-12


def _drop_fixed_rows(comm, E: sp.csr_matrix) -> tuple[sp.csr_matrix, np.ndarray]:
    """E with its round-off rows emptied, and which rows they are: the nodes whose value the essential conditions fix.

    At a vertex where Γ_C meets a traction-free side of normal n_N, the AW vertex value σ(v) (one tensor) lies
    in the null space of σ(v)n_N = 0.  If the side is in line with Γ_C (n_N = n), σ_c = n·σ(v)n and
    σ_t = t·σ(v)n vanish identically; at a right-angled corner (t = ±n_N) σ_t does.  Such a row is zero up
    to the round-off of the DG P3 tabulation and the prolongation; emptying it makes the value exactly the
    traction lifting's (0 on a traction-free side), so no round-off pressure or shear is reported at a node
    the contact condition cannot act on.  Every other row has entries of order one.
    """
    largest = comm.allreduce(float(np.max(np.abs(E.data), initial=0.0)), op=MPI.MAX)
    row_max = np.zeros(E.shape[0])
    rows = np.repeat(np.arange(E.shape[0]), np.diff(E.indptr))
    np.maximum.at(row_max, rows, np.abs(E.data))
    fixed = row_max <= FIXED_ROW_TOL * largest
    if np.any(fixed):
        E = (sp.diags((~fixed).astype(np.float64)) @ E).tocsr()
    E.eliminate_zeros()
    return E, fixed


def _evaluation(comm, spaces: MixedSpaces, cells, X, weights, rows, block, nq: int):
    """A stress value at the contact nodes (component ``weights`` of (σ_xx, σ_xy, σ_yy)): the distributed matrix
    (canonical node rows, this rank's ``block``), this rank's rows with local and with global AW columns, and the
    traction lifting's value and the nodes whose value the essential conditions fix (both replicated)."""
    E_dg = stress_evaluation(spaces.dg, cells, X, weights)
    E_loc = (E_dg @ spaces.space.prolongation_for_rows(np.unique(E_dg.tocsr().indices))).tocsr()
    E_loc, fixed = _drop_fixed_rows(comm, E_loc)
    gi = spaces.space.global_indices
    rows_global = sp.csr_matrix(
        (E_loc.data, gi[E_loc.indices], E_loc.indptr), shape=(E_loc.shape[0], spaces.space.num_dofs)
    )
    Ec = E_loc.tocoo()
    E = DistributedMatrix(
        coo_matrix(
            comm,
            rows[Ec.row],
            gi[Ec.col],
            Ec.data,
            (block[1] - block[0], nq),
            (spaces.n_sigma, spaces.space.num_dofs),
        )
    )
    lifting = gather_rows(comm, rows, E_dg @ spaces.s0, nq)
    return E, E_loc, rows_global, lifting, gather_rows(comm, rows, fixed, nq)


class ContactNodes:
    """The Γ_C contact nodes (replicated ``q_points``, ``q_weights``, ``q_normals``, gap ``q_gap``), Q and the penalty.

    σ_c at the nodes is Q c + ``q0`` (``q0``: the traction lifting's share); this rank evaluates the nodes
    ``rows`` (canonical indices), Q holds its block ``range`` of rows.  ``epsilon``: the penalty ε (None: no
    contact term; the nodes still serve the profile and the gap load).
    """

    def __init__(
        self,
        msh: dmesh.Mesh,
        facet_tags: dmesh.MeshTags,
        facets: np.ndarray,
        spaces: MixedSpaces,
        epsilon: float | None,
        *,
        tangential: bool = False,
    ) -> None:
        comm = self.comm = msh.comm
        self.epsilon = epsilon
        self.obstacle: Obstacle | None = None  #: set with the gap by ``set_obstacle``
        bf = BoundaryFacets(msh, facets)
        vertex_gid = spaces.space.global_vertex_indices
        pts, wq, cells, normals, vertex = bf.lobatto_nodes(vertex_gid)
        (self.q_points, self.q_weights, self.q_normals, q_vertex, local_nodes, rows) = merge_contact_nodes(
            comm, pts, wq, normals, vertex
        )
        nq = self.q_points.shape[0]
        self.rows = rows  #: canonical index of the contact nodes this rank evaluates
        self.range = layout(comm, nq)
        cells, normals = cells[local_nodes], normals[local_nodes]
        X = reference_coordinates(msh, cells, pts[local_nodes])
        #: σ_c at the contact nodes (canonical order), this rank's block of rows: Q c (+ ``q0``); its rows here
        #: with local (``Q_local``) and global (``Q_rows_global``: the penalty pattern of the saddle-point matrix)
        #: AW columns; ``q0``: σ_t,c of the traction lifting (zero without tractions), replicated
        #: ``normal_fixed``: the nodes where the essential conditions fix σ_c (its Q row is empty), replicated
        self.Q, self.Q_local, self.Q_rows_global, self.q0, self.normal_fixed = _evaluation(
            comm, spaces, cells, X, normal_weights(normals), rows, self.range, nq
        )
        #: with ``tangential``: σ_t = t·σn at the nodes (t = (−n_y, n_x)) alike (the friction law's rows), else None
        #: (``shear_fixed``: the nodes where the essential conditions fix σ_t, e.g. the right-angled corners of Γ_C
        #: with a traction-free side, where σ_t = 0 whatever the pressure)
        self.T = self.T_local = self.T_rows_global = self.t0 = self.shear_fixed = None
        if tangential:
            self.T, self.T_local, self.T_rows_global, self.t0, self.shear_fixed = _evaluation(
                comm, spaces, cells, X, tangential_weights(normals), rows, self.range, nq
            )
        # u_h·n at the nodes from the DG P1 displacement (one adjacent cell per node)
        el = spaces.U.ufl_element().sub_elements[0].basix_element
        if cells.size:
            phi = el.tabulate(0, X)[0, :, :, 0]  # (N, 3)
            dofs = spaces.U.dofmap.list[cells].astype(np.int64)
            ucols = 2 * dofs[:, :, None] + np.arange(2)
            vals = phi[:, :, None] * normals[:, None, :]
            urows = np.broadcast_to(np.arange(cells.size)[:, None, None], ucols.shape)
            self.Un = sp.csr_matrix((vals.ravel(), (urows.ravel(), ucols.ravel())), shape=(cells.size, spaces.n_u))
        else:
            self.Un = sp.csr_matrix((0, spaces.n_u))
        # nodes on Γ_D (the clamped corners) are left out of the profile, as in the primal one
        tdim = msh.topology.dim
        msh.topology.create_connectivity(tdim - 1, 0)
        f2v = msh.topology.connectivity(tdim - 1, 0).array.reshape(-1, 2)
        dirichlet = facet_tags.find(Boundary.GAMMA_D)
        clamped = vertex_gid[f2v[dirichlet].ravel()] if dirichlet.size else np.zeros(0, np.int64)
        if comm.size > 1:
            clamped = np.concatenate(comm.allgather(clamped))
        self.profile_nodes = ~np.isin(q_vertex, clamped) | (q_vertex < 0)

    def set_obstacle(self, obstacle: Obstacle | None) -> None:
        """The gap g at the nodes and the load F_g = Qᵀ W g (−∫_ΓC g τ_c moved to the right-hand side)."""
        self.q_gap, _ = obstacle_at_nodes(obstacle, self.q_points, self.q_normals)  # replicated nodes: no comm
        self.F_gap = self.Q.T @ self.block(self.q_weights * self.q_gap)
        self.obstacle = obstacle

    def block(self, values: np.ndarray) -> np.ndarray:
        """This rank's block (rows of ``Q``) of a replicated array over the contact nodes."""
        return values[self.range[0] : self.range[1]]

    def replicate(self, block: np.ndarray) -> np.ndarray:
        """The replicated array over the contact nodes from every rank's block (canonical order)."""
        return block if self.comm.size == 1 else np.concatenate(self.comm.allgather(block))

    def stress(self, c: np.ndarray) -> np.ndarray:
        """σ_c at the contact nodes of the stress P c + σ_t (replicated)."""
        return self.replicate(self.Q @ c) + self.q0

    def penalty_force(self, s: np.ndarray) -> np.ndarray:
        """(1/ε) Qᵀ W (σ_c)⁺ for replicated σ_c (owned AW entries)."""
        return self.Q.T @ self.block(self.q_weights * np.maximum(s, 0.0) / self.epsilon)

    def penalty_matrix(self, active: np.ndarray) -> sp.csr_matrix:
        """(1/ε) Qᵀ W H Q for the penalty-active nodes, this rank's rows of Q (local AW columns; serial: all)."""
        act = active[self.rows]
        Qa = self.Q_local[np.flatnonzero(act)]
        return (Qa.T @ sp.diags(self.q_weights[self.rows][act] / self.epsilon) @ Qa).tocsr()

    def penalty_weights(self, active: np.ndarray) -> np.ndarray:
        """w_q/ε at the nodes this rank evaluates where ``active`` (replicated), else 0: the diagonal of the
        penalty block Qᵀ (W/ε) H Q of the saddle-point Jacobian."""
        rows = self.rows
        return np.where(active[rows], self.q_weights[rows] / self.epsilon, 0.0)

    def penalty_energy(self, s: np.ndarray) -> float:
        """(1/2ε) Σ_q w_q ((σ_c)⁺)² for replicated σ_c: the penalty's part of the complementary energy."""
        return 0.5 * np.sum(self.q_weights * np.maximum(s, 0.0) ** 2) / self.epsilon

    def profile(self, c: np.ndarray) -> MixedContactProfile:
        """σ_c and u_c = −(σ_c)⁺/ε at the nodes (clamped corners excluded), sorted; on every rank."""
        keep = self.profile_nodes
        sigma_c = self.stress(c)[keep]
        return MixedContactProfile(
            self.q_points[keep, 1],
            -np.maximum(sigma_c, 0.0) / self.epsilon,
            sigma_c,
            self.q_points[keep],
            self.q_weights[keep],
            self.q_normals[keep],
            self.q_gap[keep],
        )

    def normal_trace(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(y, u_h·n) of the DG P1 displacement u (owned coefficients) at the profile's nodes."""
        keep = self.profile_nodes
        un = gather_rows(self.comm, self.rows, self.Un @ u, self.q_points.shape[0])
        return self.q_points[keep, 1], un[keep]

    def tangential_stress(self, c: np.ndarray) -> np.ndarray:
        """t·σn at the contact nodes of the stress P c + s₀ (s₀ the traction lifting; replicated; ``tangential``
        nodes only)."""
        return self.replicate(self.T @ c) + self.t0

    def destroy(self) -> None:
        """Free the PETSc matrices Q (and T) (collective)."""
        self.Q.destroy()
        if self.T is not None:
            self.T.destroy()
