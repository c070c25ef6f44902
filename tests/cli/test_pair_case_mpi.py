"""A two-body case under ``mpiexec``: the two-body solves are serial, so the run is refused with exit 2 before
anything is written (the contact surfaces are not gathered across ranks), and check-mesh says so."""

from pathlib import Path

import pytest
from mpi_jobs import on_every_rank

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.cli import main

pytestmark = pytest.mark.mpi

CASE = Path(__file__).parents[2] / "cases" / "two_blocks.toml"


def test_a_two_body_case_is_refused_on_two_ranks(shared_tmp_path, capsys):
    out = shared_tmp_path / "pair"
    assert main(["run", "--case", str(CASE), "--no-plots", "--out", str(out)]) == 2
    assert on_every_rank(not out.exists())
    assert main(["check-mesh", "--case", str(CASE)]) == 2
    err = on_every_rank(capsys.readouterr().err)
    assert err.count("two-body contact runs on one process") == 2
