"""Two deformable bodies in contact: the contact patch test (segment-to-segment against node-to-segment, 2D and
3D), the cost of the 3D clipped quadrature, two-body Hertz (an elastic cylinder on a block) under refinement (the
nodal pressure and the pressure the pair transmits, at the quadrature points; Algorithm 1 on the same pair), and
Algorithm 1 against the monolithic solve.

    python benchmarks/two_body.py --refinements 0.5 1 2 --sizes 32 64 --out benchmarks/results/two_body.md
"""

import argparse
import sys
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

sys.path.insert(0, str(Path(__file__).parent))

from common import write_report  # noqa: E402

import fenics_contact as fc  # noqa: E402
from fenics_contact.fem.mortar import project, surface  # noqa: E402
from fenics_contact.fem.two_body import transmitted_pressure  # noqa: E402
from fenics_contact.problem.analytic import hertz_errors, hertz_pair  # noqa: E402

T = fc.PairTag
H1, H2, D = 0.5, 0.4, 0.01
#: the Gauss degree on each piece of the segment-to-segment quadrature the transmitted pressure is integrated with
#: (the solve's is 3: the exact profile's square-root edge wants more points to integrate the error)
TRACTION_DEGREE = 8


def patch(
    n_lower: int, n_upper: int, slave: str, rule: str, *, dim: int = 2, degree: int = 3, basis: str | None = None
) -> tuple[float, float]:
    """The largest relative error of the nodal pressure on either surface, and the force imbalance."""
    materials = ((1.0, 0.3), (5.0, 0.2))
    m = fc.two_blocks(n_lower, n_upper, heights=(H1, H2), dim=dim)
    up = dim - 1
    push = np.zeros(dim)
    push[up] = -D
    pair = (T.UPPER_BOTTOM, T.LOWER_TOP) if slave == "upper" else (T.LOWER_TOP, T.UPPER_BOTTOM)
    sides = (fc.Support(T.LOWER_SIDES, components=(1,)), fc.Support(T.UPPER_SIDES, components=(1,)))
    problem = fc.TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(fc.Body(T.LOWER, *materials[0]), fc.Body(T.UPPER, *materials[1])),
        pair=fc.ContactPair(*pair, quadrature_degree=degree, rule=rule, basis=basis),
        supports=(
            fc.Support(T.LOWER_BOTTOM, components=(up,)),
            fc.Support(T.LOWER_LEFT, components=(0,)),
            fc.Support(T.UPPER_LEFT, components=(0,)),
            fc.Support(T.UPPER_TOP, push, components=(up,)),
        )
        + (sides if dim == 3 else ()),
    )
    result = fc.solve(problem, "primal-monolithic")
    soft = [E / (1 - nu**2) for E, nu in materials]  # plane strain; in 3D rollers on y = 0, W and x free
    p = D / (H1 / soft[0] + H2 / soft[1] + result.delta)
    error = max(np.max(np.abs(prof.sigma_c + p)) / p for prof in (result.slave, result.master))
    return float(error), result.force_balance()


def quadrature_cost(n: int) -> str:
    """The 3D segment-to-segment quadrature on two boxes of n and n + 3 cells across (the upper slave): facets,
    points, the time of ``contact_quadrature`` and of the whole monolithic solve."""
    from dolfinx import fem

    from fenics_contact.fem.mortar import contact_quadrature, surface

    m = fc.two_blocks(n, n + 3, heights=(H1, H2), dim=3)
    V = fem.functionspace(m.mesh, ("Lagrange", 1, (3,)))
    slave = surface(V, m.facet_tags, T.UPPER_BOTTOM)
    master = surface(V, m.facet_tags, T.LOWER_TOP)
    num = V.dofmap.index_map.size_local * 3
    start = time.perf_counter()
    Q = contact_quadrature(slave, master, num, 3, 3, nodal=False)
    gauss = time.perf_counter() - start
    start = time.perf_counter()
    contact_quadrature(slave, master, num, 3, 3)
    nodal = time.perf_counter() - start
    problem = fc.TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(fc.Body(T.LOWER, 1.0, 0.3), fc.Body(T.UPPER, 5.0, 0.2)),
        pair=fc.ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP),
        supports=(
            fc.Support(T.LOWER_BOTTOM, components=(2,)),
            fc.Support(T.LOWER_LEFT, components=(0,)),
            fc.Support(T.UPPER_LEFT, components=(0,)),
            fc.Support(T.LOWER_SIDES, components=(1,)),
            fc.Support(T.UPPER_SIDES, components=(1,)),
            fc.Support(T.UPPER_TOP, (0.0, 0.0, -D), components=(2,)),
        ),
    )
    result = fc.solve(problem, "primal-monolithic")
    return (
        f"| {n}/{n + 3} | {slave.coords.shape[0]} | {master.coords.shape[0]} | {Q.B.shape[0]} | "
        f"{Q.B.shape[0] / slave.coords.shape[0]:.0f} | {gauss:.2f} | {nodal:.2f} | {result.time_s:.2f} |"
    )


RADIUS, A = 5.0, 0.05  #: the cylinder's radius and the expected contact half-width


def hertz_problem(m, slave: str, depth: float, basis: str | None = None) -> fc.TwoBodyProblem:
    """An elastic cylinder (E = 2, ν = 0.25) pressed by ``depth`` onto a block (E = 1, ν = 0.3) on the mesh ``m``
    (``cylinder_on_block``); ``slave``: "cylinder" or "block"; ``basis`` of the pressure (None: the default)."""
    surfaces = (T.UPPER_BOTTOM, T.LOWER_TOP) if slave == "cylinder" else (T.LOWER_TOP, T.UPPER_BOTTOM)
    return fc.TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(fc.Body(T.LOWER, 1.0, 0.3), fc.Body(T.UPPER, 2.0, 0.25)),
        pair=fc.ContactPair(*surfaces, basis=basis),
        supports=(fc.Support(T.LOWER_BOTTOM), fc.Support(T.UPPER_TOP, (0.0, -depth))),
    )


class TractionErrors(NamedTuple):
    """The pressure profile of the pair against Hertz on one face (a and p₀ from its own resultant): the P1
    interpolant Σ_p λ_p N_p of the nodal pressures (``PairTraction.nodal``): its relative L² error, its part farther
    than two contact cells from x = ±a, its peak error; the L² error of the best P1 pressure on the slave nodes
    (the L² projection of the exact profile: what any P1 pressure on them can reach), and that of the field the
    penalty applies (``PairTraction.pressure``: Σ_p λ_p φ_p, the interpolant itself with the standard basis)."""

    l2: float
    interior: float
    peak: float
    best: float
    applied: float


def traction_errors(result, side: str, h: float) -> TractionErrors:
    """``TractionErrors`` of the pressure ``result`` (a monolithic two-body solution) transmits, on the ``side``
    "slave" (at the slave quadrature points) or "master" (at their closest points on the master), integrated with
    the segment-to-segment quadrature of degree ``TRACTION_DEGREE``."""
    r_star, e_star = hertz_pair((RADIUS, np.inf), (2.0, 1.0), (0.25, 0.3))
    t = transmitted_pressure(result, TRACTION_DEGREE)
    x = (t.points if side == "slave" else t.master_points)[:, 0]
    w, p = t.weights, t.nodal
    force = float(np.sum(w * p))
    a = 2.0 * np.sqrt(r_star * force / (np.pi * e_star))
    p0 = 2.0 * force / (np.pi * a)
    exact = p0 * np.sqrt(np.maximum(1.0 - (x / a) ** 2, 0.0))
    norm = np.sqrt(np.sum(w * exact**2))
    far = np.abs(np.abs(x) - a) > 2.0 * h
    # the best P1 pressure on the slave nodes: M c = ∫ N_i p_exact (the same quadrature)
    problem = result.problem
    slave = surface(result.u.function_space, problem.facet_tags, problem.pair.slave)
    on = project(t.points, slave)
    blocks = slave.blocks[on.facet]
    nodes, index = np.unique(blocks, return_inverse=True)
    N = sp.csr_matrix((on.bary.ravel(), (index.ravel(), np.repeat(np.arange(x.size), blocks.shape[1]))))
    c = spla.spsolve((N @ sp.diags(w) @ N.T).tocsc(), N @ (w * exact))
    best = np.sqrt(np.sum(w * (N.T @ c - exact) ** 2)) / norm
    return TractionErrors(
        float(np.sqrt(np.sum(w * (p - exact) ** 2)) / norm),
        float(np.sqrt(np.sum((w * (p - exact) ** 2)[far])) / norm),
        float(p.max() / p0 - 1.0),
        float(best),
        float(np.sqrt(np.sum(w * (t.pressure - exact) ** 2)) / norm),
    )


def hertz(refinement: float, slave: str, basis: str, *, depth: float = 1.1e-3) -> list[str]:
    """Two-body Hertz (``hertz_problem``) at contact cells a/(20 r) with the pressure ``basis``: per surface the
    nodal pressure's errors and the L² errors of the pressure profile and of the applied field."""
    start = time.perf_counter()
    m = fc.cylinder_on_block(RADIUS, A, refinement=refinement)
    result = fc.solve(hertz_problem(m, slave, depth, basis), "primal-monolithic")
    elapsed = time.perf_counter() - start
    r_star, e_star = hertz_pair((RADIUS, np.inf), (2.0, 1.0), (0.25, 0.3))
    h = A / (20 * refinement)
    rows = []
    other = "block" if slave == "cylinder" else "cylinder"
    for side, profile, face in ((slave, result.slave, "slave"), (other, result.master, "master")):
        e = hertz_errors(profile, radius=r_star, E=e_star, nu=0.0, h_contact=h)
        t = traction_errors(result, face, h)
        rows.append(
            f"| {refinement:g} | {m.mesh.topology.index_map(2).size_local} | {slave} | {basis} | {side} | "
            f"{e.force:.5e} | {e.a:.4f} | "
            f"{e.half_width_cells:+.2f} | {100 * e.peak_error:+.2f}% | {100 * e.l2_error:.2f}% | "
            f"{100 * t.l2:.2f}% | {100 * t.applied:.2f}% | {result.newton.steps} | {result.force_balance():.1e} | "
            f"{elapsed:.1f} |"
        )
    return rows


def hertz_algorithm_1(refinement: float, slave: str, *, depth: float = 1.1e-3) -> str:
    """Algorithm 1 (interface Newton, transmission residual 1e-8) on the two-body Hertz pair against the monolithic
    solve."""
    m = fc.cylinder_on_block(RADIUS, A, refinement=refinement)
    problem = hertz_problem(m, slave, depth)
    reference = fc.solve(problem, "primal-monolithic")
    result = fc.solve(problem, "primal", tol=1e-8)
    error = np.linalg.norm(result.u.x.array - reference.u.x.array) / np.linalg.norm(reference.u.x.array)
    return (
        f"| {refinement:g} | {slave} | {result.converged} | {result.iterations} | {result.interface_newton_steps} | "
        f"{result.transmission_residual:.1e} | {error:.1e} | {result.force_balance():.1e} | {result.time_s:.2f} | "
        f"{reference.time_s:.2f} |"
    )


def _interpolant_error(x: np.ndarray, a: float) -> float:
    """Relative L² error of the P1 interpolant, on the nodes x, of the Hertz profile √(1 − x²/a²)."""
    xs = np.sort(x)
    t = np.linspace(-1.5 * a, 1.5 * a, 200001)
    exact = np.sqrt(np.maximum(1.0 - (t / a) ** 2, 0.0))
    exact_nodes = np.sqrt(np.maximum(1.0 - (xs / a) ** 2, 0.0))
    return float(np.sqrt(np.trapezoid((np.interp(t, xs, exact_nodes) - exact) ** 2, t) / np.trapezoid(exact**2, t)))


def hertz_edge(
    refinement: float, depth: float, slave: str, *, delta_scale: float = 1.0, size: float = 1.0, basis: str = "dual"
) -> list[str]:
    """Two-body Hertz as in ``hertz`` at one depth, the block ``size`` times wider and deeper, δ times
    ``delta_scale``: per surface the L² error of the nodal pressure, its part from the nodes farther than two
    contact cells from the edges x = ±a, the L² error of the exact profile's own P1 interpolant on the same
    nodes (what a nodal pressure can reach at that spacing), and the pressure profile's ``TractionErrors``; with
    the pressure ``basis``."""
    m = fc.cylinder_on_block(RADIUS, A, refinement=refinement, width=80.0 * size, depth=40.0 * size)
    problem = hertz_problem(m, slave, depth, basis)
    delta = None
    if delta_scale != 1.0:
        delta = delta_scale * fc.solve(problem, "primal-monolithic").delta
    result = fc.solve(problem, "primal-monolithic", delta=delta)
    r_star, e_star = hertz_pair((RADIUS, np.inf), (2.0, 1.0), (0.25, 0.3))
    h = A / (20 * refinement)
    rows = []
    sides = {"cylinder": (result.slave, "slave") if slave == "cylinder" else (result.master, "master")}
    sides["block"] = (result.master, "master") if slave == "cylinder" else (result.slave, "slave")
    for side, (profile, face) in sides.items():
        e = hertz_errors(profile, radius=r_star, E=e_star, nu=0.0, h_contact=h)
        x, p, w = profile.points[:, 0], -profile.sigma_c, profile.weights
        exact = e.p0 * np.sqrt(np.maximum(1.0 - (x / e.a) ** 2, 0.0))
        far = np.abs(np.abs(x) - e.a) > 2.0 * h
        interior = np.sqrt(np.sum((w * (p - exact) ** 2)[far]) / np.sum(w * exact**2))
        t = traction_errors(result, face, h)
        rows.append(
            f"| {refinement:g} | {depth:.3g} | {size:g} | {delta_scale:g} | {basis} | {slave} | {side} | "
            f"{e.a / h:.1f} | "
            f"{e.half_width_cells:+.2f} | {100 * e.peak_error:+.2f}% | {100 * e.l2_error:.2f}% | "
            f"{100 * interior:.2f}% | {100 * _interpolant_error(x, e.a):.2f}% | {100 * t.l2:.2f}% | "
            f"{100 * t.interior:.2f}% | {100 * t.peak:+.2f}% | {100 * t.best:.2f}% |"
        )
    return rows


def edge_nodes(refinement: float, slave: str, basis: str, *, depth: float = 1.1e-3, count: int = 5) -> list[str]:
    """The slave nodes at the contact edge x = +a (the last ``count`` - 1 active ones and the first open one): the
    nodal penalty pressure λ_p = (s̃_p)⁺/δ (the transmitted pressure's nodal value) and the nodal pressure σ_c
    against Hertz, a and p₀ from the slave's resultant."""
    m = fc.cylinder_on_block(RADIUS, A, refinement=refinement)
    result = fc.solve(hertz_problem(m, slave, depth, basis), "primal-monolithic")
    Q, V = result.quadrature, result.u.function_space
    u = result.u.x.array[: Q.B.shape[1]]
    lam = np.maximum(Q.B @ u - Q.gap, 0.0) / result.delta
    x = V.tabulate_dof_coordinates()[Q.nodes, 0]
    r_star, e_star = hertz_pair((RADIUS, np.inf), (2.0, 1.0), (0.25, 0.3))
    e = hertz_errors(result.slave, radius=r_star, E=e_star, nu=0.0, h_contact=A / (20 * refinement))
    order = np.argsort(x)
    x, lam = x[order], lam[order]
    profile = result.slave
    at = np.argsort(profile.points[:, 0])
    sigma = np.interp(x, profile.points[at, 0], -profile.sigma_c[at])  # (the profile's points are these nodes)
    last = int(np.flatnonzero(lam > 0.0).max())
    rows = []
    for i in range(last - count + 2, last + 2):
        exact = np.sqrt(max(1.0 - (x[i] / e.a) ** 2, 0.0))
        rows.append(
            f"| {refinement:g} | {slave} | {basis} | {x[i] / e.a:.3f} | {lam[i] / e.p0:.3f} | {exact:.3f} | "
            f"{sigma[i] / e.p0:.3f} |"
        )
    return rows


def gauss_point_penalty(refinement: float, slave: str, delta_scale: float, *, depth: float = 1.1e-3) -> str:
    """The same pair solved with a penalty at every Gauss point (the rows of ``contact_quadrature(nodal=False)``,
    δ times ``delta_scale``) instead of the nodal gaps: the L² error of its pressure (s_q)⁺/δ at the points."""
    from dolfinx import fem

    from fenics_contact.fem.mortar import contact_quadrature
    from fenics_contact.fem.newton import semismooth_newton_loop
    from fenics_contact.fem.two_body import TwoBodySystem, load_vector, stiffness, supported_dofs, two_body_penalty

    m = fc.cylinder_on_block(RADIUS, A, refinement=refinement)
    problem = hertz_problem(m, slave, depth)
    V = fem.functionspace(m.mesh, ("Lagrange", 1, (2,)))
    n = V.dofmap.index_map.size_local * 2
    slave_s = surface(V, m.facet_tags, problem.pair.slave)
    master_s = surface(V, m.facet_tags, problem.pair.master)
    delta = delta_scale * two_body_penalty(problem, slave_s, master_s, None)
    Q = contact_quadrature(slave_s, master_s, n, 2, problem.pair.quadrature_degree, nodal=False)
    system = TwoBodySystem(stiffness(problem, V), load_vector(problem, V), *supported_dofs(problem, V), Q, delta)
    try:
        trace = semismooth_newton_loop(
            system, system.penetration() >= 0.0, name="Gauss-point penalty", max_steps=100, line_search="always",
            rtol=1e-10, atol=1e-14, refinements=2, sizes="active points",
        )  # fmt: skip
    finally:
        system.destroy()
    x, w, p = Q.points[:, 0], Q.weights, np.maximum(system.penetration(), 0.0) / delta
    r_star, e_star = hertz_pair((RADIUS, np.inf), (2.0, 1.0), (0.25, 0.3))
    force = float(np.sum(w * p))
    a = 2.0 * np.sqrt(r_star * force / (np.pi * e_star))
    p0 = 2.0 * force / (np.pi * a)
    exact = p0 * np.sqrt(np.maximum(1.0 - (x / a) ** 2, 0.0))
    l2 = np.sqrt(np.sum(w * (p - exact) ** 2) / np.sum(w * exact**2))
    return (
        f"| {refinement:g} | {slave} | {delta_scale:g} | {len(trace.residuals)} | {a:.4f} | "
        f"{100 * (p.max() / p0 - 1.0):+.1f}% | {100 * l2:.1f}% |"
    )


def algorithm_1(n: int, accel: str) -> str:
    """Algorithm 1 on two blocks (the lower layered, contrast 1e3; the upper overhanging) against the monolithic
    solve: evaluations of T, transmission residual, distance to the monolithic solution, time."""
    m = fc.two_blocks(n, int(0.7 * n) + 1, heights=(H1, H2), offset=0.2)
    problem = fc.TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(
            fc.Body(T.LOWER, lambda x: np.where(np.floor(-x[1] / 0.1) % 2 == 0, 1e3, 1.0), 0.3),
            fc.Body(T.UPPER, 2.0, 0.25),
        ),
        pair=fc.ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP),
        supports=(fc.Support(T.LOWER_BOTTOM), fc.Support(T.UPPER_TOP, (0.0, -0.005))),
    )
    reference = fc.solve(problem, "primal-monolithic")
    result = fc.solve(problem, "primal", accel=accel, tol=1e-8, max_iterations=5000)
    error = np.linalg.norm(result.u.x.array - reference.u.x.array) / np.linalg.norm(reference.u.x.array)
    return (
        f"| {n} | {accel} | {result.converged} | {result.iterations} | {result.transmission_residual:.1e} | "
        f"{error:.1e} | {result.time_s:.2f} | {reference.time_s:.2f} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--refinements", type=float, nargs="+", default=[0.5, 1.0, 2.0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 64])
    parser.add_argument("--cost-sizes", type=int, nargs="+", default=[4, 8, 16])
    parser.add_argument("--edge-refinements", type=float, nargs="*", default=[1.0, 1.5])
    parser.add_argument("--out", default="benchmarks/results/two_body.md")
    args = parser.parse_args()
    lines = [
        "# Two deformable bodies in contact",
        "",
        f"Command: `python benchmarks/two_body.py --refinements {' '.join(f'{r:g}' for r in args.refinements)} "
        f"--sizes {' '.join(map(str, args.sizes))} --cost-sizes {' '.join(map(str, args.cost_sizes))} "
        f"--edge-refinements {' '.join(f'{r:g}' for r in args.edge_refinements)} --out {args.out}`",
        "",
        "## 1. Contact patch test: two blocks pressed together, non-matching meshes",
        "",
        "Lower block 1 × 0.5 (E = 1, ν = 0.3), upper 1 × 0.4 (E = 5, ν = 0.2), rollers on the bottom and left "
        "sides, the upper top pushed down by 0.01; the exact pressure is uniform (the blocks slide along each "
        "other). Error: the largest relative error of the nodal pressure on either surface; balance: "
        "|F_slave + F_master|/|F|. 3D: two boxes 1 × 1, rollers on the faces y = 0 and 1 as well, the slave "
        "triangles clipped against the master's.",
        "",
        "| dim | cells across (lower/upper) | slave | quadrature | pressure basis | pressure error | force balance |",
        "|---|---|---|---|---|---|---|",
    ]
    cases = [(2, 7, 10, s, "segments", 3, b) for b in ("dual", "standard") for s in ("upper", "lower")]
    cases += [(2, 7, 10, s, "vertices", 3, "standard") for s in ("upper", "lower")]
    cases += [(3, 3, 4, s, "segments", 3, b) for b in ("dual", "standard") for s in ("upper", "lower")]
    cases += [(3, 5, 7, "upper", "segments", k, "dual") for k in (2, 3)]
    cases += [(3, 3, 4, "upper", "vertices", 3, "standard")]
    for dim, nl, nu, slave, rule, degree, basis in cases:
        error, balance = patch(nl, nu, slave, rule, dim=dim, degree=degree, basis=basis)
        label = "node-to-segment (vertices)" if rule == "vertices" else f"segment-to-segment, degree {degree}"
        lines.append(f"| {dim} | {nl}/{nu} | {slave} | {label} | {basis} | {error:.1e} | {balance:.1e} |")
    lines += [
        "",
        "## 2. Cost of the 3D segment-to-segment quadrature",
        "",
        "Two boxes as above, n and n + 3 cells across, the upper the slave, degree 3 (6 points per triangle): "
        "every slave triangle cut by the master triangles projected onto its plane, the pieces fan-triangulated. "
        "Times in seconds, one process: the quadrature at the Gauss points, with the mortar-weighted nodal rows "
        "(what the solve uses), and the whole monolithic solve (mesh excluded, quadrature included).",
        "",
        "| cells across | slave triangles | master triangles | points | points per slave triangle | "
        "quadrature | nodal rows | monolithic solve |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for n in args.cost_sizes:
        lines.append(quadrature_cost(n))
    lines += [
        "",
        "## 3. Two-body Hertz: an elastic cylinder on a block",
        "",
        "Cylinder R = 5 (E = 2, ν = 0.25) pressed by 1.1e-3 onto a block 4 × 2 (E = 1, ν = 0.3); contact cells "
        "a/(20 r) on both bodies, non-matching; R* = R, 1/E* = (1 − ν₁²)/E₁ + (1 − ν₂²)/E₂; F read off each "
        "surface, a and p₀ from F; the pressure basis of the penalty dual (the default) or standard. Half-width: "
        "half the extent of the nodes carrying contact forces, its error in contact cells. L² error: of the nodal "
        "pressure (σ_c, the nodal contact forces over the lumped weights; the sum over the nodes). Pressure L²: of "
        "the pressure profile, the P1 interpolant of the nodal penalty pressures λ_p = (s̃_p)⁺/δ on the slave "
        f"facets, at the segment-to-segment quadrature points (degree {TRACTION_DEGREE} on each piece) on the slave "
        "face and at their closest points on the master face, a and p₀ from its own resultant. Applied L²: of the "
        "field the penalty applies, Σ_p λ_p φ_p (φ_p the basis; the same as the pressure profile with the standard "
        "basis, with the dual basis a field that reproduces constants only).",
        "",
        "| r | cells | slave | basis | surface | F | a | (a_h − a)/h | p_max/p₀ − 1 | L² error | pressure L² | "
        "applied L² | Newton steps | balance | time [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in args.refinements:
        for slave in ("cylinder", "block"):
            for basis in ("dual", "standard"):
                lines += hertz(r, slave, basis)
    lines += [
        "",
        "### Algorithm 1 on the Hertz pair",
        "",
        "Strips of 2 cell layers, α_p = E_p/√(h L_ref) (L_ref the pair's size), interface Newton, stop at the transmission residual 1e-8; against "
        "the monolithic solve of the same pair.",
        "",
        "| r | slave | converged | evaluations of T | interface Newton steps | transmission residual | "
        "‖u − u_mono‖/‖u_mono‖ | balance | time [s] | monolithic [s] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in args.refinements:
        for slave in ("cylinder", "block"):
            lines.append(hertz_algorithm_1(r, slave))
    lines += [
        "",
        "### Where the L² error at a/20 comes from",
        "",
        "The same pair at five depths (the contact edge crosses a contact cell), then at one depth with the block "
        "twice as wide and deep (size 2) and with δ/100, 10δ, 100δ and 1000δ, both pressure bases. L² error: all "
        "nodes; interior: without the nodes within two contact cells of x = ±a; P1 interpolant: the L² error of the "
        "exact profile's own P1 interpolant on the surface's nodes (what a nodal pressure can reach at that "
        "spacing). Pressure: the L² error of the pressure profile (as above), its interior part, its peak error, "
        "and the L² error of the best P1 pressure on the slave nodes (the L² projection of the exact profile).",
        "",
        "| r | depth | size | δ factor | basis | slave | surface | a/h | (a_h − a)/h | p_max/p₀ − 1 | L² error | "
        "interior | P1 interpolant | pressure L² | pressure interior | pressure peak | best P1 |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in args.edge_refinements:
        for depth in np.linspace(1.0e-3, 1.2e-3, 5):
            for slave in ("cylinder", "block"):
                for basis in ("dual", "standard"):
                    lines += hertz_edge(r, float(depth), slave, basis=basis)
    if args.edge_refinements:
        lines += hertz_edge(args.edge_refinements[0], 1.1e-3, "cylinder", size=2.0)
        for scale in (0.01, 10.0, 100.0, 1000.0):
            for slave in ("cylinder", "block"):
                lines += hertz_edge(args.edge_refinements[0], 1.1e-3, slave, delta_scale=scale)
        lines += [
            "",
            "The slave nodes at the contact edge x = +a at the first edge refinement and the depth of the table "
            "above: the nodal penalty pressure λ_p = (s̃_p)⁺/δ (the nodal value of the pressure profile), the "
            "exact profile and the nodal pressure σ_c, over p₀ (a, p₀ from the slave's resultant).",
            "",
            "| r | slave | basis | x/a | λ_p/p₀ | exact/p₀ | nodal σ_c/p₀ |",
            "|---|---|---|---|---|---|---|",
        ]
        for slave in ("cylinder", "block"):
            for basis in ("dual", "standard"):
                lines += edge_nodes(args.edge_refinements[0], slave, basis)
        lines += [
            "",
            "A penalty at every Gauss point instead (the same pair at the first edge refinement, the solve on the "
            "rows of the segment-to-segment quadrature itself, δ times the factor): its pressure (s_q)⁺/δ at the "
            "points against Hertz.",
            "",
            "| r | slave | δ factor | Newton steps | a | p_max/p₀ − 1 | L² error |",
            "|---|---|---|---|---|---|---|",
        ]
        for scale in (1.0, 100.0, 1.0e4):
            for slave in ("cylinder", "block"):
                lines.append(gauss_point_penalty(args.edge_refinements[0], slave, scale))
    lines += [
        "",
        "## 4. Algorithm 1 for two bodies",
        "",
        "Two blocks, the lower (n cells across) layered (E alternating 1e3 and 1 every 0.1), the upper (E = 2, "
        "0.7n + 1 cells across) shifted by 0.2 and pushed down by 0.005; strips of 2 cell layers, α_p = E_p/√(h L_ref) (L_ref the pair's size); "
        "stop at the transmission residual 1e-8 (at most 5000 evaluations of T).",
        "",
        "| n | update | converged | evaluations of T | transmission residual | ‖u − u_mono‖/‖u_mono‖ | time [s] | "
        "monolithic [s] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for n in args.sizes:
        for accel in ("newton", "anderson", "none"):
            lines.append(algorithm_1(n, accel))
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
