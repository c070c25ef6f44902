"""GAMG in 3D on 1 and 2 ranks: the data of a weak-scaling estimate for a cluster.

The 3D channel model (``problem.models3d.channels_3d``, contrast ``--contrast``) solved by ``primal-monolithic``
with ``solver="amg"`` (CG + aggregation AMG with the rigid-body near-nullspace, ``fem.amg``; rtol 10⁻⁸) on the unit
cube 1/n: DOFs, ranks, Newton steps, active-set sizes, CG iterations per Newton step, the wall time of the solve,
its CPU time (all ranks) in all and per DOF and Newton step (on a shared machine the CPU time is the measure), each
rank's peak memory; ``--solver direct``: the same with MUMPS, the reference for the steps and active sets.  Run it
once per rank count, the mesh grown with the ranks (DOFs per rank about constant):

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/amg_weak_scaling.py --n 16 20
    OMP_NUM_THREADS=1 .venv/bin/mpiexec -n 2 .venv/bin/python benchmarks/amg_weak_scaling.py --n 20 25

Each line printed (rank 0) is one JSON record; docs/performance.md collects them.
"""

import argparse
import json
import time

from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.fem.amg import LinearSolverOptions
from fenics_contact.io import peak_rss_bytes
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, nargs="+", default=[16, 20], help="1/h of the cube meshes")
    parser.add_argument("--contrast", type=float, default=1e3)
    parser.add_argument(
        "--solver", choices=("amg", "direct"), default="amg", help="direct: MUMPS, the AMG solve's reference"
    )
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    for n in args.n:
        problem = channels_3d(E_high=args.contrast).on(channels_3d_mesh(n))
        cpu = time.process_time()
        solution = fc.solve(problem, "primal-monolithic", solver=LinearSolverOptions(kind=args.solver))
        cpu = comm.allreduce(time.process_time() - cpu)
        peak = comm.allgather(peak_rss_bytes() / 1e9)
        record = {
            "n": n,
            "ranks": comm.size,
            "dofs": solution.dofs,
            "newton": solution.newton.steps,
            "active": solution.newton.active_sizes,
            "cg": solution.krylov_iterations,
            "solve_s": solution.time_s,
            "cpu_s": cpu,
            "cpu_us_per_dof_step": 1e6 * cpu / (solution.dofs * solution.newton.steps),
            "peak_gb_per_rank": [round(p, 3) for p in peak],
        }
        if comm.rank == 0:
            print(json.dumps(record), flush=True)


if __name__ == "__main__":
    main()
