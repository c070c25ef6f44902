"""Units for two deformable bodies: a pair in Pa and m or in MPa and mm gives the answers of the same pair with
E ~ 1 and lengths ~ 1, scaled by the units, with the same Newton steps and the same stick/slip sets.

The pair: two blocks on non-matching meshes (7 against 10 cells across), the lower one in strata of contrast 10⁶
(E₀ and 10⁶ E₀: steel-like strata under a rubber-like block of E₀), the upper block E₀, its top pressed down and
tilted so that part of the contact surface opens.  In units (E₀, L) — the mesh scaled by L, every modulus by E₀,
the prescribed displacement by L — the contact forces / (E₀ L), u / L and the nodal pressures / E₀ are those of
E₀ = L = 1 to 1e-10, and every count is the same: Newton steps, interface Newton steps, evaluations of T.

What this checks: the defaults that carry units (the penalty δ = 1e-3 h/E, Algorithm 1's α_p = E_p/√(h L_ref) with
L_ref the pair's size, ``TwoBodyProblem.length``) and the stick/slip state rule at a node on its threshold (a node
that slipped in the last load step, ``fem.friction.TIE``).
"""

import numpy as np
import pytest
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.hybrid.certificate import FLOOR_MARGIN
from fenics_contact.hybrid.two_body import TwoBodyHybridOptions
from fenics_contact.problem.pair import Body, ContactPair, Support, TwoBodyProblem
from fenics_contact.problem.pair_meshes import PairTag as T
from fenics_contact.problem.pair_meshes import two_blocks

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial: the pair's unit checks")

CONTRAST = 1e6
#: (E₀, L): steel-sized moduli in Pa on a 5 cm pair, in MPa (N/mm²) on the same pair in mm, rubber in Pa on a mm pair
UNITS = [(2.1e11, 0.05), (2.1e5, 50.0), (5e6, 1e-3)]
RTOL = 1e-10


def _pair(E0: float, L: float, top, *, nu: float = 0.3, law=None, basis=None, upper: float = 1.0) -> TwoBodyProblem:
    """The tilted pair in units (E₀, L): the upper block's top moved by L·(top_x, top_y + 0.02 x/L), its modulus
    ``upper`` E₀."""
    m = two_blocks(7, 10, heights=(0.5, 0.4), offset=0.1, comm=MPI.COMM_SELF)
    m.mesh.geometry.x[:] *= L

    def strata(x):
        return E0 * np.where(np.sin(12.0 * x[1] / L) > 0.0, CONTRAST, 1.0)

    def pressed(x):
        return np.vstack([np.full(x.shape[1], top[0] * L), (top[1] + 0.02 * x[0] / L) * L])

    return TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(Body(T.LOWER, strata, nu), Body(T.UPPER, upper * E0, nu)),
        pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP, friction=law, basis=basis),
        supports=(Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP, pressed)),
    )


def _counts(result) -> tuple:
    if hasattr(result, "interface_newton_steps"):
        return result.interface_newton_steps, result.iterations, tuple(h.steps for h in result.newton)
    return (result.newton.steps,)


def _scaled(result, E0: float, L: float) -> dict:
    out = {
        "force": np.asarray(result.forces[0]) / (E0 * L),
        "u": result.u.x.array / L,
        "pressure": result.slave.sigma_c / E0,
        "counts": _counts(result),
    }
    if result.friction is not None:
        out["sets"] = (result.friction.stick.copy(), result.friction.slip.copy())
        out["dissipation"] = result.dissipation / (E0 * L * L)
    return out


def _assert_same(a: dict, b: dict, rtol: float = RTOL, utol: float = RTOL) -> None:
    """The same counts and stick/slip sets, u to ``utol``, forces and pressures to ``rtol``, dissipation to rtol or
    1e-8."""
    assert a["counts"] == b["counts"]
    for key, tol in (("force", rtol), ("u", utol), ("pressure", rtol)):
        assert np.linalg.norm(a[key] - b[key]) <= tol * np.linalg.norm(b[key]), key
    if "sets" in b:
        assert all(np.array_equal(x, y) for x, y in zip(a["sets"], b["sets"], strict=True))
        assert a["dissipation"] == pytest.approx(b["dissipation"], rel=max(rtol, 1e-8), abs=1e-14)


@pytest.mark.parametrize(("nu", "accel"), [(0.3, "newton"), (0.3, "anderson"), (0.4999, "newton")])
def test_algorithm_1_on_a_pair_in_physical_units_takes_the_unit_free_steps(accel, nu):
    """Algorithm 1 (a strip on each side) on the tilted pair: in Pa/m, MPa/mm and Pa on a mm pair the same
    interface Newton steps (or Anderson iterations), contact Newton steps and scaled answers as with E₀ = L = 1, and
    the monolithic solution of its units to 10·tol.  (Anderson at ν = 0.4999 does not reach 1e-9 in its 500
    evaluations of T, in any unit.)"""
    tol = 1e-10 if accel == "newton" else 1e-9
    unit_free = fc.solve(_pair(1.0, 1.0, (0.0, -0.01), nu=nu), "primal", accel=accel, tol=tol)
    assert unit_free.converged
    reference = _scaled(unit_free, 1.0, 1.0)
    for E0, L in UNITS:
        problem = _pair(E0, L, (0.0, -0.01), nu=nu)
        result = fc.solve(problem, "primal", accel=accel, tol=tol)
        _assert_same(_scaled(result, E0, L), reference)
        mono = fc.solve(problem, "primal-monolithic")
        assert np.linalg.norm(result.u.x.array - mono.u.x.array) <= 10 * tol * np.linalg.norm(mono.u.x.array)


@pytest.mark.parametrize("method", ["primal-monolithic", "primal"])
def test_coulomb_pair_path_in_physical_units_is_the_unit_free_path(method):
    """Coulomb friction (μ = 0.3) along a press–press–drag path, each step from the last one's state: in every unit
    the Newton steps, the stick/slip sets, forces, pressures and dissipation of E₀ = L = 1.  The second press starts
    with a node on its threshold (it slipped in the first: |t_trial| = τ up to round-off), which slips on in every
    unit."""
    path = ((0.0, -0.005), (0.0, -0.01), (0.004, -0.01))
    law = fc.Friction("coulomb", mu=0.3)

    def run(E0, L):
        state, out = None, []
        for top in path:
            result = fc.solve(_pair(E0, L, top, law=law), method, state=state)
            assert result.converged if hasattr(result, "converged") else True
            state = result.state
            out.append(_scaled(result, E0, L))
        return out

    reference = run(1.0, 1.0)
    assert np.any(reference[-1]["sets"][1])  # the drag slips
    for E0, L in UNITS:
        for a, b in zip(run(E0, L), reference, strict=True):
            _assert_same(a, b)


@pytest.mark.parametrize("basis", ["dual", "standard"])
def test_steel_on_rubber_patch_test_in_pa_and_mm(basis):
    """The contact patch test across units: a rubber-stiff block (5 MPa) pressed flat onto a steel-stiff one
    (210 GPa), ν = 0 (the clamped ends then leave the stress uniaxial and uniform), non-matching meshes: the dual
    basis transmits the uniform pressure to 1e-9 of it at every slave node; either basis gives in Pa/m and MPa/mm
    the pressures / E and steps of E = 1 (rubber) against 4.2e4 (steel) with lengths ~ 1."""

    def run(stress, L):
        m = two_blocks(7, 10, heights=(0.5, 0.4), comm=MPI.COMM_SELF)
        m.mesh.geometry.x[:] *= L
        problem = TwoBodyProblem(
            m.mesh,
            m.cell_tags,
            m.facet_tags,
            bodies=(Body(T.LOWER, 2.1e11 / stress, 0.0), Body(T.UPPER, 5e6 / stress, 0.0)),
            pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP, basis=basis),
            supports=(Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP, (0.0, -0.002 * L))),
        )
        return fc.solve(problem, "primal-monolithic")

    unit_free = run(5e6, 1.0)
    pressure = unit_free.slave.sigma_c
    if basis == "dual":
        assert np.max(np.abs(pressure - pressure.mean())) <= 1e-9 * abs(pressure.mean())
    for stress, L in ((1.0, 0.05), (1e6, 50.0)):  # Pa and m; MPa and mm
        result = run(stress, L)
        assert result.newton.steps == unit_free.newton.steps
        scaled = result.slave.sigma_c * stress / 5e6
        assert np.max(np.abs(scaled - pressure)) <= RTOL * np.max(np.abs(pressure))


def test_contrast_1e6_between_the_bodies_in_physical_units():
    """The upper block 10⁶ times stiffer than the lower one's top stratum, Coulomb μ = 0.3 along the press–drag path:
    the monolithic path is the unit-free one in every unit (steps, stick/slip sets, u to 1e-8 and the forces to 1e-6:
    the round-off of a contrast of 10⁶ at the contact, measured 8e-10 and 5e-8), and Algorithm 1
    reaches it in every unit with the same stick/slip sets, u to 1e-8 and the forces to 1e-6.  Algorithm 1's counts
    are not compared: on the stiff side of γ the Robin data are 10⁶ times the traction they carry, the transmission
    residual's round-off floor is 10⁻⁹–2·10⁻⁸, at its default tolerance 1e-8, so a unit can take one more
    evaluation of T (docs/limits.md)."""
    path = ((0.0, -0.005), (0.0, -0.01), (0.004, -0.01))
    law = fc.Friction("coulomb", mu=0.3)

    def run(E0, L, method):
        state, out = None, []
        for top in path:
            result = fc.solve(_pair(E0, L, top, law=law, upper=CONTRAST), method, state=state)
            state = result.state
            out.append(_scaled(result, E0, L))
        return out

    reference = run(1.0, 1.0, "primal-monolithic")
    for E0, L in [(1.0, 1.0), *UNITS]:
        mono = reference if E0 == L == 1.0 else run(E0, L, "primal-monolithic")
        for a, b in zip(mono, reference, strict=True):
            _assert_same(a, b, rtol=1e-6, utol=1e-8)
        for a, b in zip(run(E0, L, "primal"), mono, strict=True):
            assert all(np.array_equal(x, y) for x, y in zip(a["sets"], b["sets"], strict=True))
            assert np.linalg.norm(a["u"] - b["u"]) <= 1e-8 * np.linalg.norm(b["u"])
            assert np.linalg.norm(a["force"] - b["force"]) <= 1e-6 * np.linalg.norm(b["force"])


def test_a_stiff_stratum_pressed_on_a_soft_one_at_nu_04999_ends_at_the_round_off_floor():
    """Coulomb friction (μ = 0.3), ν = 0.4999 on both bodies, the upper block 10⁶ times stiffer than the lower one's
    top stratum: the first press's transmission residual scatters over 3·10⁻⁷–1.3·10⁻⁶ once the pair glues (its
    solves' errors, times the 6.5·10⁵ by which the stiff side's Robin data exceed the traction they carry), above the
    default tolerance 10⁻⁸.  Algorithm 1 ends there converged with status "floor" in a few evaluations of T
    (measured 4), the floor it reports above the tolerance and within ``FLOOR_MARGIN`` of the residual, and u the
    monolithic solution to the floor (measured 9·10⁻¹¹); the next press glues below the tolerance ("converged"), in
    every unit."""
    law = fc.Friction("coulomb", mu=0.3)
    for E0, L in [(1.0, 1.0), UNITS[0]]:
        state = mono_state = None
        for top, status in (((0.0, -0.005), "floor"), ((0.0, -0.01), "converged")):
            problem = _pair(E0, L, top, nu=0.4999, law=law, upper=CONTRAST)
            result = fc.solve(problem, "primal", state=state)
            mono = fc.solve(problem, "primal-monolithic", state=mono_state)
            assert result.converged and result.status == status, (top, result.status, result.residuals)
            if status == "floor":
                assert result.iterations <= 6
                assert TwoBodyHybridOptions().tol < result.floor <= result.transmission_residual * FLOOR_MARGIN
                assert result.transmission_residual <= FLOOR_MARGIN * result.floor
            else:
                assert result.transmission_residual < TwoBodyHybridOptions().tol
            error = np.linalg.norm(result.u.x.array - mono.u.x.array) / np.linalg.norm(mono.u.x.array)
            assert error <= result.floor, (top, error, result.floor)
            state, mono_state = result.state, mono.state
