"""Independent work items (local eigenproblems, patch problems, coarse-cell blocks) shared out across MPI ranks.

Every rank holds the same list of items with an estimated cost; ``share``
assigns each item to one rank (longest first, to the least loaded rank: the
same answer on every rank, no communication), so no item is computed twice.
``gather_dict`` then gives every rank every result: each rank broadcasts its results
in one pickle (protocol 5) whose NumPy arrays travel out of band, one ``Bcast`` per
array straight into the receivers' buffers (no pickling copy of the data, no message
larger than one array).
"""

import pickle

import numpy as np
from mpi4py import MPI

__all__ = ["share", "my_items", "gather_dict"]


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


def gather_dict(results: dict, n: int, comm: MPI.Comm) -> list:
    """The list of all n items on every rank, from the ranks' dicts {index: item} (each item on one rank).

    Each rank in turn broadcasts its dict: a protocol-5 pickle whose contiguous NumPy arrays travel out of
    band, packed into one byte buffer (``Bcast`` in chunks of at most 2³⁰ bytes) that the unpickled arrays of
    the receivers then view; other objects and non-contiguous arrays travel inside the pickle.
    """
    if comm.size == 1:
        return [results[i] for i in range(n)]
    out = [None] * n
    for root in range(comm.size):
        mine = root == comm.rank
        if mine:
            buffers = []
            head = pickle.dumps(results, protocol=5, buffer_callback=buffers.append)
            raw = [np.frombuffer(b.raw(), dtype=np.uint8) for b in buffers]
        head, sizes = comm.bcast((head, [r.size for r in raw]) if mine else None, root=root)
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        packed = np.concatenate(raw) if mine and raw else np.empty(offsets[-1], dtype=np.uint8)
        _bcast_bytes(comm, packed, root)
        views = [packed[a:z] for a, z in zip(offsets[:-1], offsets[1:])]
        items = results if mine else pickle.loads(head, buffers=views)
        for k, v in items.items():
            out[k] = v
    if any(o is None for o in out) and n:
        raise RuntimeError("an offline item was computed by no rank")
    return out


def _bcast_bytes(comm: MPI.Comm, data: np.ndarray, root: int, chunk: int = 1 << 30) -> None:
    for start in range(0, data.size, chunk):
        comm.Bcast([data[start : start + chunk], MPI.BYTE], root=root)
