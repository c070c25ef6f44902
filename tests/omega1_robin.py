"""The Ω₁ Robin problem of the CEM tests (``test_multiscale``, ``test_patch_group``): the unit square at h = 1/32
with coarse squares of side 1/8 (a module fixture, registered in ``conftest.py``), Robin data on γ, and the
multiscale solution's energy error against an independent fine solve."""

import numpy as np
import pytest

from fenics_contact.fem.primal import PrimalSubproblem
from fenics_contact.multiscale import cem
from fenics_contact.problem import geometry

__all__ = ["fine_robin_error", "mesh_32_8", "robin_data"]


@pytest.fixture(scope="module")
def mesh_32_8():
    """The unit square, h = 1/32, coarse squares of side H = 1/8 (Ω₂ the last column of them)."""
    return geometry.unit_square(32, 8)


def robin_data(om: cem.Omega1Multiscale) -> np.ndarray:
    """Smooth Robin data on the γ DOFs of ``om``: sin(3y) + 0.3 in x, 0.5 cos(2y) in y."""
    y = om.V.tabulate_dof_coordinates()[om.ops.gamma // 2, 1]
    return np.where(om.ops.gamma % 2 == 0, np.sin(3.0 * y) + 0.3, 0.5 * np.cos(2.0 * y))


def fine_robin_error(om: cem.Omega1Multiscale, g: np.ndarray) -> float:
    """Relative energy error of the multiscale Ω₁ Robin solution against an independent fine solve."""
    fine = PrimalSubproblem(
        om.ops.V.mesh, om.facet_tags, om.fields, delta=None, alpha=om.alpha_fn, prefix="test_ms_fine_gap_", V=om.V
    )
    try:
        fine.g.x.array[:] = 0.0
        fine.g.x.array[om.ops.gamma] = g
        fine.solve()
        ref = fine.u.x.array.copy()
    finally:
        fine.destroy()
    d = om.solver.solve(g) - ref
    return float(np.sqrt(d @ om.ops.K @ d / (ref @ om.ops.K @ ref)))
