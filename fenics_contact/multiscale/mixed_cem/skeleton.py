"""Stage II of the mixed CEM (Algorithm 4) by static condensation onto the coarse skeleton: ``stage_two``.

A patch system is the sum of its coarse cells' blocks, coupled only through the AW vertex and edge DOFs shared
by two coarse cells (the skeleton).  Each coarse cell's own unknowns (inner stress functions, displacements,
aux multipliers) are eliminated once (Schur complement S_K on its skeleton, MUMPS LU); each patch factorizes
only Σ_K T_Γᵀ S_K T_Γ on its skeleton (4.7·10³ instead of 1.0·10⁵ unknowns for an interior patch at h = 1/128,
H = 1/16, m = 3; symmetric positive definite: MUMPS Cholesky, its analysis reused per sparsity pattern); the
own unknowns are recovered coarse cell by coarse cell for all patches reaching it in one multi-right-hand-side
solve with the LU kept from the condensation (``KEEP_FACTORS_BYTES``).  The same linear systems as one LU per
patch, up to rounding.
"""

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

from fenics_contact.fem.linalg import ReusedAnalysis
from fenics_contact.fem.mixed_linear import saddle_point_scaling
from fenics_contact.multiscale import work
from fenics_contact.multiscale.coarse import CoarseGrid
from fenics_contact.multiscale.mixed_cem.bases import CoarseCellDofs, LocalFactor, PatchFunctions, cell_coarse
from fenics_contact.multiscale.mixed_cem.blocks import cell_rows
from fenics_contact.multiscale.mixed_cem.local_space import (
    Topology,
    aw_map,
    boundary_vertex_null_spaces,
    local_stress_space,
    local_triplets,
)
from fenics_contact.multiscale.mixed_cem.operators import CellOperators
from fenics_contact.multiscale.mixed_cem.spectral import StageI

__all__ = ["KEEP_FACTORS_BYTES", "held_cells", "stage_two"]

log = logging.getLogger(__name__)


def _skeleton_entities(topo: Topology, grid: CoarseGrid) -> tuple[np.ndarray, np.ndarray]:
    """Masks (vertices, edges) of Ω₁ touching two or more coarse cells: the coarse skeleton."""
    cc = np.repeat(cell_coarse(grid), 3)
    out = []
    for conn, n in ((topo.c2v, topo.nv), (topo.c2e, topo.ne)):
        lo = np.full(n, np.iinfo(np.int64).max)
        hi = np.full(n, -1, dtype=np.int64)
        np.minimum.at(lo, conn.ravel(), cc)
        np.maximum.at(hi, conn.ravel(), cc)
        out.append(hi > lo)
    return out[0], out[1]


def _skeleton_aw(topo: Topology, skeleton: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Mask over the AW DOFs of Ω₁: the DOFs of the skeleton vertices and edges."""
    out = np.zeros(3 * topo.nv + 4 * topo.ne + 3 * topo.nc, dtype=bool)
    out[: 3 * topo.nv] = np.repeat(skeleton[0], 3)
    out[3 * topo.nv : 3 * topo.nv + 4 * topo.ne] = np.repeat(skeleton[1], 4)
    return out


@dataclass(slots=True)
class _CellSystem:
    """The Stage II equations restricted to one coarse cell K, in the unknowns [I | Γ].

    I: the stress functions owned by K (support in K; AW coefficients on K: ``WI``), the displacements
    on K and the y of K's aux functions; Γ: the skeleton DOFs of K (AW vertex and edge DOFs shared with
    other coarse cells, AW functions restricted to K).  Every patch containing K contains these
    unknowns with these equations, so a patch system is the sum of its coarse cells' blocks (coupled on Γ).
    """

    skel: np.ndarray  #: sorted global AW DOFs of Γ_K
    WI: sp.csr_matrix  #: (|aw_K| × n_s) AW coefficients on K of the owned stress functions
    gpos: np.ndarray  #: position of each skeleton DOF in dofs.aw[K]
    n_s: int  #: owned stress functions
    n_u: int  #: displacement DOFs (6|K|)
    M_II: sp.csr_matrix
    M_IG: sp.csr_matrix
    M_GG: np.ndarray
    b: np.ndarray  #: (n_I + |Γ|, k) K's own right-hand sides: l_K basis columns, Robin data columns, load

    @property
    def n_I(self) -> int:
        return self.M_II.shape[0]

    def factor_II(self, scale: float) -> LocalFactor:
        """The LU of M_II, equilibrated by diag(s I_σ, I_u/s, I_y) (``CellOperators.scale``)."""
        scaling = saddle_point_scaling(scale, self.n_s, self.n_u, self.n_I - self.n_s - self.n_u)
        return LocalFactor.from_csr(self.M_II, scaling=scaling)


def _has_load(ops: CellOperators, cells: np.ndarray, source: bool) -> bool:
    """Whether a coarse cell gets a source corrector: f or the boundary data's stress-side load F act on it."""
    return source and bool(np.any(ops.G[cells] != 0.0) or (ops.F is not None and np.any(ops.F[cells] != 0.0)))


def _cell_system(
    ops: CellOperators,
    topo: Topology,
    dofs: CoarseCellDofs,
    aux: StageI,
    skeleton: tuple,
    skel_aw: np.ndarray,
    K: int,
    source: bool,
) -> _CellSystem:
    """The coarse cell K's block of every Stage II patch system (``_CellSystem``), assembled from cell blocks."""
    cK, awK = dofs.cells[K], dofs.aw[K]
    nK = cK.size
    space = local_stress_space(ops, topo, cK, raw=skeleton)  # owned functions + raw skeleton functions
    is_skel = np.zeros(space.size, dtype=bool)
    is_skel[: space.aw_inner.size] = skel_aw[space.aw_inner]
    skel_cols, own_cols = np.flatnonzero(is_skel), np.flatnonzero(~is_skel)
    n_s, n_G = own_cols.size, skel_cols.size
    Zk = (ops.S[cK] @ aux.modes[K]).reshape(6 * nK, -1)
    lk = Zk.shape[1]
    n_I = n_s + 6 * nK + lk
    new = np.empty(space.size, dtype=np.int64)
    new[own_cols] = np.arange(n_s)
    new[skel_cols] = n_I + np.arange(n_G)
    (ar, ac, av), (br, bc, bv) = local_triplets(ops, space)
    zr, zc = np.nonzero(Zk)
    zv = Zk[zr, zc]
    eye = n_s + 6 * nK + np.arange(lk)
    rows = np.concatenate([new[ar], n_s + br, new[bc], n_s + zr, n_s + 6 * nK + zc, eye])
    cols = np.concatenate([new[ac], new[bc], n_s + br, n_s + 6 * nK + zc, n_s + zr, eye])
    vals = np.concatenate([av, bv, bv, -zv, -zv, np.ones(lk)])
    M = sp.csr_matrix((vals, (rows, cols)), shape=(n_I + n_G, n_I + n_G))
    T = aw_map(space, awK)
    # K's own right-hand sides (those of the patch systems): −Z e_j; Robin data C_K g; the load on K
    Ci = ops.C[cell_rows(cK, 30)]
    gcols = np.unique(Ci.indices)
    load = _has_load(ops, cK, source)
    b = np.zeros((n_I + n_G, lk + gcols.size + int(load)))
    b[n_s : n_s + 6 * nK, :lk] = -Zk
    if gcols.size:
        b[new, lk : lk + gcols.size] = (T.T @ (dofs.P(ops, K).T @ Ci[:, gcols])).toarray()
    if load:
        b[n_s : n_s + 6 * nK, -1] = ops.G[cK].ravel()
        if ops.F is not None:  # the boundary data's stress-side load F|K in the τ rows
            b[new, -1] = T.T @ (dofs.P(ops, K).T @ ops.F[cK].ravel())
    skel = space.aw_inner[skel_cols]
    return _CellSystem(
        skel,
        T[:, own_cols].tocsr(),
        np.searchsorted(awK, skel),
        n_s,
        6 * nK,
        M[:n_I, :n_I],
        M[:n_I, n_I:],
        M[n_I:, n_I:].toarray(),
        b,
    )


#: Bytes of coarse-cell LUs (and what goes with them) a rank keeps from the condensation for the back substitution;
#: beyond it a cell is assembled and factorized again.  By this count (``_CellElimination.nbytes``, 12 bytes per
#: factor entry) h = 1/128, H = 1/16 holds 0.79 GB in all (3–4 MB per cell: all kept, for 0.08 GB more peak RSS
#: in ``benchmarks/mixed_ms_scaling.py``), h = 1/256 about 4× that (a third kept).
KEEP_FACTORS_BYTES = 1.0e9


class _CellElimination:
    """What the back substitution on a coarse cell K needs: the LU of M_II (kept from the condensation, or a new
    one), M_IΓ, the AW coefficients of the owned stress functions and M_II⁻¹ b_I (``own``; added after the solve
    with −M_IΓ x_Γ: putting b_I into that right-hand side instead moves Algorithm 4 by 1e-10 from one LU per patch)."""

    def __init__(self, system: _CellSystem, lu: LocalFactor, own: np.ndarray) -> None:
        self.skel, self.WI, self.gpos = system.skel, system.WI, system.gpos
        self.n_s, self.n_u, self.M_IG = system.n_s, system.n_u, system.M_IG
        self.lu, self.own = lu, own

    @classmethod
    def factorized(cls, system: _CellSystem, scale: float) -> "_CellElimination":
        """A new LU of M_II (a cell whose condensation was not kept; ``scale``: ``CellOperators.scale``)."""
        lu = system.factor_II(scale)
        try:
            return cls(system, lu, lu.solve(system.b[: system.n_I]))
        except Exception:
            lu.destroy()
            raise

    @property
    def nbytes(self) -> int:
        """Memory held: the LU (``SparseFactor.nbytes``) and the arrays."""
        return int(self.lu.nbytes + self.own.nbytes + self.M_IG.data.nbytes * 2 + self.WI.data.nbytes * 2)

    def destroy(self) -> None:
        self.lu.destroy()


def _condense(system: _CellSystem, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, _CellElimination]:
    """(skeleton DOFs, Schur complement S_K = M_ΓΓ − M_ΓI M_II⁻¹ M_IΓ, condensed own data b_Γ − M_ΓI M_II⁻¹ b_I,
    the data of the back substitution: M_II's LU is kept, not factorized again; ``scale``: ``CellOperators.scale``)."""
    n_I, n_G = system.n_I, system.skel.size
    lu = system.factor_II(scale)
    try:
        X = lu.solve(np.hstack([system.M_IG.toarray(), system.b[:n_I]]))
    except Exception:
        lu.destroy()
        raise
    S = system.M_GG - system.M_IG.T @ X[:, :n_G]
    S = 0.5 * (S + S.T)
    c = system.b[n_I:] - system.M_IG.T @ X[:, n_G:]
    return system.skel, S, c, _CellElimination(system, lu, np.ascontiguousarray(X[:, n_G:]))


def _skeleton_columns(
    topo: Topology, skeleton: tuple, cells: np.ndarray, G: np.ndarray
) -> tuple[sp.csr_matrix, np.ndarray]:
    """T_Γ (|G| × n): the functions of X_h(ω) (``local_stress_space`` of the fine cells ω) on the skeleton DOFs G
    of ω: the AW functions of the skeleton vertices and edges inside ω, the inner-boundary vertex functions
    (null-space values z) of the skeleton vertices on ∂ω or on a traction-free side; edges there are dropped.
    Also returns the inner DOFs (sorted global AW DOFs; column k < |inner| of T_Γ is the unit vector of inner[k])."""
    v_in = np.bincount(topo.c2v[cells].ravel(), minlength=topo.nv)
    e_in = np.bincount(topo.c2e[cells].ravel(), minlength=topo.ne)
    skel_v, skel_e = skeleton
    v_int = np.flatnonzero(skel_v & (v_in > 0) & (v_in == topo.v_deg) & ~topo.tf_vertex)
    v_bnd = np.flatnonzero(skel_v & (v_in > 0) & ((v_in < topo.v_deg) | topo.tf_vertex))
    e_int = np.flatnonzero(skel_e & (e_in > 0) & (e_in == topo.e_deg) & ~topo.tf_edge)
    e_bnd = np.flatnonzero(((e_in == 1) & (topo.e_deg == 2)) | ((e_in > 0) & topo.tf_edge))
    inner = np.concatenate(
        [(3 * v_int[:, None] + np.arange(3)).ravel(), (3 * topo.nv + 4 * e_int[:, None] + np.arange(4)).ravel()]
    )
    null, extra, ncol = boundary_vertex_null_spaces(topo, v_bnd, e_bnd, inner.size)
    kk, qq = np.nonzero(extra >= 0)
    rows = [np.searchsorted(G, inner)] + [np.searchsorted(G, 3 * v_bnd[kk] + i) for i in range(3)]
    cols = [np.arange(inner.size)] + [extra[kk, qq]] * 3
    vals = [np.ones(inner.size)] + [null[kk, i, qq] for i in range(3)]
    rows, cols, vals = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    keep = vals != 0.0
    return sp.csr_matrix((vals[keep], (rows[keep], cols[keep])), shape=(G.size, inner.size + ncol)), inner


def _skeleton_solve(
    ops: CellOperators,
    topo: Topology,
    grid: CoarseGrid,
    dofs: CoarseCellDofs,
    skeleton: tuple,
    condensed: list,
    i: int,
    layers: int,
    glob: "_GlobalSkeleton",
) -> tuple[np.ndarray, np.ndarray]:
    """The patch K_{i,m} condensed onto its skeleton: (skeleton AW DOFs G, their values (|G|, k) for coarse
    cell i's right-hand sides).  On the skeleton the patch space X_h(K_{i,m}) is T_Γ: the AW functions of
    the skeleton vertices and edges inside the patch and the inner-boundary vertex functions on its boundary
    (``local_stress_space``; the patch-boundary edge DOFs are dropped)."""
    patch = np.sort(np.asarray(grid.patch(i, layers), dtype=np.int64))
    G = np.unique(np.concatenate([condensed[j][0] for j in patch]))
    c = condensed[i][2]
    rhs = np.zeros((G.size, c.shape[1]))
    rhs[np.searchsorted(G, condensed[i][0])] = c
    TG, inner = _skeleton_columns(topo, skeleton, np.concatenate([dofs.cells[j] for j in patch]), G)
    if TG.shape[1] == 0:
        return G, np.zeros_like(rhs)
    lu, own = glob.factors.factor(glob.patch_matrix(G, TG, inner, [condensed[j][:2] for j in patch]))
    try:
        xs = lu.solve(np.asarray(TG.T @ rhs))
    finally:
        if own:
            lu.destroy()
    return G, np.asarray(TG @ xs)


def _patch_classes(grid: CoarseGrid, patches: list, condensed: list) -> np.ndarray:
    """A label per patch: patches with one label are translates of each other with the same number of skeleton
    DOFs on every coarse cell, which on a Cartesian grid gives them one skeleton sparsity pattern (h = 1/128,
    H = 1/16, m = 3: 81 patterns among 240 patches; ``ReusedAnalysis`` checks the pattern itself, a label
    only orders the work).  All labels distinct on a general partition (no ``grid.ij``)."""
    if grid.ij is None:
        return np.arange(len(patches), dtype=np.int64)
    labels: dict = {}
    out = np.empty(len(patches), dtype=np.int64)
    for i, p in enumerate(patches):
        rel = grid.ij[p] - grid.ij[i]
        key = tuple(sorted(zip(rel[:, 0].tolist(), rel[:, 1].tolist(), [condensed[j][0].size for j in p])))
        out[i] = labels.setdefault(key, len(labels))
    return out


class _GlobalSkeleton:
    """Σ_K S_K over all coarse cells of Ω₁ (upper triangle, canonical CSR, on the sorted skeleton DOFs ``dofs``).

    A patch skeleton matrix T_Γᵀ (Σ_{K in the patch} S_K) T_Γ takes its inner block from here: an inner DOF of
    a patch lies on a skeleton vertex or edge all of whose coarse cells are in the patch, so every entry in an
    inner row has all its contributions from patch cells.  Only the columns of the patch-boundary vertex
    functions (null-space combinations, a few dozen) are summed from the patch's own cells.
    """

    def __init__(self, condensed: list) -> None:
        #: the patch skeleton factorizations, reusing MUMPS' analysis per pattern: a third of MUMPS' time on a
        #: 4.7·10³ skeleton at h = 1/128 (116 ms with the analysis, 75 ms without).  The patches of one class
        #: (``_patch_classes``: translates, e.g. all interior patches of a structured mesh) share one pattern and
        #: come one after the other (serially grouped by class; in the cost order of ``work.run_balanced``, where
        #: a class's patches have one cost and classes of equal cost are kept apart).
        self.factors = ReusedAnalysis(keep=2, factor_class=LocalFactor)
        self.dofs = np.unique(np.concatenate([c[0] for c in condensed]))
        n = self.dofs.size
        rows, cols, vals = [], [], []
        for skel, S, *_ in condensed:
            pos = np.searchsorted(self.dofs, skel)  # skel sorted: the local upper triangle is the global one
            iu, ju = np.triu_indices(pos.size)
            rows.append(pos[iu])
            cols.append(pos[ju])
            vals.append(S[iu, ju])
        self.upper = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
        self.upper.sum_duplicates()

    def patch_matrix(self, G: np.ndarray, TG: sp.csr_matrix, inner: np.ndarray, blocks: list) -> sp.csr_matrix:
        """Upper triangle (canonical CSR) of T_Γᵀ (Σ_K S_K) T_Γ for a patch with skeleton DOFs G, T_Γ and inner
        DOFs from ``_skeleton_columns`` and its cells' ``blocks`` = [(skeleton DOFs of K, S_K)]."""
        pos = np.searchsorted(self.dofs, inner)
        A = self.upper[pos][:, pos]  # the inner block (pos increasing: still upper triangular)
        A.sum_duplicates()  # canonical for PETSc (SciPy checks first: no sort when already sorted)
        n_I, n_B = inner.size, TG.shape[1] - inner.size
        if n_B == 0:
            return A
        NB = TG[:, n_I:].tocsr()  # the boundary vertex functions on G (a few hundred columns, ≤ 3 rows each)
        on_b = np.diff(NB.indptr) > 0
        rows_x, cols_x, vals_x = [], [], []
        for skel, S in blocks:  # (Σ_K S_K) N_B, from the cells touching the patch boundary
            rows = np.searchsorted(G, skel)
            b = on_b[rows]
            if b.any():
                Nk = NB[rows[b]]
                cols = np.unique(Nk.indices)
                Nk = sp.csr_matrix(
                    (Nk.data, np.searchsorted(cols, Nk.indices), Nk.indptr), shape=(Nk.shape[0], cols.size)
                )
                rows_x.append(np.repeat(rows, cols.size))
                cols_x.append(np.tile(cols, rows.size))
                vals_x.append(np.asarray(Nk.T @ S[b]).T.ravel())  # S[:, b] N_k (S symmetric)
        X = sp.csr_matrix(
            (np.concatenate(vals_x), (np.concatenate(rows_x), np.concatenate(cols_x))), shape=(G.size, n_B)
        )
        BB = (NB.T @ X).toarray()
        A = sp.bmat(
            [[A, X[np.searchsorted(G, inner)]], [None, sp.csr_matrix(np.triu(0.5 * (BB + BB.T)))]], format="csr"
        )
        A.sum_duplicates()  # sorts the indices too: canonical for PETSc
        return A


def _cell_values(elim: _CellElimination, K: int, reach: list, values: list) -> dict:
    """Back substitution on coarse cell K for every patch i reaching it: {i: (AW coefficients on K (|aw_K|, k_i),
    displacements (6|K|, k_i))}, x_I = M_II⁻¹(b_I δ_{iK} − M_IΓ x_Γ) with K's kept LU."""
    xg = [values[i][1][np.searchsorted(values[i][0], elim.skel)] for i in reach]
    widths = np.array([x.shape[1] for x in xg])
    XG = np.hstack(xg)
    rhs = -np.asarray(elim.M_IG @ XG)
    start = np.concatenate([[0], np.cumsum(widths)])
    XI = elim.lu.solve(rhs)
    if K in reach:  # K's own right-hand sides
        q = reach.index(K)
        XI[:, start[q] : start[q + 1]] += elim.own
    A = np.asarray(elim.WI @ XI[: elim.n_s])  # AW coefficients on K, all patches in one product
    A[elim.gpos] += XG
    U = XI[elim.n_s : elim.n_s + elim.n_u]
    cols = [slice(start[q], start[q + 1]) for q in range(len(reach))]  # contiguous pieces: sent out of band by MPI
    return {int(i): (np.ascontiguousarray(A[:, c]), np.ascontiguousarray(U[:, c])) for i, c in zip(reach, cols)}


def _columns(x: np.ndarray | None, cols: slice) -> np.ndarray | None:
    """A contiguous copy of the columns ``cols`` of a patch-function piece (None: held by another rank)."""
    return None if x is None else np.ascontiguousarray(x[:, cols])


def _stage_two_condensed(
    ops: CellOperators,
    topo: Topology,
    grid: CoarseGrid,
    dofs: CoarseCellDofs,
    aux: StageI,
    layers: int,
    source: bool,
    comm: MPI.Comm,
    distributed: bool = False,
) -> tuple[list[PatchFunctions], list[PatchFunctions]]:
    """Stage II by static condensation (a substructuring of every patch along the coarse skeleton).

    A patch system is the sum of its coarse cells' blocks (``_cell_system``), coupled only through the
    skeleton DOFs.  1. Each coarse cell's owned unknowns are eliminated once (Schur complement S_K on its
    skeleton, and its own right-hand sides condensed); 2. each patch factorizes only its skeleton system
    Σ_K T_Γᵀ S_K T_Γ (a few thousand unknowns instead of 10⁵ at h = 1/128); 3. the owned unknowns are
    recovered coarse cell by coarse cell, for all patches reaching it in one multi-right-hand-side solve.
    Exact (the same linear systems as one LU per patch, up to rounding).
    """
    skeleton = _skeleton_entities(topo, grid)
    skel_aw = _skeleton_aw(topo, skeleton)
    size = _cell_cost(dofs)
    patches = [np.sort(np.asarray(grid.patch(i, layers), dtype=np.int64)) for i in range(grid.size)]
    kept: dict[int, _CellElimination] = {}  # this rank's coarse cells: condensed here, recovered here (cell_owner)
    held = 0  # bytes in ``kept``

    def condense(K: int) -> tuple:
        nonlocal held
        skel, S, c, elim = _condense(_cell_system(ops, topo, dofs, aux, skeleton, skel_aw, K, source), ops.scale)
        nbytes = elim.nbytes
        if held + nbytes <= KEEP_FACTORS_BYTES:
            kept[K] = elim
            held += nbytes
        else:
            elim.destroy()
        return skel, S, c

    def recover(K: int) -> dict:
        elim = kept.pop(K, None)
        if elim is None:  # not kept (KEEP_FACTORS_BYTES): assembled and factorized again
            system = _cell_system(ops, topo, dofs, aux, skeleton, skel_aw, K, source)
            elim = _CellElimination.factorized(system, ops.scale)
        try:
            return _cell_values(elim, K, reach[K], values)  # noqa: F821 (bound before recover runs; deleted after)
        finally:
            elim.destroy()

    try:
        cell_owner = np.empty(grid.size, dtype=np.int64)  # who condensed K keeps its LU: it back-substitutes K
        condensed = work.run_shared(
            size, comm, "mixed CEM Stage II (coarse cells)", condense, balanced=True, owner=cell_owner, logger=log
        )
        cost = np.array([sum(condensed[j][0].size for j in p) for p in patches], dtype=float)
        # patches of one class one after the other (MUMPS' analysis reused: ``ReusedAnalysis``); a class's
        # patches have one cost, so a relative 1e-9 per class label groups them in the cost order of MPI too
        label = _patch_classes(grid, patches, condensed)
        glob = _GlobalSkeleton(condensed)
        try:
            values = work.run_shared(
                cost**1.5 * (1.0 + 1e-9 * label / max(len(patches), 1)),
                comm,
                "mixed CEM Stage II (patch skeletons)",
                lambda i: _skeleton_solve(ops, topo, grid, dofs, skeleton, condensed, i, layers, glob),  # noqa: F821
                balanced=True,
                items=np.lexsort((np.arange(label.size), label)) if comm.size == 1 else None,
                logger=log,
            )
        finally:
            glob.factors.release()
        del glob, condensed
        reach = [[] for _ in range(grid.size)]
        for i, p in enumerate(patches):
            for K in p:
                reach[int(K)].append(i)
        parts = work.run_shared(
            size,
            comm,
            "mixed CEM Stage II (back substitution)",
            recover,
            gather=not distributed,
            items=np.flatnonzero(cell_owner == comm.rank),
            logger=log,
        )
        if distributed and comm.size > 1:  # pieces for the coarse cells this rank recovered (``held_cells``) only
            parts = [parts.get(K) for K in range(grid.size)]
    finally:
        for elim in kept.values():  # left over only after a failure
            elim.destroy()
    del values
    n_g = ops.num_gamma_values
    basis, corr = [], []
    for i, p in enumerate(patches):
        li = aux.modes[i].shape[2]
        pieces = [(None, None) if parts[int(K)] is None else parts[int(K)].pop(i) for K in p]
        held_here = next((a for a, _ in pieces if a is not None), None)  # (distributed: some pieces are elsewhere)
        width = None if held_here is None else held_here.shape[1]
        first, rest = slice(0, li), slice(li, None)
        basis.append(
            PatchFunctions(
                p,
                aux.offsets[i] + np.arange(li),
                [_columns(a, first) for a, _ in pieces],
                [_columns(u, first) for _, u in pieces],
            )
        )
        cK = dofs.cells[i]
        gcols = np.unique(ops.C[cell_rows(cK, 30)].indices)
        load = _has_load(ops, cK, source)
        n_corr = gcols.size + int(load)
        if width is not None and width != li + n_corr:
            raise RuntimeError(f"patch {i}: {width} back-substituted columns, expected {li} + {n_corr}")
        if n_corr == 0:
            corr.append(None)
            continue
        corr.append(
            PatchFunctions(
                p,
                np.concatenate([gcols, [n_g]]) if load else gcols,
                [_columns(a, rest) for a, _ in pieces],
                [_columns(u, rest) for _, u in pieces],
            )
        )
    return basis, corr


def stage_two(
    ops: CellOperators,
    topo: Topology,
    grid: CoarseGrid,
    aux: StageI,
    layers: int,
    source: bool = True,
    *,
    dofs: CoarseCellDofs | None = None,
    comm: MPI.Comm = MPI.COMM_SELF,
    distributed: bool = False,
) -> tuple[list[PatchFunctions], list[PatchFunctions]]:
    """Basis functions ψ_j^i (index = aux index) and data correctors (index = data index), per coarse cell.

    The data are d = [g; 1]: the γ values g (index 0..n_g−1; Robin correctors Q_i, N_i on the
    patches of the coarse cells touching γ) and, with ``source``, the load (index n_g; the source
    correctors of the coarse cells where f ≠ 0).  ``corr[i]`` is None for a cell with neither.
    Under ``comm`` the patches are shared out (``work.run_shared``) and every rank gets all results; with
    ``distributed`` each rank keeps only the pieces on its ``held_cells`` (no gather of the functions).
    """
    dofs = dofs or CoarseCellDofs.of(ops, grid)
    return _stage_two_condensed(ops, topo, grid, dofs, aux, layers, source, comm, distributed)


def _cell_cost(dofs: CoarseCellDofs) -> np.ndarray:
    """The estimated cost of a coarse cell's condensation and back substitution: |K|^1.5."""
    return np.array([len(c) for c in dofs.cells], dtype=float) ** 1.5


def held_cells(basis: list[PatchFunctions]) -> np.ndarray:
    """The coarse cells K whose pieces this rank holds (all, unless ``stage_two(distributed=True)`` under MPI):
    those where the basis of K's own patch has its piece on K."""
    return np.array(
        [i for i, f in enumerate(basis) if f.sigma[int(np.searchsorted(f.coarse, i))] is not None], dtype=np.int64
    )
