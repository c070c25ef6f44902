"""The mixed hybrid methods (Algorithms 2 and 4) on an interface γ that bends.

The strip Ω₂ is the band of cells within a width of Γ_C that cuts the columns of right triangles between their
centroids (``problem.strip.automatic_split``): γ is a zigzag of mesh edges, bending at almost every vertex, in the
heterogeneous model 2 (inclusions of E = 10³).  At a bend the Robin data hold one traction per side
(``fem.mixed_interface.GammaBends``), so the fixed point of the iteration is the mixed solution on the space with
σn continuous across γ (σ_tt doubled only at the straight vertices of γ: ``split_interface=True``), and its
distance to the standard Arnold–Winther solution falls with h.
"""

import numpy as np
import pytest
from bent_interfaces import box_problem, zigzag_problem

import fenics_contact as fc
from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.mixed import solve_mixed_hybrid
from fenics_contact.multiscale.mixed import solve_mixed_ms_hybrid
from fenics_contact.multiscale.mixed_cem.options import MixedCEMOptions
from fenics_contact.problem.validation import interface_bends_of


@pytest.fixture(scope="module")
def algorithm_2():
    """Per h: the bends of γ, Algorithm 2 (interface Newton, tol 1e-10) against the split and the standard
    monolithic mixed solutions."""
    out = {}
    for n in (16, 24):
        problem = zigzag_problem(n)
        split = solve_mixed_monolithic(problem, split_interface=True)
        standard = fc.solve(problem, "mixed-monolithic", epsilon=split.epsilon)
        options = IterationOptions(accel="newton", tol=1e-10)
        exact = solve_mixed_hybrid(problem, reference=split, options=options)
        against = solve_mixed_hybrid(problem, reference=standard, options=options, step=exact.step)
        out[n] = (interface_bends_of(problem.cm).shape[0], exact, against, split, standard)
    return out


def test_algorithm_2_on_a_bent_interface_is_the_split_monolithic_solution(algorithm_2):
    """The fixed point is the mixed solution with σn continuous on γ: to round-off, with the certificate."""
    for n, (bends, exact, _, split, _) in algorithm_2.items():
        assert bends > n  # γ bends at most of its vertices
        assert exact.converged and exact.history.residuals[-1] < 1e-10
        assert exact.e_sigma < 1e-9 and exact.e_u < 1e-9, (n, exact.e_sigma, exact.e_u)
        assert abs(exact.profile.force - split.profile.force) < 1e-9 * abs(split.profile.force)


def test_algorithm_2_on_a_bent_interface_approaches_the_standard_solution(algorithm_2):
    """Against the standard AW solution (``fc.solve(problem, "mixed-monolithic")``) the difference is the σ_tt
    doubled at the straight vertices of γ: small and falling with h (e_σ 5.0e-5 → 2.6e-5, e_u 5.5e-7 → 1.9e-7
    from h = 1/16 to 1/24)."""
    (_, _, coarse, _, standard16), (_, _, fine, _, standard24) = algorithm_2[16], algorithm_2[24]
    assert coarse.e_sigma < 1e-4 and coarse.e_u < 1e-5
    assert fine.e_sigma < 0.7 * coarse.e_sigma and fine.e_u < 0.5 * coarse.e_u, (coarse.e_sigma, fine.e_sigma)
    for result, standard in ((coarse, standard16), (fine, standard24)):
        assert abs(result.profile.force - standard.profile.force) < 1e-6 * abs(standard.profile.force)


def test_algorithm_2_on_a_bent_interface_with_anderson():
    """The fixed-point update (Anderson) reaches the same fixed point: the certificate holds at 1e-10."""
    problem = zigzag_problem(16)
    split = solve_mixed_monolithic(problem, split_interface=True)
    result = solve_mixed_hybrid(problem, reference=split, options=IterationOptions(accel="anderson", tol=1e-10))
    assert result.converged and result.history.residuals[-1] < 1e-10
    assert result.e_sigma < 1e-8 and result.e_u < 1e-8


def test_algorithm_4_on_a_bent_interface_falls_with_the_layers():
    """Algorithm 4 on the zigzag γ with coarse cells of side 1/4 (γ cuts them, slivers merged): the certificate
    holds, and the error against the fixed point of the fine splitting falls with the oversampling layers m
    (e_σ 0.10, 6.1e-3 for m = 1, 2); at m = 3 every patch is the whole Ω₁, and Algorithm 4 is Algorithm 2."""
    problem = zigzag_problem(16, H=0.25)
    assert interface_bends_of(problem.cm).shape[0] > 16
    split = solve_mixed_monolithic(problem, split_interface=True)
    errors = []
    for m in (1, 2, 3):
        result = solve_mixed_ms_hybrid(
            problem, cem=MixedCEMOptions(layers=m), reference=split, options=IterationOptions(accel="newton", tol=1e-10)
        )
        assert result.converged and result.history.residuals[-1] < 1e-10
        errors.append(result.e_sigma)
    assert errors[1] < 0.1 * errors[0], errors
    assert errors[1] < 1e-2 and errors[2] < 1e-9, errors


def test_algorithms_2_and_4_on_a_box_strip():
    """A box-shaped Ω₂ (γ with two right-angle corners) in model 2, whose inclusions meet γ: Algorithm 2 is the
    split monolithic solution to round-off; Algorithm 4's error falls with m (e_σ 8.3e-2, 4.0e-3 for m = 1, 2).
    Against the standard AW solution the difference stays at e_σ ≈ 4e-3 (h = 1/16 and 1/32): where E jumps
    across γ, σ_tt jumps too, which X̃_h (σ_tt doubled at the straight vertices of γ) holds and AW does not."""
    problem = box_problem(16)
    corners = interface_bends_of(problem.cm)
    assert np.allclose(np.sort(corners[:, 1]), [0.25, 0.75]) and np.allclose(corners[:, 0], 0.75)
    split = solve_mixed_monolithic(problem, split_interface=True)
    options = IterationOptions(accel="newton", tol=1e-10)
    result = solve_mixed_hybrid(problem, reference=split, options=options)
    assert result.converged and result.history.residuals[-1] < 1e-10
    assert result.e_sigma < 1e-9 and result.e_u < 1e-9
    errors = []
    for m in (1, 2):
        ms = solve_mixed_ms_hybrid(problem, cem=MixedCEMOptions(layers=m), reference=split, options=options)
        assert ms.converged and ms.history.residuals[-1] < 1e-10
        errors.append(ms.e_sigma)
    assert errors[1] < 0.1 * errors[0] and errors[1] < 1e-2, errors


def test_algorithm_2_on_a_homogeneous_box_strip_approaches_the_standard_solution():
    """The same box in one material: the fixed point approaches the standard AW solution fast (e_σ 2.8e-4 →
    2.9e-6, e_u 8.1e-6 → 4.4e-8 from h = 1/16 to 1/32)."""
    errors = []
    for n in (16, 32):
        problem = box_problem(n, E_high=1.0)
        standard = fc.solve(problem, "mixed-monolithic")
        result = solve_mixed_hybrid(problem, reference=standard, options=IterationOptions(accel="newton", tol=1e-10))
        assert result.converged and result.history.residuals[-1] < 1e-10
        errors.append((result.e_sigma, result.e_u))
    (s16, u16), (s32, u32) = errors
    assert s16 < 1e-3 and u16 < 1e-4
    assert s32 < 0.1 * s16 and u32 < 0.1 * u16, errors
