"""Test oracles of the multiscale methods: independent, slower computations that the package's fast paths match.

``stage_two_reference``: Stage II of the mixed CEM-GMsFEM (Algorithm 4) with one sparse LU of each whole patch
system (the bases ψ_j^i and the Robin and source correctors of every coarse cell i on K_{i,m}),
against which the package's static condensation onto the coarse skeleton (``mixed_cem.stage_two``) is checked.
"""

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

from fenics_contact.multiscale.mixed_cem.bases import CoarseCellDofs, PatchFunctions, patch_system
from fenics_contact.multiscale.mixed_cem.blocks import cell_rows
from fenics_contact.multiscale.mixed_cem.local_space import aw_map
from fenics_contact.multiscale.work import run_shared

__all__ = ["stage_two_reference"]


def stage_two_reference(
    ops,
    topo,
    grid,
    aux,
    layers: int,
    source: bool = True,
    *,
    dofs: CoarseCellDofs | None = None,
    comm: MPI.Comm = MPI.COMM_SELF,
    distributed: bool = False,
) -> tuple[list[PatchFunctions], list[PatchFunctions]]:
    """``mixed_cem.stage_two`` with one sparse LU of the whole saddle-point system per patch (every rank gets every
    function, ``distributed`` or not): the same linear systems as the static condensation of the package."""
    dofs = dofs or CoarseCellDofs.of(ops, grid)
    cost = np.array([sum(len(grid.cells[j]) for j in grid.patch(i, layers)) for i in range(grid.size)], dtype=float)
    out = run_shared(
        cost**1.5,
        comm,
        "mixed CEM Stage II (patches)",
        lambda i: _patch_functions(ops, topo, grid, dofs, aux, i, layers, source),
    )
    return [b for b, _ in out], [c for _, c in out]


def _split_by_coarse(
    dofs: CoarseCellDofs,
    patch: np.ndarray,
    space,
    aw: np.ndarray,
    T: sp.csr_matrix,
    x: np.ndarray,
    n_loc: int,
    n_u: int,
) -> tuple[list, list]:
    """Patch solutions x → per coarse cell of the patch: (AW coefficients, displacements); T = aw_map(space, aw)."""
    a = T @ x[:n_loc]
    xu = x[n_loc : n_loc + n_u]
    sig, dis = [], []
    for j in patch:
        sig.append(np.ascontiguousarray(a[np.searchsorted(aw, dofs.aw[j])]))
        dis.append(np.ascontiguousarray(xu[cell_rows(np.searchsorted(space.cells, dofs.cells[j]), 6)]))
    return sig, dis


def _patch_functions(
    ops, topo, grid, dofs: CoarseCellDofs, aux, i: int, layers: int, source: bool
) -> tuple[PatchFunctions, PatchFunctions | None]:
    """The Stage II basis functions ψ_j^i and the data correctors of coarse cell i on K_{i,m}."""
    n_g = ops.num_gamma_values
    patch = np.sort(np.asarray(grid.patch(i, layers), dtype=np.int64))
    space, lu, Z, aux_cols, n_loc, n_u = patch_system(ops, topo, grid, aux, patch)
    try:
        n_tot = n_loc + n_u + Z.shape[1]
        li = aux.modes[i].shape[2]
        ci = dofs.cells[i]
        pos = np.searchsorted(space.cells, ci)
        c0 = aux_cols[int(i)]
        # Robin data on γ ∩ ∂K_i: C_i g in the τ rows, mapped to the local basis through the AW coefficients
        Ci = ops.C[cell_rows(ci, 30)]
        gcols = np.unique(Ci.indices)
        load = source and bool(np.any(ops.G[ci] != 0.0) or (ops.F is not None and np.any(ops.F[ci] != 0.0)))
        nd = gcols.size + int(load)
        rhs = np.zeros((n_tot, li + nd))
        rhs[n_loc : n_loc + n_u, :li] = -Z[:, c0 : c0 + li].toarray()
        aw = np.unique(np.concatenate([dofs.aw[j] for j in patch]))  # the AW functions touching the patch
        T = aw_map(space, aw)
        if gcols.size:
            Caw = dofs.P(ops, i).T @ Ci[:, gcols]  # (|aw_K_i|, n) sparse
            rhs[:n_loc, li : li + gcols.size] = (T[np.searchsorted(aw, dofs.aw[i])].T @ Caw).toarray()
        if load:
            # −(div ψ, v) + s(πq, πv) = (f χ_{K_i}, v): Bψ − Zy = −F_i = G on K_i
            rhs[n_loc + cell_rows(pos, 6), -1] = ops.G[ci].ravel()
            if ops.F is not None:  # the boundary data's stress-side load F|K_i in the τ rows
                rhs[:n_loc, -1] = T[np.searchsorted(aw, dofs.aw[i])].T @ (dofs.P(ops, i).T @ ops.F[ci].ravel())
        sol = lu.solve(rhs)
    finally:
        lu.destroy()
    sig, dis = _split_by_coarse(dofs, patch, space, aw, T, sol, n_loc, n_u)
    basis = PatchFunctions(patch, aux.offsets[i] + np.arange(li), [s[:, :li] for s in sig], [d[:, :li] for d in dis])
    if not nd:
        return basis, None
    index = np.concatenate([gcols, [n_g]]) if load else gcols
    corr = PatchFunctions(
        patch, index, [np.ascontiguousarray(s[:, li:]) for s in sig], [np.ascontiguousarray(d[:, li:]) for d in dis]
    )
    return basis, corr
