"""Primal solves with boundary conditions and obstacles; key numbers as JSON (rank 0).

Used by test_mpi_boundary.py, once serially and once under ``mpiexec -n 2``: u_D, two traction
groups, a curved gap (the manufactured problem of test_boundary_conditions.py), Algorithm 1 (Anderson
and the interface Newton), and
the Hertz cylinder with a moving obstacle (load steps).
"""

import json
import sys
from pathlib import Path

import fenics_contact  # noqa: F401
from mpi4py import MPI

sys.path[:0] = [str(Path(__file__).parent), str(Path(__file__).parents[1])]
import test_boundary_conditions as bc  # noqa: E402

from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic  # noqa: E402
from fenics_contact.hybrid.iteration import IterationOptions  # noqa: E402
from fenics_contact.hybrid.primal import solve_primal_hybrid  # noqa: E402
from fenics_contact.indentation import force_indentation  # noqa: E402
from fenics_contact.problem.analytic import hertz_model  # noqa: E402
from fenics_contact.problem.meshes import hertz_block  # noqa: E402

cm = bc._mesh(16)
model = bc.manufactured_model()
delta = default_penalty(cm.h, 1.0)
ref = solve_primal_monolithic(model.on(cm), delta=delta)
alg1 = solve_primal_hybrid(model.on(cm), delta=delta, reference=ref.u, options=IterationOptions(tol=1e-10, accel="anderson"))
newton = solve_primal_hybrid(model.on(cm), delta=delta, reference=ref.u,
                             options=IterationOptions(tol=1e-10, accel="newton"))
block, _ = hertz_block(0.05, refinement=0.5)
curve = force_indentation(hertz_model(radius=5.0, depth=0.0).on(block), "primal-monolithic", [6e-4, 1.2e-3],
                          direction=(0.0, -1.0))
out = {
    "ranks": MPI.COMM_WORLD.size,
    "force": ref.profile.force,
    "l2": ref.problem.l2_norm2(ref.u),
    "alg1_iterations": alg1.iterations,
    "alg1_e_u": alg1.e_u,
    "newton_converged": newton.converged,
    "newton_steps": newton.history.newton_steps,
    "newton_e_u": newton.e_u,
    "hertz_forces": curve.forces.tolist(),
    "hertz_zone": curve.steps[-1].profile.contact_zone(),
}
if MPI.COMM_WORLD.rank == 0:
    print("RESULT " + json.dumps(out))
