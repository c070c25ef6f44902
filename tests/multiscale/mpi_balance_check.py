"""The balanced sharing of offline items (``multiscale.work.run_shared(balanced=True)``) under ``mpiexec -n 2``.

Rank 1 is made three times slower per item (a sleep); the items are handed out on request, so rank 1 must
end with clearly fewer items, every item computed exactly once, every rank getting every result, and
``owner`` telling who computed what.  Then equal items on equal ranks (10 ms sleeps): each rank must compute
about half (a request that rank 0 sees one item late gives the asking rank a third).  Prints the numbers as
JSON (rank 0).
"""

import json
import time

import fenics_contact  # noqa: F401
import numpy as np
from mpi4py import MPI

from fenics_contact.multiscale.work import run_shared

comm = MPI.COMM_WORLD
n = 60
cost = np.linspace(1.0, 3.0, n)  # the estimate; the true time is cost × (1 on rank 0, 3 on rank 1)
done = []


def work(i: int) -> float:
    done.append(i)
    time.sleep(0.004 * cost[i] * (3.0 if comm.rank == 1 else 1.0))
    return float(i) ** 2


owner = np.empty(n, dtype=np.int64)
results = run_shared(cost, comm, "balance check", work, balanced=True, owner=owner)
counts = comm.allgather(len(done))
everything = comm.allgather(sorted(done))
equal = []
run_shared(np.ones(100), comm, "equal items", lambda i: equal.append(i) or time.sleep(0.01), balanced=True,
           gather=False)
out = {
    "counts": counts,
    "equal_counts": comm.allgather(len(equal)),
    "once": sorted(i for d in everything for i in d) == list(range(n)),
    "results": bool(np.array_equal(results, np.arange(n, dtype=float) ** 2)),
    "owner_matches": bool(all(np.array_equal(np.flatnonzero(owner == r), everything[r]) for r in range(comm.size))),
}
if comm.rank == 0:
    print("RESULT " + json.dumps(out), flush=True)
