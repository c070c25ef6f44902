"""What the benchmark scripts share: their Markdown results file and its table rows; the layered two-body pair."""

from pathlib import Path

import numpy as np
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.problem.pair_meshes import fault_strata

__all__ = ["friction_ratio", "strata_pair", "table_row", "write_report"]


def write_report(path: str | Path, lines: list[str], comm: MPI.Comm = MPI.COMM_WORLD) -> None:
    """A benchmark's Markdown results file (its lines), written on rank 0 (parent directories made)."""
    if comm.rank != 0:
        return
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    print(f"wrote {path}")


def table_row(*cells: str) -> str:
    """The Markdown table row ``| a | b | … |`` of ``cells``, printed as it is made (a long run shows its rows)."""
    row = "| " + " | ".join(cells) + " |"
    print(row, flush=True)
    return row


def friction_ratio(friction) -> float:
    """Q/N = Σ w|t| over the normal force of a frictional contact result (μ once every node slips)."""
    return float(np.sum(friction.weights * np.linalg.norm(friction.traction, axis=1)) / friction.normal_force)


def strata_pair(m, top, friction: fc.Friction | None = None, *, contrast: float, nu: tuple[float, float]):
    """The layered pair of the two-body benchmarks on the two-block mesh ``m``: E of the strata of
    ``pair_meshes.fault_strata(contrast)``, Poisson ratios ``nu`` (lower, upper), the lower block's bottom held,
    the upper block's top moved by ``top``, the contact law ``friction`` (None: frictionless)."""
    lower, upper = fault_strata(contrast)
    T = fc.PairTag
    return fc.TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(fc.Body(T.LOWER, lower, nu[0]), fc.Body(T.UPPER, upper, nu[1])),
        pair=fc.ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP, friction=friction),
        supports=(fc.Support(T.LOWER_BOTTOM), fc.Support(T.UPPER_TOP, top)),
    )
