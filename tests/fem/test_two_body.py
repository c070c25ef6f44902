"""Two deformable bodies in contact (``problem.pair``, ``fem.mortar``, ``fem.two_body``): the contact patch test on
non-matching meshes, the initial gap, force balance, two-body Hertz, 3D, and what is refused."""

import numpy as np
import pytest
import scipy.spatial
from mpi4py import MPI
from pair_problems import hertz_cylinder_pair

import fenics_contact as fc
from fenics_contact.errors import InputError
from fenics_contact.fem.two_body import transmitted_pressure
from fenics_contact.problem.analytic import hertz_errors, hertz_pair
from fenics_contact.problem.pair import Body, ContactPair, Support, TwoBodyProblem
from fenics_contact.problem.pair_meshes import PairTag as T
from fenics_contact.problem.pair_meshes import cylinder_on_block, two_blocks

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="two-body contact runs on one process")

#: lower block (0, 1) × (−½, 0) and upper block (0, 1) × (g, g + 0.4): moduli and Poisson ratios
E1, NU1, E2, NU2 = 1.0, 0.3, 5.0, 0.2
H1, H2 = 0.5, 0.4


def _stacked(
    n_lower=7, n_upper=10, *, slave="upper", d=0.01, gap=0.0, rule="segments", dim=2, nus=(NU1, NU2), basis=None
):
    """The two blocks pressed together by u_y = −d on the upper top: rollers on the bottom and the left sides
    (the blocks expand sideways freely: they slide along each other where ν₁ ≠ ν₂); ``basis`` of the pressure."""
    m = two_blocks(n_lower, n_upper, heights=(H1, H2), gap=gap, dim=dim)
    up = dim - 1
    pair = (T.UPPER_BOTTOM, T.LOWER_TOP) if slave == "upper" else (T.LOWER_TOP, T.UPPER_BOTTOM)
    push = np.zeros(dim)
    push[up] = -d
    return TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(Body(T.LOWER, E1, nus[0]), Body(T.UPPER, E2, nus[1])),
        pair=ContactPair(*pair, rule=rule, basis=basis),
        supports=(
            Support(T.LOWER_BOTTOM, components=(up,)),
            Support(T.LOWER_LEFT, components=(0,)),
            Support(T.UPPER_LEFT, components=(0,)),
            Support(T.UPPER_TOP, push, components=(up,)),
        )
        + ((Support(T.LOWER_SIDES, components=(1,)), Support(T.UPPER_SIDES, components=(1,))) if dim == 3 else ()),
    )


def _pressure(d, gap, delta, nus=(NU1, NU2)):
    """The exact uniform pressure: d − g = p (H₁/E₁' + H₂/E₂') + δ p, E' = E/(1 − ν²) (plane strain in 2D; in 3D
    σ_xx = 0 and ε_yy = 0: the blocks expand freely along x between rollers on the faces y = 0, W)."""
    soft = lambda E, nu: E / (1 - nu**2)  # noqa: E731
    return max(d - gap, 0.0) / (H1 / soft(E1, nus[0]) + H2 / soft(E2, nus[1]) + delta)


@pytest.mark.parametrize("basis", ["dual", "standard"])
@pytest.mark.parametrize("slave", ["upper", "lower"])
def test_patch_test_non_matching_meshes_transmits_a_uniform_pressure(slave, basis):
    """7 against 10 cells across, either side the slave, either pressure basis: the pressure is the exact constant
    to round-off on both surfaces, the pressure the pair transmits too at every quadrature point, and the forces on
    the two bodies are equal and opposite to round-off."""
    result = fc.solve(_stacked(slave=slave, basis=basis), "primal-monolithic")
    p = _pressure(0.01, 0.0, result.delta)
    for profile in (result.slave, result.master):
        assert np.max(np.abs(profile.sigma_c + p)) < 1e-9 * p
        assert profile.force == pytest.approx(p * 1.0, rel=1e-10)  # width 1
    slave_force, master_force = result.forces
    assert np.abs(slave_force + master_force).max() < 1e-13 * p
    traction = transmitted_pressure(result)
    assert np.max(np.abs(traction.pressure - p)) < 1e-9 * p
    assert np.allclose(traction.master_points[:, 0], traction.points[:, 0], rtol=0.0, atol=1e-14)
    resultant = (traction.weights * traction.pressure) @ traction.nu
    assert np.abs(resultant + slave_force).max() < 1e-13 * p
    assert result.force_balance() < 1e-12
    assert result.newton.steps == 1  # linearized at the touching points, the first step is the solution


def test_a_body_held_by_contact_alone_under_a_traction():
    """The upper block held only sideways (a roller on its left side) and pushed down by a traction p on its top:
    the contact carries exactly p whatever δ (the first Newton step starts from the touching points)."""
    m = two_blocks(7, 10, heights=(H1, H2))
    pressure = 0.02
    problem = TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(Body(T.LOWER, E1, NU1), Body(T.UPPER, E2, NU2)),
        pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP),
        supports=(
            Support(T.LOWER_BOTTOM, components=(1,)),
            Support(T.LOWER_LEFT, components=(0,)),
            Support(T.UPPER_LEFT, components=(0,)),
        ),
        tractions={T.UPPER_TOP: (0.0, -pressure)},
    )
    result = fc.solve(problem, "primal-monolithic")
    for profile in (result.slave, result.master):
        assert np.max(np.abs(profile.sigma_c + pressure)) < 1e-9 * pressure
    assert result.slave.penetration == pytest.approx(result.delta * pressure, rel=1e-8)


def test_node_to_segment_fails_the_patch_test():
    """The one-pass node-to-segment rule (slave vertices, lumped weights) does not transmit a uniform pressure
    across these non-matching meshes, with either side the slave: why the package integrates segment to segment."""
    for slave in ("upper", "lower"):
        result = fc.solve(_stacked(slave=slave, rule="vertices"), "primal-monolithic")
        p = _pressure(0.01, 0.0, result.delta)
        worst = max(np.max(np.abs(prof.sigma_c + p)) for prof in (result.slave, result.master))
        assert worst > 1e-2 * p


def test_the_initial_gap_is_closed_first():
    """A gap g between the blocks: a push d < g leaves them apart (no force), d > g transmits p(d − g)."""
    gap = 0.004
    apart = fc.solve(_stacked(gap=gap, d=0.5 * gap), "primal-monolithic")
    assert np.all(apart.slave.sigma_c == 0.0) and apart.slave.force == 0.0
    assert np.allclose(apart.slave.u_c[np.isfinite(apart.slave.u_c)], -0.5 * gap, rtol=1e-9)
    closed = fc.solve(_stacked(gap=gap, d=0.01), "primal-monolithic")
    p = _pressure(0.01, gap, closed.delta)
    assert np.max(np.abs(closed.master.sigma_c + p)) < 1e-9 * p
    assert closed.slave.penetration == pytest.approx(closed.delta * p, rel=1e-8)  # the penalty law s = δ p


@pytest.mark.parametrize(("slave", "cells"), [("upper", (3, 4)), ("lower", (5, 3))])
def test_three_dimensions_patch_test_to_round_off(slave, cells):
    """Two boxes with non-matching tetrahedral meshes (3 against 4 and 5 against 3 cells across), different E and ν
    (they slide along each other): the slave triangles clipped against the master's, the pressure is the exact
    constant to round-off on both surfaces (and the pressure the pair transmits at every quadrature point), the
    forces are equal and opposite; Algorithm 1 with the same code reaches the monolithic solution."""
    problem = _stacked(*cells, dim=3, slave=slave)
    result = fc.solve(problem, "primal-monolithic")
    p = _pressure(0.01, 0.0, result.delta)
    for profile in (result.slave, result.master):
        assert np.max(np.abs(profile.sigma_c + p)) < 1e-9 * p
        assert profile.force == pytest.approx(p * 1.0, rel=1e-10)  # area 1
    assert np.max(np.abs(transmitted_pressure(result).pressure - p)) < 1e-9 * p
    slave_force, master_force = result.forces
    assert np.abs(slave_force + master_force).max() < 1e-13 * p
    assert result.force_balance() < 1e-12
    assert result.newton.steps == 1
    if slave == "upper":  # Algorithm 1 with the same code: its fixed point is this solution
        hybrid = fc.solve(problem, "primal", layers=1, tol=1e-10)
        assert hybrid.converged
        assert np.linalg.norm(hybrid.u.x.array - result.u.x.array) < 1e-9 * np.linalg.norm(result.u.x.array)


@pytest.mark.slow
def test_two_body_hertz_on_non_matching_meshes():
    """An elastic cylinder (R = 5, E = 2, ν = 0.25) on a block (E = 1, ν = 0.3), contact cells a/40: Hertz with
    R* = R and E* from both bodies, on both surfaces: the half-width within 2 contact cells, the peak within
    1 %, the L² profile within 1.5 % (measured with the dual basis: -0.6/+1.2 cells, +0.08 %, 0.26/0.43 %; the
    standard basis 0.92/0.99 %)."""
    radius, a, refinement = 5.0, 0.05, 2.0
    m = cylinder_on_block(radius, a, refinement=refinement)
    problem = TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(Body(T.LOWER, 1.0, 0.3), Body(T.UPPER, 2.0, 0.25)),
        pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP),
        supports=(Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP, (0.0, -1.1e-3))),
    )
    result = fc.solve(problem, "primal-monolithic")
    assert result.force_balance() < 1e-12
    r_star, e_star = hertz_pair((radius, np.inf), (2.0, 1.0), (0.25, 0.3))
    assert r_star == radius
    for profile in (result.slave, result.master):
        errors = hertz_errors(profile, radius=r_star, E=e_star, nu=0.0, h_contact=a / (20 * refinement))
        assert 0.8 * a < errors.a < 1.2 * a
        assert abs(errors.half_width_cells) < 2.0
        assert abs(errors.peak_error) < 0.01
        assert errors.l2_error < 0.015


def _hertz_l2(traction, pressure: np.ndarray, h: float) -> tuple[float, float, float]:
    """The relative L² error against Hertz of ``pressure`` at the points of ``traction`` (a and p₀ from its own
    resultant), its peak error, and the largest |x| where it is nonzero beyond a + h (0: none)."""
    x, w = traction.points[:, 0], traction.weights
    r_star, e_star = hertz_pair((5.0, np.inf), (2.0, 1.0), (0.25, 0.3))
    force = float(np.sum(w * pressure))
    a = 2.0 * np.sqrt(r_star * force / (np.pi * e_star))
    p0 = 2.0 * force / (np.pi * a)
    exact = p0 * np.sqrt(np.maximum(1.0 - (x / a) ** 2, 0.0))
    l2 = np.sqrt(np.sum(w * (pressure - exact) ** 2) / np.sum(w * exact**2))
    beyond = np.abs(x[(pressure != 0.0) & (np.abs(x) > a + h)])
    return float(l2), float(pressure.max() / p0 - 1.0), float(beyond.max(initial=0.0))


@pytest.mark.parametrize("slave", ["cylinder", "block"])
def test_the_pressure_the_pair_transmits_at_a_20(slave):
    """Two-body Hertz at contact cells a/20 (the pair of the test above), either body the slave, the dual pressure
    basis (the default): the nodal pressures λ_p = (s̃_p)⁺/δ are the slave's nodal pressures σ_c (no mass matrix
    couples the slave nodes); their P1 interpolant vanishes beyond a contact cell past ±a, peaks within 1 % of p₀
    and is within 1.5 % of Hertz in L² over the whole contact (measured 1.48 % and 0.79 %), below the P1 pressure of
    the standard basis (3.21 % and 1.72 %: its nodal values over- and undershoot at the edge).  The field the
    penalty applies, Σ_p λ_p ψ_p, has the resultant of the contact forces and that of the interpolant."""
    h = 0.05 / 20
    result = fc.solve(hertz_cylinder_pair(slave, 1.0), "primal-monolithic")
    assert result.problem.pair.basis == "dual"
    traction = transmitted_pressure(result, degree=8)
    w, p = traction.weights, traction.pressure
    resultant = (w * p) @ traction.nu
    assert np.abs(resultant + result.forces[0]).max() < 1e-12 * np.abs(resultant).max()
    assert np.sum(w * traction.nodal) == pytest.approx(np.sum(w * p), rel=1e-12)
    l2, peak, beyond = _hertz_l2(traction, traction.nodal, h)
    assert l2 < 0.015 and abs(peak) < 0.01 and beyond == 0.0
    Q, V = result.quadrature, result.u.function_space
    lam = np.maximum(Q.B @ result.u.x.array[: Q.B.shape[1]] - Q.gap, 0.0) / result.delta
    x = V.tabulate_dof_coordinates()[Q.nodes, :2]
    profile = result.slave
    distance, at = scipy.spatial.cKDTree(profile.points).query(x)
    assert distance.max() < 1e-14
    assert np.max(np.abs(profile.sigma_c[at] + lam)) < 1e-3 * lam.max()  # the normals differ by < 1e-3 rad
    standard = fc.solve(hertz_cylinder_pair(slave, 1.0, basis="standard"), "primal-monolithic")
    t_standard = transmitted_pressure(standard, degree=8)
    assert np.array_equal(t_standard.pressure, t_standard.nodal)
    assert _hertz_l2(t_standard, t_standard.pressure, h)[0] > l2


def test_the_pressure_basis_of_a_pair():
    """Dual by default for a segment-to-segment pair with or without friction, standard node-to-segment; the dual
    basis refuses the node-to-segment rule, and an unknown basis is refused."""
    assert ContactPair(1, 2).basis == "dual"
    assert ContactPair(1, 2, friction=fc.Friction("coulomb", mu=0.3)).basis == "dual"
    assert ContactPair(1, 2, rule="vertices", friction=fc.Friction("coulomb", mu=0.3)).basis == "standard"
    assert ContactPair(1, 2, rule="vertices").basis == "standard"
    assert ContactPair(1, 2, basis="standard").basis == "standard"
    assert ContactPair(1, 2, friction=fc.Friction("tresca", threshold=0.1), basis="dual").basis == "dual"
    with pytest.raises(InputError, match="needs the segment-to-segment rule"):
        ContactPair(1, 2, rule="vertices", basis="dual")
    with pytest.raises(InputError, match="must be 'standard' or 'dual'"):
        ContactPair(1, 2, basis="biorthogonal")


def test_methods_that_cannot_do_two_bodies_refuse():
    problem = _stacked(2, 3)
    for method in ("mixed", "mixed-monolithic", "mixed-ms"):
        with pytest.raises(InputError, match="cannot solve two deformable bodies"):
            fc.solve(problem, method)
    with pytest.raises(InputError, match="needs H"):
        fc.solve(problem, "primal-ms")
    with pytest.raises(InputError, match="takes the options"):
        fc.solve(problem, "primal-monolithic", tol=1e-8)
    with pytest.raises(InputError, match="takes the options"):
        fc.solve(problem, "primal", cem=None)
    with pytest.raises(InputError, match="unknown update"):
        fc.solve(problem, "primal", accel="multigrid")
    with pytest.raises(InputError, match="solved once"):
        fc.METHODS["primal-monolithic"].build(problem)
