"""Friction in the mixed methods: the sliding block (mixed monolithic and Algorithm 2), Algorithm 2 = the monolithic
frictional solution on X̃_h along a load path and Algorithm 4 within its multiscale error of it, Cattaneo–Mindlin
and Mindlin–Deresiewicz at ν = 0.4999."""

import numpy as np
import pytest

from fenics_contact.fem.mixed import MixedSolution, solve_mixed_monolithic
from fenics_contact.problem.analytic import cattaneo_mindlin, hertz_model
from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.meshes import hertz_block
from fenics_contact.problem.models import get_model
from fenics_contact.problem.obstacles import Plane
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.sliding import slide

MU, THRESHOLD = 0.3, 3e-3
WALL = Plane((1.0, 0.0), (-1.0, 0.0))  # flush with Γ_C = {x = 1}
#: press the wall 0.01 into the block, then drag it along Γ_C past sliding
BLOCK_PATH = [(-0.005, 0.0), (-0.01, 0.0), (-0.01, 0.005), (-0.01, 0.02), (-0.01, 0.05)]
HYBRID = {"tol": 1e-11}


def _block(law):
    return ContactProblem(1.0, 0.3, obstacle=WALL, law=law).on(unit_square(16, 4, clamped=("left",)))


def _corners_and_slip(step, carrying):
    """The sticking nodes are ends of Γ_C, where the traction-free sides force σ_t = σ_xy = 0 (the AW vertex value
    is one tensor); every other node of the ``carrying`` ones (with a threshold τ > 0) slips."""
    fp = step.friction
    assert set(fp.points[fp.stick, 1]) <= {0.0, 1.0}
    assert np.all(np.abs(fp.shear[fp.stick]) <= 1e-12 * np.max(np.abs(fp.shear)))
    assert step.slip_nodes == np.count_nonzero(carrying) - step.stick_nodes > 40
    return fp


@pytest.mark.parametrize("law", [Friction("coulomb", mu=MU), Friction("tresca", threshold=THRESHOLD)])
def test_the_forms_state_the_friction_law(law):
    """The residual assembled from the UFL forms (``forms_mixed.friction_term``: the law written on σ_t, the sticking
    target a DG P3 function at the Gauss–Lobatto points) vanishes at the Newton solution to round-off (measured
    4e-13–1.2e-12 of the size of its terms on two machines, with stick and slip nodes), and moving every anchor by
    1e-3 changes it as it changes the nodal residual the Newton solves (both ‖D F‖ 2.5e-4)."""
    problem = ContactProblem(1.0, 0.3, obstacle=WALL.translated((-0.01, 0.0)), law=law)
    sub = solve_mixed_monolithic(problem.on(unit_square(16, 4, clamped=("left",)))).problem  # (verify=True)
    fp = sub.friction.profile()
    assert np.any(fp.stick) and np.any(fp.slip)
    norm, scale = sub.ufl_residual_norm()
    assert norm < 1e-11 * scale
    sub.friction.anchor += 1e-3
    moved, nodal = sub.ufl_residual_norm()[0], sub.residual()[0]
    assert moved > 1e-3 * scale and abs(moved - nodal) < 1e-10 * nodal


@pytest.mark.parametrize("method", ["mixed-monolithic", "mixed", "mixed-ms"])
def test_sliding_block_coulomb(method):
    """Pressed, then dragged past sliding: every contact node slips but the two ends of Γ_C, and the tangential force
    of the slipping nodes is μ times their normal force plus the slip penalty's excess ε_t × slip (measured 5.4e-4
    relative: ε_t = 6.25e-5, the last step slips 0.03); the path dissipates (each step ≥ 0)."""
    nodes = []
    path = slide(
        _block(Friction("coulomb", mu=MU)),
        method,
        BLOCK_PATH,
        on_step=lambda step, solver: nodes.append(solver.contact.contact_nodes),
        **(HYBRID if method != "mixed-monolithic" else {}),
    )
    last = path.steps[-1]
    fp = _corners_and_slip(last, last.friction.pressure > 0.0)
    T, N = last.tangential_force, last.normal_force
    assert abs(T[0]) < 1e-12 * N and abs(fp.normal_force / N - 1.0) < 1e-7  # (N: σ_c; fp: (−σ_c)⁺)
    slipping = np.sum(fp.weights[fp.slip] * np.abs(fp.shear[fp.slip])) / (
        MU * np.sum((fp.weights * fp.pressure)[fp.slip])
    )
    assert 0.0 < slipping - 1.0 < 2e-3, slipping
    # the essential conditions fix σ_t = 0 at the two right-angled corners and nowhere else (σ_c stays free there):
    # the tangential force is μ times the normal force off them (+ the slip penalty's excess, measured 5.4e-4), the
    # corner with its pressure carrying 2.3 % of N (h = 1/16; ``test_the_corner_share_of_the_normal_force``)
    fixed = nodes[-1].shear_fixed[nodes[-1].profile_nodes]
    assert set(fp.points[fixed, 1]) == {0.0, 1.0} and not np.any(nodes[-1].normal_fixed)
    assert np.all(fp.shear[fixed] == 0.0)
    corner = float(np.sum((fp.weights * fp.pressure)[fixed]))
    assert 0.0 < T[1] / (MU * (N - corner)) - 1.0 < 2e-3
    assert 0.02 < corner / N < 0.03 and abs(T[1] / (MU * N) - 1.0) < 0.03
    assert all(s.dissipation >= 0.0 for s in path.steps) and path.dissipation > 0.0
    assert all(s.converged for s in path.steps)
    first_drag = path.steps[2]  # dragged 0.005: a stick zone remains, below sliding
    assert first_drag.stick_nodes > 2 and abs(first_drag.tangential_force[1]) < MU * first_drag.normal_force


@pytest.mark.parametrize("method", ["mixed-monolithic", "mixed", "mixed-ms"])
def test_sliding_block_tresca(method):
    """Tresca: the slipping nodes carry s (+ ε_t × slip: measured 6.2e-4 relative), the tangential force is s times
    the length of Γ_C but the two end nodes' weights h/12 each (measured 0.9902 = (1 − 1/96)(1 + 6.2e-4))."""
    path = slide(
        _block(Friction("tresca", threshold=THRESHOLD)),
        method,
        BLOCK_PATH,
        **(HYBRID if method != "mixed-monolithic" else {}),
    )
    last = path.steps[-1]
    fp = _corners_and_slip(last, np.ones(last.friction.points.shape[0], bool))
    excess = np.abs(fp.shear[fp.slip]) / THRESHOLD - 1.0
    assert np.all(excess > 0.0) and np.max(excess) < 1e-3
    length = float(np.sum(fp.weights))
    ends = float(np.sum(fp.weights[fp.stick]))
    assert abs(length - 1.0) < 1e-12
    ratio = last.tangential_force[1] / (THRESHOLD * (length - ends))
    assert 0.0 < ratio - 1.0 < 1e-3, ratio


def test_the_corner_share_of_the_normal_force():
    """The pressure at the corner where σ_t is fixed to 0 grows like a corner singularity, p ~ h^(λ−1), so its share
    w p/N (w = h/12) of the normal force, the sliding block's tangential deficit 1 − T/(μN), falls like h^λ:
    measured 2.32 %, 1.41 %, 0.86 % at h = 1/16, 1/32, 1/64 (λ ≈ 0.71); asserted: at least like h^½ from 1/16 to
    1/32, and T = μ(N − the corner's share) (+ the slip penalty's excess) at both."""
    shares = []
    for n in (16, 32):
        nodes = []
        problem = ContactProblem(1.0, 0.3, obstacle=WALL, law=Friction("coulomb", mu=MU))
        path = slide(
            problem.on(unit_square(n, n // 4, clamped=("left",))),
            "mixed-monolithic",
            BLOCK_PATH,
            on_step=lambda step, solver: nodes.append(solver.contact.contact_nodes),
        )
        last = path.steps[-1]
        fp, N = last.friction, last.normal_force
        fixed = nodes[-1].shear_fixed[nodes[-1].profile_nodes]
        corner = float(np.sum((fp.weights * fp.pressure)[fixed]))
        assert 0.0 < last.tangential_force[1] / (MU * (N - corner)) - 1.0 < 2e-3
        shares.append(corner / N)
    assert 0.0 < shares[1] < shares[0] / np.sqrt(2.0) and shares[0] < 0.03, shares


def _split_monolithic_path(problem, path):
    """The monolithic frictional path on X̃_h (σ_tt split at the γ vertices: Algorithm 2's fixed point), with a
    MixedSolution of each step."""
    solutions = []

    def keep(step, solver):
        sub = solver.contact
        solutions.append(
            MixedSolution(sub.sigma_function(), sub.u_function(), None, None, sub.epsilon, {}, 0.0, 0.0, None, True)
        )

    return slide(problem, "mixed-monolithic", path, split_interface=True, on_step=keep), solutions


def _model3_path(n: int, n_coarse: int):
    """Model 3 (stiff channels through γ up to Γ_C, contrast 1e3), Coulomb μ = 0.3, the wall pressed in by 2e-3 in
    two steps and dragged by 0.002, 0.008, 0.03."""
    depth = 2e-3
    path = [(-depth / 2, 0.0), (-depth, 0.0), (-depth, 0.002), (-depth, 0.008), (-depth, 0.03)]
    model = get_model(3, E_high=1e3).with_(obstacle=WALL, law=Friction("coulomb", mu=MU))
    return model.on(unit_square(n, n_coarse)), path


def _against(problem, path, method, **options):
    """``method``'s path and its (e_σ, e_u) per step against the monolithic frictional path on X̃_h."""
    mono, solutions = _split_monolithic_path(problem, path)
    errors = []

    def compare(step, solver):
        solver.set_reference(solutions[len(errors)])
        errors.append(solver.errors())

    return mono, slide(problem, method, path, on_step=compare, **options), errors


def test_algorithm_2_is_the_monolithic_frictional_path():
    """Model 3 (stiff channels through γ up to Γ_C, contrast 1e3, h = 1/16, H = 1/4), Coulomb μ = 0.3, pressed then
    dragged: at every step Algorithm 2 (tolerance 1e-11) is the monolithic frictional solution on X̃_h with
    e_σ, e_u < 1e-8 (its frictionless tolerance), the same stick/slip nodes, tractions and dissipation."""
    mono, hybrid, errors = _against(*_model3_path(16, 4), "mixed", **HYBRID)
    for a, b, (e_s, e_u) in zip(mono.steps, hybrid.steps, errors):
        assert b.converged and e_s < 1e-8 and e_u < 1e-8, (e_s, e_u)
        assert np.array_equal(a.friction.stick, b.friction.stick) and np.array_equal(a.friction.slip, b.friction.slip)
        scale = np.max(np.abs(a.friction.traction))
        assert np.max(np.abs(a.friction.traction - b.friction.traction)) <= 1e-8 * scale
        assert abs(a.dissipation - b.dissipation) <= 1e-8 * hybrid.dissipation
    assert hybrid.steps[-1].slip_nodes > hybrid.steps[2].slip_nodes > 0


def test_algorithm_4_along_a_frictional_path():
    """Algorithm 4 on the same path (h = 1/16, H = 1/4): with m = 2 layers e_σ = 2.5e-4 at every step (measured; the
    frictionless solve has the same), with m = 3 (every patch all of Ω₁) e_σ ≤ 1.2e-11: the multiscale stress
    space is then the fine one; the stick and slip nodes those of the monolithic path; e_u = 0.12–0.14 for both,
    the displacement's floor in the multiscale space (U_aux; model 3 loads Ω₁), as frictionless."""
    problem, path = _model3_path(16, 4)
    for layers, bound in ((2, 5e-4), (3, 1e-9)):
        mono, ms, errors = _against(problem, path, "mixed-ms", layers=layers, tol=1e-10)
        for a, b, (e_s, e_u) in zip(mono.steps, ms.steps, errors):
            assert b.converged and e_s < bound and e_u < 0.2, (layers, e_s, e_u)
            assert np.array_equal(a.friction.stick, b.friction.stick) and np.array_equal(
                a.friction.slip, b.friction.slip
            )


A = 0.05
#: a half-space to the contact: the block 1000a × 500a, graded from the contact cells to 64a cells far away; the
#: cylinder's radius 1000a (the law's tangent, normal to the cylinder, turns by |x|/R ≤ 10⁻³ across the contact)
HALF_SPACE = {"width": 1000.0, "depth": 500.0, "h_far": 64.0}
R, PRESS, DRAG = 1000.0 * A, 1.7e-4, 2.4e-5
#: measured at h_c = a/10, a/20 (``benchmarks/results/friction_mixed.md``): the L² errors of p (pressed), of q at
#: the two drag steps and moved back, and the bounds asserted
CATTANEO_BOUNDS = {0.5: (0.012, 0.05, 0.05), 1.0: (0.005, 0.025, 0.03)}


def _l2(values, exact, weights, inside):
    return np.sqrt(np.sum((weights * (values - exact) ** 2)[inside]) / np.sum((weights * exact**2)[inside]))


def _contact_half_width(x, p):
    """Half the extent of the run of nodes in contact (p > 0) around the axis."""
    order = np.argsort(x)
    x, touching = x[order], p[order] > 0.0
    lo = hi = int(np.argmin(np.abs(x)))
    while lo > 0 and touching[lo - 1]:
        lo -= 1
    while hi < x.size - 1 and touching[hi + 1]:
        hi += 1
    return 0.5 * (x[hi] - x[lo])


def _ends_carry_nothing(nodes, profile, hertz_a, hc):
    """Γ_C (|x| ≤ 3a) ends next to the traction-free top, in line with it: the AW vertex value there has σn = 0, so
    σ_c = 0 identically.  Those two nodes and no other are the ones whose σ_c the essential conditions fix (their
    rows of Q empty; every other row has an entry ≥ 0.1 of Q's largest, measured 0.37), σ_c is exactly 0 there
    (their gap is open), and no node beyond the Hertz zone (a + one cell) carries a pressure."""
    keep = nodes.profile_nodes
    fixed = nodes.normal_fixed[keep]
    x = profile.points[:, 0]
    assert np.allclose(np.sort(x[fixed]), [-3.0 * A, 3.0 * A], rtol=0.0, atol=1e-12)
    assert np.all(profile.sigma_c[fixed] == 0.0) and np.all(profile.gap[fixed] > 0.0)
    Q = nodes.Q_local
    row_max = np.array([np.max(np.abs(Q.getrow(k).data), initial=0.0) for k in range(Q.shape[0])])
    assert np.all(row_max[~nodes.normal_fixed[nodes.rows]] >= 0.1 * np.max(row_max))
    assert not np.any(profile.active & (np.abs(x) > hertz_a + hc))
    assert np.all(profile.sigma_c[np.abs(x) > hertz_a + hc] >= 0.0)


def test_no_pressure_at_the_ends_of_the_contact_boundary():
    """Frictionless Hertz block at h_c = a/10, ν = 0.3, pressed by 1.7e-4 (``_ends_carry_nothing``)."""
    cm, spec = hertz_block(A, refinement=0.5, **HALF_SPACE)
    model = hertz_model(radius=R, E=1.0, nu=0.3, depth=PRESS)
    solution = solve_mixed_monolithic(model.on(cm))
    hertz = cattaneo_mindlin(
        solution.profile.points[:, 0], normal=solution.profile.force, tangential=0.0, mu=0.3, radius=R, nu=0.3
    )
    _ends_carry_nothing(solution.problem.contact_nodes, solution.profile, hertz.a, spec.h_contact)


@pytest.mark.parametrize("refinement", [0.5, pytest.param(1.0, marks=pytest.mark.slow)], ids=["a/10", "a/20"])
def test_cattaneo_mindlin_incompressible(refinement):
    """A cylinder pressed into a half-space-like block with P, then moved sideways until Q < μP, ν = 0.4999 (no
    normal–tangential coupling: Cattaneo–Mindlin is the exact half-space answer): stick zone |x| ≤ c,
    c = a√(1 − Q/(μP)), q(x) = μp₀[√(1 − x²/a²) − (c/a)√(1 − x²/c²)], a and p₀ Hertz's for the computed P.
    The mixed method does not lock.

    Measured (``benchmarks/friction.py --mixed --half-space``) at Q/μP = 0.33 and 0.64: the pressed state's p
    within 0.8 % (a/10) and 0.2 % (a/20) of Hertz in L² and so under Q, its contact half-width within 0.3 cells
    of a; the stick zone within 0.15 cells of c, its centre within 0.22 cells of the axis; q's L² error over the
    contact zone 3.6 %, 1.5 % (a/10) and 1.7 %, 1.1 % (a/20).  Asserted: p and q within ``CATTANEO_BOUNDS``, the
    half-width within 1 cell, the centre within 1 cell, the slip zone at μp plus the slip penalty's excess,
    dissipation ≥ 0.  Then moved back (Mindlin–Deresiewicz, below).
    """
    nu, mu = 0.4999, 0.3
    bound_p, bound_q, bound_md = CATTANEO_BOUNDS[refinement]
    cm, spec = hertz_block(A, refinement=refinement, **HALF_SPACE)
    model = hertz_model(radius=R, E=1.0, nu=nu, depth=0.0).with_(law=Friction("coulomb", mu=mu))
    motions = [(0.0, -PRESS / 2), (0.0, -PRESS), (DRAG, -PRESS), (2 * DRAG, -PRESS), (DRAG, -PRESS)]
    nodes = []
    path = slide(
        model.on(cm),
        "mixed-monolithic",
        motions,
        on_step=lambda step, solver: nodes.append(solver.contact.contact_nodes),
    )
    hc = spec.h_contact
    pressed = path.steps[1].friction
    x, w = pressed.points[:, 0], pressed.weights
    hertz = cattaneo_mindlin(x, normal=path.steps[1].normal_force, tangential=0.0, mu=mu, radius=R, nu=nu)
    assert 0.9 < hertz.a / A < 1.1  # measured 1.014
    _ends_carry_nothing(nodes[1], path.steps[1].profile, hertz.a, hc)
    assert np.all(pressed.pressure[np.abs(x) > hertz.a + hc] == 0.0)
    assert (
        _l2(pressed.pressure, hertz.p0 * np.sqrt(np.maximum(1.0 - (x / hertz.a) ** 2, 0.0)), w, slice(None)) < bound_p
    )
    assert abs(_contact_half_width(x, pressed.pressure) - hertz.a) <= 1.0 * hc
    ratios = []
    for step in path.steps[2:4]:
        fp = step.friction
        P, Q = step.normal_force, abs(step.tangential_force[0])
        x, w = fp.points[:, 0], fp.weights
        cat = cattaneo_mindlin(x, normal=P, tangential=Q, mu=mu, radius=R, nu=nu)
        ratios.append(Q / (mu * P))
        lo, hi = fp.extent("stick")
        assert abs(0.5 * (hi - lo) - cat.c) <= 1.0 * hc
        assert abs(0.5 * (hi + lo)) <= 1.0 * hc
        assert _l2(np.abs(fp.traction[:, 0]), cat.shear, w, np.abs(x) < cat.a) < bound_q
        hertz = cat.p0 * np.sqrt(np.maximum(1.0 - (x / cat.a) ** 2, 0.0))
        assert _l2(fp.pressure, hertz, w, slice(None)) < bound_p  # Q leaves p alone: no coupling
        slip = fp.slip
        excess = np.abs(fp.traction[slip, 0]) - mu * fp.pressure[slip]
        assert np.all(excess >= 0.0) and np.max(excess) < 1e-3 * mu * cat.p0
        assert step.dissipation >= 0.0
    assert 0.2 < ratios[0] < 0.45 < ratios[1] < 0.8  # measured 0.33, 0.64
    # Mindlin–Deresiewicz: moved back from Q* to Q, reverse slip in c' < |x| < a, c' = a√(1 − (Q* − Q)/(2μP)),
    # q = μp₀[−√(1 − x²/a²) + 2(c'/a)√(1 − x²/c'²) − (c/a)√(1 − x²/c²)] (measured at Q/μP = 0.32: the stick zone
    # within 0.14 cells of c', its centre on the axis; q within 3.6 % (a/10), 2.1 % (a/20) in L²)
    step, loaded = path.steps[4], path.steps[3]
    fp, P = step.friction, step.normal_force
    Q_star, Q = loaded.tangential_force[0], step.tangential_force[0]
    x, w = fp.points[:, 0], fp.weights
    md = cattaneo_mindlin(x, normal=P, tangential=Q, mu=mu, radius=R, nu=nu, peak=Q_star)
    assert 0.2 < Q / (mu * P) < 0.45
    lo, hi = fp.extent("stick")
    assert abs(0.5 * (hi - lo) - md.c_back) <= 1.0 * hc and abs(0.5 * (hi + lo)) <= 1.0 * hc
    q = fp.traction[:, 0]
    assert _l2(q, md.shear, w, np.abs(x) < md.a) < bound_md
    assert np.all(q[fp.slip] <= 1e-12 * mu * md.p0) and step.dissipation >= 0.0  # the reverse slip
