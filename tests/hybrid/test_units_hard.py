"""Units on the hard cases: contrast 10⁶, an AMG Ω₁ in 3D, Algorithm 3 with its Gram from the patch equations, and
user gmsh meshes (graded, inclusions cut by γ), in Pa and m or in MPa and mm against the same problem with E ~ 1.

A problem in units (E₀, L) is the unit-free one with every modulus times E₀, every length times L and the body
force times E₀/L; its displacements are L times, its contact forces E₀ L^(d−1) times those of E₀ = L = 1, and its
counts (iterations, Newton steps, GMRES products) and active sets are the same.  The material patterns are
evaluated at x/L + 10⁻⁹: a pattern edge through a cell midpoint is a tie that the round-off of x/L would decide.
"""

import gmsh
import numpy as np
import pytest
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.fem.amg import LinearSolverOptions
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.cem import coarse as cem_coarse
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.case import load_case
from fenics_contact.problem.geometry import gmsh_session, read_mesh, unit_square
from fenics_contact.problem.models import model_3
from fenics_contact.problem.models3d import CHANNELS_3D, channels_3d_mesh, slab_load
from fenics_contact.problem.problem import ContactProblem

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial: the unit checks")

CONTRAST = 1e6
#: (E₀, L): steel-sized moduli in Pa on a 5 cm body, and in MPa (N/mm²) on the same body in mm
UNITS = [(2.1e11, 0.05), (2.1e5, 50.0)]
#: the AMG Ω₁'s CG tolerance and the transmission residual (tests/hybrid/test_krylov_band.py)
AMG = LinearSolverOptions(kind="amg", rtol=1e-12)
#: the AMG runs' transmission tolerance: above the Newton–GMRES's round-off floor at contrast 10⁶ (1–3·10⁻¹⁰ with CG
#: to 10⁻¹²), where the round-off of the units decides whether a combination of solved Ω₁ states is accepted or
#: corrected, and with it the counts (docs/limits.md)
TOL = 1e-9


def _scaled(field, E0: float, L: float, power: int):
    """x ↦ E₀ L^power field(x/L + 10⁻⁹)."""
    return lambda x: E0 * L**power * field(x / L + 1e-9)


def _scaled_mesh(cm, L: float):
    cm.mesh.geometry.x[:] *= L
    return cm._replace(h=cm.h * L, H=None if cm.H is None else cm.H * L)


def _channels(x: np.ndarray) -> np.ndarray:
    inside = np.zeros(x.shape[1], dtype=bool)
    for y0, y1, z0, z1 in CHANNELS_3D:
        inside |= (x[0] > 0.25) & (x[1] > y0) & (x[1] < y1) & (x[2] > z0) & (x[2] < z1)
    return np.where(inside, CONTRAST, 1.0)


def _channel_cube(E0: float, L: float) -> ContactProblem:
    """The 3D channel model (contrast 10⁶, h = 1/6) in units (E₀, L): rollers on z = 0 and z = L."""
    problem = ContactProblem(
        name="channels in units",
        youngs_modulus=_scaled(_channels, E0, L, 0),
        poisson_ratio=0.35,
        load=_scaled(slab_load(1.0), E0, L, -1),
        boundary=BoundaryConditions(rollers=((2, 0.0), (2, L))),
    )
    return problem.on(_scaled_mesh(channels_3d_mesh(6), L))


def test_amg_newton_gmres_on_the_channel_cube_in_pa_and_mm():
    """Algorithm 1 with Ω₁ by CG + AMG (the band-preconditioned Newton–GMRES) on the 3D channel cube at contrast
    10⁶: in Pa/m and MPa/mm the iterations, Newton steps, GMRES products, active set and force / (E₀ L²) of
    E₀ = L = 1, and the monolithic solution of its units to 1e-9."""

    def run(E0, L):
        problem = _channel_cube(E0, L)
        mono = fc.solve(problem, "primal-monolithic", solver="direct")
        result = fc.solve(problem, "primal", reference=mono.u, tol=TOL, solver=AMG)
        assert result.converged and result.e_u <= 1e-9
        products = result.step.krylov_interface().products
        counts = (result.iterations, result.history.newton_steps, products, mono.newton.steps)
        return counts, result.profile.active.copy(), result.profile.force / (E0 * L * L)

    counts, active, force = run(1.0, 1.0)
    for E0, L in UNITS:
        c, a, f = run(E0, L)
        assert c == counts and np.array_equal(a, active)
        assert f == pytest.approx(force, rel=1e-9)


def test_algorithm_3_with_the_gram_from_the_patch_equations_in_pa(monkeypatch):
    """Algorithm 3 on model 3 (stiff channels through γ up to Γ_C) at contrast 10⁶ inside Ω₁, h = 1/32, H = 1/8,
    m = 2: its ZᵀKZ comes from the patch equations in every unit (the pivot test is Jacobi-scaled), with the
    iterations, interface Newton steps, active set, force / (E₀ L) and distance to the monolithic solution of
    E₀ = L = 1."""
    taken = []
    resolves = cem_coarse.resolves
    monkeypatch.setattr(cem_coarse, "resolves", lambda *a, **k: taken.append(resolves(*a, **k)) or taken[-1])
    base = model_3(E_high=CONTRAST)

    def run(E0, L):
        problem = base.with_(
            youngs_modulus=_scaled(base.youngs_modulus, E0, L, 0), load=_scaled(base.load, E0, L, -1)
        ).on(_scaled_mesh(unit_square(32, 8), L))
        mono = fc.solve(problem, "primal-monolithic")
        result = fc.solve(problem, "primal-ms", reference=mono.u, cem=CEMOptions(layers=2), tol=1e-10)
        assert result.converged
        counts = (result.iterations, result.history.newton_steps, mono.newton.steps)
        return counts, result.profile.active.copy(), result.profile.force / (E0 * L), result.e_u

    counts, active, force, e_u = run(1.0, 1.0)
    for E0, L in UNITS:
        c, a, f, e = run(E0, L)
        assert c == counts and np.array_equal(a, active)
        assert f == pytest.approx(force, rel=1e-9) and e == pytest.approx(e_u, rel=1e-6)
    assert taken == [True] * (1 + len(UNITS))


# -- user gmsh meshes ------------------------------------------------------------------------------------------


def _affine(src, dst, L: float) -> None:
    """The gmsh file ``src`` with its nodes scaled by L, written to ``dst`` (the same mesh in other units)."""
    with gmsh_session():
        gmsh.merge(str(src))
        gmsh.model.mesh.affineTransform([L, 0, 0, 0, 0, L, 0, 0, 0, 0, L, 0])
        gmsh.write(str(dst))


#: (centre, radius) of the spheres of the 3D block; the last is cut by γ (x = 3/4, the strip of width ¼)
SPHERES = [((0.3, 0.5, 0.5), 0.15), ((0.62, 0.3, 0.5), 0.12), ((0.75, 0.7, 0.4), 0.1)]


def _block_with_spheres(path) -> None:
    """The unit cube with three spherical inclusions (volume groups matrix and inclusions), Γ_D the face x = 0,
    Γ_C the face x = 1, cells graded from 0.1 at Γ_C to 0.25 at Γ_D."""
    with gmsh_session():
        gmsh.model.add("block")
        occ = gmsh.model.occ
        box = occ.addBox(0, 0, 0, 1, 1, 1)
        occ.fragment([(3, box)], [(3, occ.addSphere(*c, r)) for c, r in SPHERES])
        occ.synchronize()
        volumes = [t for _, t in gmsh.model.getEntities(3)]
        matrix = max(volumes, key=lambda t: occ.getMass(3, t))
        gmsh.model.addPhysicalGroup(3, [matrix], name="matrix")
        gmsh.model.addPhysicalGroup(3, [t for t in volumes if t != matrix], name="inclusions")
        for x, name in ((0.0, "Gamma_D"), (1.0, "Gamma_C")):
            faces = gmsh.model.getEntitiesInBoundingBox(x - 1e-6, -1e-6, -1e-6, x + 1e-6, 1 + 1e-6, 1 + 1e-6, 2)
            gmsh.model.addPhysicalGroup(2, [t for _, t in faces], name=name)
        size = gmsh.model.mesh.field.add("MathEval")
        gmsh.model.mesh.field.setString(size, "F", "0.1 + 0.15 * (1 - x)")
        gmsh.model.mesh.field.setAsBackgroundMesh(size)
        for option in ("MeshSizeExtendFromBoundary", "MeshSizeFromPoints", "MeshSizeFromCurvature"):
            gmsh.option.setNumber(f"Mesh.{option}", 0)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))


def _spheres(x: np.ndarray) -> np.ndarray:
    inside = np.zeros(x.shape[1], dtype=bool)
    for c, r in SPHERES:
        inside |= np.sum((x - np.array(c)[:, None]) ** 2, axis=0) < r * r
    return np.where(inside, CONTRAST, 1.0)


def _push(x: np.ndarray) -> np.ndarray:
    f = np.zeros((3, x.shape[1]))
    f[0] = np.where((x[0] > 0.4) & (x[0] < 0.7), np.where(x[1] < 0.5, 1.0, 0.3), 0.0)
    return f


def test_amg_path_on_a_user_gmsh_block_with_inclusions_cut_by_gamma(tmp_path):
    """A gmsh block (graded tetrahedra, three stiff spheres of contrast 10⁶, one cut by γ) pushed onto the wall:
    Algorithm 1 with the AMG Ω₁ equals the monolithic solution to 1e-9 in m/Pa and mm/MPa with the active set,
    counts and force / (E₀ L²) of the file in unit lengths, E ~ 1; the profile in the same node order (the scaled
    file's coordinates carry the round-off of its units: ``fem.contact.profile_order`` compares them to 1e-9 of
    the extent, and sorts a face in 3D by its third coordinate too)."""
    base = tmp_path / "block.msh"
    _block_with_spheres(base)

    def run(E0, L):
        path = tmp_path / f"block_{L:g}.msh"
        _affine(base, path, L)
        cm = read_mesh(path, H=0.25 * L)
        problem = ContactProblem(
            name="user block",
            youngs_modulus=_scaled(_spheres, E0, L, 0),
            poisson_ratio=0.3,
            load=_scaled(_push, E0, L, -1),
        ).on(cm)
        mono = fc.solve(problem, "primal-monolithic", solver="direct")
        result = fc.solve(problem, "primal", reference=mono.u, tol=TOL, solver=AMG)
        assert result.converged and result.e_u <= 1e-9
        products = result.step.krylov_interface().products
        assert products <= 60
        counts = (result.iterations, result.history.newton_steps, products, mono.newton.steps)
        return counts, result.profile.active.copy(), result.profile.force / (E0 * L * L)

    counts, active, force = run(1.0, 1.0)
    assert np.count_nonzero(active) > 0
    for E0, L in UNITS:
        c, a, f = run(E0, L)
        assert c == counts and np.array_equal(a, active)
        assert f == pytest.approx(force, rel=1e-9)


def test_amg_path_at_its_round_off_floor_with_the_default_band(tmp_path):
    """The gmsh block with a sphere of contrast 10⁶ cut by γ, the default band of 2 cell layers and a tolerance at
    the Newton–GMRES's round-off floor (10⁻¹⁰): the minimal residual's coefficients stay finite where its images
    become dependent within the products' CG errors, and the Newton, once a step near the tolerance fails to halve
    the residual, solves every trial's Ω₁: it converges to the monolithic solution."""
    path = tmp_path / "block.msh"
    _block_with_spheres(path)
    problem = ContactProblem(name="user block", youngs_modulus=_spheres, poisson_ratio=0.3, load=_push).on(
        read_mesh(path, H=0.25)
    )
    mono = fc.solve(problem, "primal-monolithic", solver="direct")
    result = fc.solve(problem, "primal", reference=mono.u, tol=1e-10, solver=AMG)
    assert result.converged and result.e_u <= 1e-9
    assert np.array_equal(result.profile.active, mono.profile.active)


def _steel_and_rubber(path) -> None:
    """A steel block 50 × 25 mm with a stiff disc (r = 2.5 mm, its top 0.5 mm under the contact face) and a rubber
    half cylinder (R = 20 mm) on it, meshed apart, cells from 1 mm at the contact to 6 mm; lengths in mm."""
    with gmsh_session():
        gmsh.model.add("pair")
        occ = gmsh.model.occ
        pieces, _ = occ.fragment([(2, occ.addRectangle(0, -25, 0, 50, 25))], [(2, occ.addDisk(20, -3, 0, 2.5, 2.5))])
        upper = occ.cut([(2, occ.addDisk(25, 20, 0, 20, 20))], [(2, occ.addRectangle(0, 20, 0, 50, 25))])[0][0][1]
        occ.synchronize()
        lower = [t for d, t in pieces if d == 2]
        disc = min(lower, key=lambda t: occ.getMass(2, t))
        gmsh.model.addPhysicalGroup(2, [t for t in lower if t != disc], name="steel")
        gmsh.model.addPhysicalGroup(2, [disc], name="disc")
        gmsh.model.addPhysicalGroup(2, [upper], name="rubber")

        def on_line(y, bodies):
            boundary = {t for _, t in gmsh.model.getBoundary([(2, b) for b in bodies], oriented=False)}
            box = gmsh.model.getEntitiesInBoundingBox(-1e-3, y - 1e-3, -1e-3, 50 + 1e-3, y + 1e-3, 1e-3, 1)
            return [t for _, t in box if t in boundary]

        top = on_line(20.0, [upper])
        arc = [t for _, t in gmsh.model.getBoundary([(2, upper)], oriented=False) if t not in top]
        contact = on_line(0.0, lower)
        for name, curves in (
            ("lower_bottom", on_line(-25.0, lower)),
            ("lower_top", contact),
            ("upper_bottom", arc),
            ("upper_top", top),
        ):
            gmsh.model.addPhysicalGroup(1, curves, name=name)
        field = gmsh.model.mesh.field
        distance = field.add("Distance")
        field.setNumbers(distance, "CurvesList", contact + arc)
        field.setNumber(distance, "Sampling", 200)
        size = field.add("Threshold")
        for key, value in (("InField", distance), ("SizeMin", 1.0), ("SizeMax", 6.0), ("DistMin", 2.0)):
            field.setNumber(size, key, value)
        field.setNumber(size, "DistMax", 20.0)
        field.setAsBackgroundMesh(size)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.model.mesh.generate(2)
        gmsh.write(str(path))


PAIR_CASE = """
[mesh]
file = "{mesh}"
[bodies.lower]
cells = ["steel", "disc"]
E = {{steel = {steel}, disc = {disc}}}
nu = 0.3
supports = [{{facets = "lower_bottom"}}]
[bodies.upper]
cells = "rubber"
E = {rubber}
nu = 0.45
supports = [{{facets = "upper_top", displacement = [{dx}, {dy}]}}]
[pair]
slave = "upper_bottom"
master = "lower_top"
[friction]
law = "coulomb"
mu = 0.3
"""


@pytest.mark.parametrize("method", ["primal-monolithic", "primal"])
def test_coulomb_pair_on_a_user_gmsh_mesh_in_mm_and_m(tmp_path, method):
    """A rubber half cylinder (5 MPa) pressed and dragged on a steel block (210 GPa) holding a disc of 10⁶ × steel
    under its contact face (inside the strips of Algorithm 1), Coulomb μ = 0.3, the dual basis: the case file's mesh
    in mm with E in MPa and the same mesh in m with E in Pa give the same Newton steps, stick/slip sets, the
    displacements to 1e-12 and the contact forces to 1e-7 (the penalty's penetration is about 10⁻⁵ of u: a
    pressure carries that round-off, in any unit)."""
    base = tmp_path / "pair_mm.msh"
    _steel_and_rubber(base)

    def run(length, stress):  # the unit of length in m, of stress in Pa
        s = 1e-3 / length  # mm → the file's unit
        path = tmp_path / f"pair_{length:g}.msh"
        _affine(base, path, s)
        case = tmp_path / f"pair_{length:g}.toml"
        moduli = dict(steel=2.1e11 / stress, disc=2.1e17 / stress, rubber=5e6 / stress)
        case.write_text(PAIR_CASE.format(mesh=path, dx=0.2 * s, dy=-0.5 * s, **moduli))
        pair = load_case(case)
        result = fc.solve(pair.problem(pair.build_mesh(MPI.COMM_SELF)), method)
        counts = (result.newton.steps,) if method == "primal-monolithic" else (result.interface_newton_steps,)
        sets = (result.friction.stick.copy(), result.friction.slip.copy())
        return counts, sets, result.u.x.array * length, np.asarray(result.forces[0]) * stress * length

    counts, sets, u, force = run(1e-3, 1e6)
    assert np.any(sets[0]) and np.any(sets[1])  # sticks in the middle, slips at the edges
    c, s, u_m, force_m = run(1.0, 1.0)
    assert c == counts and all(np.array_equal(a, b) for a, b in zip(s, sets, strict=True))
    assert np.linalg.norm(u_m - u) <= 1e-12 * np.linalg.norm(u)
    assert np.linalg.norm(force_m - force) <= 1e-7 * np.linalg.norm(force)
