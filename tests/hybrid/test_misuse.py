"""Misuse of the Python API gives the right package error; residual checks never reject a converged solve."""

import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import ConvergenceError, InputError, MeshTagError
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.mixed import solve_mixed_hybrid
from fenics_contact.hybrid.primal import solve_primal_hybrid
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.primal import solve_primal_ms_hybrid
from fenics_contact.problem.fields import material_fields
from fenics_contact.problem.geometry import read_mesh, unit_square
from fenics_contact.problem.models import get_model, model_1, model_3, pixel_field

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial API checks")


@pytest.fixture(scope="module")
def cm():
    return unit_square(16, 4)


@pytest.fixture(scope="module")
def other_reference():
    coarse = unit_square(8, 4)
    return solve_primal_monolithic(model_1().on(coarse), delta=1e-4)


def _zero_load(model):
    return model.with_(load=lambda x: np.zeros((2, x.shape[1])))


def _empty_tags(cm, dim):
    return dmesh.meshtags(cm.mesh, dim, np.zeros(0, np.int32), np.zeros(0, np.int32))


MISUSE = {
    # (call, error class, words of the message)
    "zero load, Algorithm 1": (
        lambda cm, ref: solve_primal_hybrid(_zero_load(model_1()).on(cm), delta=1e-4),
        InputError,
        "body force",
    ),
    "zero load, Algorithm 3": (
        lambda cm, ref: solve_primal_ms_hybrid(_zero_load(model_1()).on(cm), delta=1e-4, cem=CEMOptions(layers=1)),
        InputError,
        "body force",
    ),
    "zero load, Algorithm 2": (
        lambda cm, ref: solve_mixed_hybrid(_zero_load(model_1()).on(cm)),
        InputError,
        "body force",
    ),
    "reference on another mesh, Algorithm 1": (
        lambda cm, ref: solve_primal_hybrid(model_1().on(cm), delta=1e-4, reference=ref.u),
        InputError,
        "another mesh",
    ),
    "reference on another mesh, Algorithm 3": (
        lambda cm, ref: solve_primal_ms_hybrid(model_1().on(cm), delta=1e-4, cem=CEMOptions(layers=1), reference=ref.u),
        InputError,
        "another mesh",
    ),
    "reference not a Function": (
        lambda cm, ref: solve_primal_hybrid(model_1().on(cm), delta=1e-4, reference=ref),
        InputError,
        "pass its .u",
    ),
    "mixed reference of the wrong kind": (
        lambda cm, ref: solve_mixed_hybrid(model_1().on(cm), reference=ref.u),
        InputError,
        "solve_mixed_monolithic",
    ),
    "no cell tags": (
        lambda cm, ref: solve_primal_hybrid(model_1().on(cm._replace(cell_tags=_empty_tags(cm, 2))), delta=1e-4),
        MeshTagError,
        "Omega1",
    ),
    "no facet tags": (
        lambda cm, ref: solve_primal_hybrid(model_1().on(cm._replace(facet_tags=_empty_tags(cm, 1))), delta=1e-4),
        MeshTagError,
        "Gamma_D",
    ),
    "no facet tags, monolithic": (
        lambda cm, ref: solve_primal_monolithic(model_1().on(cm._replace(facet_tags=_empty_tags(cm, 1))), delta=1e-4),
        MeshTagError,
        "Gamma_D",
    ),
    "cell tags as facet tags": (
        lambda cm, ref: solve_primal_monolithic(model_1().on(cm._replace(facet_tags=cm.cell_tags)), delta=1e-4),
        MeshTagError,
        "dimension 1",
    ),
    "a dolfinx Mesh for a ContactMesh": (
        lambda cm, ref: solve_primal_hybrid(model_1().on(cm.mesh), delta=1e-4),
        InputError,
        "ContactMesh",
    ),
    "a model number for a model": (lambda cm, ref: solve_primal_hybrid(1, delta=1e-4), InputError, "ContactProblem"),
    "options as a dict": (
        lambda cm, ref: solve_primal_hybrid(model_1().on(cm), delta=1e-4, options={"tol": 1e-3}),
        InputError,
        "IterationOptions",
    ),
    "Newton options as a dict": (
        lambda cm, ref: solve_mixed_hybrid(model_1().on(cm), newton={"rtol": 1e-3}),
        InputError,
        "NewtonOptions",
    ),
    "delta = inf (contact switched off)": (
        lambda cm, ref: solve_primal_hybrid(model_1().on(cm), delta=float("inf")),
        InputError,
        "primal penalty δ must be a finite number > 0",
    ),
    "delta as a string": (lambda cm, ref: solve_primal_hybrid(model_1().on(cm), delta="1e-4"), InputError, "penalty"),
    "alpha as a list": (
        lambda cm, ref: solve_primal_hybrid(model_1().on(cm), delta=1e-4, alpha=[1, 2]),
        InputError,
        "transmission coefficient",
    ),
    "default_penalty with E = 0": (lambda cm, ref: default_penalty(0.1, 0.0), InputError, "default_penalty"),
    "read_mesh with H = 0": (
        lambda cm, ref: read_mesh("meshes/unit_square_n16_H4.msh", H=0),
        InputError,
        "coarse size",
    ),
    "unit_square with a string": (lambda cm, ref: unit_square("16", 4), InputError, "1/h"),
    "max_iterations 2.5": (lambda cm, ref: IterationOptions(max_iterations=2.5), InputError, "integer"),
    "Newton max_iterations 0": (lambda cm, ref: NewtonOptions(max_iterations=0), InputError, "integer"),
    "pixel field of strings": (lambda cm, ref: pixel_field("abc"), InputError, "2D array"),
    "E field of the wrong shape": (
        lambda cm, ref: material_fields(cm.mesh, model_1().with_(youngs_modulus=lambda x: 1.0)),
        InputError,
        "must map points",
    ),
    "load of the wrong shape": (
        lambda cm, ref: material_fields(cm.mesh, model_1().with_(load=lambda x: np.zeros(x.shape[1]))),
        InputError,
        "values of shape (2, N)",
    ),
    "unknown model": (lambda cm, ref: get_model(6), InputError, "built-in models"),
    "E = 1e308 (overflow)": (
        lambda cm, ref: solve_primal_hybrid(model_1(E_high=1e308).on(cm), delta=1e-4),
        InputError,
        "Rescale the units",
    ),
}


@pytest.mark.parametrize("case", list(MISUSE))
def test_api_misuse_gives_a_package_error(cm, other_reference, case, monkeypatch):
    monkeypatch.chdir(__import__("pathlib").Path(__file__).parents[2])
    call, error, words = MISUSE[case]
    with pytest.raises(error) as info:
        call(cm, other_reference)
    assert words in str(info.value), str(info.value)


# ---------------------------------------------------------------------------------------------
# residual checks scaled by the size of the terms they balance
# ---------------------------------------------------------------------------------------------
def _backward_error(problem) -> float:
    final, size = problem.residual_check()
    return final / size


@pytest.mark.parametrize(
    "E_high, factor", [(1e3, 1e-3), (1e3, 1e-6), (1e3, 1e-9), (1e3, 1e-12), (1e8, 1e-3), (1e12, 1e-3)]
)
def test_primal_newton_accepts_converged_solves_for_any_penalty_and_contrast(E_high, factor):
    """Model 3 (stiff channels through the strip up to Γ_C): δ = factor·h/E_C down to 1e-12, contrast up to 1e12.

    The former check ‖F‖ ≤ 1e-8‖b‖ rejected δ = 1e-12 h/E (‖F‖/‖b‖ = 1.3e-3 at h = 1/16) and contrast 1e8
    (1.2e-7 at h = 1/32): the stiff and penalty terms cancel to the load, and rounding sees their size.
    """
    cm = unit_square(32, 8)
    delta = default_penalty(cm.h, E_high, factor)  # E_C = E_high: the channels reach Γ_C
    sol = solve_primal_monolithic(model_3(E_high=E_high).on(cm), delta=delta)
    assert _backward_error(sol.problem) < 1e-14  # rounding level, whatever δ and the contrast
    # the penetration is O(δ) (complementarity up to the penalty): it scales with the factor
    assert sol.profile.penetration <= 5.0 * factor * 6.6e-5 / 1e-3
    # and the check is not blind: a wrong value at one node is rejected
    u = sol.problem.u
    k = int(np.argmax(np.abs(u.x.array)))
    u.x.array[k] *= 1.0 + 1e-6
    assert _backward_error(sol.problem) > NewtonOptions().rtol


def test_hybrid_with_a_tiny_penalty_converges_to_the_monolithic_solution():
    """The issue's case: the former Ω₂ Newton check (‖F‖ ≤ 1e-8‖b‖) rejected δ ≤ 1e-7·h/E_C on model 3 at h = 1/32.

    Now the check is scaled, and a settled step that misses it gets a refinement step (5.9e-6 → passes here).
    """
    cm = unit_square(32, 8)
    model = model_3()
    delta = default_penalty(cm.h, 1e3, 1e-12)
    ref = solve_primal_monolithic(model.on(cm), delta=delta)
    res = solve_primal_hybrid(model.on(cm), delta=delta, reference=ref.u, options=IterationOptions(tol=1e-9))
    assert res.converged and res.e_u < 1e-6


def test_mixed_reference_at_contrast_1e8():
    cm = unit_square(16, 4)
    sol = solve_mixed_monolithic(model_3(E_high=1e8).on(cm))  # verify=True: the UFL residual check passes
    norm, size = sol.problem.ufl_residual_norm()
    assert norm <= 1e-10 * size and sol.profile.max_tensile >= 0.0


def test_a_singular_problem_is_a_convergence_error(cm):
    """Newton that cannot settle is a numerical failure (ConvergenceError), not bad input."""
    problem = model_1().on(cm)
    with pytest.raises(ConvergenceError, match="did not converge in 1 steps"):
        solve_primal_monolithic(problem, delta=1e-4, newton=NewtonOptions(max_iterations=1))
