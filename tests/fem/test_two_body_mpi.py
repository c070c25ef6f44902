"""Two-body contact under MPI: the problem is built and validated collectively, and the solve refuses on every
rank with a message that says to run it on one process."""

import pytest
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.errors import InputError

pytestmark = pytest.mark.mpi


def test_two_body_solve_refuses_on_several_ranks():
    T = fc.PairTag
    blocks = fc.two_blocks(4, 5, comm=MPI.COMM_WORLD)
    problem = fc.TwoBodyProblem(
        blocks.mesh,
        blocks.cell_tags,
        blocks.facet_tags,
        bodies=(fc.Body(T.LOWER, 1.0, 0.3), fc.Body(T.UPPER, 2.0, 0.3)),
        pair=fc.ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP),
        supports=(fc.Support(T.LOWER_BOTTOM), fc.Support(T.UPPER_TOP, (0.0, -0.01))),
    )
    assert problem.contact_moduli() == (2.0, 1.0)
    for method in ("primal-monolithic", "primal"):
        with pytest.raises(InputError, match="runs on one process"):
            fc.solve(problem, method)
