"""Friction between two bodies on two ranks (``fem.two_body_mpi`` with the pair's friction law): the contact
reduced to the slave nodes' relative displacements, the same on every rank; along a press-then-shear path past
sliding the forces, tractions, stick/slip states and dissipation are the serial ones (``mpiexec -n 2``, against
the same path on ``COMM_SELF``), from the API and from ``fenics-contact run --case cases/fault_sliding.toml``."""

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI
from mpi_jobs import run_summary, serial_cli

import fenics_contact as fc
from fenics_contact.cli import main
from fenics_contact.problem.pair import Body, ContactPair, Support, TwoBodyProblem
from fenics_contact.problem.pair_meshes import PairTag as T
from fenics_contact.problem.pair_meshes import two_blocks

pytestmark = pytest.mark.mpi

PATH = ((0.0, -0.005), (0.0, -0.01), (0.002, -0.01), (0.01, -0.01), (0.03, -0.01))
CASE = Path(__file__).parents[2] / "cases" / "fault_sliding.toml"


def _path(comm: MPI.Comm, law) -> list:
    m = two_blocks(7, 10, heights=(0.5, 0.4), comm=comm)
    state, out = None, []
    for top in PATH:
        problem = TwoBodyProblem(
            m.mesh,
            m.cell_tags,
            m.facet_tags,
            bodies=(Body(T.LOWER, 1.0, 0.3), Body(T.UPPER, 5.0, 0.2)),
            pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP, friction=law),
            supports=(Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP, top)),
        )
        out.append(fc.solve(problem, "primal-monolithic", state=state))
        state = out[-1].state
    return out


@pytest.mark.parametrize(
    "law", [fc.Friction("coulomb", mu=0.3), fc.Friction("tresca", threshold=0.002)], ids=["coulomb", "tresca"]
)
def test_two_ranks_give_the_serial_frictional_path(law):
    parallel, serial = _path(MPI.COMM_WORLD, law), _path(MPI.COMM_SELF, law)
    assert MPI.COMM_WORLD.size > 1
    for p, s in zip(parallel, serial, strict=True):
        for fp, fs in zip(p.forces, s.forces, strict=True):
            assert np.linalg.norm(fp - fs) <= 1e-10 * np.linalg.norm(fs)
        assert p.force_balance() < 1e-12
        assert np.array_equal(p.friction.stick, s.friction.stick) and np.array_equal(p.friction.slip, s.friction.slip)
        assert np.max(np.abs(p.friction.traction - s.friction.traction)) <= 1e-9 * np.max(np.abs(s.friction.traction))
        assert p.dissipation == pytest.approx(s.dissipation, rel=1e-8, abs=1e-15)
    assert np.all(parallel[-1].friction.slip)


def test_a_fault_sliding_case_on_two_ranks_is_the_serial_run(shared_tmp_path):
    args = ["run", "--case", str(CASE), "--no-plots"]
    code, err, serial = serial_cli(*args, "--out", str(shared_tmp_path / "serial"))
    assert code == 0, err[-3000:]
    out = shared_tmp_path / "parallel"
    assert main([*args, "--out", str(out)]) == 0
    parallel = run_summary(out)
    assert parallel["mpi_ranks"] == 2
    for p, s in zip(parallel["load_steps"]["steps"], serial["load_steps"]["steps"], strict=True):
        assert np.linalg.norm(np.subtract(p["force_slave"], s["force_slave"])) <= 1e-10 * np.linalg.norm(
            s["force_slave"]
        )
        assert p["friction"]["slip_nodes"] == s["friction"]["slip_nodes"]
    assert parallel["dissipation"] == pytest.approx(serial["dissipation"], rel=1e-8)
