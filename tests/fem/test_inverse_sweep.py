"""One triangle of a symmetric block of A⁻¹ from MUMPS' factors (``inverse_entries.inverse_block(sweep=...)``).

The entries (i, j) with sweep[i] ≥ sweep[j] are computed and the block is filled by symmetry: it equals the
block of the dense inverse to 1e-12 relative to its largest entry, is exactly symmetric, and equals the block
computed whole (every entry requested) to the same tolerance, for distinct, tied and reversed sweeps, with and
without an equilibrated factorization (D A D); a block wider than the columns MUMPS takes at a time (``BLOCKING``)
is the dense inverse's too, and the call leaves the factor's controls of ordinary solves as they were.
"""

import numpy as np
import pytest
import scipy.sparse as sp
from petsc4py import PETSc

from fenics_contact.fem.inverse_entries import BLOCKING, available
from fenics_contact.fem.linalg import DirectSolver
from fenics_contact.fem.matrices import scipy_to_petsc

pytestmark = pytest.mark.skipif(not available(), reason="no PETSc library for entries of inverses")

TOL = 1e-12


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


@pytest.mark.parametrize("scaled", [False, True])
def test_one_triangle_by_symmetry_equals_the_whole_block(scaled):
    rng = np.random.default_rng(11)
    n = 60
    R = sp.random(n, n, density=0.08, random_state=rng)
    A = (R + R.T + 8.0 * sp.eye(n)).tocsr()  # symmetric positive definite (diagonally dominant)
    d = 2.0 ** rng.integers(-3, 4, n) if scaled else None
    solver = DirectSolver(PETSc.COMM_SELF, prefix=f"test_inverse_sweep_{int(scaled)}_", scaling=d, spd=True)
    Am = scipy_to_petsc(A if d is None else sp.diags(d) @ A @ sp.diags(d))
    solver.set_operator(Am)
    assert solver.has_inverse_entries()
    rows = rng.permutation(n)[:17]
    exact = np.linalg.inv(A.toarray())[np.ix_(rows, rows)]
    whole = solver.inverse_block(rows)
    sweeps = {
        "distinct": rng.standard_normal(rows.size),
        "tied": np.repeat([0.0, 1.0, 2.0], [6, 6, 5]),
        "reversed": -np.arange(rows.size, dtype=float),
    }
    for sweep in sweeps.values():
        block = solver.inverse_block(rows, sweep=sweep)
        assert np.array_equal(block, block.T)
        assert _relative(block, exact) < TOL and _relative(block, whole) < TOL
    for obj in (solver, Am):
        obj.destroy()


def test_blocks_of_many_columns_leave_the_solves_controls():
    """A block wider than MUMPS' column blocking (``BLOCKING``, ICNTL(27)) equals the dense inverse's, whole and by
    one triangle, and the factor's controls of ordinary solves (ICNTL(20), (27), (30)) are as before the call."""
    rng = np.random.default_rng(5)
    n = 2 * BLOCKING + 40
    R = sp.random(n, n, density=0.02, random_state=rng)
    A = (R + R.T + 8.0 * sp.eye(n)).tocsr()
    solver = DirectSolver(PETSc.COMM_SELF, prefix="test_inverse_blocking_", spd=True)
    Am = scipy_to_petsc(A)
    solver.set_operator(Am)
    factor = solver.ksp.getPC().getFactorMatrix()
    controls = {k: factor.getMumpsIcntl(k) for k in (20, 27, 30)}
    rows = rng.permutation(n)[: 2 * BLOCKING + 7]
    exact = np.linalg.inv(A.toarray())[np.ix_(rows, rows)]
    assert _relative(solver.inverse_block(rows), exact) < TOL
    assert _relative(solver.inverse_block(rows, sweep=rng.standard_normal(rows.size)), exact) < TOL
    assert {k: factor.getMumpsIcntl(k) for k in controls} == controls
    for obj in (solver, Am):
        obj.destroy()
