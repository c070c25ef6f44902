"""Independent work items (local eigenproblems, patch problems, coarse-cell blocks) shared out across MPI ranks.

Every rank holds the same list of items with an estimated cost; ``share``
assigns each item to one rank (longest first, to the least loaded rank: the
same answer on every rank, no communication), so no item is computed twice.
``gather`` then gives every rank every result: each item is broadcast from the
rank that computed it, one at a time, so no message holds more than one item.
"""

import numpy as np
from mpi4py import MPI

__all__ = ["share", "my_items", "gather"]


def share(costs: np.ndarray, size: int) -> np.ndarray:
    """Owner rank of every item: longest processing time first, each to the least loaded rank."""
    costs = np.asarray(costs, dtype=np.float64)
    owner = np.zeros(costs.size, dtype=np.int64)
    if size == 1:
        return owner
    load = np.zeros(size)
    for item in np.argsort(-costs, kind="stable"):
        r = int(np.argmin(load))
        owner[item] = r
        load[r] += costs[item]
    return owner


def my_items(owner: np.ndarray, comm: MPI.Comm) -> np.ndarray:
    """The items this rank computes (ascending)."""
    return np.flatnonzero(owner == comm.rank)


def gather(comm: MPI.Comm, owner: np.ndarray, mine: dict) -> list:
    """Every item's result on every rank: item i is broadcast from rank owner[i] (``mine`` holds this rank's)."""
    if comm.size == 1:
        return [mine[i] for i in range(owner.size)]
    return [comm.bcast(mine.get(i) if owner[i] == comm.rank else None, root=int(owner[i])) for i in range(owner.size)]
