"""Algorithm 4 with its offline phase shared over MPI ranks; prints key numbers as JSON (rank 0).

Used by test_mixed_ms_mpi.py: once serially and once under ``mpiexec -n 2``; the numbers must agree.
Every rank holds the whole mesh (COMM_SELF: the Arnold–Winther space is serial); the Stage I cells,
Stage II patches and coarse-operator cells are shared out over COMM_WORLD.
"""

import hashlib
import json
import sys

import fenics_contact  # noqa: F401
import numpy as np
from mpi4py import MPI

from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.multiscale.mixed import solve_mixed_ms_hybrid
from fenics_contact.multiscale.mixed_cem import MixedCEMOptions
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model


def band_load(x):
    """A load inside Ω₁ too (source correctors on many patches): push y < 1/2, pull above."""
    f = np.zeros((2, x.shape[1]))
    f[0] = np.where((x[0] > 0.5) & (x[1] < 0.5), 1.0, 0.0) - np.where((x[0] > 0.5) & (x[1] > 0.75), 1.0, 0.0)
    return f


n, n_coarse, layers = (int(a) for a in sys.argv[1:4])
cache_dir = sys.argv[4] if len(sys.argv) > 4 else None
comm = MPI.COMM_WORLD
cm = unit_square(n, n_coarse, comm=MPI.COMM_SELF)
model = get_model(1).with_(load=band_load)
ref = solve_mixed_monolithic(model.on(cm))
res = solve_mixed_ms_hybrid(model.on(cm), cem=MixedCEMOptions(layers=layers), reference=ref, offline_comm=comm,
                            cache_dir=cache_dir, options=IterationOptions(tol=1e-8, accel="anderson"))
om = res.step.omega1
r, w = om.solve(res.step.g12)
out = {
    "ranks": comm.size,
    "iterations": res.iterations,
    "e_sigma": res.e_sigma,
    "e_u_post": res.e_u_post,
    "cache": om.cache_status,
    "nbasis": list(om.nbasis_range),
    "gap": om.spectral_gap,
    "Gt_norm": float(np.linalg.norm(om.co.Gt)),
    "stress_norm2": om.a_norm2(om.fine_stress(r, res.step.g12)),
    "trace": om.response.trace(res.step.g12).tolist(),
    "rel_changes": [float(x) for x in res.history.rel_changes],
    "distributed": om.distributed,
    "function_bytes": int(comm.allreduce(sum(f.nbytes for f in om.basis + om.corr if f is not None), op=MPI.MAX)),
}
# Ω₁'s AW space (its cells' nodal bases shared out over the ranks): the same on every rank, bit for bit
P = res.step.sub[0].space.prolongation
out["P_sha1"] = comm.allgather(hashlib.sha1(P.data.tobytes() + P.indices.tobytes() + P.indptr.tobytes()).hexdigest())
# every rank iterated to the same state
same = comm.allgather(res.step.g12.copy())
out["ranks_agree"] = bool(all(np.array_equal(same[0], g) for g in same))
if comm.rank == 0:
    print("RESULT " + json.dumps(out), flush=True)
