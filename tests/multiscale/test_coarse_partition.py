"""Any domain for the multiscale methods: coarse grids over the bounding box, user
partitions, oversampling by coarse-cell adjacency, and the automatic contact strip Ω₂.

Unit checks: the Cartesian grid over the bounding box of a rectangle 2×1 and of an L-shape, a refused
unresolved grid, the adjacency layers and the colouring of a general partition, the strip built along
Γ_C. Verification: Algorithm 3 on the L-shape, the rectangle and a user partition of an unstructured mesh
reproduces the monolithic solution with all modes and global patches, and its error falls with m.
"""

import gc

import gmsh
import numpy as np
import pytest
from mpi4py import MPI
from multiscale_layers import layer_errors

import fenics_contact  # noqa: F401
from fenics_contact.errors import InputError
from fenics_contact.fem import primal
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.multiscale import cem
from fenics_contact.multiscale import primal as primal_ms
from fenics_contact.problem import geometry, models
from fenics_contact.problem.tags import Boundary, Subdomain

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial test (its MPI twin is in test_multiscale)")


@pytest.fixture(scope="module", autouse=True)
def _teardown():
    yield
    gc.collect()
    MPI.COMM_WORLD.Barrier()


def _structured_model(boxes, n_per_unit: int, contact, dirichlet, *, name="domain") -> None:
    """Union of axis-aligned boxes (x0, x1, y0, y1) meshed with right triangles of side 1/n_per_unit.

    ``contact`` and ``dirichlet`` select boundary curves by a predicate on their midpoint. Only the
    groups Gamma_D, Gamma_C and one 2D group ``name`` are written (no Omega1/Omega2/gamma).
    """
    occ = gmsh.model.occ
    gmsh.model.add("test")
    tags = [occ.addRectangle(x0, y0, 0, x1 - x0, y1 - y0) for x0, x1, y0, y1 in boxes]
    occ.fragment([(2, t) for t in tags], [])
    occ.synchronize()
    for dim, tag in gmsh.model.getEntities(1):
        a, b = (gmsh.model.getValue(0, p[1], []) for p in gmsh.model.getBoundary([(1, tag)]))
        gmsh.model.mesh.setTransfiniteCurve(tag, int(round(np.linalg.norm(b - a) * n_per_unit)) + 1)
    for dim, tag in gmsh.model.getEntities(2):
        gmsh.model.mesh.setTransfiniteSurface(tag, "Right")
    contact_c, dirichlet_c = [], []
    for dim, tag in gmsh.model.getBoundary(gmsh.model.getEntities(2), combined=True, oriented=False):
        mid = np.array(occ.getCenterOfMass(1, abs(tag)))
        if contact(mid):
            contact_c.append(abs(tag))
        elif dirichlet(mid):
            dirichlet_c.append(abs(tag))
    gmsh.model.addPhysicalGroup(1, dirichlet_c, 11, name="Gamma_D")
    gmsh.model.addPhysicalGroup(1, contact_c, 12, name="Gamma_C")
    gmsh.model.addPhysicalGroup(2, [t for _, t in gmsh.model.getEntities(2)], 1, name=name)
    gmsh.model.mesh.generate(2)


def _write(tmp_path, fname, build) -> str:
    path = str(tmp_path / fname)
    with geometry.gmsh_session():
        build()
        gmsh.write(path)
        gmsh.model.remove()
    return path


@pytest.fixture(scope="module")
def l_shape(tmp_path_factory):
    """L-shape (0,1)² minus [1/2,1]×[1/2,1], h = 1/16; clamped on x = 0, contact on x = 1 (y < 1/2)."""
    path = _write(
        tmp_path_factory.mktemp("lshape"),
        "l.msh",
        lambda: _structured_model(
            [(0, 0.5, 0, 0.5), (0.5, 1, 0, 0.5), (0, 0.5, 0.5, 1)],
            16,
            contact=lambda m: abs(m[0] - 1) < 1e-9,
            dirichlet=lambda m: abs(m[0]) < 1e-9,
        ),
    )
    return geometry.read_mesh(path, H=1 / 8)


@pytest.fixture(scope="module")
def rectangle(tmp_path_factory):
    """Rectangle (0,2)×(0,1), h = 1/16; clamped on x = 0, contact on x = 2."""
    path = _write(
        tmp_path_factory.mktemp("rect"),
        "r.msh",
        lambda: _structured_model(
            [(0, 2, 0, 1)], 16, contact=lambda m: abs(m[0] - 2) < 1e-9, dirichlet=lambda m: abs(m[0]) < 1e-9
        ),
    )
    return geometry.read_mesh(path, H=1 / 4)


def _load(x):
    """Push the lower half (y < 1/2) towards the obstacle, pull the rest, everywhere (loads in Ω₁)."""
    f = np.zeros((2, x.shape[1]))
    f[0] = np.where(x[1] < 0.5, 1.0, -0.5)
    return f


MODEL = models.get_model(2).with_(load=_load)


def _cell_area(cm, cells):
    from dolfinx import mesh as dmesh

    geo = dmesh.entities_to_geometry(cm.mesh, 2, cells.astype(np.int32))
    p = cm.mesh.geometry.x[geo][:, :, :2]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    return float(np.sum(0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])))


# -- unit checks ------------------------------------------------------------------------------------
def test_strip_built_along_contact_boundary(l_shape, rectangle):
    """No Omega1/Omega2/gamma in the file: Ω₂ = the coarse squares along Γ_C, γ between."""
    cm = l_shape
    assert _cell_area(cm, cm.cell_tags.find(Subdomain.OMEGA2)) == pytest.approx(0.5 / 8)  # 4 squares of 1/8
    assert _cell_area(cm, cm.cell_tags.find(Subdomain.OMEGA1)) == pytest.approx(0.75 - 0.5 / 8)
    x = cm.mesh.geometry.x
    from dolfinx import mesh as dmesh

    gamma = dmesh.entities_to_geometry(cm.mesh, 1, cm.facet_tags.find(Boundary.INTERFACE))
    xg = x[gamma]
    # γ: the segment x = 7/8, 0 ≤ y ≤ 1/2 (the strip ends at the L-shape's boundary y = 1/2)
    assert np.allclose(xg[:, :, 0], 7 / 8) and xg[:, :, 1].max() == pytest.approx(0.5)
    assert cm.H == pytest.approx(1 / 8)
    rect = rectangle
    assert _cell_area(rect, rect.cell_tags.find(Subdomain.OMEGA2)) == pytest.approx(0.25)


def test_cartesian_grid_over_the_bounding_box(l_shape, rectangle):
    om, _, _ = cem.build_omega1_multiscale(MODEL.on(l_shape), cem=cem.CEMOptions(layers=1))
    grid = om.grid
    # L-shape minus the strip: 3 quadrants of 16 squares, minus the 4 strip squares
    assert grid.size == 3 * 16 - 4
    assert grid.ij is not None and grid.n_coarse == 8
    assert np.allclose(grid.cell_size, 1 / 8)
    at = {tuple(ij): k for k, ij in enumerate(grid.ij)}
    # a square at the re-entrant corner: its 8 neighbours minus the 2 in the hole
    assert grid.patch(at[4, 3], 1).size == 7
    # layers follow the domain, not the bounding box: (5, 3) is 2 squares from (3, 5) in the box
    # (|Δi|, |Δj| ≤ 2) but 3 adjacency steps away around the re-entrant corner
    assert grid.distance(at[3, 5])[at[5, 3]] == 3
    assert at[5, 3] not in grid.patch(at[3, 5], 2) and at[5, 3] in grid.patch(at[3, 5], 3)
    om_r, _, _ = cem.build_omega1_multiscale(MODEL.on(rectangle), cem=cem.CEMOptions(layers=1))
    assert om_r.grid.size == 7 * 4 and om_r.grid.n_coarse is None


def test_colouring_separates_cells_sharing_a_vertex(l_shape):
    om, _, _ = cem.build_omega1_multiscale(MODEL.on(l_shape), cem=cem.CEMOptions(layers=1))
    grid, ops = om.grid, om.ops
    nodes = [set(np.unique(ops.cell_nodes[c]).tolist()) for c in grid.cells]
    for a in range(grid.size):
        for b in range(a + 1, grid.size):
            if nodes[a] & nodes[b]:
                assert grid.colors[a] != grid.colors[b]
    assert grid.num_colors == 4


def test_unresolved_grid_is_refused(l_shape):
    """H = 1/6 does not fit the 1/16 fine grid: the multiscale Ω₁ refuses it with a clear InputError."""
    cm = l_shape
    from fenics_contact.problem.partition import cartesian_coarse_cells

    coarse, _ = cartesian_coarse_cells(cm.mesh, 1 / 6)
    assert np.any(coarse < 0)
    bad = cm._replace(H=1 / 6, coarse_cell=coarse.astype(np.int32))
    with pytest.raises(InputError, match="does not resolve the coarse grid"):
        cem.build_omega1_multiscale(MODEL.on(bad), cem=cem.CEMOptions(layers=1))


def _partitioned_model(nx: int, ny: int, side: float, h: float) -> None:
    """(0, nx·side)×(0, ny·side) split into nx×ny coarse squares, each its own 2D physical group
    ``coarse_<k>``, meshed unstructured (frontal Delaunay, size h, conforming across the squares)."""
    occ = gmsh.model.occ
    gmsh.model.add("partition")
    tags = [occ.addRectangle(i * side, j * side, 0, side, side) for j in range(ny) for i in range(nx)]
    out, _ = occ.fragment([(2, t) for t in tags], [])
    occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMin", h)
    gmsh.option.setNumber("Mesh.MeshSizeMax", h)
    contact_c, dirichlet_c = [], []
    for dim, tag in gmsh.model.getBoundary(gmsh.model.getEntities(2), combined=True, oriented=False):
        mid = np.array(occ.getCenterOfMass(1, abs(tag)))
        if abs(mid[0] - nx * side) < 1e-9:
            contact_c.append(abs(tag))
        elif abs(mid[0]) < 1e-9:
            dirichlet_c.append(abs(tag))
    gmsh.model.addPhysicalGroup(1, dirichlet_c, 11, name="Gamma_D")
    gmsh.model.addPhysicalGroup(1, contact_c, 12, name="Gamma_C")
    for k, (_, t) in enumerate(sorted(gmsh.model.getEntities(2))):
        gmsh.model.addPhysicalGroup(2, [t], 100 + k, name=f"coarse_{k}")
    gmsh.model.mesh.generate(2)


@pytest.fixture(scope="module")
def partitioned(tmp_path_factory):
    """A user mesh: (0,2)×(0,1), unstructured h ≈ 1/12, coarse partition = 8×4 squares given as groups."""
    path = _write(tmp_path_factory.mktemp("part"), "p.msh", lambda: _partitioned_model(8, 4, 0.25, 1 / 12))
    return geometry.read_mesh(path)  # no H: the coarse cells are the physical groups


def test_user_partition_from_physical_groups(partitioned):
    cm = partitioned
    assert cm.H == pytest.approx(0.25)
    assert _cell_area(cm, cm.cell_tags.find(Subdomain.OMEGA2)) == pytest.approx(0.25)  # the 4 squares at x = 2
    om, _, _ = cem.build_omega1_multiscale(MODEL.on(cm), cem=cem.CEMOptions(layers=1))
    grid = om.grid
    assert grid.size == 7 * 4
    assert np.allclose(grid.cell_size, 0.25)
    # an interior square of the partition has 8 neighbours (shared vertex), whatever the fine mesh
    assert max(grid.patch(k, 1).size for k in range(grid.size)) == 9


@pytest.mark.parametrize("case", ["l_shape", "rectangle", "partitioned"])
@pytest.mark.slow
def test_algorithm3_on_any_domain_matches_monolithic_with_all_modes(case, request):
    """All local modes and global patches: V_ms is the fine space, so Algorithm 3 lands on the monolithic
    solution (loads in Ω₁, traction-free sides)."""
    cm = request.getfixturevalue(case)
    delta = primal.default_penalty(cm.h, 1.0)
    ref = primal.solve_primal_monolithic(MODEL.on(cm), delta=delta)
    res = primal_ms.solve_primal_ms_hybrid(
        MODEL.on(cm),
        alpha="Emin",
        delta=delta,
        cem=cem.CEMOptions(layers=50, nbasis=None),
        reference=ref.u,
        options=IterationOptions(tol=1e-11),
    )
    assert res.converged
    assert res.e_u < 1e-9 and res.step.error_energy() < 1e-8


@pytest.mark.parametrize("case", ["l_shape", "partitioned"])
@pytest.mark.slow
def test_algorithm3_on_any_domain_error_falls_with_layers(case, request):
    cm = request.getfixturevalue(case)
    delta = primal.default_penalty(cm.h, 1.0)
    ref = primal.solve_primal_monolithic(MODEL.on(cm), delta=delta)
    e = layer_errors(cm, MODEL, (1, 2, 3), delta=delta, reference=ref.u)
    assert np.all(e[:-1] / e[1:] > 3.0), e


@pytest.mark.parametrize("case", ["l_shape", "partitioned"])
@pytest.mark.slow
def test_algorithm4_on_any_domain_error_falls_with_layers(case, request):
    """Algorithm 4 (mixed CEM Ω₁) on a user mesh: the L-shape (Cartesian grid over its bounding box, traction-free
    sides, the re-entrant corner in Ω₁) and the user partition of an unstructured mesh, loads in Ω₁ pushing and
    pulling: converged, and e_σ against the fine monolithic mixed solution falls with the layers (measured at m = 1,
    2, 3:
    L-shape 0.25, 2.6e-2, 2.6e-3; user partition 0.51, 2.7e-2, 1.3e-3)."""
    from fenics_contact.fem.mixed import solve_mixed_monolithic
    from fenics_contact.multiscale.mixed import solve_mixed_ms_hybrid
    from fenics_contact.multiscale.mixed_cem import MixedCEMOptions

    cm = request.getfixturevalue(case)
    ref = solve_mixed_monolithic(MODEL.on(cm))
    errors = []
    for layers in (1, 2, 3):
        res = solve_mixed_ms_hybrid(
            MODEL.on(cm),
            cem=MixedCEMOptions(layers=layers),
            reference=ref,
            options=IterationOptions(tol=1e-10, accel="newton"),
        )
        assert res.converged and res.history.transmission_residual < 1e-10
        errors.append(res.e_sigma)
    e = np.array(errors)
    assert np.all(e[:-1] / e[1:] > 3.0), e
