"""The manufactured contact problem that exercises every boundary condition at once (u_D, two traction groups, a
curved gap with the whole of Γ_C in contact): u quadratic with ε_xy = 0, so σ is linear with σ_xy = 0."""

import numpy as np
from mpi4py import MPI

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.obstacles import SignedDistance
from fenics_contact.problem.problem import ContactProblem, constant_field

__all__ = ["E", "NU", "LAM", "MU", "GROUPS", "displacement", "stress", "manufactured_model", "manufactured_mesh"]

E, NU = 1.0, 0.3
LAM, MU = E * NU / ((1 + NU) * (1 - 2 * NU)), E / (2 * (1 + NU))
GROUPS = {"top": "Gamma_N_top", "bottom": "Gamma_N_bottom"}


def displacement(x):
    """The exact displacement u (quadratic, ε_xy = 0)."""
    return np.vstack([-0.1 * x[0] ** 2 + 0.05 * x[1] ** 2 - 0.2 * x[0], -0.1 * x[0] * x[1] + 0.02 * x[1] ** 2])


def stress(x):
    """The exact stress (σ_xx, σ_xy, σ_yy), linear with σ_xy = 0."""
    exx, eyy = -0.2 * x[0] - 0.2, -0.1 * x[0] + 0.04 * x[1]
    return np.vstack([(LAM + 2 * MU) * exx + LAM * eyy, 0 * x[0], LAM * exx + (LAM + 2 * MU) * eyy])


def manufactured_model() -> ContactProblem:
    """E = 1, ν = 0.3, the constant load −div σ, u = u_D on Γ_D, the exact tractions on GROUPS, the gap u_x(1, y)."""
    f = np.array([0.2 * (LAM + 2 * MU) + 0.1 * LAM, -0.04 * (LAM + 2 * MU)])  # −div σ (constant)
    top = lambda x: np.vstack([0 * x[0], stress(x)[2]])  # noqa: E731  σn, n = (0, 1)
    bottom = lambda x: np.vstack([0 * x[0], -stress(x)[2]])  # noqa: E731  n = (0, −1)
    gap = SignedDistance(
        lambda x: 0.05 * x[1] ** 2 - 0.3 + (1.0 - x[0]),
        normal=lambda x: np.vstack([-np.ones(x.shape[1]), np.zeros(x.shape[1])]),
    )
    return ContactProblem(
        name="manufactured",
        youngs_modulus=constant_field(E),
        poisson_ratio=constant_field(NU),
        load=lambda x: np.repeat(f[:, None], x.shape[1], axis=1),
        boundary=BoundaryConditions(
            displacement=displacement, tractions={GROUPS["top"]: top, GROUPS["bottom"]: bottom}
        ),
        obstacle=gap,
    )


def manufactured_mesh(n: int, comm: MPI.Comm = MPI.COMM_WORLD):
    """The unit square with h = 1/n, H = 1/4, the left side Γ_D and the two traction groups of GROUPS."""
    return unit_square(n, 4, clamped=("left",), neumann=GROUPS, comm=comm)
