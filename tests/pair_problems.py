"""A two-body problem shared by the MPI tests of the pair: two blocks, the upper one tilted onto the lower one.

The upper block's top is pushed down on the left and lifted on the right (across a gap in the plane), so only part
of the contact surface touches and the active set changes while the Newton iterates: the case on which a
parallel contact search and a parallel solve can differ from the serial ones.
"""

import numpy as np
from mpi4py import MPI

from fenics_contact.problem.pair import Body, ContactPair, Support, TwoBodyProblem
from fenics_contact.problem.pair_meshes import PairTag as T
from fenics_contact.problem.pair_meshes import fault_strata, two_blocks

__all__ = ["strata_pair", "tilted_pair"]


def tilted_pair(comm: MPI.Comm, cells: tuple[int, int], dim: int = 2) -> TwoBodyProblem:
    """Blocks of ``cells`` = (lower, upper) cells per side, E = 1 and 5; the top moved by (push − tilt·x) downwards."""
    if dim == 2:
        m = two_blocks(*cells, heights=(0.5, 0.4), gap=0.004, comm=comm)
        top = lambda x: np.vstack([0.0 * x[0], 0.01 - 0.03 * x[0]])  # noqa: E731
    else:
        m = two_blocks(*cells, heights=(0.5, 0.4), dim=3, comm=comm)
        top = lambda x: np.vstack([0.0 * x[0], 0.0 * x[0], 0.005 - 0.02 * x[0]])  # noqa: E731
    return TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(Body(T.LOWER, 1.0, 0.3), Body(T.UPPER, 5.0, 0.2)),
        pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP),
        supports=(Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP, top)),
    )


def strata_pair(m, friction=None, top=(0.0, -0.005), tractions=None, contrast: float = 1e3) -> TwoBodyProblem:
    """The fault-like pair on the two-block mesh ``m``: the strata of ``pair_meshes.fault_strata(contrast)`` (ν = 0.3
    below, 0.2 above), the lower block's bottom held, the upper block's top moved by ``top`` (a vector or a
    callable), the contact law ``friction`` (None: frictionless)."""
    lower, upper = fault_strata(contrast)
    return TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(Body(T.LOWER, lower, 0.3), Body(T.UPPER, upper, 0.2)),
        pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP, friction=friction),
        supports=(Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP, top)),
        tractions=tractions or {},
    )
