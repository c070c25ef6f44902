"""Lowest-order conforming Arnold–Winther stress space on triangles for DOLFINx.

The Arnold–Winther (AW) element [Arnold & Winther 2002] is the space of symmetric
2x2 tensors that are cubic on each triangle and whose divergence is linear,

    X_T = {σ ∈ P3(T; S) : div σ ∈ P1(T; R²)},   dim X_T = 24,

glued together so that the normal traction σn is continuous across edges
(H(div)-conforming, strongly symmetric).  Its 24 local degrees of freedom are

* at each vertex the three Cartesian components σ_xx, σ_xy, σ_yy (9),
* on each edge e the averages (1/|e|)∫_e σn·n q ds and (1/|e|)∫_e σn·t q ds
  for q ∈ {1, 2s-1}, s ∈ [0, 1] the arc-length parameter of e from its lower to
  its higher *global* vertex number, t the unit tangent in that direction and
  n = (t_y, -t_x) (12),
* the three cell averages (1/|T|)∫_T σ_ij dx (3).

Edge moments are normalised by |e| (they are averages) so that every DOF has
the size of a stress value; this keeps the local 24x24 systems well conditioned.

basix does not ship the element (it is not affine-equivalent), so forms are
written on a discontinuous vector P3 space ``dg`` holding (σ_xx, σ_xy, σ_yy),
and a sparse *prolongation* matrix ``P`` maps AW coefficients to DG
coefficients.  For every cell the local nodal basis is computed in physical
coordinates from a spanning set in scaled coordinates ξ = (x - x_T)/h_T:
18 symmetric P2 tensors plus the 6 Airy stresses curl curl(ξ^a η^b), a+b = 5
(homogeneous cubic, divergence-free), which together span exactly X_T.  The
AW matrices are then Pᵀ A P, B P, Pᵀ b.

Essential conditions σn·t = 0 and σn = 0 on straight facets are imposed by
removing columns of ``P`` (edge moments dropped; vertex values restricted to
the null space of the vertex constraints, which also handles corners).  A
prescribed traction σn = t on some of the σn = 0 facets is a *lifting*: a
fixed stress σ_t (``lifting_dg``) whose edge moments are those of t and whose
vertex values solve the stacked vertex constraints with right-hand side t
(least squares where the data of two edges meeting at a corner disagree), so
that the stress is σ = P c + σ_t with c free.

Serial and distributed meshes (any number of MPI ranks) of affine triangles are
supported: the numbering, constraints and P are built as described in
:class:`ArnoldWintherSpace`; the operators are distributed PETSc matrices.
"""

from __future__ import annotations

try:  # the dolfinx-solver wheels need this import before dolfinx/petsc4py
    import dolfinx_solver  # noqa: F401
except ImportError:  # pragma: no cover - a source/conda DOLFINx needs nothing
    pass

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import basix
import basix.ufl
import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh
import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.fem.distributed import SaddlePointMatrix
from fenics_contact.fem.distributed import local_rows_to_petsc as _local_rows_to_petsc
from fenics_contact.fem.distributed import offsets as _offsets
from fenics_contact.fem.distributed import owner_of as _owner_of
from fenics_contact.fem.distributed import scatter_to_ghosts as _scatter_to_ghosts

__all__ = [
    "ArnoldWintherSpace",
    "MixedElasticitySolution",
    "compliance",
    "lame_parameters",
    "local_nodal_basis",
    "solve_mixed_elasticity",
    "solve_saddle_point",
    "symmetric_tensor",
]

# ---------------------------------------------------------------------------
# Reference data
# ---------------------------------------------------------------------------

#: Local edge k of the basix reference triangle joins these local vertices.
_EDGE_VERTICES = np.array([[1, 2], [0, 2], [0, 1]], dtype=np.int64)
#: Monomials ξ^p η^q of degree ≤ 3.
_MONOMIALS = np.array([(p, d - p) for d in range(4) for p in range(d, -1, -1)], dtype=np.int64)
_NUM_LOCAL = 24


def _gauss_legendre_01(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre points/weights on [0, 1], weights summing to 1."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


_EDGE_S, _EDGE_W = _gauss_legendre_01(4)  # exact to degree 7 (integrand degree 4)
_CELL_Q, _CELL_W = basix.make_quadrature(basix.CellType.triangle, 6)
_CELL_W = _CELL_W / _CELL_W.sum()  # averages on the cell


def _span_coefficients() -> np.ndarray:
    """Monomial coefficients of the 24 spanning functions, shape (10, 3, 24).

    Entry [m, j, k]: coefficient of monomial m in component j ∈ (xx, xy, yy)
    of spanning function k.  Functions 0..17 are the symmetric P2 tensors, 18..23
    the Airy stresses [[φ_ηη, -φ_ξη], [-φ_ξη, φ_ξξ]] / 20 of φ = ξ^a η^(5-a).
    """
    index = {tuple(m): i for i, m in enumerate(_MONOMIALS)}
    C = np.zeros((len(_MONOMIALS), 3, _NUM_LOCAL))
    k = 0
    for m, (p, q) in enumerate(_MONOMIALS):
        if p + q <= 2:
            for j in range(3):
                C[m, j, k] = 1.0
                k += 1
    for a in range(6):
        b = 5 - a
        if b >= 2:  # σ_xx = ∂ηη φ
            C[index[(a, b - 2)], 0, k] = b * (b - 1) / 20.0
        if a >= 1 and b >= 1:  # σ_xy = -∂ξη φ
            C[index[(a - 1, b - 1)], 1, k] = -a * b / 20.0
        if a >= 2:  # σ_yy = ∂ξξ φ
            C[index[(a - 2, b)], 2, k] = a * (a - 1) / 20.0
        k += 1
    assert k == _NUM_LOCAL
    return C


_SPAN = _span_coefficients()


def _monomials(xi: np.ndarray) -> np.ndarray:
    """Monomials of degree ≤ 3 at scaled points ξ (..., 2) -> (..., 10), in ``_MONOMIALS`` order."""
    x, y = xi[..., 0], xi[..., 1]
    x2, y2 = x * x, y * y
    return np.stack([np.ones_like(x), x, y, x2, x * y, y2, x2 * x, x2 * y, x * y2, y2 * y], axis=-1)


def _span_of(mono: np.ndarray) -> np.ndarray:
    """Monomial coefficients (..., 10) -> values (..., 3, 24) of the spanning functions (one 2-D product)."""
    return (mono.reshape(-1, len(_MONOMIALS)) @ _SPAN.reshape(len(_MONOMIALS), -1)).reshape(
        mono.shape[:-1] + (3, _NUM_LOCAL))


def _eval_span(xi: np.ndarray) -> np.ndarray:
    """Spanning functions at scaled points ξ (..., 2) -> values (..., 3, 24)."""
    return _span_of(_monomials(xi))


def _edge_frames(start: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weights (..., 3) giving σn·n and σn·t from (σ_xx, σ_xy, σ_yy) on edges start→end."""
    d = end - start
    t = d / np.linalg.norm(d, axis=-1, keepdims=True)
    n = np.stack([t[..., 1], -t[..., 0]], axis=-1)
    wn = np.stack([n[..., 0] ** 2, 2.0 * n[..., 0] * n[..., 1], n[..., 1] ** 2], axis=-1)
    wt = np.stack(
        [n[..., 0] * t[..., 0], n[..., 0] * t[..., 1] + n[..., 1] * t[..., 0], n[..., 1] * t[..., 1]],
        axis=-1,
    )
    return wn, wt


def _edge_moments(values: np.ndarray, wn: np.ndarray, wt: np.ndarray) -> np.ndarray:
    """Edge DOFs from values (..., nq, 3, K) at the edge Gauss points -> (..., 4, K).

    Order: σn·n against 1, 2s-1, then σn·t against 1, 2s-1.
    """
    q = np.stack([_EDGE_W, _EDGE_W * (2.0 * _EDGE_S - 1.0)])  # (2, nq)
    snn = np.einsum("...j,...qjk->...qk", wn, values)
    snt = np.einsum("...j,...qjk->...qk", wt, values)
    return np.concatenate(
        [np.einsum("lq,...qk->...lk", q, snn), np.einsum("lq,...qk->...lk", q, snt)], axis=-2
    )


def _edge_points(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Gauss points on edges start→end: (..., 2) -> (..., nq, 2)."""
    return start[..., None, :] + _EDGE_S[:, None] * (end - start)[..., None, :]


def _map_to_cells(vertices: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Affine map of reference points (m, 2) into cells (n, 3, 2) -> (n, m, 2)."""
    v0 = vertices[:, 0, :]
    J = np.stack([vertices[:, 1] - v0, vertices[:, 2] - v0], axis=-1)  # (n, 2, 2)
    return v0[:, None, :] + np.einsum("nij,mj->nmi", J, ref)


#: cells per batch of ``local_nodal_basis`` (its temporaries, ~20 MB at 2048 cells, are reused from batch to batch
#: instead of growing with the mesh: fresh memory costs 2–4 s/GiB to touch on the virtual machines we run on)
NODAL_BASIS_BATCH = 2048


def local_nodal_basis(
    vertices: npt.NDArray[np.floating],
    edge_flip: npt.NDArray[np.bool_],
    points: npt.NDArray[np.floating],
    out: np.ndarray | None = None,
    column_order: np.ndarray | None = None,
) -> np.ndarray:
    """Values of the AW nodal basis of a batch of cells at reference points.

    φ_i ∈ X_T with ℓ_j(φ_i) = δ_ij, evaluated at x = F_T(points).

    Args:
        vertices: (n, 3, 2) physical vertex coordinates, basix local order.
        edge_flip: (n, 3) bool; True if local edge k (opposite vertex k) is
            oriented from its higher to its lower local vertex (the orientation
            must come from global vertex numbers so that neighbours agree).
        points: (m, 2) points on the reference triangle.

        out: optional (n, m, 3, 24) float64 array to write into.
        column_order: optional (n, 24): the basis functions of cell c in the order column_order[c] (out[c, …, k]
            is function column_order[c, k]).

    Returns:
        (n, m, 3, 24) array: component j ∈ (xx, xy, yy) of basis function i.
        Local DOF order: vertex v comp j -> 3v+j; edge k moment l -> 9+4k+l
        (l: nn·1, nn·(2s-1), nt·1, nt·(2s-1)); cell average comp j -> 21+j.
        Cells are done in batches of ``NODAL_BASIS_BATCH`` (each cell's numbers do not depend on the batch).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    edge_flip = np.asarray(edge_flip, dtype=bool)
    points = np.asarray(points, dtype=np.float64)
    n = vertices.shape[0]
    if out is None:
        out = np.empty((n, points.shape[0], 3, _NUM_LOCAL))
    for lo in range(0, n, NODAL_BASIS_BATCH):
        hi = min(n, lo + NODAL_BASIS_BATCH)
        batch = _nodal_basis_batch(vertices[lo:hi], edge_flip[lo:hi], points)
        if column_order is not None:
            batch = np.take_along_axis(batch, column_order[lo:hi, None, None, :], axis=3)
        out[lo:hi] = batch
    return out


def _nodal_basis_batch(vertices: np.ndarray, edge_flip: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``local_nodal_basis`` of one batch of cells."""
    n = vertices.shape[0]
    centre = vertices.mean(axis=1)  # (n, 2)
    edges = vertices[:, _EDGE_VERTICES[:, 1]] - vertices[:, _EDGE_VERTICES[:, 0]]
    h = np.linalg.norm(edges, axis=-1).max(axis=1)  # (n,)

    def scaled(x: np.ndarray) -> np.ndarray:
        shape = (n,) + (1,) * (x.ndim - 2) + (2,)
        return (x - centre.reshape(shape)) / h.reshape(shape[:-1] + (1,))

    D = np.empty((n, _NUM_LOCAL, _NUM_LOCAL))
    # vertex values
    D[:, 0:9, :] = _eval_span(scaled(vertices)).reshape(n, 9, _NUM_LOCAL)
    # edge moments, taken on the monomials first (10 numbers per moment, not 72 per Gauss point)
    a = np.where(edge_flip, _EDGE_VERTICES[:, 1], _EDGE_VERTICES[:, 0])  # (n, 3)
    b = np.where(edge_flip, _EDGE_VERTICES[:, 0], _EDGE_VERTICES[:, 1])
    rows = np.arange(n)[:, None]
    start, end = vertices[rows, a], vertices[rows, b]  # (n, 3, 2)
    wn, wt = _edge_frames(start, end)
    q = np.stack([_EDGE_W, _EDGE_W * (2.0 * _EDGE_S - 1.0)])  # (2, nq)
    moments = _span_of(np.einsum("lq,neqm->nelm", q, _monomials(scaled(_edge_points(start, end)))))
    D[:, 9:21, :] = np.concatenate(
        [np.einsum("nej,nelji->neli", wn, moments), np.einsum("nej,nelji->neli", wt, moments)], axis=2
    ).reshape(n, 12, _NUM_LOCAL)
    # cell averages
    D[:, 21:24, :] = _span_of(np.einsum("q,nqm->nm", _CELL_W, _monomials(scaled(_map_to_cells(vertices, _CELL_Q)))))

    C = np.linalg.solve(D, np.broadcast_to(np.eye(_NUM_LOCAL), D.shape))  # span coeffs
    values = _eval_span(scaled(_map_to_cells(vertices, points)))  # (n, m, 3, 24)
    return (values.reshape(n, 3 * points.shape[0], _NUM_LOCAL) @ C).reshape(n, points.shape[0], 3, _NUM_LOCAL)


def shared_nodal_basis(
    vertices: npt.NDArray[np.floating], edge_flip: npt.NDArray[np.bool_], points: npt.NDArray[np.floating],
    comm: MPI.Comm, column_order: np.ndarray | None = None,
) -> np.ndarray:
    """``local_nodal_basis`` of all cells on every rank of ``comm``, each rank computing a contiguous share
    (the ranks hold the same cells: a replicated serial mesh) and one ``Allgatherv`` joining them."""
    n = vertices.shape[0]
    bounds = np.linspace(0, n, comm.size + 1).astype(np.int64)
    lo, hi = bounds[comm.rank], bounds[comm.rank + 1]
    out = np.empty((n, np.asarray(points).shape[0], 3, _NUM_LOCAL))
    local_nodal_basis(vertices[lo:hi], edge_flip[lo:hi], points, out=out[lo:hi],
                      column_order=None if column_order is None else column_order[lo:hi])
    width = int(np.prod(out.shape[1:], dtype=np.int64))
    comm.Allgatherv(MPI.IN_PLACE, [out, (np.diff(bounds) * width, bounds[:-1] * width), MPI.DOUBLE])
    return out


# ---------------------------------------------------------------------------
# UFL helpers
# ---------------------------------------------------------------------------


def symmetric_tensor(s: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """(s0, s1, s2) ↦ [[s0, s1], [s1, s2]]."""
    return ufl.as_matrix([[s[0], s[1]], [s[1], s[2]]])


def lame_parameters(E: float | ufl.core.expr.Expr, nu: float | ufl.core.expr.Expr):
    """Plane-strain Lamé parameters λ = Eν/((1+ν)(1-2ν)), μ = E/(2(1+ν))."""
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def compliance(sigma: ufl.core.expr.Expr, lmbda, mu) -> ufl.core.expr.Expr:
    """Plane-strain compliance Aσ = (σ - λ/(2λ+2μ) tr(σ) I) / (2μ)."""
    return (sigma - lmbda / (2 * lmbda + 2 * mu) * ufl.tr(sigma) * ufl.Identity(2)) / (2 * mu)


# ---------------------------------------------------------------------------
# The space
# ---------------------------------------------------------------------------


def _cell_rows_csr(sblocks: np.ndarray, rows: np.ndarray, scols: np.ndarray, shape: tuple[int, int]) -> sp.csr_matrix:
    """CSR matrix with rows[c, i] holding sblocks[c, i, :] at columns scols[c] (each row in one cell), sorted.

    Each cell's columns ``scols[c]`` increasing.  Built straight from the cell blocks (no COO
    conversion) when the cells' rows cover 0..shape[0]-1 once; when they are 0, 1, 2, … in cell-major order
    (a serial DG numbering) the matrix's data is a view of ``sblocks`` (no copy).
    """
    nc, a, b = sblocks.shape
    flat = rows.ravel()
    if flat.size != shape[0] or not np.array_equal(np.bincount(flat, minlength=shape[0]), np.ones(shape[0], np.int64)):
        P = sp.csr_matrix((sblocks.ravel(), (np.repeat(rows, b, axis=1).ravel(), np.tile(scols, (1, a)).ravel())),
                          shape=shape)
        P.sort_indices()
        return P
    if np.array_equal(flat, np.arange(shape[0])):
        data = sblocks.reshape(-1)
        indices = np.repeat(scols, a, axis=0).ravel()
    else:
        where = np.empty(shape[0], dtype=np.int64)
        where[flat] = np.arange(flat.size)  # row -> (cell, i) position
        data = sblocks.reshape(-1, b)[where].ravel()
        indices = scols[where // a].ravel()
    return sp.csr_matrix((data, indices, b * np.arange(shape[0] + 1, dtype=np.int64)), shape=shape)


def _as_form(form) -> dolfinx.fem.Form:
    return form if isinstance(form, dolfinx.fem.Form) else dolfinx.fem.form(form)


class ArnoldWintherSpace:
    """Lowest-order Arnold–Winther stress space X_h ⊂ H(div; Ω; S) on a (distributed) triangle mesh.

    Forms are written on ``self.dg`` (DG P3, value shape (3,) = (σ_xx, σ_xy,
    σ_yy)); use :meth:`stress` to obtain the symmetric tensor and
    :meth:`assemble_matrix` / :meth:`assemble_vector` to obtain the AW
    operators Pᵀ A P, B P, Pᵀ b.

    **Numbering.**  On each rank the *full* local numbering is 3v + j for the
    local vertices v (owned, then ghosts), 3n_v + 4e + k for the local edges,
    3n_v + 4n_e + 3c + j for the owned cells.  The (reduced) space numbers its
    degrees of freedom globally: each rank owns those of its owned vertices, edges
    and cells — the kept full ones in local order, then the constrained vertices'
    null-space coefficients, then the split-interface coefficients — and learns the
    numbers of its ghosts from their owners (DOLFINx scatters over the topology's
    index maps).  Essential constraints are gathered from all ranks (boundary data,
    small), so every rank forms the same constraint rows and null spaces at a vertex
    shared by ranks.  In serial the numbering is the raw one above.

    Args:
        mesh: mesh of affine triangles, gdim 2 (serial or distributed).
        zero_tangential_facets: local facet (edge) indices of straight edges on which
            σn·t = 0 is imposed essentially (frictionless / sliding).
        zero_traction_facets: local facet indices on which σn = 0 is imposed
            essentially (traction-free).
        prescribed_tractions: pairs (facets, t) with facets among
            ``zero_traction_facets`` and t a callable x (3, N) -> (2, N): σn = t
            there (outward n), carried by the lifting ``lifting_dg``.
        split_interface: (facets, cells): at the vertices of these facets (γ) the
            stress gets extra functions living on ``cells`` only (one side of γ) whose
            normal trace on γ vanishes: σ_tt may differ on the two sides of a γ vertex.
    """

    def __init__(
        self,
        mesh: dolfinx.mesh.Mesh,
        *,
        zero_tangential_facets: npt.ArrayLike | None = None,
        zero_traction_facets: npt.ArrayLike | None = None,
        prescribed_tractions: list | None = None,
        split_interface: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
        basis_comm: MPI.Comm | None = None,
    ) -> None:
        """``basis_comm``: ranks that each hold this same serial mesh (a replicated Ω₁ of Algorithm 4) and
        share out the cells' nodal bases (``shared_nodal_basis``); the space is the same as without."""
        t0 = time.perf_counter()
        if mesh.topology.cell_type != dolfinx.mesh.CellType.triangle:
            raise ValueError(f"Arnold–Winther needs a triangle mesh, got {mesh.topology.cell_type}.")
        if mesh.geometry.dim != 2:
            raise ValueError("Arnold–Winther needs a mesh with geometric dimension 2.")
        if len(mesh.geometry.cmaps) != 1 or mesh.geometry.cmaps[0].degree != 1:
            raise ValueError("Arnold–Winther needs an affine (degree 1) geometry.")
        self.mesh = mesh
        self.comm = mesh.comm
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
        self._c2v, self._c2e, self._e2v, self._vx, self._c2v_all = c2v, c2e, e2v, vx, c2v_all
        self.num_cells, self.num_vertices, self.num_edges = nc, nv, ne
        self._vertex_gid = im0.local_to_global(np.arange(nv, dtype=np.int32)).astype(np.int64)
        self._edge_gid = im1.local_to_global(np.arange(ne, dtype=np.int32)).astype(np.int64)

        # sanity: local edge k is opposite local vertex k (basix numbering)
        loc = np.sort(c2v[:, _EDGE_VERTICES], axis=-1)  # (nc, 3, 2)
        if not np.array_equal(loc, np.sort(e2v[c2e], axis=-1)):
            raise RuntimeError("Unexpected local edge numbering in the mesh topology.")
        gnum = self._vertex_gid
        edge_flip = gnum[c2v[:, _EDGE_VERTICES[:, 0]]] > gnum[c2v[:, _EDGE_VERTICES[:, 1]]]
        lower = gnum[e2v[:, 0]] < gnum[e2v[:, 1]]
        self._edge_start = np.where(lower, e2v[:, 0], e2v[:, 1])  # orientation from global vertex numbers
        self._edge_end = np.where(lower, e2v[:, 1], e2v[:, 0])

        # DG P3 space for (σ_xx, σ_xy, σ_yy)
        scalar = basix.ufl.element("DG", "triangle", 3)
        self.dg = dolfinx.fem.functionspace(mesh, basix.ufl.blocked_element(scalar, shape=(3,)))
        bel = scalar.basix_element
        ref_pts = np.asarray(bel.points)
        interp = np.asarray(bel.interpolation_matrix)  # (10, 10), identity for Lagrange

        # local AW -> full local numbering
        self.num_dofs_full = 3 * nv + 4 * ne + 3 * nc
        l2g = np.empty((nc, _NUM_LOCAL), dtype=np.int64)
        l2g[:, 0:9] = (3 * c2v[:, :, None] + np.arange(3)).reshape(nc, 9)
        l2g[:, 9:21] = (3 * nv + 4 * c2e[:, :, None] + np.arange(4)).reshape(nc, 12)
        l2g[:, 21:24] = 3 * nv + 4 * ne + 3 * np.arange(nc)[:, None] + np.arange(3)
        self._l2g = l2g

        # per-cell nodal basis at the DG nodes -> DG coefficients: the cells' blocks of the full P, each cell's
        # columns (AW numbers) increasing.  Read-only: the CSR P_full may share their memory.  The CSR matrices
        # P_full and P are made when first asked for (Algorithm 4's Ω₁ never asks: its cell operators read the
        # blocks, its interface maps the γ cells' rows, ``prolongation_for_rows``)
        order = np.argsort(l2g, axis=1, kind="stable")
        self._cell_cols = np.take_along_axis(l2g, order, axis=1)  # (nc, 24)
        if basis_comm is not None and basis_comm.size > 1 and self.comm.size == 1:
            values = shared_nodal_basis(vx[c2v], edge_flip, ref_pts, basis_comm, column_order=order)
        else:
            values = local_nodal_basis(vx[c2v], edge_flip, ref_pts, column_order=order)  # (nc, 10, 3, 24)
        if not np.array_equal(interp, np.eye(interp.shape[0])):
            values = np.einsum("pq,nqjk->npjk", interp, values)
        self._cell_P = values.reshape(nc, 30, _NUM_LOCAL)
        self._cell_P.flags.writeable = False
        del values
        dg_dofs = self.dg.dofmap.list[:nc].astype(np.int64)  # (nc, 10) blocks (owned: DG)
        rows = (3 * dg_dofs[:, :, None] + np.arange(3)).reshape(nc, 30)
        self._n_dg = 3 * self.dg.dofmap.index_map.size_local
        self._P_full_csr: sp.csr_matrix | None = None
        self._P_csr: sp.csr_matrix | None = None
        self._dg_rows = rows
        #: stacked essential constraint rows (k, 3) acting on the vertex value σ(v), per constrained local vertex
        self.vertex_constraints: dict[int, np.ndarray] = {}
        self._vertex_rhs: dict[int, np.ndarray] = {}
        self._constraints(zero_tangential_facets, zero_traction_facets, prescribed_tractions)
        self._split_bases: dict[int, np.ndarray] = {}
        if split_interface is not None:
            self._split_null_spaces(*split_interface)
        self._number()
        self._split_cells: np.ndarray | None = None
        if split_interface is not None and self._X_local is not None:
            cells = np.asarray(split_interface[1], dtype=np.int64)
            self._split_cells = cells[cells < nc]
        #: DG coefficients of the traction lifting σ_t (None without prescribed tractions)
        self.lifting_dg: np.ndarray | None = None
        #: local vertices where the prescribed tractions of two edges are incompatible (least-squares value used)
        self.incompatible_vertices: np.ndarray = np.zeros(0, dtype=np.int64)
        if prescribed_tractions:
            self.lifting_dg = self._P_full @ self._lifting()
        self._P_petsc: PETSc.Mat | None = None
        self.build_time = time.perf_counter() - t0

    # -- constraints ---------------------------------------------------------

    def _constraints(self, tangential, traction, prescribed) -> None:
        """Gather the constrained facets of all ranks; constraint rows, right-hand sides and kept edge moments.

        On each listed edge e (unit normal n, tangent t) the moments of σn·t
        (and of σn·n for traction-free edges) are dropped, and at its vertices
        the value σ(v) is restricted to the null space of the rows
        σ ↦ σn·t (resp. σ ↦ σn), stacked over all constrained edges at v (in the order
        kind, global facet number: the same on every rank).  The right-hand sides of the
        rows (zero, or the prescribed traction at v) are kept for the lifting.
        """
        sets = [np.unique(np.asarray([] if f is None else f, dtype=np.int64)) for f in (tangential, traction)]
        for facets in sets:
            if facets.size and (facets.min() < 0 or facets.max() >= self.num_edges):
                raise ValueError("Facet index out of range.")
        group_of = np.full(self.num_edges, -1, dtype=np.int64)
        for k, (facets, _) in enumerate(prescribed or []):
            facets = np.asarray(facets, dtype=np.int64)
            if not np.all(np.isin(facets, sets[1])):
                raise ValueError("prescribed-traction facets must be among the zero_traction_facets")
            group_of[facets] = k
        self._tractions = [value for _, value in (prescribed or [])]
        # records: kind (0 tangential, 1 traction), facet gid, vertex gids, rows (2, 3), nrows, rhs (2 vertices, 2), group
        recs = []
        for kind, facets in enumerate(sets):
            if facets.size == 0:
                continue
            start, end = self._vx[self._edge_start[facets]], self._vx[self._edge_end[facets]]
            _, wt = _edge_frames(start, end)
            t = (end - start) / np.linalg.norm(end - start, axis=-1, keepdims=True)
            n0, n1 = t[:, 1], -t[:, 0]
            F = facets.size
            rows = np.zeros((F, 2, 3))
            rhs = np.zeros((F, 2, 2))
            if kind == 0:
                rows[:, 0] = wt
            else:
                rows[:, 0, 0], rows[:, 0, 1], rows[:, 1, 1], rows[:, 1, 2] = n0, n1, n0, n1
                outward = self._outward_sign(facets, np.stack([n0, n1], axis=1))
                for i, e in enumerate(facets):
                    if group_of[e] < 0:
                        continue
                    x = np.zeros((3, 2))
                    x[:2] = self._vx[self._e2v[e]].T
                    val = np.asarray(self._tractions[group_of[e]](x), dtype=np.float64).reshape(2, 2)
                    rhs[i] = outward[i] * val.T  # σ n_e = ±t(v), n_e = ±(outward normal)
            recs.append({
                "kind": np.full(F, kind, dtype=np.int64), "gid": self._edge_gid[facets],
                "v": self._vertex_gid[self._e2v[facets]], "rows": rows, "rhs": rhs, "group": group_of[facets],
            })
        keys = ("kind", "gid", "v", "rows", "rhs", "group")
        empty = {"kind": np.zeros(0, np.int64), "gid": np.zeros(0, np.int64), "v": np.zeros((0, 2), np.int64),
                 "rows": np.zeros((0, 2, 3)), "rhs": np.zeros((0, 2, 2)), "group": np.zeros(0, np.int64)}
        local = {k: np.concatenate([r[k] for r in recs]) if recs else empty[k] for k in keys}
        if self.comm.size > 1:
            parts = self.comm.allgather(local)
            local = {k: np.concatenate([p[k] for p in parts]) for k in keys}
        _, first = np.unique(np.stack([local["kind"], local["gid"]], axis=1), axis=0, return_index=True)
        rec = {k: v[first] for k, v in local.items()}  # unique, sorted by (kind, gid)
        self._constrained = rec
        # kept edge moments of the local edges
        keep_edge = np.ones((self.num_edges, 4), dtype=bool)
        for kind, dropped in ((0, [2, 3]), (1, [0, 1, 2, 3])):
            hit = np.isin(self._edge_gid, rec["gid"][rec["kind"] == kind])
            keep_edge[np.ix_(hit, dropped)] = False
        self._keep_edge = keep_edge
        # stacked rows and right-hand sides at the local constrained vertices
        order = np.argsort(self._vertex_gid, kind="stable")
        gids_sorted = self._vertex_gid[order]
        rows_at: dict[int, list[np.ndarray]] = {}
        rhs_at: dict[int, list[np.ndarray]] = {}
        for i in range(rec["gid"].size):
            nrow = 1 if rec["kind"][i] == 0 else 2
            for side in range(2):
                g = rec["v"][i, side]
                pos = np.searchsorted(gids_sorted, g)
                if pos >= gids_sorted.size or gids_sorted[pos] != g:
                    continue  # the vertex is not on this rank
                v = int(order[pos])
                rows_at.setdefault(v, []).append(rec["rows"][i, :nrow])
                rhs_at.setdefault(v, []).append(rec["rhs"][i, side, :nrow])
        self._null: dict[int, np.ndarray] = {}
        for v in sorted(rows_at):
            stacked = np.vstack(rows_at[v])
            self.vertex_constraints[v] = stacked
            self._vertex_rhs[v] = np.concatenate(rhs_at[v])
            _, sv, vt = np.linalg.svd(stacked)
            null = vt[int(np.sum(sv > 1e-10 * sv.max())) :]  # (k, 3) orthonormal rows
            null[np.abs(null) < 1e-14] = 0.0
            self._null[v] = null

    def _split_null_spaces(self, facets, cells) -> None:
        """Extra vertex functions of the split interface: null space of σ ↦ σn (γ) and the vertex's constraints."""
        facets = np.unique(np.asarray(facets, dtype=np.int64))
        start, end = self._vx[self._edge_start[facets]], self._vx[self._edge_end[facets]]
        t = (end - start) / np.linalg.norm(end - start, axis=-1, keepdims=True) if facets.size else np.zeros((0, 2))
        local = {"gid": self._edge_gid[facets], "v": self._vertex_gid[self._e2v[facets]], "t": t}
        if self.comm.size > 1:
            parts = self.comm.allgather(local)
            local = {k: np.concatenate([p[k] for p in parts]) for k in local}
        _, first = np.unique(local["gid"], return_index=True)
        order = np.argsort(self._vertex_gid, kind="stable")
        gids_sorted = self._vertex_gid[order]
        rows_at: dict[int, list[np.ndarray]] = {}
        for i in first:
            n0, n1 = local["t"][i, 1], -local["t"][i, 0]
            rows = np.array([[n0, n1, 0.0], [0.0, n0, n1]])
            for g in local["v"][i]:
                pos = np.searchsorted(gids_sorted, g)
                if pos < gids_sorted.size and gids_sorted[pos] == g:
                    rows_at.setdefault(int(order[pos]), []).append(rows)
        for v in sorted(rows_at):
            # the side-2 value z must also satisfy the essential conditions at v (a γ end on a
            # traction-free, traction or contact side): z in the null space of all rows
            rows = rows_at[v] + ([self.vertex_constraints[v]] if v in self.vertex_constraints else [])
            _, sv, vt = np.linalg.svd(np.vstack(rows))
            null = vt[int(np.sum(sv > 1e-10 * sv.max())) :]
            if null.shape[0]:
                self._split_bases[v] = null

    def _number(self) -> None:
        """Global numbering of the reduced space; T (full local -> reduced local) and the split part X."""
        comm = self.comm
        top = self.mesh.topology
        im0, im1 = top.index_map(0), top.index_map(1)
        nv_own, ne_own, nc = im0.size_local, im1.size_local, self.num_cells
        nv, ne = self.num_vertices, self.num_edges
        constrained = np.zeros(nv, dtype=bool)
        constrained[list(self._null)] = True
        k_null = np.zeros(nv, dtype=np.int64)
        for v, null in self._null.items():
            k_null[v] = null.shape[0]
        k_split = np.zeros(nv, dtype=np.int64)
        for v, z in self._split_bases.items():
            k_split[v] = z.shape[0]
        # owned reduced DOFs: kept full DOFs (local full order), null-space coefficients, split coefficients
        red_v = np.full((nv, 3), -1, dtype=np.int64)
        red_e = np.full((ne, 4), -1, dtype=np.int64)
        red_x = np.full((nv, 3), -1, dtype=np.int64)
        free_v = np.flatnonzero(~constrained[:nv_own])
        keep_e = self._keep_edge[:ne_own]
        n_kept_v, n_kept_e = 3 * free_v.size, int(keep_e.sum())
        cons_v = np.flatnonzero(constrained[:nv_own])
        split_v = np.flatnonzero(k_split[:nv_own] > 0)
        n_own = n_kept_v + n_kept_e + 3 * nc + int(k_null[cons_v].sum()) + int(k_split[split_v].sum())
        offs = _offsets(comm, n_own)
        off = int(offs[comm.rank])
        red_v[free_v] = off + np.arange(n_kept_v).reshape(-1, 3)
        pos = off + n_kept_v
        red_e[:ne_own][keep_e] = pos + np.arange(n_kept_e)
        pos += n_kept_e
        red_c = pos + np.arange(3 * nc).reshape(nc, 3)
        pos += 3 * nc
        for v in cons_v:
            red_v[v, : k_null[v]] = pos + np.arange(k_null[v])
            pos += k_null[v]
        for v in split_v:
            red_x[v, : k_split[v]] = pos + np.arange(k_split[v])
            pos += k_split[v]
        assert pos == off + n_own
        if comm.size > 1:
            red_v = _scatter_to_ghosts(im0, red_v[:nv_own])
            red_e = _scatter_to_ghosts(im1, red_e[:ne_own])
            if comm.allreduce(bool(self._split_bases), op=MPI.LOR):
                red_x = _scatter_to_ghosts(im0, red_x[:nv_own])
        # local reduced numbering: owned block, then the ghosts (sorted by global number)
        used = np.concatenate([red_v.ravel(), red_e.ravel(), red_x.ravel()])
        used = np.unique(used[(used >= 0) & ((used < off) | (used >= off + n_own))])
        self.num_owned = n_own
        self.ghosts = used
        self.ghost_owners = _owner_of(used, offs)
        self._offsets = offs
        self.global_indices = np.concatenate([off + np.arange(n_own), used])  # local reduced -> global

        def to_local(g: np.ndarray) -> np.ndarray:
            out = np.where(g >= 0, g - off, -1)
            ghost = (g >= 0) & ((g < off) | (g >= off + n_own))
            out[ghost] = n_own + np.searchsorted(used, g[ghost])
            return out

        lv, le, lc, lx = to_local(red_v), to_local(red_e), to_local(red_c), to_local(red_x)
        n_loc = n_own + used.size
        # T: full local -> reduced local
        r_idx, c_idx, vals = [], [], []
        free = np.flatnonzero(~constrained)
        r_idx.append((3 * free[:, None] + np.arange(3)).ravel())
        c_idx.append(lv[free].ravel())
        vals.append(np.ones(3 * free.size))
        for v, null in self._null.items():  # σ(v) = Σ_q c_q z_q
            for q, z in enumerate(null):
                nz = np.flatnonzero(z)
                r_idx.append(3 * v + nz)
                c_idx.append(np.full(nz.size, lv[v, q]))
                vals.append(z[nz])
        ei, ek = np.nonzero(self._keep_edge)
        r_idx.append(3 * nv + 4 * ei + ek)
        c_idx.append(le[ei, ek])
        vals.append(np.ones(ei.size))
        r_idx.append(3 * nv + 4 * ne + np.arange(3 * nc))
        c_idx.append(lc.ravel())
        vals.append(np.ones(3 * nc))
        r, c, w = np.concatenate(r_idx), np.concatenate(c_idx), np.concatenate(vals)
        if np.any(c < 0):
            raise RuntimeError("an Arnold–Winther degree of freedom has no global number")
        identity = n_loc == self.num_dofs_full and r.size == n_loc and np.array_equal(r, c) and np.all(w == 1.0)
        self._T_local = None if identity else sp.csr_matrix((w, (r, c)), shape=(self.num_dofs_full, n_loc))
        self._X_local = None
        if self._split_bases:
            r_idx, c_idx, vals = [], [], []
            for v, zs in self._split_bases.items():
                for q, z in enumerate(zs):
                    nz = np.flatnonzero(z)
                    r_idx.append(3 * v + nz)
                    c_idx.append(np.full(nz.size, lx[v, q]))
                    vals.append(z[nz])
            self._X_local = sp.csr_matrix(
                (np.concatenate(vals), (np.concatenate(r_idx), np.concatenate(c_idx))), shape=(self.num_dofs_full, n_loc)
            )

    def _outward_sign(self, facets: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """+1 where the edge normal n_e (global orientation) points out of the mesh, −1 where it points in."""
        f2c = self.mesh.topology.connectivity(1, 2)
        counts = np.diff(f2c.offsets)[facets]
        if np.any(counts < 1):
            raise ValueError("a traction facet does not belong to a cell")
        cells = f2c.array[f2c.offsets[facets]]
        mid = 0.5 * (self._vx[self._edge_start[facets]] + self._vx[self._edge_end[facets]])
        centre = self._vx[self._c2v_all[cells]].mean(axis=1)
        return np.where(np.sum(normals * (mid - centre), axis=1) > 0.0, 1.0, -1.0)

    def _lifting(self) -> np.ndarray:
        """Full local AW coefficients of the traction lifting: edge moments of ±t on the traction edges,
        vertex values by least squares on the stacked vertex constraints (min-norm: ⊥ the free part)."""
        nv = self.num_vertices
        d = np.zeros(self.num_dofs_full)
        q = np.stack([_EDGE_W, _EDGE_W * (2.0 * _EDGE_S - 1.0)])  # (2, nq)
        rec = self._constrained
        for k, value in enumerate(self._tractions):
            gids = rec["gid"][(rec["kind"] == 1) & (rec["group"] == k)]
            facets = np.flatnonzero(np.isin(self._edge_gid, gids))
            if facets.size == 0:
                continue
            start, end = self._vx[self._edge_start[facets]], self._vx[self._edge_end[facets]]
            tan = (end - start) / np.linalg.norm(end - start, axis=1, keepdims=True)
            nrm = np.stack([tan[:, 1], -tan[:, 0]], axis=1)
            sign = self._outward_sign(facets, nrm)
            pts = _edge_points(start, end)  # (F, nq, 2)
            x = np.zeros((3, pts.shape[0] * pts.shape[1]))
            x[:2] = pts.reshape(-1, 2).T
            t = np.asarray(value(x), dtype=np.float64).reshape(2, -1).T.reshape(pts.shape)  # (F, nq, 2)
            tn = sign[:, None] * np.einsum("fqi,fi->fq", t, nrm)  # σn_e·n_e
            tt = sign[:, None] * np.einsum("fqi,fi->fq", t, tan)  # σn_e·t_e
            moments = np.concatenate([tn @ q.T, tt @ q.T], axis=1)  # (F, 4)
            d[(3 * nv + 4 * facets[:, None] + np.arange(4)).ravel()] = moments.ravel()
        bad = []
        for v, rows in self.vertex_constraints.items():
            rhs = self._vertex_rhs[v]
            if not np.any(rhs):
                continue
            value, *_ = np.linalg.lstsq(rows, rhs, rcond=None)
            if np.linalg.norm(rows @ value - rhs) > 1e-10 * max(np.linalg.norm(rhs), 1e-300):
                bad.append(v)
            d[3 * v : 3 * v + 3] = value
        self.incompatible_vertices = np.asarray(bad, dtype=np.int64)
        return d

    def vertex_coordinates(self, vertices: npt.ArrayLike) -> np.ndarray:
        """Coordinates (N, 2) of local topology vertices."""
        return self._vx[np.asarray(vertices, dtype=np.int64)]

    # -- public API ----------------------------------------------------------

    @property
    def num_dofs(self) -> int:
        """Global number of (reduced) AW degrees of freedom."""
        return int(self._offsets[-1])

    @property
    def global_vertex_indices(self) -> np.ndarray:
        """Global number of every local topology vertex (owned, then ghosts)."""
        return self._vertex_gid

    @property
    def owned_range(self) -> tuple[int, int]:
        """(first, last + 1) global number of the DOFs this rank owns."""
        return int(self._offsets[self.comm.rank]), int(self._offsets[self.comm.rank + 1])

    @property
    def _P_full(self) -> sp.csr_matrix:
        if self._P_full_csr is None:
            self._P_full_csr = _cell_rows_csr(self._cell_P, self._dg_rows, self._cell_cols,
                                              (self._n_dg, self.num_dofs_full))
        return self._P_full_csr

    def _constrain_rows(self, P_full: sp.csr_matrix, split_cells: np.ndarray | None) -> sp.csr_matrix:
        """P = P_full T (+ the split-interface functions on ``split_cells``), row by row from ``P_full``."""
        T = self._T_local
        P = P_full if T is None else (P_full @ T).tocsr()
        if split_cells is not None:
            mask = np.zeros(self._n_dg)
            mask[self._dg_rows[split_cells].ravel()] = 1.0
            P = (P + sp.diags(mask) @ P_full @ self._X_local).tocsr()
        P.sort_indices()
        return P

    @property
    def _P(self) -> sp.csr_matrix:
        if self._P_csr is None:
            self._P_csr = self._constrain_rows(self._P_full, self._split_cells)
        return self._P_csr

    @property
    def prolongation(self) -> sp.csr_matrix:
        """Local P (SciPy CSR): owned DG coefficients × local AW coefficients (owned, then ``ghosts``).

        In serial: AW coefficients -> coefficients of ``self.dg``.  Made when first asked for and kept
        (``release_prolongation`` drops it).
        """
        return self._P

    def prolongation_for_rows(self, rows: npt.ArrayLike) -> sp.csr_matrix:
        """P where it has been made; else P's rows in the cells holding the given ``dg`` rows, the other rows
        empty (same shape): Q P = Q P_rows for any Q whose nonzero columns are among ``rows``.

        Row for row the same numbers as P (each row is formed from its own row of P_full); it costs only those
        cells (e.g. the interface maps of Algorithm 4's Ω₁: the γ cells, where P is never made).
        """
        if self._P_csr is not None:
            return self._P_csr
        cell_of = np.empty(self._n_dg, dtype=np.int64)
        cell_of[self._dg_rows.ravel()] = np.repeat(np.arange(self.num_cells), self._dg_rows.shape[1])
        cells = np.unique(cell_of[np.asarray(rows, dtype=np.int64)])
        P_full = _cell_rows_csr(self._cell_P[cells], self._dg_rows[cells], self._cell_cols[cells],
                                (self._n_dg, self.num_dofs_full))
        split = None if self._split_cells is None else np.intersect1d(self._split_cells, cells)
        return self._constrain_rows(P_full, split)

    def cell_prolongation(self) -> tuple[np.ndarray, np.ndarray]:
        """(cols (n, 24), blocks (n, 30, 24)): P_full's rows of each owned cell (``dg_rows`` order) at its AW
        columns, columns increasing (read-only arrays, kept by the space)."""
        return self._cell_cols, self._cell_P

    @property
    def dg_rows(self) -> np.ndarray:
        """(n, 30) the ``dg`` coefficient (3·DOF + component) of each owned cell's local stress entries."""
        return self._dg_rows

    def release_prolongation(self) -> None:
        """Drop the CSR (and PETSc) P and P_full (made again when asked for); the cell blocks stay."""
        self._P_full_csr = self._P_csr = None
        if self._P_petsc is not None:
            self._P_petsc.destroy()
            self._P_petsc = None

    @property
    def prolongation_petsc(self) -> PETSc.Mat:
        """P as a distributed PETSc AIJ matrix (global AW numbering; created once)."""
        if self._P_petsc is None:
            self._P_petsc = _local_rows_to_petsc(self.comm, self._P, self.global_indices,
                                                 (self.num_owned, self.num_dofs))
        return self._P_petsc

    @property
    def full_prolongation(self) -> sp.csr_matrix:
        """Local P of the unconstrained space: full local AW coefficients -> owned ``dg`` coefficients."""
        return self._P_full

    @property
    def constraint_basis(self) -> sp.csr_matrix:
        """T: reduced local AW coefficients -> full local AW coefficients (identity if unconstrained)."""
        return sp.identity(self.num_dofs_full, format="csr") if self._T_local is None else self._T_local

    @staticmethod
    def stress(s: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """Symmetric tensor [[s0, s1], [s1, s2]] of a function/argument on ``dg``."""
        return symmetric_tensor(s)

    def to_dg(self, coeffs: npt.ArrayLike, out: dolfinx.fem.Function | None = None) -> dolfinx.fem.Function:
        """Owned AW coefficients c ↦ DG P3 function with coefficients P c (collective)."""
        out = dolfinx.fem.Function(self.dg) if out is None else out
        P = self.prolongation_petsc
        x, y = P.createVecs()
        x.array[:] = np.asarray(coeffs, dtype=np.float64)
        P.mult(x, y)
        out.x.array[: self._n_dg] = y.array
        out.x.scatter_forward()
        x.destroy()
        y.destroy()
        return out

    def interpolate(self, sigma: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """AW interpolant: DOF functionals ℓ_i(σ) of a stress field, as owned (reduced) AW coefficients.

        Args:
            sigma: callable x -> components, x of shape (3, N) (dolfinx
                convention, x[2] = 0), returning (3, N) = (σ_xx, σ_xy, σ_yy).
        """
        nv, ne, nc = self.num_vertices, self.num_edges, self.num_cells
        vx = self._vx
        start, end = vx[self._edge_start], vx[self._edge_end]
        epts = _edge_points(start, end)  # (ne, nq, 2)
        cpts = _map_to_cells(vx[self._c2v], _CELL_Q)  # (nc, nqc, 2)
        pts = np.concatenate([vx, epts.reshape(-1, 2), cpts.reshape(-1, 2)])
        x = np.zeros((3, pts.shape[0]))
        x[:2] = pts.T
        val = np.asarray(sigma(x), dtype=np.float64).reshape(3, -1).T  # (N, 3)
        d = np.empty(self.num_dofs_full)
        d[: 3 * nv] = val[:nv].ravel()
        ev = val[nv : nv + epts.shape[0] * epts.shape[1]].reshape(ne, len(_EDGE_S), 3, 1)
        wn, wt = _edge_frames(start, end)
        d[3 * nv : 3 * nv + 4 * ne] = _edge_moments(ev, wn, wt).reshape(-1)
        cv = val[nv + epts.shape[0] * epts.shape[1] :].reshape(nc, len(_CELL_W), 3)
        d[3 * nv + 4 * ne :] = np.einsum("q,nqj->nj", _CELL_W, cv).ravel()
        c = d if self._T_local is None else self._T_local.T @ d
        return c[: self.num_owned]

    def is_stress_space(self, V) -> bool:
        """True if V (python or C++ function space) is ``self.dg``."""
        cpp = getattr(V, "_cpp_object", V)
        return cpp == self.dg._cpp_object

    def assemble_matrix(self, a) -> PETSc.Mat:
        """Assemble a bilinear form; stress arguments are reduced: Pᵀ A P, Pᵀ A or A P (distributed)."""
        form = _as_form(a)
        A = dolfinx.fem.petsc.assemble_matrix(form)
        A.assemble()
        test_s, trial_s = (self.is_stress_space(V) for V in form.function_spaces)
        P = self.prolongation_petsc
        if test_s and trial_s:
            R = A.PtAP(P)
        elif trial_s:
            R = A.matMult(P)
        elif test_s:
            R = P.transposeMatMult(A)
        else:
            return A
        A.destroy()
        return R

    def assemble_vector(self, L) -> np.ndarray:
        """Assemble a linear form to a numpy array of owned entries; on the stress space returns Pᵀ b."""
        form = _as_form(L)
        b = dolfinx.fem.petsc.assemble_vector(form)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if self.is_stress_space(form.function_spaces[0]):
            P = self.prolongation_petsc
            x = P.createVecRight()
            P.multTranspose(b, x)
            arr = x.array.copy()
            x.destroy()
        else:
            arr = b.getArray(readonly=True).copy()
        b.destroy()
        return arr


# ---------------------------------------------------------------------------
# Solvers
# ---------------------------------------------------------------------------


def solve_saddle_point(
    K: PETSc.Mat, B: PETSc.Mat, F: npt.ArrayLike, G: npt.ArrayLike
) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """Solve [[K, Bᵀ], [B, 0]] [x; y] = [F; G] by MUMPS LU (distributed; F, G, x, y owned entries).

    Returns (x, y, timings) with timings 'block' (matrix build) and 'lu'.
    """
    t0 = time.perf_counter()
    comm = K.getComm()
    saddle = SaddlePointMatrix(K, B)
    M = saddle.mat
    t1 = time.perf_counter()
    rhs, sol = saddle.create_vecs()
    n = saddle.nx
    rhs.array[:n] = F
    rhs.array[n:] = G
    ksp = PETSc.KSP().create(comm)
    ksp.setOperators(M)
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("lu")
    pc.setFactorSolverType("mumps")
    ksp.setFromOptions()
    ksp.solve(rhs, sol)
    reason = ksp.getConvergedReason()
    if reason < 0:
        raise RuntimeError(f"MUMPS LU failed (KSP reason {reason}).")
    x = sol.array[:n].copy()
    y = sol.array[n:].copy()
    t2 = time.perf_counter()
    for obj in (ksp, M, rhs, sol):
        obj.destroy()
    return x, y, {"block": t1 - t0, "lu": t2 - t1}


@dataclass
class MixedElasticitySolution:
    """Result of :func:`solve_mixed_elasticity`."""

    sigma: dolfinx.fem.Function  #: stress on ``space.dg`` (σ_xx, σ_xy, σ_yy)
    u: dolfinx.fem.Function  #: displacement, DG P1 vector
    sigma_coeffs: np.ndarray  #: AW coefficients of σ_h (owned entries)
    timings: dict[str, float] = field(default_factory=dict)


def solve_mixed_elasticity(
    space: ArnoldWintherSpace,
    *,
    E: float = 1.0,
    nu: float = 0.3,
    f: ufl.core.expr.Expr | None = None,
    u_D: ufl.core.expr.Expr | None = None,
) -> MixedElasticitySolution:
    """Hellinger–Reissner mixed elasticity with AW stresses and DG P1 displacements.

    Find (σ, u) ∈ X_h × U_h: (Aσ, τ) + (div τ, u) = ⟨u_D, τn⟩_∂Ω,  (div σ, v) = -(f, v).
    The displacement u_D enters naturally on ∂Ω (where the space imposes σn·t = 0
    only its normal part acts, where σn = 0 nothing).  E, ν are plane-strain
    constants; f, u_D are UFL vector expressions (None means zero).
    """
    timings: dict[str, float] = {"build_P": space.build_time}
    mesh = space.mesh
    U = dolfinx.fem.functionspace(mesh, ("DG", 1, (2,)))
    Ec = dolfinx.fem.Constant(mesh, PETSc.ScalarType(E))
    nuc = dolfinx.fem.Constant(mesh, PETSc.ScalarType(nu))
    lmbda, mu = lame_parameters(Ec, nuc)
    s, t = ufl.TrialFunction(space.dg), ufl.TestFunction(space.dg)
    v = ufl.TestFunction(U)
    S, T = space.stress(s), space.stress(t)
    dx = ufl.dx(mesh)
    t0 = time.perf_counter()
    a = dolfinx.fem.form(ufl.inner(compliance(S, lmbda, mu), T) * dx)
    b = dolfinx.fem.form(ufl.inner(ufl.div(S), v) * dx)
    timings["forms"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    K = space.assemble_matrix(a)
    timings["PtAP"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    B = space.assemble_matrix(b)
    timings["BP"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if u_D is not None:
        n = ufl.FacetNormal(mesh)
        F = space.assemble_vector(ufl.inner(u_D, ufl.dot(T, n)) * ufl.ds(mesh))
    else:
        F = np.zeros(space.num_owned)
    if f is not None:
        G = space.assemble_vector(-ufl.inner(f, v) * dx)
    else:
        G = np.zeros(U.dofmap.index_map.size_local * 2)
    timings["rhs"] = time.perf_counter() - t0
    x, y, tsolve = solve_saddle_point(K, B, F, G)
    timings.update(tsolve)
    K.destroy()
    B.destroy()
    uh = dolfinx.fem.Function(U)
    uh.x.array[: y.size] = y
    uh.x.scatter_forward()
    return MixedElasticitySolution(space.to_dg(x), uh, x, timings)
