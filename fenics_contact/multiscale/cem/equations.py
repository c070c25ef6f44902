"""ZᵀAZ of the primal CEM (Algorithm 3) from the patch equations, Z = [Ψ, N, N_f].

A function z_c of Z solved on a patch P (interior DOFs I, aux columns J) satisfies the saddle-point system
[[A_II, B_IJ], [B_IJᵀ, −I]] [x_c; μ_c] = [r_c; e_c] (``bases``: e_c a unit vector for a basis, r_c the γ rows of
a Robin datum or the load of a source corrector), so (A z_c)_I = r_c − B_IJ μ_c and, outside I, A z_c is nonzero
only on the ring ρ of the DOFs of P's cells that are not interior.  For any z_d (another patch's too):

    z_dᵀ A z_c = z_dᵀ r_c − (Bᵀz_d)_J · μ_c + z_d[ρ]ᵀ (A[ρ, I] x_c + B[ρ, J] μ_c),

with Bᵀz_d = μ_d + e_d on d's aux columns (zero elsewhere: B has no row outside a patch's cells).  Every term is
sparse or small (the ring, the aux columns), so ZᵀAZ costs no product of dense blocks with the fine matrices; the
lifting u_g of a prescribed displacement (in N_f's column, on Γ_D where B has no rows) adds Zᵀ(A u_g) to that
column.  ZᵀKZ = ZᵀAZ − Z_γᵀ R_γγ Z_γ (R = α G lives on γ).

The terms carry the round-off of the patch solves (≈ (H/h)² ε relative, against ε for the products of the
functions with A), harmless unless ΨᵀAΨ is nearly singular (dependent functions, as when every local mode is
kept): ``resolves`` says whether its Jacobi-scaled pivots stay above ``PIVOT_FLOOR``; ``coarse.gram_matrices``
forms the products otherwise.
"""

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp
from mpi4py import MPI

from fenics_contact.multiscale.work import run_shared

__all__ = ["PIVOT_FLOOR", "PatchEquations", "patch_equations", "resolves", "stiffness_gram"]

#: smallest Jacobi-scaled pivot of ΨᵀAΨ (pivoted Cholesky) for which ZᵀKZ is taken from the patch equations
#: (model 3, h = 1/256, H = 1/16, m = 4, three modes: 1.7e-2; every mode kept: dependent functions, pivots of
#: the size of the round-off)
PIVOT_FLOOR = 1e-8


@dataclass(slots=True)
class PatchEquations:
    """What ``stiffness_gram`` needs of one patch problem with k solutions: their Z ``columns`` (k), the patch's aux
    columns ``J``, ``mu`` (|J| × k) and Bᵀx = μ + e (``Btx``, |J| × k), the ``ring`` DOFs and ``ring_values``
    A[ρ, I] x + B[ρ, J] μ (|ρ| × k), the right-hand sides' fine part ``rhs`` (n × k sparse: r_c, global rows)."""

    columns: np.ndarray
    J: np.ndarray
    mu: np.ndarray
    Btx: np.ndarray
    ring: np.ndarray
    ring_values: np.ndarray
    rhs: sp.csc_matrix


def patch_equations(
    A: sp.csr_matrix,
    B: sp.csr_matrix,
    ring: np.ndarray,
    inner: np.ndarray,
    J: np.ndarray,
    solution: np.ndarray,
    rhs_t: sp.csr_matrix,
    columns: np.ndarray,
) -> PatchEquations:
    """The ``PatchEquations`` of the solutions ``solution`` ((|I| + |J|) × k: [x; μ]) of right-hand sides
    ``rhs_t`` (k × (|I| + |J|), their transpose) on the patch with interior DOFs ``inner``, aux columns ``J``
    and ring DOFs ``ring``."""
    nI = inner.size
    x, mu = solution[:nI], solution[nI:]
    e = rhs_t[:, nI:].toarray().T  # |J| × k
    # A[ρ, I] x: the few interior DOFs next to the ring only (x is column-major: no copy of all of it)
    rows = A[ring].tocoo()
    pos = np.minimum(np.searchsorted(inner, rows.col), nI - 1)
    keep = inner[pos] == rows.col
    near, at = np.unique(pos[keep], return_inverse=True)
    A_ring = sp.csr_matrix((rows.data[keep], (rows.row[keep], at)), shape=(ring.size, near.size))
    ring_values = A_ring @ np.ascontiguousarray(x[near]) + B[ring][:, J] @ np.ascontiguousarray(mu)
    r = rhs_t[:, :nI].tocoo()
    rhs = sp.csc_matrix((r.data, (inner[r.col], r.row)), shape=(A.shape[0], columns.size))
    return PatchEquations(columns, J, np.ascontiguousarray(mu), mu + e, ring, np.ascontiguousarray(ring_values), rhs)


def _add_columns(G: np.ndarray, columns: np.ndarray, block: np.ndarray) -> None:
    """G[:, columns] += block, repeated columns summed."""
    uniq, inverse = np.unique(columns, return_inverse=True)
    if uniq.size == columns.size:
        G[:, columns] += block
        return
    gather = sp.csr_matrix((np.ones(columns.size), (np.arange(columns.size), inverse)), shape=(columns.size, uniq.size))
    G[:, uniq] += np.asarray(block @ gather)


def _by_dofs(space) -> list:
    """The functions of Ψ and N by patch problem: [(dofs, [(values, Z columns)])] (``MultiscaleSpace.blocks``)."""
    return [(p.dofs, [(p.values, p.columns)]) for p in space.blocks]


def _rows_of(parts: list, rows: np.ndarray) -> np.ndarray:
    """The values of the functions ``parts`` (one DOF array) at the positions ``rows``, side by side."""
    return np.hstack([values[rows] for values, _ in parts])


def _add_rows(block: np.ndarray, parts: list, product: np.ndarray) -> None:
    """block[Z columns of the functions ``parts``] += the rows of ``product`` (one per function, in order)."""
    at = 0
    for values, columns in parts:
        block[columns] += product[at : at + columns.size]
        at += columns.size


def stiffness_gram(ops, space, equations: list, Zg: np.ndarray, *, comm: MPI.Comm = MPI.COMM_SELF) -> np.ndarray:
    """ZᵀKZ for Z = [Ψ, N, N_f] from the ``PatchEquations`` of every patch problem (module docstring) and the trace
    Z_γ (``coarse.trace_matrix``); the patches shared out over ``comm`` (a static share) and the sums Allreduced."""
    n_ms, ng = space.size, space.n_gamma
    nz = n_ms + ng + 1
    Nf = space.Nf if space.Nf is not None else np.zeros(ops.size)
    by_dofs = _by_dofs(space)
    # Bᵀ Z (aux × Z columns): μ + e of every solution, in its columns
    BtZ = np.zeros((space.aux.size, nz))
    for eq in equations:
        block = np.zeros((eq.J.size, nz))
        _add_columns(block, eq.columns, eq.Btx)
        BtZ[eq.J] += block
    # the right-hand sides' fine parts in their columns: the source correctors' loads (one vector: the column of N_f),
    # the Robin data and A u_g (in N_f's column; sparse, near γ and Γ_D); with them the ring terms A[ρ, I] x + B[ρ, J] μ
    # (Zᵀ of both: one sparse product per patch problem's functions)
    load = np.zeros(ops.size)
    rows, cols, vals = [], [], []
    for eq in equations:
        r = eq.rhs.tocoo()
        source = eq.columns[r.col] == nz - 1
        np.add.at(load, r.row[source], r.data[source])
        rows.append(r.row[~source])
        cols.append(eq.columns[r.col[~source]])
        vals.append(r.data[~source])
        rows.append(np.repeat(eq.ring, eq.columns.size))
        cols.append(np.tile(eq.columns, eq.ring.size))
        vals.append(eq.ring_values.ravel())
    if ops.lifting is not None:
        Au = ops.A @ ops.lifting
        at = np.flatnonzero(Au)
        rows.append(at)
        cols.append(np.full(at.size, nz - 1))
        vals.append(Au[at])
    rhs = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(ops.size, nz)
    )  # (duplicates summed)
    G = np.zeros((nz, nz))

    def add_patch(q: int) -> None:
        if q < len(by_dofs):  # Zᵀ (rhs + ring terms), the rows of this DOF group's functions
            dofs, parts = by_dofs[q]
            local = rhs[dofs]
            rows = np.flatnonzero(np.diff(local.indptr))
            if rows.size:
                _add_rows(G, parts, np.asarray(local[rows].T @ _rows_of(parts, rows)).T)
            on = load[dofs]
            for values, columns in parts:
                G[columns, nz - 1] += on @ values
        if q == 0:
            G[nz - 1] += rhs.T @ Nf
            G[nz - 1, nz - 1] += Nf @ load
        if q >= len(equations):
            return
        eq = equations[q]
        _add_columns(G, eq.columns, -(BtZ[eq.J].T @ eq.mu))  # −(Bᵀz_d)_J · μ_c

    count = max(len(equations), len(by_dofs))
    run_shared(np.ones(count), comm, "CEM stiffness Gram", add_patch, gather=False)
    if comm.size > 1:
        comm.Allreduce(MPI.IN_PLACE, G, op=MPI.SUM)
    G -= Zg.T @ (ops.R[ops.gamma][:, ops.gamma] @ Zg)
    return 0.5 * (G + G.T)  # (symmetric as the products it stands for)


def resolves(ops, GK: np.ndarray, Zg: np.ndarray, n_ms: int) -> bool:
    """Whether ΨᵀAΨ (from ZᵀKZ and the trace Z_γ) has all its Jacobi-scaled pivots above ``PIVOT_FLOOR``."""
    Zp = Zg[:, :n_ms]
    A = GK[:n_ms, :n_ms] + Zp.T @ (ops.R[ops.gamma][:, ops.gamma] @ Zp)
    d = np.diag(A).copy()
    if np.any(d <= 0):
        return False
    scale = 1.0 / np.sqrt(d)
    _, _, rank, info = scipy.linalg.lapack.dpstrf(A * scale[:, None] * scale[None, :], lower=1, tol=PIVOT_FLOOR)
    return info >= 0 and rank == n_ms
