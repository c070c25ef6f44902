"""Independent work items (local eigenproblems, patch problems, coarse-cell blocks) shared out across MPI ranks.

Every rank holds the same list of items with an estimated cost; ``share``
assigns each item to one rank (longest first, to the least loaded rank: the
same answer on every rank, no communication), so no item is computed twice.
``run_balanced`` deals the items out in rounds instead, at the ranks' measured
speeds (a rank on a busier core, or whose items cost more than estimated, gets
less; one allgather per round).
``gather_dict`` then gives every rank every result: each rank broadcasts its results
in one pickle (protocol 5) whose NumPy arrays travel out of band, one ``Bcast`` per
array straight into the receivers' buffers (no pickling copy of the data, no message
larger than one array).
"""

import logging
import pickle
import time

import numpy as np
from mpi4py import MPI

from fenics_contact.errors import ConvergenceError
from fenics_contact.progress import Progress

__all__ = ["share", "my_items", "gather_dict", "run_balanced", "run_shared"]

log = logging.getLogger(__name__)


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


#: measured relative speeds of the ranks (cost units per second), carried from one shared phase to the next
_RANK_SPEEDS: dict[tuple[int, int], np.ndarray] = {}
#: a round hands out this fraction of each rank's share (the first round of a communicator a quarter)
_ROUND_FRACTION = 0.5
#: the last round hands out everything once the remaining estimated cost is below this fraction of the total
_LAST_ROUND = 0.1


def run_balanced(cost: np.ndarray, comm: MPI.Comm, work, *, bar=None, owner: np.ndarray | None = None,
                 desc: str = "offline items") -> dict:
    """This rank's results {i: work(i)}: the items are dealt out in rounds (longest first, each to the rank that
    would finish it first at the speeds measured so far); a round takes half of each rank's share (a quarter
    in the first round, speeds unknown), everything once less than ``_LAST_ROUND`` of the cost is left.
    Between rounds the ranks exchange what they did and how long it took (one allgather; no one-sided MPI:
    it needs the target rank to enter MPI, which a rank busy in a local solve does not).  The results do not
    depend on who computes what (each item is a pure function of its index)."""
    cost = np.asarray(cost, dtype=float)
    n = cost.size
    key = (comm.py2f(), comm.size)
    speed = _RANK_SPEEDS.get(key)
    fraction = _ROUND_FRACTION if speed is not None else 0.5 * _ROUND_FRACTION
    speed = np.ones(comm.size) if speed is None else speed.copy()
    who = np.full(n, -1, dtype=np.int64)
    remaining = np.argsort(-cost, kind="stable")
    total = float(cost.sum()) or 1.0
    results: dict = {}
    error = None
    while remaining.size:
        load = np.zeros(comm.size)
        dealt = np.empty(remaining.size, dtype=np.int64)
        for k, i in enumerate(remaining):
            r = int(np.argmin(load + cost[i] / speed))
            dealt[k] = r
            load[r] += cost[i] / speed[r]
        mine = remaining[dealt == comm.rank]
        last = float(cost[remaining].sum()) <= _LAST_ROUND * total or remaining.size <= 2 * comm.size
        if not last and mine.size:
            upto = np.cumsum(cost[mine]) <= fraction * float(cost[mine].sum())
            mine = mine[: max(1, int(np.count_nonzero(upto)))]
        fraction = _ROUND_FRACTION
        t0 = time.perf_counter()
        try:
            for i in mine:
                results[int(i)] = work(int(i))
                if bar is not None:
                    bar.update()
        except Exception as err:  # noqa: BLE001 -- re-raised below on every rank
            error = err
        elapsed = time.perf_counter() - t0
        rounds = comm.allgather((mine, elapsed, None if error is None else f"{type(error).__name__}: {error}"))
        failures = [f for _, _, f in rounds if f]
        if error is not None:
            raise error
        if failures:
            raise ConvergenceError(f"{desc}: another rank failed ({failures[0]})")
        for r, (items, took, _) in enumerate(rounds):
            who[items] = r
            if items.size and took > 0.0:
                speed[r] = float(cost[items].sum()) / took
            if r != comm.rank and bar is not None:
                bar.update(items.size)
        remaining = remaining[who[remaining] < 0]
    speed /= speed.max()
    _RANK_SPEEDS[key] = speed
    if owner is not None:
        owner[:] = who
    return results


def run_shared(cost: np.ndarray, comm: MPI.Comm, desc: str, work, *, gather: bool = True,
               items: np.ndarray | None = None, balanced: bool = False, owner: np.ndarray | None = None,
               logger: logging.Logger = log) -> list | dict:
    """work(i) for the items i of this rank (``share``, or ``items``), with progress; every rank gets all
    results (``gather``), or this rank's as a dict {i: result}.

    ``balanced`` (under MPI, without ``items``): the items are dealt out in rounds (``run_balanced``) so that
    a rank that runs slower (a busier core, costs off the estimate) gets less.  ``owner`` (n,) is filled with
    the rank that computed each item.  Collective-safe: an exception on one rank is raised on every rank
    (after all have stopped).
    """
    if balanced and items is None and comm.size > 1:
        with Progress(cost.size, desc, comm=comm, logger=logger) as bar:
            results = run_balanced(cost, comm, work, bar=bar, owner=owner, desc=desc)
        return gather_dict(results, cost.size, comm) if gather else results
    mine = my_items(share(cost, comm.size), comm) if items is None else np.asarray(items, dtype=np.int64)
    if owner is not None:
        owner[:] = -1
        owner[mine] = comm.rank
        if comm.size > 1:
            comm.Allreduce(MPI.IN_PLACE, owner, op=MPI.MAX)
    results, error = {}, None
    with Progress(mine.size, desc, comm=comm, logger=logger) as bar:
        try:
            for i in mine:
                results[int(i)] = work(int(i))
                bar.update()
        except Exception as err:  # noqa: BLE001 -- re-raised below on every rank
            error = err
    failures = comm.allgather(None if error is None else f"{type(error).__name__}: {error}")
    if error is not None:
        raise error
    if any(failures):
        raise ConvergenceError(f"{desc}: another rank failed ({next(f for f in failures if f)})")
    return gather_dict(results, cost.size, comm) if gather else results
