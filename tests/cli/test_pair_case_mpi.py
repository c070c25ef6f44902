"""A two-body case under ``mpiexec -n 2``: ``primal-monolithic`` runs in parallel (the contact surfaces gathered,
``fem.two_body_mpi``) and its summary is the serial command's to 1e-10 at every load step, with the same files
(Algorithms 1 and 3 on two ranks: ``tests/hybrid/test_two_body_hybrid_mpi.py``)."""

from pathlib import Path

import numpy as np
import pytest
from mpi_jobs import on_every_rank, run_summary, serial_cli

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.cli import main

pytestmark = pytest.mark.mpi

CASE = Path(__file__).parents[2] / "cases" / "two_blocks.toml"


def test_a_two_body_case_on_two_ranks_is_the_serial_run(shared_tmp_path):
    args = ["run", "--case", str(CASE)]
    code, err, serial = serial_cli(*args, "--out", str(shared_tmp_path / "serial"))
    assert code == 0, err[-3000:]
    out = shared_tmp_path / "parallel"
    assert main([*args, "--out", str(out)]) == 0
    parallel = run_summary(out)
    assert parallel["mpi_ranks"] == 2 and serial["mpi_ranks"] == 1
    for p, s in zip(parallel["load_steps"]["steps"], serial["load_steps"]["steps"], strict=True):
        for key in ("force_slave", "force_master"):
            assert np.linalg.norm(np.subtract(p[key], s[key])) <= 1e-10 * np.linalg.norm(s[key])
        assert p["max_contact_pressure_slave"] == pytest.approx(s["max_contact_pressure_slave"], rel=1e-10)
        assert p["force_balance"] < 1e-12
    files = on_every_rank(sorted(f.name for f in out.iterdir()))
    assert {"fields.pvd", "contact.pvd", "pair.png", "E.png", "force_displacement.png", "summary.json"} <= set(files)
