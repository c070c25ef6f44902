"""Algorithm 3 (primal CEM hybrid) on a model with loads in Ω₁; key numbers as JSON (rank 0).

Used by test_multiscale.py: once serially (writing the solution to ``out``) and once under
``mpiexec -n 2`` (comparing its solution with the serial one, DOF by DOF, matched by coordinates);
then the interface Newton on the same step (its fields against the Robin iteration's).

    python mpi_check_primal_ms.py n n_coarse out.npz [serial.npz]
"""

import json
import sys

import fenics_contact  # noqa: F401
import numpy as np
from mpi4py import MPI

from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.primal import solve_primal_ms_hybrid
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model


def load(x):
    """Bands inside Ω₁ (x ∈ [1/2, 15/16]): push the lower half, pull the upper half."""
    f = np.zeros((2, x.shape[1]))
    inside = (x[0] > 0.5) & (x[0] < 15 / 16)
    f[0, inside & (x[1] < 0.5)] = 1.0
    f[0, inside & (x[1] > 0.5)] = -1.0
    return f


n, n_coarse = int(sys.argv[1]), int(sys.argv[2])
out_path = sys.argv[3]
compare = sys.argv[4] if len(sys.argv) > 4 else None
cm = unit_square(n, n_coarse)
comm = cm.comm
problem = get_model(1).with_(load=load).on(cm)
delta = default_penalty(cm.h, 1.0)
ref = solve_primal_monolithic(problem, delta=delta)
res = solve_primal_ms_hybrid(problem, alpha="Emin", delta=delta, cem=CEMOptions(layers=2, nbasis=3), reference=ref.u,
                             options=IterationOptions(tol=1e-10, accel="anderson"))
# the interface Newton on the same step (Ω₁'s response from the coarse solver, gathered over the ranks)
newton = solve_primal_ms_hybrid(problem, alpha="Emin", delta=delta, cem=CEMOptions(layers=2, nbasis=3), step=res.step,
                                options=IterationOptions(tol=1e-10, accel="newton"))
scale = comm.allreduce(float(np.abs(res.u.x.array).max()), op=MPI.MAX)
newton_vs_robin = comm.allreduce(float(np.abs(newton.u.x.array - res.u.x.array).max()), op=MPI.MAX) / scale
V = res.u.function_space
n_owned = V.dofmap.index_map.size_local
bs = V.dofmap.index_map_bs
x = V.tabulate_dof_coordinates()[:n_owned, :2]
u = res.u.x.array[: n_owned * bs].reshape(n_owned, bs)
xs = np.concatenate(comm.allgather(x))
us = np.concatenate(comm.allgather(u))
key = np.round(xs * n).astype(np.int64)  # vertices of the uniform grid (h = 1/n)
order = np.lexsort((key[:, 1], key[:, 0]))
xs, us = xs[order], us[order]
out = {
    "ranks": comm.size,
    "iterations": res.iterations,
    "converged": bool(res.converged),
    "e_u": res.e_u,
    "e_a": res.step.error_energy(),
    "rel_changes": res.history.rel_changes.tolist(),
    "dim_ms": res.dofs["omega1_ms"],
    "newton_converged": bool(newton.converged),
    "newton_steps": newton.history.newton_steps,
    "newton_vs_robin": newton_vs_robin,
    "patches_here": comm.allgather(res.step.omega1.space.times["patches_here"]),
}
if compare is not None:
    with np.load(compare) as data:
        assert np.allclose(data["x"], xs, rtol=0, atol=1e-12)
        out["max_diff"] = float(np.abs(data["u"] - us).max() / np.abs(data["u"]).max())
elif comm.rank == 0:
    np.savez(out_path, x=xs, u=us)
if comm.rank == 0:
    print("RESULT " + json.dumps(out))
