"""Run the monolithic solve and Algorithm 1 and print key numbers as JSON (rank 0).

    python mpi_check.py n n_coarse model [accel]     (accel: anderson (default), newton)

Used by test_mpi.py: once serially and once under ``mpiexec -n 2``; the numbers must agree.
"""

import json
import sys

import fenics_contact  # noqa: F401
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx import fem

from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.primal import solve_primal_hybrid

n, n_coarse, model_number = (int(a) for a in sys.argv[1:4])
accel = sys.argv[4] if len(sys.argv) > 4 else "anderson"
cm = unit_square(n, n_coarse)
problem = get_model(model_number).on(cm)
delta = default_penalty(cm.h, 1e3 if model_number == 3 else 1.0)  # model 3: stiff channels reach Γ_C
ref = solve_primal_monolithic(problem, delta=delta)
res = solve_primal_hybrid(problem, alpha="E", delta=delta, reference=ref.u,
                          options=IterationOptions(tol=1e-8 if accel == "anderson" else 1e-10, accel=accel))


def norm(u):
    local = fem.assemble_scalar(fem.form(ufl.inner(u, u) * ufl.dx))
    return float(np.sqrt(cm.comm.allreduce(local, op=MPI.SUM)))


out = {
    "ranks": cm.comm.size,
    "newton_steps": ref.newton.steps,
    "active_sizes": ref.newton.active_sizes,
    "ref_norm": norm(ref.u),
    "hybrid_norm": norm(res.u),
    "iterations": res.iterations,
    "rel_changes": res.history.rel_changes.tolist(),
    "residuals": res.history.residuals.tolist(),
    "converged": res.converged,
    "interface_newton_steps": res.history.newton_steps,
    "e_u": res.e_u,
    "active_set": res.profile.active_interval(),
    "ref_active_set": ref.profile.active_interval(),
    "sigma_c": ref.profile.sigma_c.tolist(),
}
if cm.comm.rank == 0:
    print("RESULT " + json.dumps(out))
