"""Independent work items (local eigenproblems, patch problems, coarse-cell blocks) shared out across MPI ranks.

Every rank holds the same list of items with an estimated cost; ``share``
assigns each item to one rank (longest first, to the least loaded rank: the
same answer on every rank, no communication), so no item is computed twice.
``run_balanced`` hands them out one at a time on request instead (rank 0
answers between its own items), so a rank on a busier core, or whose items
cost more than estimated, gets less.
``gather_dict`` then gives every rank every result: each rank broadcasts its results
in one pickle (protocol 5) whose NumPy arrays travel out of band, one ``Bcast`` per
array straight into the receivers' buffers (no pickling copy of the data, no message
larger than one array).
"""

import logging
import pickle

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


#: tags of the dispatcher's messages (on a duplicate of the caller's communicator: no clash with other traffic)
_REQUEST, _ITEM = 71, 72
#: Iprobe calls before rank 0 decides that no request is waiting
_PROBES = 3
#: one duplicate communicator per (communicator, size), made on first use
_DISPATCH_COMMS: dict[tuple[int, int], MPI.Comm] = {}


def _dispatch_comm(comm: MPI.Comm) -> MPI.Comm:
    key = (comm.py2f(), comm.size)
    if key not in _DISPATCH_COMMS:
        _DISPATCH_COMMS[key] = comm.Dup()
    return _DISPATCH_COMMS[key]


def _describe(error: Exception | None) -> str | None:
    return None if error is None else f"{type(error).__name__}: {error}"


def _raise_failures(comm: MPI.Comm, error: Exception | None, desc: str) -> None:
    """Collective: re-raise this rank's error, or a ConvergenceError naming another rank's, on every rank."""
    failures = comm.allgather(_describe(error))
    if error is not None:
        raise error
    if any(failures):
        raise ConvergenceError(f"{desc}: another rank failed ({next(f for f in failures if f)})")


def run_balanced(
    cost: np.ndarray, comm: MPI.Comm, work, *, bar=None, owner: np.ndarray | None = None, desc: str = "offline items"
) -> dict:
    """This rank's results {i: work(i)}, the items handed out one at a time on request.

    Ranks r > 0 take items from the front of the cost order (largest first): each starts with item r − 1 and
    asks rank 0 for its next item *before* it computes the one it holds (one request always in flight, so its
    answer is waiting when the item is done).  Rank 0 computes items from the back (cheapest first) and
    answers the requests between its own items (point-to-point messages of one integer; no one-sided MPI:
    with MPICH ch4 a passive-target atomic waits until the target rank enters MPI, which a rank busy in a
    local solve does not).  A rank that runs slower (a busier core, items costlier than estimated) therefore
    asks less often and gets less; the ranks finish within about one item of each other (the items where
    front and back meet).  The results do not depend on who computes what (each item is a pure function of
    its index).  An error on any rank stops the handing out and is raised on every rank.
    """
    cost = np.asarray(cost, dtype=float)
    n = cost.size
    order = np.argsort(-cost, kind="stable")
    dc = _dispatch_comm(comm)
    size, rank = dc.size, dc.rank
    results: dict = {}
    error = None
    who = np.full(n, -1, dtype=np.int64)

    def compute(i: int) -> None:
        nonlocal error
        if error is not None:
            return
        try:
            results[i] = work(i)
        except Exception as err:  # noqa: BLE001 -- re-raised below on every rank
            error = err
        if bar is not None:
            bar.update()

    if rank == 0:
        # the other ranks take items from the front of the cost order (largest first), rank 0 from the back (the
        # cheapest): it answers between its own items, so a request never waits longer than the cheapest item
        front = min(size - 1, n)
        who[order[:front]] = np.arange(1, front + 1)
        back = n - 1
        finished, failed = 1 + (size - 1 - front), False  # ranks without a first item never ask
        status = MPI.Status()

        def answer(block: bool) -> None:
            nonlocal front, finished, failed
            # Iprobe more than once: after a long computation the first call only lets MPI take in what has
            # arrived (measured with MPICH ch4:ucx: a request sent long before is seen by the second call)
            while finished < size and (
                block or any(dc.Iprobe(source=MPI.ANY_SOURCE, tag=_REQUEST) for _ in range(_PROBES))
            ):
                report = dc.recv(source=MPI.ANY_SOURCE, tag=_REQUEST, status=status)
                r = status.Get_source()
                failed = failed or report is not None
                if front <= back and not failed and error is None:
                    i = int(order[front])
                    front += 1
                    who[i] = r
                else:
                    i = -1
                    finished += 1
                dc.send(i, dest=r, tag=_ITEM)
                if bar is not None and report is None:
                    bar.update()  # (approximately: one item late) an item of rank r is done

        while True:
            answer(False)
            if front > back or failed or error is not None:
                break
            i = int(order[back])
            back -= 1
            who[i] = 0
            compute(i)
        answer(True)
    elif rank <= n:
        held = int(order[rank - 1])
        while held >= 0:
            dc.send(_describe(error), dest=0, tag=_REQUEST)
            compute(held)
            held = dc.recv(source=0, tag=_ITEM)
    _raise_failures(dc, error, desc)
    if owner is not None:
        dc.Bcast(who, root=0)
        owner[:] = who
    return results


def run_shared(
    cost: np.ndarray,
    comm: MPI.Comm,
    desc: str,
    work,
    *,
    gather: bool = True,
    items: np.ndarray | None = None,
    balanced: bool = False,
    owner: np.ndarray | None = None,
    logger: logging.Logger = log,
) -> list | dict:
    """work(i) for the items i of this rank (``share``, or ``items``), with progress; every rank gets all
    results (``gather``), or this rank's as a dict {i: result}.

    ``balanced`` (under MPI, without ``items``): the items are handed out on request (``run_balanced``) so
    that a rank that runs slower (a busier core, costs off the estimate) gets less.  ``owner`` (n,) is filled with
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
    _raise_failures(comm, error, desc)
    return gather_dict(results, cost.size, comm) if gather else results
