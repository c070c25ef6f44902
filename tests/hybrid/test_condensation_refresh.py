"""A load step moves the obstacle: the interface Newton's condensation is refreshed from what stays.

When the obstacle moves, only the contact normals in Qᵀ change: ``PrimalPart`` keeps the block of J₀⁻¹ that
MUMPS computed (no second call), and ``CondensedInterface(previous=...)`` keeps K = I − P₁P₂ (Yc is
unchanged).  The refreshed pieces equal the back-solves at the new normals and a condensation built from
scratch, to 1e-12 relative to the largest entry.
"""

import numpy as np
import pytest

from fenics_contact.fem.inverse_entries import available
from fenics_contact.fem.linalg import DirectSolver
from fenics_contact.hybrid.condensation import CondensedInterface
from fenics_contact.hybrid.iteration import InterfaceNewtonOptions
from fenics_contact.hybrid.primal import PrimalHybridStep
from fenics_contact.hybrid.response import AffinePart
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model
from fenics_contact.problem.obstacles import Circle

pytestmark = pytest.mark.skipif(not available(), reason="no PETSc library for entries of inverses")

TOL = 1e-12


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max(initial=0.0) / max(np.abs(b).max(initial=0.0), np.finfo(float).tiny))


def test_moved_obstacle_keeps_the_inverse_block_and_the_interface_matrix(monkeypatch):
    calls = []
    entries = DirectSolver.inverse_block
    monkeypatch.setattr(
        DirectSolver, "inverse_block", lambda self, rows, **kw: calls.append(rows.size) or entries(self, rows, **kw)
    )
    cm = unit_square(32, 8)
    cylinder = Circle((3.0, 0.5), 2.0)
    problem = get_model(3, E_high=1e3).with_(obstacle=cylinder.indented(0.01, (-1.0, 0.0))).on(cm)
    step = PrimalHybridStep(problem)
    step.prepare()
    interface = step.interface_problem(InterfaceNewtonOptions())
    first = CondensedInterface(interface)
    made = len(calls)  # Ω₁'s response and Ω₂'s J₀ block
    step.contact.set_obstacle(cylinder.indented(0.02, (-1.0, 0.0)))
    assert interface.omega2.refresh()  # the normals moved
    kept = CondensedInterface(interface, previous=first)
    assert len(calls) == made  # J₀⁻¹ on the γ and Γ_C unknowns: kept
    assert kept.lu is first.lu and kept.P1 is first.P1
    assert np.array_equal(kept.Yc, first.Yc) and _relative(kept.Yq, first.Yq) > 1e-6
    solves = AffinePart.responses(interface.omega2, contact=True, chunk=16)  # back-solves at the new normals
    for new, old in zip((kept.Yc, kept.Sc, kept.Yq, kept.Sq), solves):
        assert _relative(new, old) < TOL
    fresh = CondensedInterface(interface)
    assert _relative(kept.M, fresh.M) < TOL and _relative(kept.Gq, fresh.Gq) < TOL
    interface.omega2.destroy()
