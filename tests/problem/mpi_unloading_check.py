"""Load steps down to a vanishing solution on N ranks: print each step's numbers as JSON (rank 0).

    python mpi_unloading_check.py method accel

Used by test_obstacles.py under ``mpiexec -n 2`` (two ranks once failed here where one rank passed: the
warm-started Ω₂ solve at nearly collapsed data missed its own residual check before the collapse was seen).
"""

import json
import sys

import fenics_contact  # noqa: F401
from mpi4py import MPI

from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.indentation import force_indentation
from fenics_contact.problem.analytic import layered_model
from fenics_contact.problem.geometry import unit_square

method, accel = sys.argv[1:3]
cm = unit_square(8, 4, clamped=("left",))
model = layered_model([0.0, 0.5, 1.0], [1.0, 100.0], depth=0.0)
curve = force_indentation(model.on(cm), method, [0.01, 0.0, -0.01], direction=(-1.0, 0.0),
                          options=IterationOptions(tol=1e-9, accel=accel, max_iterations=300))
if MPI.COMM_WORLD.rank == 0:
    print("RESULT " + json.dumps({
        "ranks": MPI.COMM_WORLD.size,
        "steps": [dict(converged=s.converged, force=s.force, residual=s.transmission_residual,
                       iterations=s.iterations) for s in curve.steps],
    }), flush=True)
