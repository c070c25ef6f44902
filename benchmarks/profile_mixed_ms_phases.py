"""Per-rank timing of Algorithm 4's shared offline phases: compute, gather, waiting (h = 1/128 by default).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/profile_mixed_ms_phases.py [--n 128]
    OMP_NUM_THREADS=1 .venv/bin/mpiexec -n 2 .venv/bin/python benchmarks/profile_mixed_ms_phases.py [--n 128]

Runs the offline + online of ``mixed_ms_scaling.py --worker mixed-ms`` (model 2, H = 1/16, m = 3, no cache) with
``multiscale.work.run_balanced`` / ``gather_dict`` / ``run_shared`` wrapped by timers, and prints per
rank: each handed-out phase's wall time, the CPU of its items (``work``), how many items the rank computed and
how long it waited at the phase's end for the other ranks; each gather's time; each ``run_shared`` call's wall
time.  Compare the serial run's phases with the ranks' to see which phase does not scale.
"""

import runpy
import sys
import time
from pathlib import Path

import dolfinx_solver  # noqa: F401  (before dolfinx / petsc4py)
from mpi4py import MPI

import fenics_contact.multiscale.work as work

records = []
_run_balanced, _gather_dict, _run_shared = work.run_balanced, work.gather_dict, work.run_shared


def run_balanced(cost, comm, item, **kwargs):
    spent = [0.0, 0]

    def timed(i):
        t = time.perf_counter()
        out = item(i)
        spent[0] += time.perf_counter() - t
        spent[1] += 1
        return out

    t0 = time.perf_counter()
    out = _run_balanced(cost, comm, timed, **kwargs)
    t1 = time.perf_counter()
    comm.Barrier()
    records.append(
        f"{kwargs.get('desc')}: handed out {t1 - t0:.2f} s, items' CPU {spent[0]:.2f} s, "
        f"{spent[1]} items, waited at the end {time.perf_counter() - t1:.2f} s"
    )
    return out


def gather_dict(results, n, comm):
    t0 = time.perf_counter()
    out = _gather_dict(results, n, comm)
    records.append(f"  gather of {n} items: {time.perf_counter() - t0:.2f} s")
    return out


def run_shared(cost, comm, desc, item, **kwargs):
    t0 = time.perf_counter()
    out = _run_shared(cost, comm, desc, item, **kwargs)
    records.append(f"run_shared {desc}: {time.perf_counter() - t0:.2f} s")
    return out


work.run_balanced, work.gather_dict, work.run_shared = run_balanced, gather_dict, run_shared
n = sys.argv[sys.argv.index("--n") + 1] if "--n" in sys.argv else "128"
sys.argv = ["mixed_ms_scaling.py", "--worker", "mixed-ms", "--n", n]
try:
    runpy.run_path(str(Path(__file__).with_name("mixed_ms_scaling.py")), run_name="__main__")
finally:
    world = MPI.COMM_WORLD
    for r in range(world.size):
        if r == world.rank:
            print(f"rank {r} of {world.size}:", *records, sep="\n  ", flush=True)
        world.Barrier()
