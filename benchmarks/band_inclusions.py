"""The band preconditioner of the AMG Ω₁'s Newton–GMRES (``hybrid.krylov_band``) on a user gmsh block whose stiff
inclusion γ cuts.

The unit cube meshed by gmsh (tetrahedra graded from 0.07 at Γ_C = {x = 1} to 0.2 at Γ_D = {x = 0}) with three
spherical inclusions of E = contrast in a matrix of E = 1 (ν = 0.3): centres (0.3, 0.5, 0.5), (0.62, 0.3, 0.5) and
the third at (0.75, 0.7, 0.4) (``--placement cut``: γ, the face of the strip of width ¼, cuts it in half) or at
(0.45, 0.75, 0.4) (``away``), radii 0.15, 0.12, 0.1; a body force pushes the block onto the wall at Γ_C.  Per
contrast, band width (``krylov_layers``) and transmission tolerance (``--tol``): how Algorithm 1 ended (its status:
converged below tol, converged at the transmission residual's round-off floor, or not converged), that floor, its
Newton steps and GMRES products (one Ω₁ solve each), and its distance to the monolithic solution.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/band_inclusions.py --placement cut away --tol 1e-9 1e-10
"""

import argparse
import tempfile
from pathlib import Path

import gmsh
import numpy as np

import fenics_contact as fc
from fenics_contact.fem.amg import LinearSolverOptions
from fenics_contact.problem.geometry import gmsh_session, read_mesh
from fenics_contact.problem.problem import ContactProblem

SPHERES = [((0.3, 0.5, 0.5), 0.15), ((0.62, 0.3, 0.5), 0.12)]
THIRD = {"cut": ((0.75, 0.7, 0.4), 0.1), "away": ((0.45, 0.75, 0.4), 0.1)}


def block(path: Path, spheres) -> None:
    with gmsh_session():
        gmsh.model.add("block")
        occ = gmsh.model.occ
        box = occ.addBox(0, 0, 0, 1, 1, 1)
        occ.fragment([(3, box)], [(3, occ.addSphere(*c, r)) for c, r in spheres])
        occ.synchronize()
        volumes = [t for _, t in gmsh.model.getEntities(3)]
        matrix = max(volumes, key=lambda t: occ.getMass(3, t))
        gmsh.model.addPhysicalGroup(3, [matrix], name="matrix")
        gmsh.model.addPhysicalGroup(3, [t for t in volumes if t != matrix], name="inclusions")
        for x, name in ((0.0, "Gamma_D"), (1.0, "Gamma_C")):
            faces = gmsh.model.getEntitiesInBoundingBox(x - 1e-6, -1e-6, -1e-6, x + 1e-6, 1 + 1e-6, 1 + 1e-6, 2)
            gmsh.model.addPhysicalGroup(2, [t for _, t in faces], name=name)
        size = gmsh.model.mesh.field.add("MathEval")
        gmsh.model.mesh.field.setString(size, "F", "0.07 + 0.13 * (1 - x)")
        gmsh.model.mesh.field.setAsBackgroundMesh(size)
        for option in ("MeshSizeExtendFromBoundary", "MeshSizeFromPoints", "MeshSizeFromCurvature"):
            gmsh.option.setNumber(f"Mesh.{option}", 0)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))


def problem(cm, spheres, contrast: float):
    def E(x):
        inside = np.zeros(x.shape[1], dtype=bool)
        for c, r in spheres:
            inside |= np.sum((x - np.array(c)[:, None]) ** 2, axis=0) < r * r
        return np.where(inside, contrast, 1.0)

    def push(x):
        f = np.zeros((3, x.shape[1]))
        f[0] = np.where((x[0] > 0.4) & (x[0] < 0.7), np.where(x[1] < 0.5, 1.0, 0.3), 0.0)
        return f

    return ContactProblem(name="block", youngs_modulus=E, poisson_ratio=0.3, load=push).on(cm)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--placement", nargs="+", default=["cut", "away"], choices=sorted(THIRD))
    parser.add_argument("--contrast", type=float, nargs="+", default=[1.0, 1e3, 1e6])
    parser.add_argument("--layers", type=int, nargs="+", default=[2, 4])
    parser.add_argument("--tol", type=float, nargs="+", default=[1e-9, 1e-10])
    args = parser.parse_args()
    print(
        "| third sphere | DOFs | contrast | krylov_layers | tol | status | floor | Newton steps | GMRES products "
        "| ‖u − u_mono‖/‖u_mono‖ |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for placement in args.placement:
            spheres = [*SPHERES, THIRD[placement]]
            path = Path(tmp) / f"{placement}.msh"
            block(path, spheres)
            cm = read_mesh(path, H=0.25)
            for contrast in args.contrast:
                p = problem(cm, spheres, contrast)
                mono = fc.solve(p, "primal-monolithic", solver="direct")
                for layers in args.layers:
                    for tol in args.tol:
                        amg = LinearSolverOptions(kind="amg", rtol=1e-12)
                        result = fc.solve(p, "primal", reference=mono.u, tol=tol, solver=amg, krylov_layers=layers)
                        products = result.step.krylov_interface().products
                        print(
                            f"| {placement} | {mono.dofs} | {contrast:g} | {layers} | {tol:g} | "
                            f"{result.status} | {result.floor:.1e} | {result.history.newton_steps} | {products} | "
                            f"{result.e_u:.1e} |",
                            flush=True,
                        )


if __name__ == "__main__":
    main()
