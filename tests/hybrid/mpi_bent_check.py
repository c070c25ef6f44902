"""Algorithm 2 (Anderson) on the zigzag γ of ``test_mixed_bent_interface``, on however many ranks it is launched:
prints ``RESULT {json}`` on rank 0 (iterations, errors against the split monolithic solution, force)."""

import json

from mpi4py import MPI

from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.mixed import solve_mixed_hybrid
from test_mixed_bent_interface import zigzag_problem

problem = zigzag_problem(16)
split = solve_mixed_monolithic(problem, split_interface=True)
result = solve_mixed_hybrid(problem, reference=split, options=IterationOptions(accel="anderson", tol=1e-10))
if MPI.COMM_WORLD.rank == 0:
    print("RESULT " + json.dumps({
        "ranks": MPI.COMM_WORLD.size, "converged": bool(result.converged), "iterations": result.history.iterations,
        "e_sigma": result.e_sigma, "e_u": result.e_u, "residual": float(result.history.residuals[-1]),
        "force": float(result.profile.force), "force_split": float(split.profile.force),
    }))
