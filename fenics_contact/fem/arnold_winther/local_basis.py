"""The local nodal basis of the Arnold–Winther element on each cell, computed in physical coordinates.

    X_T = {σ ∈ P3(T; S) : div σ ∈ P1(T; R²)},   dim X_T = 24.

The element is not affine-equivalent, so the basis φ_i with ℓ_j(φ_i) = δ_ij (``functionals``) is computed
per cell from a spanning set in scaled coordinates ξ = (x − x_T)/h_T: the 18 symmetric P2 tensors plus the
6 Airy stresses curl curl(ξ^a η^b), a + b = 5 (homogeneous cubic, divergence-free), which together span
exactly X_T.  The 24×24 matrix D_ij = ℓ_i(span_j) is inverted cell by cell (well conditioned: every ℓ_i has
the size of a stress value, and ξ is O(1)).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fenics_contact.fem.arnold_winther.functionals import (
    CELL_Q,
    CELL_W,
    EDGE_VERTICES,
    MOMENT_WEIGHTS,
    NUM_LOCAL,
    edge_frames,
    edge_points,
    map_to_cells,
)

__all__ = ["NODAL_BASIS_BATCH", "local_nodal_basis"]

#: Monomials ξ^p η^q of degree ≤ 3.
_MONOMIALS = np.array([(p, d - p) for d in range(4) for p in range(d, -1, -1)], dtype=np.int64)


def _span_coefficients() -> np.ndarray:
    """Monomial coefficients of the 24 spanning functions, shape (10, 3, 24).

    Entry [m, j, k]: coefficient of monomial m in component j ∈ (xx, xy, yy)
    of spanning function k.  Functions 0..17 are the symmetric P2 tensors, 18..23
    the Airy stresses [[φ_ηη, -φ_ξη], [-φ_ξη, φ_ξξ]] / 20 of φ = ξ^a η^(5-a).
    """
    index = {tuple(m): i for i, m in enumerate(_MONOMIALS)}
    C = np.zeros((len(_MONOMIALS), 3, NUM_LOCAL))
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
    assert k == NUM_LOCAL
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
        mono.shape[:-1] + (3, NUM_LOCAL)
    )


def _eval_span(xi: np.ndarray) -> np.ndarray:
    """Spanning functions at scaled points ξ (..., 2) -> values (..., 3, 24)."""
    return _span_of(_monomials(xi))


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
        out = np.empty((n, points.shape[0], 3, NUM_LOCAL))
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
    edges = vertices[:, EDGE_VERTICES[:, 1]] - vertices[:, EDGE_VERTICES[:, 0]]
    h = np.linalg.norm(edges, axis=-1).max(axis=1)  # (n,)

    def scaled(x: np.ndarray) -> np.ndarray:
        shape = (n,) + (1,) * (x.ndim - 2) + (2,)
        return (x - centre.reshape(shape)) / h.reshape(shape[:-1] + (1,))

    D = np.empty((n, NUM_LOCAL, NUM_LOCAL))
    # vertex values
    D[:, 0:9, :] = _eval_span(scaled(vertices)).reshape(n, 9, NUM_LOCAL)
    # edge moments, taken on the monomials first (10 numbers per moment, not 72 per Gauss point)
    a = np.where(edge_flip, EDGE_VERTICES[:, 1], EDGE_VERTICES[:, 0])  # (n, 3)
    b = np.where(edge_flip, EDGE_VERTICES[:, 0], EDGE_VERTICES[:, 1])
    rows = np.arange(n)[:, None]
    start, end = vertices[rows, a], vertices[rows, b]  # (n, 3, 2)
    wn, wt = edge_frames(start, end)
    q = MOMENT_WEIGHTS
    moments = _span_of(np.einsum("lq,neqm->nelm", q, _monomials(scaled(edge_points(start, end)))))
    D[:, 9:21, :] = np.concatenate(
        [np.einsum("nej,nelji->neli", wn, moments), np.einsum("nej,nelji->neli", wt, moments)], axis=2
    ).reshape(n, 12, NUM_LOCAL)
    # cell averages
    D[:, 21:24, :] = _span_of(np.einsum("q,nqm->nm", CELL_W, _monomials(scaled(map_to_cells(vertices, CELL_Q)))))

    C = np.linalg.solve(D, np.broadcast_to(np.eye(NUM_LOCAL), D.shape))  # span coeffs
    values = _eval_span(scaled(map_to_cells(vertices, points)))  # (n, m, 3, 24)
    return (values.reshape(n, 3 * points.shape[0], NUM_LOCAL) @ C).reshape(n, points.shape[0], 3, NUM_LOCAL)
