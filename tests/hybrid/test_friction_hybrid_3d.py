"""Theorem 3.1 with friction on tetrahedra: Algorithm 1 along a press-then-drag path on the 3D channel model (stiff
channels through γ up to Γ_C) is the monolithic penalized Coulomb solution, by the condensed frictional system on
all three displacement components of the Γ_C nodes (``hybrid.friction``).  Algorithm 3 on coarse cubes along
the same kind of path: the monolithic solution once the patches cover Ω₁, within its localization error with one
layer."""

import numpy as np
import pytest
from friction_paths import snapshots
from mpi4py import MPI

from fenics_contact.hybrid.friction import FrictionalCondensation
from fenics_contact.problem.friction import Friction
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh
from fenics_contact.problem.obstacles import Plane

#: press the wall into Γ_C = {x = 1}, then drag it along y in three steps
PATH = [(-0.01, 0.0, 0.0), (-0.01, 0.005, 0.0), (-0.01, 0.01, 0.0), (-0.01, 0.02, 0.0)]


def _snapshots(method, problem, **options):
    return snapshots(method, problem, PATH, **options)


def _same_path(mono, other, u_mono, u_other, rtol=1e-8):
    """Each step of ``other`` converged to the monolithic displacement within ``rtol`` relative, with the same stick
    and slip nodes; the step pairs, for the checks a test adds."""
    for a, b, ua, ub in zip(mono.steps, other.steps, u_mono, u_other, strict=True):
        assert b.converged
        assert np.max(np.abs(ua - ub)) <= rtol * np.max(np.abs(ua))
        assert np.array_equal(a.friction.stick, b.friction.stick) and np.array_equal(a.friction.slip, b.friction.slip)
    return list(zip(mono.steps, other.steps))


@pytest.mark.parametrize("contrast", [1e3, 1e6])
def test_algorithm_1_is_the_monolithic_frictional_solution_in_3d(contrast):
    """Coulomb μ = 0.3 on the 6 × 6 × 6 channel mesh: at every step Algorithm 1's glued displacement equals the
    monolithic one to 1e-8 relative, with the same forces (normal and the tangential vector), stick/slip sets and
    dissipation.  The interface Newton runs the condensed frictional system and applies T at most 3 times per load
    step, with at most 2 Newton steps on the interface data after it (measured 1–2 and 0–1).  The dense contact
    Newton on the 126 Γ_C displacement components takes at most 8 steps per drag step from the committed state
    (measured 6–8), and at most 8 for the first press, the Newton on the law from the displacement of the load alone
    (measured 8 and 7): the interface Newton's steps, the dense ones with those after them, are at most 8 per load
    step (measured 6–8); the monolithic Newton at most 11 per step (measured 5–11), and at most 9 on the first
    press, the load alone's solve and the Newton on the law from it (measured 9 and 8)."""
    wall = Plane(point=(1.0, 0.5, 0.5), normal=(-1.0, 0.0, 0.0))
    model = channels_3d(E_high=contrast).on(channels_3d_mesh(6))
    problem = model.with_(obstacle=wall, law=Friction("coulomb", mu=0.3))
    mono, u_mono = _snapshots("primal-monolithic", problem)
    alg1, u_alg1 = _snapshots("primal", problem, tol=1e-11)
    assert isinstance(alg1.solver._newton.condensed, FrictionalCondensation)  # (not the "interface" strategy)
    for a, b, ua, ub in zip(mono.steps, alg1.steps, u_mono, u_alg1, strict=True):
        assert b.converged
        assert np.max(np.abs(ua - ub)) <= 1e-8 * np.max(np.abs(ua))
        assert abs(a.normal_force - b.normal_force) <= 1e-8 * a.normal_force
        assert np.max(np.abs(a.tangential_force - b.tangential_force)) <= 1e-8 * a.normal_force
        assert np.array_equal(a.friction.stick, b.friction.stick) and np.array_equal(a.friction.slip, b.friction.slip)
        assert abs(a.dissipation - b.dissipation) <= 1e-8 * mono.dissipation
        assert b.iterations <= 3 and b.interface_newton_steps - b.contact_newton_steps <= 2
        assert b.interface_newton_steps <= 8
    assert all(step.contact_newton_steps <= 8 for step in alg1.steps)
    assert mono.steps[0].iterations <= 9 and all(step.iterations <= 11 for step in mono.steps)
    assert np.linalg.norm(mono.steps[-1].tangential_force) > 0.1 * mono.steps[-1].normal_force  # a real drag
    assert mono.steps[-1].slip_nodes > mono.steps[1].slip_nodes  # the drag spreads the slip
    assert mono.dissipation > 0.0


@pytest.fixture(scope="module")
def channel_cubes():
    """The channel cube at h = 1/6 on coarse cubes of side ⅓ (Ω₁ = x < ⅔ holds 2 × 3 × 3 of them, Ω₂ is one cube
    wide; the load slab ½ < x < ¾ reaches into Ω₂), contrast 1e3, Coulomb μ = 0.3, and its monolithic path."""
    wall = Plane(point=(1.0, 0.5, 0.5), normal=(-1.0, 0.0, 0.0))
    H = 1.0 / 3.0
    model = channels_3d(E_high=1e3).on(channels_3d_mesh(6, strip=H, H=H, comm=MPI.COMM_SELF))
    problem = model.with_(obstacle=wall, law=Friction("coulomb", mu=0.3))
    return problem, *_snapshots("primal-monolithic", problem)


def test_algorithm_3_with_patches_covering_omega1_is_the_monolithic_frictional_solution(channel_cubes):
    """With m = 2 every patch is Ω₁ (no localization), so Algorithm 3's Ω₁ space holds the fine Robin solution for
    any interface data and load: along the press-and-drag path its glued displacement equals the monolithic one to
    1e-8 relative (measured ≤ 5e-12), with the same forces, stick/slip sets and dissipation; at most 8 interface
    Newton steps per load step (measured 2–4)."""
    problem, mono, u_mono = channel_cubes
    alg3, u_alg3 = _snapshots("primal-ms", problem, layers=2, tol=1e-11)
    assert alg3.solver.cem.layers == 2 and alg3.solver.cem.nbasis == 6
    for a, b, ua, ub in zip(mono.steps, alg3.steps, u_mono, u_alg3, strict=True):
        assert b.converged and b.interface_newton_steps <= 8
        assert np.max(np.abs(ua - ub)) <= 1e-8 * np.max(np.abs(ua))
        assert abs(a.normal_force - b.normal_force) <= 1e-8 * a.normal_force
        assert np.max(np.abs(a.tangential_force - b.tangential_force)) <= 1e-8 * a.normal_force
        assert np.array_equal(a.friction.stick, b.friction.stick) and np.array_equal(a.friction.slip, b.friction.slip)
        assert abs(a.dissipation - b.dissipation) <= 1e-8 * mono.dissipation
    assert np.linalg.norm(mono.steps[-1].tangential_force) > 0.1 * mono.steps[-1].normal_force  # a real drag


def test_algorithm_3_with_one_layer_along_the_frictional_path_in_3d(channel_cubes):
    """With m = 1 the bases are cut off on patches smaller than Ω₁: the displacement is within 5e-2 of the
    monolithic one at every step (measured 2.6–3.0e-2), and the normal and tangential forces are within that
    measured displacement error of the step (measured 3e-4 and 1e-4 of the normal force), with the same stick and
    slip nodes."""
    problem, mono, u_mono = channel_cubes
    alg3, u_alg3 = _snapshots("primal-ms", problem, layers=1, tol=1e-11)
    for a, b, ua, ub in zip(mono.steps, alg3.steps, u_mono, u_alg3, strict=True):
        assert b.converged and b.interface_newton_steps <= 8
        error = np.max(np.abs(ua - ub)) / np.max(np.abs(ua))
        assert 1e-6 < error <= 5e-2  # (a localization error, not round-off)
        assert abs(a.normal_force - b.normal_force) <= error * a.normal_force
        assert np.max(np.abs(a.tangential_force - b.tangential_force)) <= error * a.normal_force
        assert np.array_equal(a.friction.stick, b.friction.stick) and np.array_equal(a.friction.slip, b.friction.slip)
        assert b.dissipation >= 0.0


def test_tresca_in_3d():
    """Tresca (s = 0.05) on the channel cube at contrast 1e3, pressed and dragged: the convex energy's Newton
    (``fem.friction``: the primal–dual full step while it lowers the energy, else the exact line search) converges
    with ``primal-monolithic`` (measured 12, 64, 73, 29 steps; Algorithm 1's dense solve from the committed state
    12, 8, 8, 65) and Algorithm 1 equals it to 1e-8 with the same
    stick/slip sets; no node carries more than s, the slipping ones s, and every step dissipates."""
    wall = Plane(point=(1.0, 0.5, 0.5), normal=(-1.0, 0.0, 0.0))
    problem = (
        channels_3d(E_high=1e3).on(channels_3d_mesh(6)).with_(obstacle=wall, law=Friction("tresca", threshold=0.05))
    )
    mono, u_mono = _snapshots("primal-monolithic", problem)
    alg1, u_alg1 = _snapshots("primal", problem, tol=1e-11)
    for a, _ in _same_path(mono, alg1, u_mono, u_alg1):
        size = np.linalg.norm(a.friction.traction, axis=1)
        assert np.all(size <= 0.05 * (1.0 + 1e-10))
        assert np.allclose(size[a.friction.slip], 0.05, rtol=1e-10)
        assert a.dissipation > 0.0
    assert mono.steps[1].slip_nodes > 0 and mono.steps[1].stick_nodes > 0


@pytest.mark.parametrize("drag", [0.001, 0.005])
def test_coulomb_drag_on_the_channel_cube_at_h_one_eighth(drag):
    """Coulomb μ = 0.3 on the 8 × 8 × 8 channel mesh at contrast 1e3, pressed 0.01 and dragged along y: the
    monolithic frictional Newton converges (the energy-checked steps of ``fem.friction``), no node carries more
    than μp, the slipping ones μp, and the drag dissipates (measured 1 and 15 slipping nodes)."""
    wall = Plane(point=(1.0, 0.5, 0.5), normal=(-1.0, 0.0, 0.0))
    problem = channels_3d(E_high=1e3).on(channels_3d_mesh(8)).with_(obstacle=wall, law=Friction("coulomb", mu=0.3))
    path = [(-0.01, 0.0, 0.0), (-0.01, drag, 0.0)]
    mono, _ = snapshots("primal-monolithic", problem, path)
    step = mono.steps[-1]
    assert step.converged and step.slip_nodes > 0
    size = np.linalg.norm(step.friction.traction, axis=1)
    bound = 0.3 * step.friction.pressure
    assert np.all(size <= bound + 1e-12 * bound.max())
    assert np.allclose(size[step.friction.slip], bound[step.friction.slip], rtol=1e-10)
    assert step.dissipation > 0.0


def test_the_first_press_at_h_one_eighth_and_contrast_1e6():
    """Coulomb μ = 0.3 on the 8 × 8 × 8 channel mesh at contrast 1e6, pressed 0.01: Ω₂'s frictional solve inside
    Algorithm 1 presses from the displacement of the load alone by the Newton on the law (``fem.friction``; by the
    thresholds' fixed point it fails its residual check here), and Algorithm 1 is the monolithic solution to 1e-8
    relative with the same stick/slip sets; the dense press takes at most 8 steps (measured 8), the monolithic one at
    most 9 (the load alone's solve and 8)."""
    wall = Plane(point=(1.0, 0.5, 0.5), normal=(-1.0, 0.0, 0.0))
    problem = channels_3d(E_high=1e6).on(channels_3d_mesh(8)).with_(obstacle=wall, law=Friction("coulomb", mu=0.3))
    path = [(-0.01, 0.0, 0.0)]
    mono, u_mono = snapshots("primal-monolithic", problem, path)
    alg1, u_alg1 = snapshots("primal", problem, path, tol=1e-11)
    a, b = mono.steps[0], alg1.steps[0]
    assert a.converged and b.converged
    assert np.max(np.abs(u_mono[0] - u_alg1[0])) <= 1e-8 * np.max(np.abs(u_mono[0]))
    assert np.array_equal(a.friction.stick, b.friction.stick) and np.array_equal(a.friction.slip, b.friction.slip)
    assert a.slip_nodes > 0 and a.stick_nodes > 0
    assert b.contact_newton_steps <= 8 and a.iterations <= 9


def test_the_drags_at_h_one_fifth_and_contrast_1e6():
    """Coulomb μ = 0.3 on the 5 × 5 × 5 channel mesh at contrast 1e6, pressed and dragged along y: Algorithm 1 is the
    monolithic solution to 1e-8 relative at every step with the same stick/slip sets, and the dense Newton from the
    committed state converges with full steps (``fem.condensed_friction``: no line search on a recurring set in 3D
    from a given state) in at most 8 steps per drag (measured 7, 7, 8; with the backtracking on ‖R‖ the last drag
    stalled and took 26 in all through the trial state and the thresholds' fixed point).  The monolithic Newton
    takes full steps in 3D too (``fem.friction``): at most 8 on the last drag (measured 7; 18 with the backtracking on
    ‖F‖ once a set recurs)."""
    wall = Plane(point=(1.0, 0.5, 0.5), normal=(-1.0, 0.0, 0.0))
    problem = channels_3d(E_high=1e6).on(channels_3d_mesh(5)).with_(obstacle=wall, law=Friction("coulomb", mu=0.3))
    mono, u_mono = _snapshots("primal-monolithic", problem)
    alg1, u_alg1 = _snapshots("primal", problem, tol=1e-11)
    _same_path(mono, alg1, u_mono, u_alg1)
    assert all(step.contact_newton_steps <= 8 for step in alg1.steps[1:])
    assert mono.steps[-1].iterations <= 8
    assert mono.steps[-1].slip_nodes > 0


def test_the_monolithic_drags_at_nu_049_and_contrast_1e6():
    """Coulomb μ = 0.3 on the 6 × 6 × 6 channel mesh at ν = 0.49 and contrast 1e6, pressed and dragged along y: the
    monolithic Newton from the trial state takes full steps in 3D (``fem.friction``), at most 10 per drag (measured
    10, 8, 4; the second took 47 with the backtracking on ‖F‖ once a set recurred, its steps down to 10⁻⁹), no node
    carries more than μp, the slipping ones μp, and Algorithm 1 is the same path to 1e-8 relative with the same
    stick/slip sets.  Algorithm 1's dense Newton on the last drag fails from the committed state in its 10 steps and
    goes on from the trial state at its last iterate: at most 11 dense steps (measured 11; 14 with the trial state's
    Newton from the step's start)."""
    wall = Plane(point=(1.0, 0.5, 0.5), normal=(-1.0, 0.0, 0.0))
    model = channels_3d(E_high=1e6, nu=0.49).on(channels_3d_mesh(6))
    problem = model.with_(obstacle=wall, law=Friction("coulomb", mu=0.3))
    mono, u_mono = _snapshots("primal-monolithic", problem)
    alg1, u_alg1 = _snapshots("primal", problem, tol=1e-11)
    _same_path(mono, alg1, u_mono, u_alg1)
    assert all(step.iterations <= 10 for step in mono.steps[1:]) and mono.steps[2].iterations <= 8
    assert alg1.steps[-1].contact_newton_steps <= 11
    for step in mono.steps[1:]:
        size = np.linalg.norm(step.friction.traction, axis=1)
        bound = 0.3 * step.friction.pressure
        assert np.all(size <= bound + 1e-12 * bound.max())
        assert np.allclose(size[step.friction.slip], bound[step.friction.slip], rtol=1e-10)
        assert step.slip_nodes > 0 and step.dissipation > 0.0
