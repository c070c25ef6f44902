"""Algorithm 1 + interface Newton with the front extrapolation (model 3, E_high 1e6, h = 1/128, H = 1/16): one
RESULT line (JSON) with the contact Newton's record; run serially or under ``mpiexec -n 2`` by
``tests/test_interface_newton_fronts.py``."""

import json

import numpy as np

import fenics_contact  # noqa: F401  (before dolfinx / petsc4py)
from mpi4py import MPI

from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.primal import default_penalty
from fenics_contact.hybrid.iteration import InterfaceNewtonOptions, IterationOptions, iterate
from fenics_contact.hybrid.primal import DEFAULT_ALPHA, PrimalHybridStep
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model

cm = unit_square(128, 16)
step = PrimalHybridStep(get_model(3, E_high=1e6).on(cm), alpha=DEFAULT_ALPHA, delta=default_penalty(cm.h, 1e6),
                        newton=NewtonOptions(rtol=1e-6))
step.prepare()
history = iterate(step, IterationOptions(accel="newton", newton=InterfaceNewtonOptions(fronts=True)))
ch = history.contact_newton
cond = step.interface_problem(InterfaceNewtonOptions()).condensed
comm = MPI.COMM_WORLD
norm = float(np.sqrt(comm.allreduce(float(np.sum(history.data**2)), op=MPI.SUM)))  # the data g (owned values)
if comm.rank == 0:
    print("RESULT " + json.dumps({
        "ranks": comm.size, "converged": bool(history.converged), "residual": float(history.transmission_residual),
        "steps": int(history.newton_steps), "active_sizes": [int(a) for a in ch.active_sizes],
        "predicted": [int(e.size) for e in ch.extrapolated], "chains": [int(idx.size) for idx, _ in cond.chains],
        "norm": norm,
    }), flush=True)
