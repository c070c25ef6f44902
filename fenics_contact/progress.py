"""Progress of long loops (offline phases): a bar on a terminal, periodic log lines otherwise.

    with Progress(total=n_patches, desc="CEM bases", comm=comm) as bar:
        for patch in my_patches:
            ...
            bar.update()

On a terminal (stderr is a TTY) rank 0 draws a tqdm bar (done / total, elapsed,
estimated time left); elsewhere (CI, pipes, log files) rank 0 writes a plain log
line at most every ``interval`` seconds and one at the end. Under MPI each rank
counts its own share of the work (``total`` is that share); only rank 0 reports,
so the numbers shown are rank 0's.
"""

import logging
import sys
import time

from mpi4py import MPI

__all__ = ["Progress"]

log = logging.getLogger(__name__)


class Progress:
    """Count ``total`` work items; report on rank 0 (tqdm bar on a TTY, else log lines every ``interval`` s)."""

    def __init__(
        self,
        total: int,
        desc: str,
        *,
        comm: MPI.Comm = MPI.COMM_SELF,
        interval: float = 10.0,
        logger: logging.Logger | None = None,
        bar: bool | None = None,
    ) -> None:
        if total < 0:
            raise ValueError(f"total must be >= 0, got {total}")
        self.total, self.desc, self.interval = int(total), desc, float(interval)
        self.done = 0
        self.log = logger or log
        self._report = comm.rank == 0
        self._start = self._last = time.perf_counter()
        use_bar = sys.stderr.isatty() if bar is None else bar
        self._bar = None
        if self._report and use_bar:
            from tqdm import tqdm

            self._bar = tqdm(total=self.total, desc=desc, unit="it", leave=True, dynamic_ncols=True)

    @property
    def elapsed(self) -> float:
        """Seconds since the start."""
        return time.perf_counter() - self._start

    def eta(self) -> float | None:
        """Estimated seconds left (None before the first item)."""
        if self.done == 0:
            return None
        return self.elapsed / self.done * (self.total - self.done)

    def update(self, n: int = 1) -> None:
        """n more items done."""
        self.done += n
        if not self._report:
            return
        if self._bar is not None:
            self._bar.update(n)
            return
        now = time.perf_counter()
        if now - self._last >= self.interval and self.done < self.total:
            self._last = now
            eta = self.eta()
            self.log.info(
                "%s: %d/%d done, %.0f s elapsed, about %.0f s left",
                self.desc,
                self.done,
                self.total,
                self.elapsed,
                eta if eta is not None else float("nan"),
            )

    def close(self) -> None:
        """Finish: close the bar, or write the final log line."""
        if not self._report:
            return
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        if self.elapsed >= self.interval:
            self.log.info("%s: %d/%d done in %.1f s", self.desc, self.done, self.total, self.elapsed)

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
