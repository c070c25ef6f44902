"""The 24 degrees of freedom of the lowest-order Arnold–Winther element, their quadrature and the interpolant.

On a triangle T the DOF functionals ℓ_i are

* at each vertex the three Cartesian components σ_xx, σ_xy, σ_yy (9),
* on each edge e the averages (1/|e|)∫_e σn·n q ds and (1/|e|)∫_e σn·t q ds for q ∈ {1, 2s−1}, s ∈ [0, 1]
  the arc-length parameter from the lower to the higher *global* vertex number, t the unit tangent in that
  direction and n = (t_y, −t_x) (12),
* the three cell averages (1/|T|)∫_T σ_ij dx (3).

The edge averages use 4 Gauss–Legendre points (exact to degree 7; the integrand has degree 4), the cell
averages the degree-6 rule of basix.  Every functional has the size of a stress value.
"""

from __future__ import annotations

from collections.abc import Callable

import basix
import numpy as np

__all__ = [
    "CELL_Q",
    "CELL_W",
    "EDGE_S",
    "EDGE_VERTICES",
    "EDGE_W",
    "MOMENT_WEIGHTS",
    "NUM_LOCAL",
    "dof_values",
    "edge_frames",
    "edge_moments",
    "edge_points",
    "map_to_cells",
]

#: Local edge k of the basix reference triangle joins these local vertices.
EDGE_VERTICES = np.array([[1, 2], [0, 2], [0, 1]], dtype=np.int64)
#: Local DOFs of one cell: 9 vertex values, 12 edge moments, 3 cell averages.
NUM_LOCAL = 24


def _gauss_legendre_01(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre points/weights on [0, 1], weights summing to 1."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


#: Edge quadrature on [0, 1] (points s, weights summing to 1): exact to degree 7 (integrand degree 4).
EDGE_S, EDGE_W = _gauss_legendre_01(4)
#: Cell quadrature on the reference triangle, weights normalised to 1 (averages on the cell).
CELL_Q, CELL_W = basix.make_quadrature(basix.CellType.triangle, 6)
CELL_W = CELL_W / CELL_W.sum()
#: (2, nq): the edge weights times q = 1 and q = 2s − 1 (the two moments per traction component).
MOMENT_WEIGHTS = np.stack([EDGE_W, EDGE_W * (2.0 * EDGE_S - 1.0)])


def edge_frames(start: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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


def edge_moments(values: np.ndarray, wn: np.ndarray, wt: np.ndarray) -> np.ndarray:
    """Edge DOFs from values (..., nq, 3, K) at the edge Gauss points -> (..., 4, K).

    Order: σn·n against 1, 2s-1, then σn·t against 1, 2s-1.
    """
    q = MOMENT_WEIGHTS
    snn = np.einsum("...j,...qjk->...qk", wn, values)
    snt = np.einsum("...j,...qjk->...qk", wt, values)
    return np.concatenate([np.einsum("lq,...qk->...lk", q, snn), np.einsum("lq,...qk->...lk", q, snt)], axis=-2)


def edge_points(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Gauss points on edges start→end: (..., 2) -> (..., nq, 2)."""
    return start[..., None, :] + EDGE_S[:, None] * (end - start)[..., None, :]


def map_to_cells(vertices: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Affine map of reference points (m, 2) into cells (n, 3, 2) -> (n, m, 2)."""
    v0 = vertices[:, 0, :]
    J = np.stack([vertices[:, 1] - v0, vertices[:, 2] - v0], axis=-1)  # (n, 2, 2)
    return v0[:, None, :] + np.einsum("nij,mj->nmi", J, ref)


def dof_values(
    sigma: Callable[[np.ndarray], np.ndarray],
    vertices: np.ndarray,
    edge_start: np.ndarray,
    edge_end: np.ndarray,
    cells: np.ndarray,
) -> np.ndarray:
    """ℓ_i(σ) for every DOF of the full local numbering: 3v + j, then 3n_v + 4e + k, then 3n_v + 4n_e + 3c + j.

    ``sigma``: x (3, N) -> (σ_xx, σ_xy, σ_yy) (3, N); ``vertices`` (n_v, 2) coordinates, the edges from
    ``edge_start`` to ``edge_end`` (n_e, 2) (global orientation), ``cells`` (n_c, 3, 2) vertex coordinates.
    """
    nv, ne, nc = vertices.shape[0], edge_start.shape[0], cells.shape[0]
    epts = edge_points(edge_start, edge_end)  # (ne, nq, 2)
    cpts = map_to_cells(cells, CELL_Q)  # (nc, nqc, 2)
    pts = np.concatenate([vertices, epts.reshape(-1, 2), cpts.reshape(-1, 2)])
    x = np.zeros((3, pts.shape[0]))
    x[:2] = pts.T
    val = np.asarray(sigma(x), dtype=np.float64).reshape(3, -1).T  # (N, 3)
    d = np.empty(3 * nv + 4 * ne + 3 * nc)
    d[: 3 * nv] = val[:nv].ravel()
    ev = val[nv : nv + epts.shape[0] * epts.shape[1]].reshape(ne, len(EDGE_S), 3, 1)
    wn, wt = edge_frames(edge_start, edge_end)
    d[3 * nv : 3 * nv + 4 * ne] = edge_moments(ev, wn, wt).reshape(-1)
    cv = val[nv + epts.shape[0] * epts.shape[1] :].reshape(nc, len(CELL_W), 3)
    d[3 * nv + 4 * ne :] = np.einsum("q,nqj->nj", CELL_W, cv).ravel()
    return d
