"""Convergence rates and cost of mixed elasticity with the Arnold–Winther stress space (no contact).

Solves the Hellinger–Reissner problem (``fem.arnold_winther.solve_mixed_elasticity``: AW stresses,
DG P1 displacements, u = u_D natural on the whole boundary) on the unit square, optionally warped
(x += w·sin 2πx sin 2πy in both coordinates), for the manufactured solution u = curl ψ + w/λ with
ψ = (x(1−x)y(1−y))², w = (sin πx sin πy, x y (1−x)(1−y)) (divergence-free up to w/λ, so the error must
not grow as ν → ½).  For each 1/h it prints the AW and displacement DOF counts, the time of every
phase (nodal basis and P, forms, PtAP, BP, load, block matrix, MUMPS LU) and the L² errors of u, σ and
div σ with the rates between successive sizes (expected 2, 3, 2: ``tests/fem/test_arnold_winther.py``).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/arnold_winther_rates.py --sizes 16 32 64 --nu 0.3
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/arnold_winther_rates.py --nu 0.4999 --warp 0.03

Runs under ``mpiexec -n N`` too (the mesh is distributed over ``COMM_WORLD``; every rank prints).
"""

import argparse
import time

import dolfinx
import dolfinx.fem
import dolfinx.mesh
import numpy as np
import ufl
from mpi4py import MPI

import fenics_contact  # noqa: F401  (dolfinx_solver before dolfinx)
from fenics_contact.fem.arnold_winther import ArnoldWintherSpace, lame_parameters, solve_mixed_elasticity


def benchmark(sizes: list[int], nu: float, warp: float) -> None:
    """Unit square, u = curl ψ + w/λ: print DOFs, timings, errors and rates."""
    prev = None
    for n in sizes:
        mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, n, n)
        x = mesh.geometry.x
        bump = warp * np.sin(2 * np.pi * x[:, 0]) * np.sin(2 * np.pi * x[:, 1])
        x[:, 0] += bump
        x[:, 1] += bump
        space = ArnoldWintherSpace(mesh)
        X = ufl.SpatialCoordinate(mesh)
        lmbda, mu = lame_parameters(1.0, nu)
        psi = (X[0] * (1 - X[0]) * X[1] * (1 - X[1])) ** 2
        w = ufl.as_vector([ufl.sin(ufl.pi * X[0]) * ufl.sin(ufl.pi * X[1]), X[0] * X[1] * (1 - X[0]) * (1 - X[1])])
        u = ufl.as_vector([psi.dx(1), -psi.dx(0)]) + w / lmbda
        eps = ufl.sym(ufl.grad(u))
        sigma = 2 * mu * eps + lmbda * ufl.tr(eps) * ufl.Identity(2)
        f = -ufl.div(sigma)
        t0 = time.perf_counter()
        sol = solve_mixed_elasticity(space, E=1.0, nu=nu, f=f, u_D=u)
        total = time.perf_counter() - t0 + space.build_time
        S = space.stress(sol.sigma)
        dx = ufl.dx(domain=mesh, metadata={"quadrature_degree": 8})
        errs = np.array(
            [
                np.sqrt(dolfinx.fem.assemble_scalar(dolfinx.fem.form(ufl.inner(e, e) * dx)))
                for e in (u - sol.u, sigma - S, ufl.div(S) + f)
            ]
        )
        tim = ", ".join(f"{k} {v:.2f}s" for k, v in sol.timings.items())
        print(f"n={n}: AW dofs {space.num_dofs}, u dofs {sol.u.x.array.size}; {tim}; total {total:.2f}s")
        print(f"   errors (u, σ, div σ) = {errs}" + ("" if prev is None else f", rates {np.log2(prev / errs)}"))
        prev = errs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[16, 32, 64], help="1/h of the meshes")
    parser.add_argument("--nu", type=float, default=0.3, help="Poisson ratio (E = 1)")
    parser.add_argument("--warp", type=float, default=0.0, help="amplitude w of the mesh warp")
    args = parser.parse_args()
    benchmark(args.sizes, args.nu, args.warp)


if __name__ == "__main__":
    main()
