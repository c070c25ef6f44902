"""What the benchmark scripts share: their Markdown results file."""

from pathlib import Path

from mpi4py import MPI

__all__ = ["write_report"]


def write_report(path: str | Path, lines: list[str], comm: MPI.Comm = MPI.COMM_WORLD) -> None:
    """A benchmark's Markdown results file (its lines), written on rank 0 (parent directories made)."""
    if comm.rank != 0:
        return
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    print(f"wrote {path}")
