"""Boundary conditions, the same in every fine method: Γ_D (clamped or u_D), Γ_N tractions, traction free.

A manufactured solution exercises all of them at once with active contact against a
curved gap: u quadratic with ε_xy = 0 (so σ is linear, σ_xy = 0: frictionless on x = 1),
u = u_D on the left side, the exact tractions on two groups (top, bottom), and the gap
g(y) = u_x(1, y) along ν = (1, 0), so that the whole of Γ_C is in contact with σ_c < 0.
Arnold–Winther contains the linear stress, so the mixed solution is exact to round-off
(stress) and Algorithm 2 reaches it; P1 converges at rate 2 in L².
"""

import gmsh
import numpy as np
import pytest
import ufl
from dolfinx import fem
from manufactured import LAM, MU, E, manufactured_model
from manufactured import manufactured_mesh as _mesh
from manufactured import stress as _sigma
from mpi4py import MPI

import fenics_contact  # noqa: F401
from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.fem.arnold_winther import ArnoldWintherSpace
from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.fem.mixed_spaces import boundary_stress_space
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.mixed import solve_mixed_hybrid
from fenics_contact.hybrid.primal import solve_primal_hybrid
from fenics_contact.problem.boundary import BoundaryConditions, check_boundary_groups
from fenics_contact.problem.geometry import build_unit_square_model, gmsh_session, read_mesh, unit_square
from fenics_contact.problem.tags import neumann_tag

serial = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="mixed (Arnold–Winther) methods are serial")


def _l2(expr, msh):
    return np.sqrt(
        msh.comm.allreduce(
            fem.assemble_scalar(
                fem.form(ufl.inner(expr, expr) * ufl.dx(domain=msh, metadata={"quadrature_degree": 8}))
            ),
            op=MPI.SUM,
        )
    )


def _exact_u(msh):
    X = ufl.SpatialCoordinate(msh)
    return ufl.as_vector([-0.1 * X[0] ** 2 + 0.05 * X[1] ** 2 - 0.2 * X[0], -0.1 * X[0] * X[1] + 0.02 * X[1] ** 2])


def _exact_sigma(msh):
    X = ufl.SpatialCoordinate(msh)
    exx, eyy = -0.2 * X[0] - 0.2, -0.1 * X[0] + 0.04 * X[1]
    return ufl.as_vector([(LAM + 2 * MU) * exx + LAM * eyy, 0.0, LAM * exx + (LAM + 2 * MU) * eyy])


def test_primal_manufactured_rate_and_algorithm_1():
    errors = []
    for n in (8, 16):
        cm = _mesh(n)
        delta = default_penalty(cm.h, E)
        sol = solve_primal_monolithic(manufactured_model().on(cm), delta=delta)
        assert np.all(sol.profile.active)  # the whole of Γ_C is in contact
        errors.append(_l2(sol.u - _exact_u(cm.mesh), cm.mesh) / _l2(_exact_u(cm.mesh), cm.mesh))
    assert errors[1] < 2e-3 and np.log2(errors[0] / errors[1]) > 1.8, errors
    hybrid = solve_primal_hybrid(
        manufactured_model().on(cm), delta=delta, reference=sol.u, options=IterationOptions(tol=1e-10)
    )
    assert hybrid.converged and hybrid.e_u < 1e-8


@serial
def test_mixed_manufactured_exact_and_algorithm_2():
    cm = _mesh(8)
    model = manufactured_model()
    sol = solve_mixed_monolithic(model.on(cm))
    assert np.all(sol.profile.active)
    s_ex = _exact_sigma(cm.mesh)
    assert _l2(sol.sigma - s_ex, cm.mesh) / _l2(s_ex, cm.mesh) < 1e-11
    # u_h is the L² projection of the quadratic u: O(h²)
    assert _l2(sol.u - _exact_u(cm.mesh), cm.mesh) / _l2(_exact_u(cm.mesh), cm.mesh) < 5e-3
    split = solve_mixed_monolithic(model.on(cm), split_interface=True)
    alg2 = solve_mixed_hybrid(model.on(cm), reference=split, options=IterationOptions(tol=1e-11))
    assert alg2.converged
    assert _l2(alg2.sigma - s_ex, cm.mesh) / _l2(s_ex, cm.mesh) < 1e-8


@serial
def test_arnold_winther_traction_lifting():
    """σn = t on traction edges (moments and vertex values), σn = 0 on free edges: the exact linear
    stress lies in {P c + σ_t} (and not in the span of P alone)."""
    cm = _mesh(4)
    boundary = manufactured_model().boundary
    space = boundary_stress_space(cm.mesh, cm.facet_tags, boundary)
    assert space.lifting_dg is not None and space.incompatible_vertices.size == 0
    full = ArnoldWintherSpace(cm.mesh)  # on the unconstrained space the interpolant of a linear σ is exact
    target = full.prolongation @ full.interpolate(_sigma)
    P = space.prolongation
    c, *_ = np.linalg.lstsq(P.toarray(), target - space.lifting_dg, rcond=None)
    assert np.linalg.norm(P @ c + space.lifting_dg - target) < 1e-10 * np.linalg.norm(target)
    # without the lifting the stress is not representable (σn ≠ 0 on Γ_N)
    c0, *_ = np.linalg.lstsq(P.toarray(), target, rcond=None)
    assert np.linalg.norm(P @ c0 - target) > 1e-2 * np.linalg.norm(target)


def test_bad_boundary_input(tmp_path):
    with pytest.raises(InputError, match="Gamma_N"):
        BoundaryConditions(tractions={"top": (0, 1)})
    with pytest.raises(InputError, match="constant vector"):
        BoundaryConditions(tractions={"Gamma_N": (0, 1, 2, 3)})
    with pytest.raises(InputError, match="cannot be clamped"):
        unit_square(4, 2, clamped=("left", "top"), neumann={"top": "Gamma_N"})
    with pytest.raises(InputError, match="unknown side"):
        unit_square(4, 2, clamped=("right",))
    cm = unit_square(4, 2, clamped=("left",), neumann={"top": "Gamma_N_top"})
    assert cm.neumann_names == {neumann_tag("Gamma_N_top"): "Gamma_N_top"}
    with pytest.raises(MeshTagError, match="'Gamma_N_side'"):
        check_boundary_groups(
            cm.mesh, cm.facet_tags, BoundaryConditions(tractions={"Gamma_N_top": (0, 1), "Gamma_N_side": (1, 0)})
        )
    with pytest.raises(InputError, match="Gamma_N_top.*no traction"):
        check_boundary_groups(cm.mesh, cm.facet_tags, BoundaryConditions(), names=cm.neumann_names)
    # a Gamma_N group overlapping Gamma_D in a user's file
    path = tmp_path / "overlap.msh"
    if MPI.COMM_WORLD.rank == 0:
        with gmsh_session():
            build_unit_square_model(4, 2, clamped=("left", "bottom"))
            left = gmsh.model.getEntitiesForPhysicalGroup(1, 11)[:1]
            gmsh.model.addPhysicalGroup(1, list(left), neumann_tag("Gamma_N_load"), name="Gamma_N_load")
            gmsh.write(str(path))
    path = MPI.COMM_WORLD.bcast(path, root=0)
    with pytest.raises(MeshTagError, match="'Gamma_D' and 'Gamma_N_load' share"):
        read_mesh(path)


@serial
@pytest.mark.slow
def test_algorithm_3_takes_a_prescribed_displacement():
    """Algorithm 3 with u_D on Ω₁'s Γ_D (its lifting u_g), the tractions and the curved gap of the
    manufactured problem (whole Γ_C in contact): the error against Algorithm 1's fixed point falls with the
    oversampling m, and with patches covering Ω₁ (m = 3 on a 3 × 4 coarse Ω₁) it is that fixed point to the
    CEM's round-off; without the lifting (clamped instead) the answer is a different problem."""
    from fenics_contact.multiscale.cem import CEMOptions
    from fenics_contact.multiscale.primal import solve_primal_ms_hybrid

    cm = _mesh(16)
    model = manufactured_model()
    delta = default_penalty(cm.h, E)
    mono = solve_primal_monolithic(model.on(cm), delta=delta)
    options = IterationOptions(tol=1e-10, accel="newton")
    alg1 = solve_primal_hybrid(model.on(cm), delta=delta, reference=mono.u, options=options)
    assert alg1.converged and alg1.e_u < 1e-8
    errors = []
    for m in (1, 2, 3):
        res = solve_primal_ms_hybrid(
            model.on(cm),
            alpha="Emin",
            delta=delta,
            cem=CEMOptions(layers=m, nbasis=3),
            reference=mono.u,
            options=options,
        )
        assert res.converged
        errors.append(res.e_u)
    print("Algorithm 3 with u_D, e_u for m = 1, 2, 3:", errors)
    assert errors[2] < 1e-6 and errors[1] < errors[0] / 5 and errors[2] < errors[1] / 5, errors
    exact = _l2(_exact_u(cm.mesh), cm.mesh)
    assert _l2(mono.u - _exact_u(cm.mesh), cm.mesh) / exact < 2e-3
    clamped = solve_primal_ms_hybrid(
        model.with_(boundary=BoundaryConditions(tractions=dict(model.boundary.tractions))).on(cm),
        alpha="Emin",
        delta=delta,
        cem=CEMOptions(layers=3, nbasis=3),
        reference=mono.u,
        options=options,
    )
    assert clamped.e_u > 1e-2  # u_D matters: dropping it is not a small error
