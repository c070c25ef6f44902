"""Meshes and manufactured fields of the Arnold–Winther tests: warped, rotated unit squares, their sides, and
displacements with known stresses (locking-free, sliding, traction-free on x = 1)."""

import dolfinx
import dolfinx.mesh
import dolfinx_solver  # noqa: F401  (must precede dolfinx / petsc4py)
import numpy as np
import ufl
from mpi4py import MPI

from fenics_contact.fem.arnold_winther import lame_parameters

__all__ = [
    "unit_square",
    "rotation",
    "side_facets",
    "exact_fields",
    "locking_displacement",
    "sliding_displacement",
    "free_displacement",
]


def unit_square(
    n: int,
    *,
    warp: float = 0.0,
    angle: float = 0.0,
    diagonal=None,
    jitter: float = 0.0,
    seed=0,
    comm: MPI.Comm = MPI.COMM_WORLD,
):
    """Unit square mesh, optionally warped (x += c sin 2πx sin 2πy), jittered, then rotated."""
    kw = {} if diagonal is None else {"diagonal": diagonal}
    mesh = dolfinx.mesh.create_unit_square(comm, n, n, **kw)
    x = mesh.geometry.x
    if warp:
        bump = warp * np.sin(2 * np.pi * x[:, 0]) * np.sin(2 * np.pi * x[:, 1])
        x[:, 0] += bump
        x[:, 1] += bump
    if jitter:
        interior = (x[:, 0] > 1e-12) & (x[:, 0] < 1 - 1e-12) & (x[:, 1] > 1e-12) & (x[:, 1] < 1 - 1e-12)
        rng = np.random.default_rng(seed)
        x[interior, :2] += jitter / n * rng.uniform(-1, 1, (interior.sum(), 2))
    if angle:
        c, s = np.cos(angle), np.sin(angle)
        x[:, :2] = x[:, :2] @ np.array([[c, s], [-s, c]])  # rows: Q x
    return mesh


def rotation(angle: float):
    c, s = np.cos(angle), np.sin(angle)
    return ufl.as_matrix([[c, -s], [s, c]])


def side_facets(mesh, angle: float, which: str):
    """Facets on the image of the side {x = 1} ('right') or {y = 0} ('bottom') under the rotation."""
    c, s = np.cos(angle), np.sin(angle)

    def marker(x):
        xr = c * x[0] + s * x[1]  # Qᵀ x
        yr = -s * x[0] + c * x[1]
        return np.isclose(xr, 1.0) if which == "right" else np.isclose(yr, 0.0)

    mesh.topology.create_connectivity(1, 2)
    return dolfinx.mesh.locate_entities_boundary(mesh, 1, marker)


def exact_fields(mesh, u_fn, E, nu, angle=0.0):
    """u(x) = Q u0(Qᵀ x) for a UFL displacement u0 of the reference frame; returns (u, σ, f)."""
    x = ufl.SpatialCoordinate(mesh)
    Q = rotation(angle)
    u = Q * u_fn(Q.T * x)
    lmbda, mu = lame_parameters(E, nu)
    eps = ufl.sym(ufl.grad(u))
    sigma = 2 * mu * eps + lmbda * ufl.tr(eps) * ufl.Identity(2)
    return u, sigma, -ufl.div(sigma)


def locking_displacement(lmbda):
    """u = curl ψ + w/λ, ψ = (x(1-x)y(1-y))², both parts vanish on ∂(0,1)²."""

    def u(x):
        psi = (x[0] * (1 - x[0]) * x[1] * (1 - x[1])) ** 2
        w = ufl.as_vector([ufl.sin(ufl.pi * x[0]) * ufl.sin(ufl.pi * x[1]), x[0] * x[1] * (1 - x[0]) * (1 - x[1])])
        return ufl.as_vector([psi.dx(1), -psi.dx(0)]) + w / lmbda

    return u


def sliding_displacement(x):
    """σ_xy = 0 on x = 1: u = (eˣ sin 2y, -2e(x-1) cos 2y + cos πx sin πy)."""
    return ufl.as_vector(
        [
            ufl.exp(x[0]) * ufl.sin(2 * x[1]),
            -2 * ufl.e * (x[0] - 1) * ufl.cos(2 * x[1]) + ufl.cos(ufl.pi * x[0]) * ufl.sin(ufl.pi * x[1]),
        ]
    )


def free_displacement(x):
    """∇u = 0 (so σ = 0) on x = 1: u = (1-x)² (sin πy + x, cos(x + 2y))."""
    g = (1 - x[0]) ** 2
    return g * ufl.as_vector([ufl.sin(ufl.pi * x[1]) + x[0], ufl.cos(x[0] + 2 * x[1])])
