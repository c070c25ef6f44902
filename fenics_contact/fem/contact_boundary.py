"""The contact boundary Γ_C and the obstacle at its nodes, as both the primal and the mixed subproblems need them.

A subproblem with contact checks that Γ_C has facets when an obstacle is given (a mesh without the
physical group 'Gamma_C' would otherwise ignore the obstacle silently), and evaluates the obstacle at its
contact nodes — the primal method's Γ_C vertices, the mixed method's Gauss–Lobatto nodes — as the gap g and
the direction ν towards the obstacle, after checking that the obstacle lies on the outer side of Γ_C.
Without an obstacle the wall is flush with Γ_C: g = 0 and ν is the body's outward normal.
"""

import numpy as np
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.problem.obstacles import Obstacle, check_obstacle_side, evaluate_obstacle

__all__ = ["contact_boundary_present", "obstacle_at_nodes"]


def contact_boundary_present(comm: MPI.Comm, facets: np.ndarray, obstacle: Obstacle | None) -> bool:
    """Whether Γ_C has facets on any rank (``facets``: this rank's); InputError if an obstacle is given and it
    has none (collective)."""
    present = comm.allreduce(int(np.asarray(facets).size), op=MPI.SUM) > 0
    if not present and obstacle is not None:
        raise InputError(
            "an obstacle is given but the mesh has no contact boundary: the physical group 'Gamma_C' "
            "has no facets (tag the facets that may touch the obstacle as Gamma_C)"
        )
    return present


def obstacle_at_nodes(
    obstacle: Obstacle | None, points: np.ndarray, normals: np.ndarray, *, comm=None
) -> tuple[np.ndarray, np.ndarray]:
    """(g, ν) at contact nodes ``points`` (N, 2 or 3) with outward body normals ``normals`` (N, d), d the
    dimension: the obstacle's gap and direction (side checked: ``check_obstacle_side``), or (0, ``normals``)
    without one.
    With ``comm`` the checks are collective (nodes distributed); without, the nodes are replicated."""
    if obstacle is None:
        return np.zeros(np.asarray(points).shape[0]), normals
    g, nu = evaluate_obstacle(obstacle, points, dim=np.shape(normals)[1], comm=comm)
    check_obstacle_side(obstacle, nu, normals, g, comm=comm)
    return g, nu
