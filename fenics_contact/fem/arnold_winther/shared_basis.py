"""The local nodal bases of a replicated serial mesh, shared out over the ranks that all hold it.

Algorithm 4 replicates Ω₁ on every rank of its offline phase; instead of every rank computing the
nodal basis of every cell (``local_nodal_basis``), each computes a contiguous share and one
``Allgatherv`` gives every rank all of them (the same numbers: a cell's basis does not depend on the batch).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from fenics_contact.fem.arnold_winther.functionals import NUM_LOCAL
from fenics_contact.fem.arnold_winther.local_basis import local_nodal_basis

__all__ = ["shared_nodal_basis"]


def shared_nodal_basis(
    vertices: npt.NDArray[np.floating],
    edge_flip: npt.NDArray[np.bool_],
    points: npt.NDArray[np.floating],
    comm: MPI.Comm,
    column_order: np.ndarray | None = None,
) -> np.ndarray:
    """``local_nodal_basis`` of all cells on every rank of ``comm``, each rank computing a contiguous share
    (the ranks hold the same cells: a replicated serial mesh) and one ``Allgatherv`` joining them."""
    n = vertices.shape[0]
    bounds = np.linspace(0, n, comm.size + 1).astype(np.int64)
    lo, hi = bounds[comm.rank], bounds[comm.rank + 1]
    out = np.empty((n, np.asarray(points).shape[0], 3, NUM_LOCAL))
    local_nodal_basis(
        vertices[lo:hi],
        edge_flip[lo:hi],
        points,
        out=out[lo:hi],
        column_order=None if column_order is None else column_order[lo:hi],
    )
    width = int(np.prod(out.shape[1:], dtype=np.int64))
    comm.Allgatherv(MPI.IN_PLACE, [out, (np.diff(bounds) * width, bounds[:-1] * width), MPI.DOUBLE])
    return out
