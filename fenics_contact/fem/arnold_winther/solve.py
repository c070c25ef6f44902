"""Hellinger–Reissner mixed elasticity with AW stresses and DG P1 displacements (no contact), by MUMPS LU.

Find (σ, u) ∈ X_h × U_h: (Aσ, τ) + (div τ, u) = ⟨u_D, τn⟩_∂Ω,  (div σ, v) = −(f, v): the verification
solve of the space (rates in ``tests/fem/test_arnold_winther.py``, ``benchmarks/arnold_winther_rates.py``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import dolfinx
import dolfinx.fem
import numpy as np
import numpy.typing as npt
import ufl
from petsc4py import PETSc

from fenics_contact.fem.arnold_winther.space import ArnoldWintherSpace
from fenics_contact.fem.arnold_winther.tensors import compliance, lame_parameters
from fenics_contact.fem.distributed import SaddlePointMatrix

__all__ = ["MixedElasticitySolution", "solve_mixed_elasticity", "solve_saddle_point"]


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
