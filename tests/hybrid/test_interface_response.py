"""Interface responses of the primal subdomains (hybrid.response.PrimalPart) from MUMPS' entries of J⁻¹.

* ``fem.inverse_entries.inverse_block``: on a random non-symmetric sparse matrix, the block of the dense
  inverse on the requested unknowns (in their order, unsorted), and ordinary solves with the same factors
  still work afterwards.
* ``PrimalPart.responses`` (``DirectSolver.inverse_block``) equals the responses by back-solves with the same
  factorization, chunk by chunk (``AffinePart.responses``): Ω₁ and Ω₂ (J₀) of Algorithm 1, with and without
  the contact columns, to 1e-12 relative to the largest entry.
"""

import numpy as np
import pytest
import scipy.sparse as sp
from petsc4py import PETSc

from fenics_contact.fem.inverse_entries import available, inverse_block
from fenics_contact.fem.linalg import DirectSolver
from fenics_contact.fem.matrices import scipy_to_petsc
from fenics_contact.hybrid.primal import PrimalHybridStep
from fenics_contact.hybrid.response import AffinePart, PrimalPart
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model
from fenics_contact.problem.obstacles import Circle

pytestmark = pytest.mark.skipif(not available(), reason="no PETSc library for entries of inverses")

TOL = 1e-12


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max(initial=0.0) / max(np.abs(b).max(initial=0.0), np.finfo(float).tiny))


def test_inverse_block_of_a_nonsymmetric_matrix():
    rng = np.random.default_rng(3)
    n = 60
    A = sp.random(n, n, density=0.1, random_state=rng) + 10.0 * sp.eye(n)  # non-symmetric, well conditioned
    rows = rng.permutation(n)[:17]  # unsorted: the block is in this order
    solver = DirectSolver(PETSc.COMM_SELF, prefix="test_inverse_entries_")
    Am = scipy_to_petsc(A)
    solver.set_operator(Am)
    assert solver.has_inverse_entries()
    Ainv = np.linalg.inv(A.toarray())
    assert _relative(solver.inverse_block(rows), Ainv[np.ix_(rows, rows)]) < TOL
    b, x = Am.createVecs()
    b.setArray(rng.standard_normal(n))
    solver.solve(b, x)  # the factors still solve
    assert _relative(x.getArray(), Ainv @ b.getArray()) < TOL
    with pytest.raises(ValueError):
        inverse_block(solver.ksp.getPC().getFactorMatrix(), np.array([1, 1]))
    for obj in (solver, Am, b, x):
        obj.destroy()


@pytest.fixture(scope="module")
def parts():
    cm = unit_square(32, 8)
    problem = get_model(3, E_high=1e3).with_(obstacle=Circle((3.0, 0.5), 2.0)).on(cm)
    step = PrimalHybridStep(problem)
    step.prepare()
    omega1 = PrimalPart(step.sub[0], step.interface, 0, contact=False)
    omega2 = PrimalPart(step.sub[1], step.interface, 1, contact=True)
    yield omega1, omega2
    omega2.destroy()


@pytest.mark.parametrize("which, contact", [(0, False), (1, True), (1, False)])
def test_responses_equal_back_solves(parts, which, contact):
    part = parts[which]
    assert part.solver.has_inverse_entries()
    entries = part.responses(contact=contact, chunk=16)
    solves = AffinePart.responses(part, contact=contact, chunk=16)  # back-solves, 16 columns at a time
    assert part.n_g > 0 and (which == 0 or part.n_c > 0)
    assert np.abs(solves[0]).max() > 0.0
    for new, old in zip(entries, solves):
        assert new.shape == old.shape
        assert _relative(new, old) < TOL
