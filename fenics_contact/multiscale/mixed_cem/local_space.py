"""The local stress spaces X_h(ω) of the mixed CEM (Algorithm 4), cell by cell, and their local operators.

For fine cells ω (a coarse cell or an oversampled patch), X_h(ω) = {τ ∈ AW(ω) : τn = 0 on ∂ω ∩ Ω₁° and on
the traction-free sides of Ω₁}: the AW functions supported in ω plus, at each inner-boundary vertex, the
restrictions of the AW vertex functions with values z in the null space of τ ↦ τn (``Topology`` holds the
incidences and the raw AW numbering).  A basis is kept cell by cell (L_c = P_c T_c), so Lᵀ Ã L and B L are
assembled from dense cell blocks like element matrices (``local_triplets``, ``local_operators``).
"""

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from dolfinx import mesh as dmesh

from fenics_contact.errors import InputError
from fenics_contact.multiscale.mixed_cem.operators import CellOperators

__all__ = [
    "LocalSpace",
    "Topology",
    "aw_map",
    "boundary_vertex_null_spaces",
    "local_operators",
    "local_stress_space",
    "local_triplets",
]


class Topology:
    """Vertex/edge/cell incidences of Ω₁ and the raw AW numbering (3 per vertex, 4 per edge, 3 per cell).

    ``traction_free_facets``: edges of ∂Ω₁ with the essential condition τn = 0 (traction-free sides);
    every local space treats them like its inner boundary (``local_stress_space``).
    """

    def __init__(self, msh: dmesh.Mesh, num_aw: int, traction_free_facets: np.ndarray | None = None) -> None:
        top = msh.topology
        for d0, d1 in ((2, 0), (2, 1), (1, 0), (1, 2), (0, 2)):
            top.create_connectivity(d0, d1)
        self.nc = top.index_map(2).size_local
        self.nv = top.index_map(0).size_local
        self.ne = top.index_map(1).size_local
        if num_aw != 3 * self.nv + 4 * self.ne + 3 * self.nc:
            raise RuntimeError(
                "the local spaces are built on the unconstrained AW numbering of Ω₁ (cell_operators "
                "takes care of that); essential τn = 0 sides enter through traction_free_facets"
            )
        self.c2v = top.connectivity(2, 0).array.reshape(-1, 3)[: self.nc].astype(np.int64)
        self.c2e = top.connectivity(2, 1).array.reshape(-1, 3)[: self.nc].astype(np.int64)
        self.e2v = top.connectivity(1, 0).array.reshape(-1, 2).astype(np.int64)
        self.v_deg = np.bincount(self.c2v.ravel(), minlength=self.nv)
        self.e_deg = np.bincount(self.c2e.ravel(), minlength=self.ne)
        x = msh.geometry.x[:, :2]
        vx = np.empty((self.nv, 2))
        vx[self.c2v.ravel()] = x[msh.geometry.dofmaps[0][: self.nc].ravel()]
        self.vx = vx
        self.tf_edge = np.zeros(self.ne, dtype=bool)
        if traction_free_facets is not None and len(traction_free_facets):
            tf = np.asarray(traction_free_facets, dtype=np.int64)
            if np.any(self.e_deg[tf] != 1):
                raise InputError("traction-free facets must lie on the boundary of Ω₁")
            self.tf_edge[tf] = True
        self.tf_vertex = np.zeros(self.nv, dtype=bool)
        self.tf_vertex[self.e2v[self.tf_edge].ravel()] = True


@dataclass(slots=True)
class LocalSpace:
    """X_h(ω) on fine cells ω (sorted), cell by cell: on cell c the basis is L_c = blocks[c] (30 × w).

    Column s of L_c is the restriction to c of local basis function cols[c, s] (−1: padding, a zero
    column); the basis L (30|ω| × size) stacks these blocks in the cell-major rows of ω.
    """

    cells: np.ndarray
    blocks: np.ndarray  #: (|ω|, 30, w)
    cols: np.ndarray  #: (|ω|, w) local column of each block column, −1 for none
    size: int  #: dim X_h(ω)
    num_extra: int  #: inner-boundary vertex functions (not in AW(Ω₁))
    aw_inner: np.ndarray  #: the AW function of each of the first size − num_extra local columns
    extra_vertex: np.ndarray  #: the vertex v of each inner-boundary vertex function (the last num_extra)
    extra_z: np.ndarray  #: (num_extra, 3): its value z, i.e. the function is Σ_i z_i (AW function 3v + i) on ω

    @property
    def L(self) -> sp.csr_matrix:
        """The basis as a sparse matrix (30|ω| × dim X_h(ω)) in the cell-major rows of ω."""
        nc, a, _ = self.blocks.shape
        rows = np.broadcast_to((a * np.arange(nc)[:, None] + np.arange(a))[:, :, None], self.blocks.shape)
        cols = np.broadcast_to(self.cols[:, None, :], self.blocks.shape)
        keep = (cols >= 0) & (self.blocks != 0.0)
        return sp.csr_matrix((self.blocks[keep], (rows[keep], cols[keep])), shape=(a * nc, self.size))

    def apply(self, x: np.ndarray) -> np.ndarray:
        """L x for coefficients x (size, k), cell-major (|ω|, 30, k)."""
        xc = np.where((self.cols >= 0)[:, :, None], x[np.maximum(self.cols, 0)], 0.0)  # (|ω|, w, k)
        return self.blocks @ xc


def boundary_vertex_null_spaces(
    topo: Topology, v_bnd: np.ndarray, e_bnd: np.ndarray, first: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """Null spaces of τ ↦ τn at the inner-boundary vertices ``v_bnd`` (sorted) for the normals of their
    inner-boundary edges ``e_bnd``: (null (|v_bnd|, 3, 3) with null[k][:, q] = z_q, the local column of
    each z_q (−1: none) numbered from ``first``, the number of columns).

    No edge: all of R³ (z = e_x, e_y, e_z); parallel normals n: z = t⊗t (σ_tt free, t ⊥ n, unit
    norm in (xx, xy, yy)); two directions (a corner of ω): nothing.
    """
    nv = v_bnd.size
    null = np.zeros((nv, 3, 3))
    extra = np.full((nv, 3), -1, dtype=np.int64)
    if nv == 0:
        return null, extra, 0
    a, b = topo.vx[topo.e2v[e_bnd, 0]], topo.vx[topo.e2v[e_bnd, 1]]
    d = (b - a) / np.linalg.norm(b - a, axis=1)[:, None]
    normal = np.stack([d[:, 1], -d[:, 0]], axis=1)
    vert = topo.e2v[e_bnd].ravel()  # (2E,) each edge's two vertices
    nrm = np.repeat(normal, 2, axis=0)
    k = np.searchsorted(v_bnd, vert)
    inside = (k < nv) & (v_bnd[np.minimum(k, nv - 1)] == vert)
    k, nrm = k[inside], nrm[inside]
    count = np.bincount(k, minlength=nv)
    first_normal = np.zeros((nv, 2))
    first_normal[k[::-1]] = nrm[::-1]  # any one normal per vertex
    cross = np.abs(first_normal[k, 0] * nrm[:, 1] - first_normal[k, 1] * nrm[:, 0])
    bent = np.bincount(k, weights=(cross > 1e-10).astype(float), minlength=nv) > 0
    ncols = np.where(count == 0, 3, np.where(bent, 0, 1))
    free = count == 0
    null[free] = np.eye(3)
    line = (count > 0) & ~bent
    n0, n1 = first_normal[line, 0], first_normal[line, 1]
    z = np.stack([n1 * n1, -n0 * n1, n0 * n0], axis=1)
    z /= np.linalg.norm(z, axis=1)[:, None]
    null[line, :, 0] = np.where(np.abs(z) < 1e-14, 0.0, z)
    start = first + np.concatenate([[0], np.cumsum(ncols)[:-1]])
    for q in range(3):
        has = ncols > q
        extra[has, q] = start[has] + q
    return null, extra, int(ncols.sum())


def local_stress_space(
    ops: CellOperators,
    topo: Topology,
    cells: np.ndarray,
    raw: tuple[np.ndarray, np.ndarray] | None = None,
) -> LocalSpace:
    """Basis of {τ ∈ AW(ω) : τn = 0 on ∂ω ∩ Ω₁° and on the traction-free sides} in the cell-major layout of ω.

    ``raw``: masks (vertices, edges) whose AW functions are kept unconstrained (restricted to ω) wherever they
    lie (the skeleton unknowns of a coarse cell in the Stage II condensation, ``skeleton``).
    """
    cells = np.sort(np.asarray(cells, dtype=np.int64))
    v_in = np.bincount(topo.c2v[cells].ravel(), minlength=topo.nv)
    e_in = np.bincount(topo.c2e[cells].ravel(), minlength=topo.ne)
    raw_v, raw_e = raw if raw is not None else (np.zeros(topo.nv, dtype=bool), np.zeros(topo.ne, dtype=bool))
    v_int = np.flatnonzero((v_in > 0) & (((v_in == topo.v_deg) & ~topo.tf_vertex) | raw_v))
    v_bnd = np.flatnonzero((v_in > 0) & ((v_in < topo.v_deg) | topo.tf_vertex) & ~raw_v)
    e_int = np.flatnonzero((e_in > 0) & (((e_in == topo.e_deg) & ~topo.tf_edge) | raw_e))
    e_bnd = np.flatnonzero((((e_in == 1) & (topo.e_deg == 2)) | ((e_in > 0) & topo.tf_edge)) & ~raw_e)
    nv, ne = topo.nv, topo.ne
    inner = np.concatenate(
        [
            (3 * v_int[:, None] + np.arange(3)).ravel(),
            (3 * nv + 4 * e_int[:, None] + np.arange(4)).ravel(),
            (3 * nv + 4 * ne + 3 * cells[:, None] + np.arange(3)).ravel(),
        ]
    )
    # AW functions supported in ω: columns of P, by cell
    local = np.full(ops.num_aw, -1, dtype=np.int64)
    local[inner] = np.arange(inner.size)
    pcols = ops.P_cols[cells]
    cols = np.where(pcols >= 0, local[np.maximum(pcols, 0)], -1)
    blocks = ops.P_blocks[cells].copy()
    null, extra, ncol = boundary_vertex_null_spaces(topo, v_bnd, e_bnd, inner.size)
    if v_bnd.size:
        # the block columns of 3v, 3v+1, 3v+2 (consecutive: P_cols is sorted) become
        # L_c[:, q] = Σ_i P_c[:, 3v+i] z_q[i]
        vert = np.where((pcols >= 0) & (pcols < 3 * nv) & (pcols % 3 == 0), pcols // 3, -1)
        kpos = np.minimum(np.searchsorted(v_bnd, vert), v_bnd.size - 1)
        ci, si = np.nonzero((vert >= 0) & (v_bnd[kpos] == vert))
        ki = kpos[ci, si]
        slots = si[:, None] + np.arange(3)
        expected = 3 * v_bnd[ki][:, None] + np.arange(3)
        if np.any(slots >= pcols.shape[1]) or np.any(pcols[ci[:, None], slots] != expected):
            raise RuntimeError("an AW vertex function is missing from a cell block")
        vals = blocks[ci[:, None], :, slots]  # (m, 3 (i), 30)
        blocks[ci[:, None], :, slots] = np.einsum("mia,miq->mqa", vals, null[ki])
        cols[ci[:, None], slots] = extra[ki]
    kk, qq = np.nonzero(extra >= 0)  # row-major: in the order of the extra columns
    return LocalSpace(cells, blocks, cols, int(inner.size + ncol), ncol, inner, v_bnd[kk], null[kk, :, qq])


def _local_blocks(ops: CellOperators, space: LocalSpace) -> tuple[np.ndarray, np.ndarray]:
    """Cell blocks L_cᵀ Ã_c L_c (|ω|, w, w) and B_c L_c (|ω|, 6, w) of the local operators."""
    Lb = space.blocks
    At = np.swapaxes(Lb, 1, 2) @ (ops.kt(space.cells) @ Lb)
    Bl = ops.B[space.cells] @ Lb
    return At, Bl


def local_triplets(ops: CellOperators, space: LocalSpace) -> tuple[tuple, tuple]:
    """COO triplets (rows, cols, values) of Ã = Lᵀ Ã L and B L on X_h(ω) × U_h(ω) (duplicates to be summed)."""
    At, Bl = _local_blocks(ops, space)
    nc = space.cols.shape[0]
    cols, valid = space.cols, space.cols >= 0
    both = valid[:, :, None] & valid[:, None, :]
    r = np.broadcast_to(cols[:, :, None], At.shape)[both]
    c = np.broadcast_to(cols[:, None, :], At.shape)[both]
    a_trip = (r, c, At[both])
    u_rows = np.broadcast_to((6 * np.arange(nc)[:, None] + np.arange(6))[:, :, None], Bl.shape)
    bv = np.broadcast_to(valid[:, None, :], Bl.shape)
    b_trip = (u_rows[bv], np.broadcast_to(cols[:, None, :], Bl.shape)[bv], Bl[bv])
    return a_trip, b_trip


def local_operators(ops: CellOperators, space: LocalSpace) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """(Ã, B) of X_h(ω) × U_h(ω): Lᵀ Kt L and B L, assembled from the cell blocks."""
    (ar, ac, av), (br, bc, bv) = local_triplets(ops, space)
    n = space.size
    At = sp.csr_matrix((av, (ar, ac)), shape=(n, n))
    Bl = sp.csr_matrix((bv, (br, bc)), shape=(6 * space.cells.size, n))
    for X in (At, Bl):
        X.eliminate_zeros()
    return At, Bl


def aw_map(space: LocalSpace, aw: np.ndarray) -> sp.csr_matrix:
    """(|aw| × dim X_h(ω)): AW coefficients (on the sorted DOFs ``aw``) of the local basis functions.

    Inner functions are AW functions (one coefficient 1); an inner-boundary vertex function with
    value z is Σ_i z_i (AW function 3v + i) restricted to ω.
    """
    rows = [np.searchsorted(aw, space.aw_inner)]
    cols = [np.arange(space.aw_inner.size)]
    vals = [np.ones(space.aw_inner.size)]
    if space.num_extra:
        ext = space.aw_inner.size + np.arange(space.num_extra)
        for i in range(3):
            rows.append(np.searchsorted(aw, 3 * space.extra_vertex + i))
            cols.append(ext)
            vals.append(space.extra_z[:, i])
    rows, cols, vals = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    keep = vals != 0.0
    return sp.csr_matrix((vals[keep], (rows[keep], cols[keep])), shape=(aw.size, space.size))
