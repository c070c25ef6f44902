"""Interface Newton and the certificate with boundary data: a prescribed displacement, tractions, free sides.

A heterogeneous model (model 2, contrast 1e3) clamped on the left with a prescribed displacement
u_D ≠ 0, a traction on the top side, a traction-free bottom and a rigid plane at a gap from Γ_C
(partial contact): Newton reaches the fixed point of the Robin iteration (Anderson run to a
transmission residual of 1e-10 on the same step), Algorithm 1 + Newton equals the monolithic
solve and Algorithm 2 + Newton the monolithic solve on X̃_h; the certificate refuses an extreme α
that the relative change would accept; load steps with a moving circle (the contact direction ν
changes with the depth, so the condensation is rebuilt) give the monolithic forces.
"""

import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI

import fenics_contact  # noqa: F401
from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.iteration import IterationOptions, iterate
from fenics_contact.hybrid.mixed import MixedHybridStep, solve_mixed_hybrid
from fenics_contact.hybrid.primal import DEFAULT_ALPHA, PrimalHybridStep, solve_primal_hybrid
from fenics_contact.indentation import force_indentation
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model
from fenics_contact.problem.obstacles import Circle, Plane

serial = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="mixed (Arnold–Winther) methods are serial")
TIGHT = 1e-10
TOP = "Gamma_N_top"


def _mesh():
    return unit_square(16, 4, clamped=("left",), neumann={"top": TOP})


def _model(gap: float = 0.5):
    boundary = BoundaryConditions(
        displacement=lambda x: np.vstack([0.02 * x[1], -0.01 + 0.0 * x[0]]), tractions={TOP: (0.5, -1.0)}
    )
    return get_model(2, E_high=1e3).with_(boundary=boundary, obstacle=Plane((1.0 + gap, 0.5), (-1.0, 0.0)))


def _relative_l2(a: fem.Function, b: fem.Function) -> float:
    comm = a.function_space.mesh.comm
    d = fem.Function(a.function_space)
    d.x.array[:] = a.x.array - b.x.array
    norm = [comm.allreduce(fem.assemble_scalar(fem.form(ufl.inner(f, f) * ufl.dx)), op=MPI.SUM) for f in (d, a)]
    return float(np.sqrt(norm[0] / norm[1]))


def test_primal_newton_with_displacement_traction_and_gap():
    cm, model = _mesh(), _model()
    delta = default_penalty(cm.h, 1.0)
    ref = solve_primal_monolithic(model.on(cm), delta=delta)
    active = ref.profile.active
    assert 0 < active.sum() < active.size  # the gap matters: partial contact
    step = PrimalHybridStep(model.on(cm), alpha=DEFAULT_ALPHA, delta=delta)
    robin = solve_primal_hybrid(
        model.on(cm), delta=delta, step=step, options=IterationOptions(tol=TIGHT, max_iterations=3000)
    )
    newton = solve_primal_hybrid(
        model.on(cm), delta=delta, step=step, options=IterationOptions(tol=TIGHT, accel="newton")
    )
    assert robin.converged and newton.converged and newton.history.newton_steps <= 8
    assert _relative_l2(robin.u, newton.u) < 1e-8
    assert _relative_l2(ref.u, newton.u) < 1e-10  # Theorem 3.1: the monolithic solution
    # the Newton data are the Robin fixed point: a Robin run started there stops at once
    again = iterate(step, IterationOptions(tol=TIGHT), initial=newton.history.data)
    assert again.converged and again.iterations == 1


@pytest.mark.parametrize("accel", ["anderson", "newton"])
def test_certificate_with_boundary_data_refuses_a_wrong_answer(accel):
    """α = 1e8: the relative change falls below 1e-6 at once; only a right answer may be 'converged'."""
    cm, model = _mesh(), _model()
    delta = default_penalty(cm.h, 1.0)
    ref = solve_primal_monolithic(model.on(cm), delta=delta)
    result = solve_primal_hybrid(
        model.on(cm),
        alpha=1e8,
        delta=delta,
        reference=ref.u,
        options=IterationOptions(tol=1e-6, accel=accel, max_iterations=200),
    )
    assert not result.converged or result.e_u < 1e-5, (result.converged, result.e_u)
    if accel == "anderson":  # stalls far from the solution, and says so
        assert not result.converged and result.history.transmission_residual > 1e-2 and result.e_u > 0.1
        assert min(result.history.rel_changes) < 1e-3  # what the paper's rule would have accepted
    else:
        assert result.converged and result.e_u < 1e-6


@serial
def test_mixed_newton_with_displacement_traction_and_gap():
    cm, model = _mesh(), _model()
    split = solve_mixed_monolithic(model.on(cm), split_interface=True)
    assert 0 < split.profile.active.sum() < split.profile.active.size
    step = MixedHybridStep(model.on(cm), beta="sqrt-h")
    step.prepare()
    robin = solve_mixed_hybrid(model.on(cm), step=step, reference=split, options=IterationOptions(tol=TIGHT))
    robin_fields = [f.copy() for f in step.glued()]
    newton = solve_mixed_hybrid(
        model.on(cm), step=step, reference=split, options=IterationOptions(tol=TIGHT, accel="newton")
    )
    assert robin.converged and newton.converged and newton.history.newton_steps <= 8
    assert newton.e_sigma < 1e-10 and newton.e_u < 1e-10  # the monolithic solution on X̃_h
    assert max(_relative_l2(a, b) for a, b in zip(robin_fields, step.glued())) < 1e-8


def test_load_steps_with_newton_and_a_moving_circle():
    """ν at the Γ_C nodes changes with the circle's position: Newton rebuilds its condensation and gives
    the monolithic forces at every depth; a repeated depth is one application of T."""
    cm = unit_square(16, 4, clamped=("left",))
    model = get_model(2, E_high=1e3).with_(obstacle=Circle((3.0, 0.5), 2.0))
    depths = [0.5, 1.0, 1.0]
    newton = force_indentation(
        model.on(cm), "primal", depths, direction=(-1.0, 0.0), options=IterationOptions(tol=TIGHT, accel="newton")
    )
    mono = force_indentation(model.on(cm), "primal-monolithic", depths, direction=(-1.0, 0.0))
    assert all(s.converged and s.iterations == 1 for s in newton.steps)
    assert np.allclose(newton.forces, mono.forces, rtol=1e-8, atol=0.0), (newton.forces, mono.forces)
    assert newton.steps[0].profile.active.sum() < newton.steps[1].profile.active.sum()
