"""Algorithm 3 for two bodies on 2 and 3 ranks (``multiscale.pair`` with ``multiscale.pair_replica``): on a layered
pair (strata of contrast 1e3 with inclusions, non-matching meshes, an overhanging upper block) the result is the
serial one (the same problem on ``COMM_SELF``) to 1e-10, frictionless and along a Coulomb press-then-shear path:
the forces, the contact profiles of both surfaces, the stick/slip state, the displacement and its energy error
against Algorithm 1."""

import dolfinx.fem
import numpy as np
import pytest
import ufl
from mpi4py import MPI
from pair_problems import STRATA_PATHS, assert_serial_pair, strata_steps

import fenics_contact as fc
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.problem.materials import strain, stress
from fenics_contact.problem.pair import TwoBodyProblem

pytestmark = pytest.mark.mpi

CONTRAST = 1e3


def _energy(problem: TwoBodyProblem, d: dolfinx.fem.Function) -> float:
    """a(d, d) = ∫ σ(d) : ε(d) over both bodies (collective)."""
    f = problem.fields
    form = dolfinx.fem.form(ufl.inner(stress(strain(d), f.lmbda, f.mu), strain(d)) * ufl.dx)
    return problem.comm.allreduce(dolfinx.fem.assemble_scalar(form), op=MPI.SUM)


def _path(comm: MPI.Comm, law, path) -> list:
    """(Algorithm 3, its energy error against Algorithm 1) at each step, each method from its last state."""
    states, out = [None, None], []
    for problem in strata_steps(comm, law, path, contrast=CONTRAST):
        fine = fc.solve(problem, "primal", tol=1e-11, state=states[0])
        ms = fc.solve(problem, "primal-ms", H=0.25, cem=CEMOptions(layers=1), tol=1e-11, state=states[1])
        states = [fine.state, ms.state]
        d = dolfinx.fem.Function(ms.u.function_space)
        d.x.array[:] = ms.u.x.array - fine.u.x.array
        out.append((ms, np.sqrt(_energy(problem, d) / _energy(problem, fine.u))))
    return out


@pytest.mark.mpi(sizes=(2, 3))
@pytest.mark.parametrize(("law", "path"), **STRATA_PATHS)
def test_two_and_three_ranks_give_the_serial_algorithm_3(law, path):
    parallel, serial = _path(MPI.COMM_WORLD, law, path), _path(MPI.COMM_SELF, law, path)
    assert MPI.COMM_WORLD.size > 1
    for (p, ep), (s, es) in zip(parallel, serial, strict=True):
        assert_serial_pair(p, s, law)
        assert 1e-6 < es and abs(ep - es) <= 1e-10
        owned = MPI.COMM_WORLD.allreduce(p.strip.size, op=MPI.SUM)
        assert owned == s.strip.size
    if law is not None:
        assert np.any(parallel[-1][0].friction.slip)
