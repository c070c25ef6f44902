"""The primal monolithic contact solve on tetrahedra: 3D obstacles and meshes, a patch test, 3D Hertz."""

import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.errors import InputError
from fenics_contact.fem.primal import solve_primal_monolithic
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.geometry import mesh_size
from fenics_contact.problem.meshes3d import box_mesh, graded_planes, unit_cube
from fenics_contact.problem.obstacles import Circle, Plane, SignedDistance, Sphere, evaluate_obstacle
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.problem.tags import Boundary


def _points(*xyz):
    return np.array(xyz, dtype=float).T


def test_sphere_gap_and_direction_and_its_finite_difference_twin():
    ball = Sphere((0.0, 0.0, 2.0), 1.0)
    x = _points((0.0, 0.0, 0.0), (3.0, 0.0, 2.0), (0.0, 2.0, 4.0))
    assert np.allclose(ball.gap(x), [1.0, 2.0, np.sqrt(8.0) - 1.0])
    assert np.allclose(ball.direction(x)[:, :2].T, [[0, 0, 1], [-1, 0, 0]])
    assert np.isnan(ball.gap(_points((0.0, 0.0, 2.0)))[0])
    moved = ball.indented(0.25, (0.0, 0.0, -2.0))  # a unit direction in 3D
    assert np.allclose(moved.gap(x[:, :1]), [0.75])
    assert np.allclose(moved.translated((0.0, 0.0, 0.25)).gap(x), ball.gap(x))
    sdf = SignedDistance(lambda p: np.sqrt(p[0] ** 2 + p[1] ** 2 + (p[2] - 2.0) ** 2) - 1.0, dim=3)
    assert np.allclose(sdf.direction(x), ball.direction(x), atol=1e-8)
    g, nu = evaluate_obstacle(ball, x.T, dim=3)
    assert nu.shape == (3, 3) and np.allclose(np.linalg.norm(nu, axis=1), 1.0)


def test_planar_obstacles_are_extruded_along_z_in_3d():
    disc = Circle((0.0, 2.0), 1.0)
    x = _points((0.0, 0.0, 5.0), (3.0, 2.0, -1.0))
    g, nu = evaluate_obstacle(disc, x.T, dim=3)
    assert np.allclose(g, [1.0, 2.0]) and np.allclose(nu, [[0, 1, 0], [-1, 0, 0]])
    tilted = Plane((0.0, 0.0, 1.0), (0.0, 0.6, -0.8))  # a 3D normal
    g, nu = evaluate_obstacle(tilted, _points((0.0, 0.0, 0.0), (0.0, 1.0, 1.0)).T, dim=3)
    assert np.allclose(g, [0.8, 0.6]) and np.allclose(nu, [[0.0, -0.6, 0.8]] * 2)
    with pytest.raises(InputError, match="undefined"):  # ν out of the plane of a 2D problem
        evaluate_obstacle(tilted, _points((0.0, 0.0, 0.0)).T, dim=2)
    with pytest.raises(InputError, match="dimension"):
        SignedDistance(lambda p: p[0], dim=4)
    assert fc.Sphere is Sphere


def test_box_meshes_are_tagged_and_sized():
    cm = unit_cube(4)
    assert cm.mesh.topology.dim == 3 and np.isclose(cm.h, 0.25) and np.isclose(mesh_size(cm.mesh), 0.25)
    ds = ufl.Measure("ds", domain=cm.mesh, subdomain_data=cm.facet_tags)
    area = {
        tag: cm.comm.allreduce(fem.assemble_scalar(fem.form(1.0 * ds(tag))), op=MPI.SUM)
        for tag in (Boundary.GAMMA_C, Boundary.GAMMA_D)
    }
    assert np.isclose(area[Boundary.GAMMA_C], 1.0) and np.isclose(area[Boundary.GAMMA_D], 1.0)
    planes = graded_planes(10.0, fine=1.0, h=0.25, growth=1.5)
    assert planes[0] == 0.0 and planes[-1] == 10.0 and np.allclose(np.diff(planes[:5]), 0.25)
    assert np.all(np.diff(np.diff(planes[4:])) > 0)  # growing beyond the fine zone
    with pytest.raises(InputError, match="cannot also be clamped"):
        box_mesh(planes[:3], planes[:3], planes[:3], contact="zmax", clamped=("zmax",))
    with pytest.raises(InputError, match="unknown face"):
        box_mesh(planes[:3], planes[:3], planes[:3], clamped=("bottom",))


@pytest.mark.parametrize("axis", [0, 2])
def test_patch_block_pressed_on_a_wall_is_exact(axis):
    """A unit cube pushed by a depth d₀ into a flat wall on its face x_axis = 1, the opposite face held at the
    exact lateral expansion: uniaxial stress σ = −p e⊗e, the penalized pressure p = d₀/(δ + L/E) (the
    penalty's nodal traction is u_c/δ), u = −(p/E) x_axis e + (νp/E)(x − x_axis e) — linear, so P1 is exact.
    axis 0: a planar wall (2-vectors, extruded along z); axis 2: a wall with a 3D normal."""
    E, nu, d0 = 2.0, 0.3, 0.01
    faces = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")
    planes = np.linspace(0.0, 1.0, 4)
    cm = box_mesh(planes, planes, planes, contact=faces[2 * axis + 1], clamped=(faces[2 * axis],))
    e = np.eye(3)[axis]
    wall = Plane(tuple(e), tuple(-e)).indented(d0, tuple(-e))
    delta = 1e-3 * cm.h / E

    def lateral(x):
        u = nu / E * x.copy()
        u[axis] = 0.0
        return u * pressure

    pressure = d0 / (delta + 1.0 / E)
    problem = ContactProblem(
        youngs_modulus=E, poisson_ratio=nu, obstacle=wall, mesh=cm, boundary=BoundaryConditions(displacement=lateral)
    )
    sol = solve_primal_monolithic(problem, delta=delta)
    X = sol.u.function_space.tabulate_dof_coordinates()
    exact = lateral(X.T).T
    exact[:, axis] = -pressure / E * X[:, axis]
    error = np.max(np.abs(sol.u.x.array.reshape(-1, 3) - exact))
    assert cm.comm.allreduce(error, op=MPI.MAX) < 1e-12
    assert sol.profile.force == pytest.approx(pressure, rel=1e-11)
    assert np.allclose(sol.profile.resultant, -pressure * e, atol=1e-12)
    assert np.all(sol.profile.active) and sol.newton.steps <= 2


def test_confined_block_on_rollers_is_in_uniaxial_strain():
    """The unit cube clamped at x = 0, its four sides y, z ∈ {0, 1} on rollers (u_y = 0, u_z = 0 there), pushed
    by d₀ into a wall at x = 1: uniaxial strain, σ_xx = −p with the oedometric modulus M = λ + 2μ, so
    p = d₀/(δ + 1/M), u = −(p/M) x e_x — the rollers hold the sides that would otherwise bulge (ν > 0)."""
    E, nu, d0, delta = 1.0, 0.3, 0.01, 1e-3
    M = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    cm = unit_cube(3)
    rollers = ((1, 0.0), (1, 1.0), (2, 0.0), (2, 1.0))
    wall = Plane((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0)).indented(d0, (-1.0, 0.0, 0.0))
    problem = ContactProblem(
        youngs_modulus=E, poisson_ratio=nu, obstacle=wall, mesh=cm, boundary=BoundaryConditions(rollers=rollers)
    )
    sol = solve_primal_monolithic(problem, delta=delta)
    p = d0 / (delta + 1.0 / M)
    X = sol.u.function_space.tabulate_dof_coordinates()
    exact = np.zeros_like(X)
    exact[:, 0] = -p / M * X[:, 0]
    error = cm.comm.allreduce(float(np.max(np.abs(sol.u.x.array.reshape(-1, 3) - exact))), op=MPI.MAX)
    assert error < 1e-12 and sol.profile.force == pytest.approx(p, rel=1e-11)
    with pytest.raises(InputError, match="no exterior facet"):
        solve_primal_monolithic(problem.with_(boundary=BoundaryConditions(rollers=((1, 0.5),))))
    with pytest.raises(InputError, match="axis"):
        BoundaryConditions(rollers=((3, 0.0),))


def _hertz(
    h_over_a: float,
    *,
    growth: float,
    a: float = 0.1,
    R: float = 1.0,
    E: float = 1.0,
    nu: float = 0.3,
    size: float = 40.0,
):
    """A quarter of a block (0, L)² × (−L, 0), L = ``size``·a, under a rigid sphere of radius R pushed d = a²/R
    into its top (Hertz's contact radius a at that depth), symmetry planes x = 0 and y = 0 on rollers, the
    bottom clamped; the grid is h = ``h_over_a``·a on 1.25a around the contact and grows by ``growth``."""
    planes = graded_planes(size * a, fine=1.25 * a, h=h_over_a * a, growth=growth)
    region = lambda p: (p[0] <= 3 * a + 1e-12) & (p[1] <= 3 * a + 1e-12)  # noqa: E731
    cm = box_mesh(planes, planes, -planes[::-1], contact="zmax", clamped=("zmin",), contact_region=region, strip=2 * a)
    sphere = Sphere((0.0, 0.0, R), R).indented(a * a / R, (0.0, 0.0, -1.0))
    problem = ContactProblem(
        youngs_modulus=E,
        poisson_ratio=nu,
        obstacle=sphere,
        mesh=cm,
        boundary=BoundaryConditions(rollers=((0, 0.0), (1, 0.0))),
    )
    sol = solve_primal_monolithic(problem, solver="direct")  # (stretched cells: MUMPS beats AMG at h = a/8)
    E_star = E / (1.0 - nu**2)
    force = 4.0 * sol.profile.force  # the quarter's
    a_F = (3.0 * force * R / (4.0 * E_star)) ** (1.0 / 3.0)
    return dict(
        sol=sol,
        h=h_over_a * a,
        a=a,
        force=force,
        F_hertz=4.0 * E_star * a**3 / (3.0 * R),
        a_F=a_F,
        p0_F=3.0 * force / (2.0 * np.pi * a_F**2),
    )


def test_hertz_sphere_on_a_half_space():
    """Contact radius, peak pressure and force against Hertz, on the quarter block of ``_hertz`` with h = a/4
    (L = 40a, growth 1.4: 29478 tetrahedra, 17496 DOFs, 3 Newton steps). Measured: the outermost contact node
    at r = 1.031a (0.12h beyond a; 0.02h beyond Hertz's a for the computed force), the peak nodal pressure
    1.023 p₀(F), the force 1.082 F_Hertz(d) — P1 too stiff, 1.075 at h = a/5, 1.059 at h = a/8 (the slow test);
    the finite block (L = 40a) makes about 1 % of it. The penalty leaves u_c = δ·p at every contact node."""
    r = _hertz(0.25, growth=1.4)
    sol, h, a = r["sol"], r["h"], r["a"]
    profile = sol.profile
    radius = np.hypot(profile.points[:, 0], profile.points[:, 1])
    reach = float(radius[profile.active].max())
    assert abs(reach - a) <= 2 * h and abs(reach - r["a_F"]) <= 2 * h
    assert profile.max_pressure == pytest.approx(r["p0_F"], rel=0.05)
    assert 1.0 < r["force"] / r["F_hertz"] < 1.12
    assert profile.penetration == pytest.approx(sol.delta * profile.max_pressure, rel=1e-6)


@pytest.mark.slow
def test_hertz_force_converges_with_the_contact_cells():
    """The excess force over Hertz falls as the contact cells shrink (h = a/4 → a/8: 8.2 % → 5.9 %, measured)."""
    coarse, fine = _hertz(0.25, growth=1.4), _hertz(0.125, growth=1.3)
    excess = [r["force"] / r["F_hertz"] - 1.0 for r in (coarse, fine)]
    assert 0.0 < excess[1] < 0.8 * excess[0]
    assert fine["sol"].profile.max_pressure == pytest.approx(fine["p0_F"], rel=0.05)


def test_methods_other_than_the_primal_ones_refuse_3d_and_rollers():
    """The mixed methods refuse 3D and rollers; primal-ms refuses a cube without coarse cubes."""
    cm = unit_cube(2)
    problem = ContactProblem(
        youngs_modulus=1.0,
        poisson_ratio=0.3,
        mesh=cm,
        obstacle=Plane((1.0, 0.0), (-1.0, 0.0)).indented(0.01, (-1.0, 0.0)),
    )
    for method in ("mixed", "mixed-monolithic"):
        with pytest.raises(InputError, match="primal-monolithic"):
            fc.solve(problem, method)
    with pytest.raises(InputError, match="needs a coarse grid.*unit_cube"):  # (the cube has none: unit_cube(n, H=…))
        fc.solve(problem, "primal-ms")
    assert fc.solve(problem, "primal-monolithic").profile.force > 0
    from fenics_contact.problem.geometry import unit_square

    rolled = ContactProblem(
        youngs_modulus=1.0, poisson_ratio=0.3, mesh=unit_square(4, 2), boundary=BoundaryConditions(rollers=((1, 0.0),))
    )
    with pytest.raises(InputError, match="rollers"):
        fc.solve(rolled, "mixed")


def _gmsh_box(path, *, split: float = 0.75, h: float = 0.3, contact_on_side: bool = False):
    """A gmsh tetrahedral mesh of (0, 1)³: Omega1 x < ``split``, Omega2 beyond, gamma the plane between,
    Gamma_D the face x = 0, Gamma_C the face x = 1 (``contact_on_side``: the face y = 0, across gamma)."""
    import gmsh

    from fenics_contact.problem.geometry import gmsh_session

    with gmsh_session():
        occ = gmsh.model.occ
        gmsh.model.add("box")
        occ.fragment([(3, occ.addBox(0, 0, 0, split, 1, 1))], [(3, occ.addBox(split, 0, 0, 1 - split, 1, 1))])
        occ.synchronize()
        volumes = sorted((occ.getCenterOfMass(3, t)[0], t) for _, t in gmsh.model.getEntities(3))
        faces = {}
        for _, t in gmsh.model.getEntities(2):
            x = occ.getCenterOfMass(2, t)
            contact = abs(x[1]) < 1e-9 if contact_on_side else abs(x[0] - 1) < 1e-9
            for name, test in (
                ("Gamma_D", abs(x[0]) < 1e-9),
                ("Gamma_C", contact),
                ("gamma", abs(x[0] - split) < 1e-9),
            ):
                if test:
                    faces.setdefault(name, []).append(t)
        gmsh.model.addPhysicalGroup(3, [volumes[0][1]], 1, name="Omega1")
        gmsh.model.addPhysicalGroup(3, [volumes[1][1]], 2, name="Omega2")
        for i, (name, tags) in enumerate(sorted(faces.items())):
            gmsh.model.addPhysicalGroup(2, tags, 10 + i, name=name)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))


def test_read_mesh_takes_a_gmsh_tetrahedral_mesh_and_the_patch_test_is_exact_on_it(tmp_path):
    """The block of the patch test on an unstructured gmsh mesh: the linear solution is exact on any mesh."""
    from fenics_contact.errors import MeshTagError
    from fenics_contact.problem.geometry import read_mesh

    tmp_path = MPI.COMM_WORLD.bcast(tmp_path, root=0)  # one folder for every rank
    path = tmp_path / "box.msh"
    if MPI.COMM_WORLD.rank == 0:
        _gmsh_box(path)
    MPI.COMM_WORLD.Barrier()
    cm = read_mesh(path)
    assert cm.mesh.topology.dim == 3 and cm.h > 0
    E, nu, d0, delta = 1.0, 0.25, 0.02, 1e-4
    pressure = d0 / (delta + 1.0 / E)

    def lateral(x):
        return np.vstack([np.zeros(x.shape[1]), nu * pressure / E * x[1], nu * pressure / E * x[2]])

    wall = Plane((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0)).indented(d0, (-1.0, 0.0, 0.0))
    problem = ContactProblem(
        youngs_modulus=E, poisson_ratio=nu, obstacle=wall, mesh=cm, boundary=BoundaryConditions(displacement=lateral)
    )
    sol = solve_primal_monolithic(problem, delta=delta)
    X = sol.u.function_space.tabulate_dof_coordinates()
    exact = lateral(X.T).T
    exact[:, 0] = -pressure / E * X[:, 0]
    error = cm.comm.allreduce(float(np.max(np.abs(sol.u.x.array.reshape(-1, 3) - exact))), op=MPI.MAX)
    assert error < 1e-12
    assert sol.profile.force == pytest.approx(pressure, rel=1e-10)
    if MPI.COMM_WORLD.rank == 0:
        _gmsh_box(tmp_path / "touching.msh", h=0.5, contact_on_side=True)
    MPI.COMM_WORLD.Barrier()
    with pytest.raises(MeshTagError, match="'Gamma_C' touches 'gamma'"):  # refused, as in 2D
        read_mesh(tmp_path / "touching.msh")


def test_two_materials_in_series_by_cell_tag():
    """A user's DOLFINx box (tags of its own) of two layers x < ½ (E₁) and x > ½ (E₂), ν = 0, pushed by d₀ into
    a wall at x = 1: uniaxial stress, p = d₀/(δ + ½/E₁ + ½/E₂), u_x piecewise linear (P1-exact: the material
    interface is a grid plane), u_y = u_z = 0."""
    from dolfinx import mesh as dmesh

    msh = dmesh.create_box(MPI.COMM_WORLD, [np.zeros(3), np.ones(3)], [4, 2, 2], dmesh.CellType.tetrahedron)
    fdim = msh.topology.dim - 1
    left = dmesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[0], 0.0))
    right = dmesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[0], 1.0))
    order = np.argsort(np.concatenate([left, right]))
    facet_tags = dmesh.meshtags(
        msh,
        fdim,
        np.concatenate([left, right])[order],
        np.concatenate([np.full(left.size, 7), np.full(right.size, 8)]).astype(np.int32)[order],
    )
    imap = msh.topology.index_map(msh.topology.dim)
    cells = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
    layer = np.where(dmesh.compute_midpoints(msh, msh.topology.dim, cells)[:, 0] < 0.5, 1, 2).astype(np.int32)
    cell_tags = dmesh.meshtags(msh, msh.topology.dim, cells, layer)
    E1, E2, d0, delta = 1.0, 4.0, 0.01, 1e-3
    problem = ContactProblem.from_meshtags(
        msh,
        facet_tags,
        cell_tags,
        contact=8,
        clamped=7,
        youngs_modulus={1: E1, 2: E2},
        poisson_ratio=0.0,
        strip_width=0.25,
        obstacle=Plane((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0)).indented(d0, (-1.0, 0.0, 0.0)),
    )
    sol = solve_primal_monolithic(problem, delta=delta)
    p = d0 / (delta + 0.5 / E1 + 0.5 / E2)
    X = sol.u.function_space.tabulate_dof_coordinates()
    exact = np.zeros_like(X)
    exact[:, 0] = -p * np.where(X[:, 0] < 0.5, X[:, 0] / E1, 0.5 / E1 + (X[:, 0] - 0.5) / E2)
    error = MPI.COMM_WORLD.allreduce(float(np.max(np.abs(sol.u.x.array.reshape(-1, 3) - exact))), op=MPI.MAX)
    assert error < 1e-12 and sol.profile.force == pytest.approx(p, rel=1e-11)
    by_callable = problem.with_(youngs_modulus=lambda x: np.where(x[0] < 0.5, E1, E2))  # E(x) at the midpoints
    again = solve_primal_monolithic(by_callable, delta=delta)
    assert np.allclose(again.u.x.array, sol.u.x.array, rtol=0.0, atol=1e-14)
