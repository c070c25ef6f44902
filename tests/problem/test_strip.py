"""The strip Ω₂, γ and the coarse cells built from the physics tags alone (``problem.strip``), on meshes the
package did not make: a user's unstructured block with two materials, a DOLFINx mesh with its own tags."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI
from scipy.spatial import cKDTree

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.errors import InputError
from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.fem.primal import solve_primal_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.mixed import solve_mixed_hybrid
from fenics_contact.hybrid.primal import solve_primal_hybrid
from fenics_contact.methods import solve
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.problem import strip
from fenics_contact.problem.cell_groups import CellGroups, read_cell_groups
from fenics_contact.problem.fields import FunctionField, tag_function
from fenics_contact.problem.geometry import ContactMesh, read_mesh, unit_square
from fenics_contact.problem.models import model_2
from fenics_contact.problem.obstacles import Circle, Plane
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.problem.tags import Boundary, Subdomain
from fenics_contact.problem.validation import interface_bends_of, validate_contact_mesh

ROOT = Path(__file__).resolve().parents[2]
PAD = ROOT / "cases" / "pad.msh"
CLI = [sys.executable, "-m", "fenics_contact.launch"]


def _centroids(msh, cells):
    geo = dmesh.entities_to_geometry(msh, msh.topology.dim, cells)
    return msh.geometry.x[geo].mean(axis=1)


def _gamma_c_points(cm, samples=64):
    facets = cm.facet_tags.find(Boundary.GAMMA_C)
    x = cm.mesh.geometry.x[dmesh.entities_to_geometry(cm.mesh, 1, facets)]
    t = np.linspace(0.0, 1.0, samples)[:, None, None]
    return (x[None, :, 0] * (1 - t) + x[None, :, 1] * t).reshape(-1, 3)


def _physics_only_tags(cm):
    """The facet tags of ``cm`` without γ (what a user's mesh has)."""
    keep = cm.facet_tags.values != Boundary.INTERFACE
    return dmesh.meshtags(cm.mesh, 1, cm.facet_tags.indices[keep], cm.facet_tags.values[keep])


def test_band_strip_on_a_users_unstructured_mesh():
    """Ω₂ is the band of cells within the width of Γ_C: its cells' centroids lie within it, Ω₁'s outside, every
    cell on Γ_C is in Ω₂, no Γ_C node lies on γ, and the mesh passes the contact-mesh checks."""
    cm = read_mesh(PAD, overlay_groups=["rubber", "steel"])
    width = strip.DEFAULT_WIDTH_CELLS * strip.contact_cell_size(cm.mesh, cm.facet_tags)
    assert 0.3 < width < 1.0  # four contact cells of about 0.1 mm (sized by the mesh's own contact cells)
    tree = cKDTree(_gamma_c_points(cm)[:, :2])
    for tag, inside in ((Subdomain.OMEGA2, True), (Subdomain.OMEGA1, False)):
        d, _ = tree.query(_centroids(cm.mesh, cm.cell_tags.find(tag))[:, :2])
        assert np.all(d <= width + 1e-3) if inside else np.all(d > width - 1e-3)
    validate_contact_mesh(cm)  # Γ_C on ∂Ω₂ away from γ, γ the common boundary
    assert cm.H is None and np.all(cm.coarse_cell < 0)


def test_band_strip_with_a_coarse_size_gives_coarse_cells_without_slivers():
    cm = read_mesh(PAD, H=2.0, overlay_groups=["rubber", "steel"])
    omega1 = cm.cell_tags.find(Subdomain.OMEGA1)
    omega2 = cm.cell_tags.find(Subdomain.OMEGA2)
    coarse = np.asarray(cm.coarse_cell)
    assert np.all(coarse[omega1] >= 0) and np.all(coarse[omega2] < 0)
    counts = np.bincount(coarse[omega1])
    assert counts.min() >= strip.SLIVER * np.median(counts)
    d, _ = cKDTree(_gamma_c_points(cm)[:, :2]).query(_centroids(cm.mesh, omega2)[:, :2])
    assert d.max() <= 2.0 + 1e-3


def test_automatic_split_of_a_resolved_grid_is_the_papers_strip():
    """On the unit square that resolves the squares of side H, the strip is the last column of squares: the
    tags of the built-in mesh, cell for cell."""
    cm = unit_square(16, 4)
    split = strip.automatic_split(cm.mesh, _physics_only_tags(cm), H=0.25)
    for tag in Subdomain:
        assert np.array_equal(np.sort(split.cell_tags.find(tag)), np.sort(cm.cell_tags.find(tag)))
    assert np.array_equal(
        np.sort(split.facet_tags.find(Boundary.INTERFACE)), np.sort(cm.facet_tags.find(Boundary.INTERFACE))
    )
    assert np.array_equal(split.coarse_cell, cm.coarse_cell)


def _pad_problem(H=None):
    cm = read_mesh(PAD, H=H, overlay_groups=["rubber", "steel"])
    groups = CellGroups(cm, read_cell_groups(PAD, ["rubber", "steel"]))
    return ContactProblem(
        youngs_modulus=groups.field({"rubber": 10.0, "steel": 2.1e5}),
        poisson_ratio=groups.field({"rubber": 0.45, "steel": 0.3}),
        obstacle=Circle((0.0, 30.0), 30.0).indented(0.2, (0.0, -1.0)),
        mesh=cm,
    )


def test_algorithm_1_on_the_automatic_strip_is_the_monolithic_solution():
    """Theorem 3.1 on a strip the package built: the fixed point equals the monolithic penalized solution."""
    problem = _pad_problem()
    ref = solve_primal_monolithic(problem)
    result = solve_primal_hybrid(problem, options=IterationOptions(accel="newton", tol=1e-10), reference=ref.u)
    assert result.converged and result.e_u < 1e-9
    assert abs(result.profile.force - ref.profile.force) < 1e-9 * ref.profile.force


def test_mixed_methods_on_a_bent_and_a_straight_interface():
    """γ of a band on an unstructured mesh bends at its vertices; on a zigzag γ (a bend at most vertices) and on a
    straight one Algorithm 2 lands on the mixed solution with σn continuous on γ (``split_interface``)."""
    problem = _pad_problem()
    assert interface_bends_of(problem.cm).shape[0] > 0
    cm = unit_square(16, 4)  # a zigzag γ: the band cuts the columns of right triangles between their centroids
    zigzag = strip.automatic_split(cm.mesh, _physics_only_tags(cm), width=0.155)
    bent = model_2().on(ContactMesh(cm.mesh, zigzag.cell_tags, zigzag.facet_tags, cm.h, None, zigzag.coarse_cell))
    assert interface_bends_of(bent.cm).shape[0] > 0
    ref = solve_mixed_monolithic(bent, split_interface=True)
    result = solve_mixed_hybrid(bent, reference=ref, options=IterationOptions(accel="newton", tol=1e-10))
    assert result.e_sigma < 1e-9
    straight = strip.automatic_split(cm.mesh, _physics_only_tags(cm), width=0.125)
    problem = model_2().on(
        ContactMesh(cm.mesh, straight.cell_tags, straight.facet_tags, cm.h, None, straight.coarse_cell)
    )
    assert interface_bends_of(problem.cm).shape[0] == 0
    ref = solve_mixed_monolithic(problem, split_interface=True)
    result = solve_mixed_hybrid(problem, reference=ref, options=IterationOptions(accel="newton", tol=1e-10))
    assert result.e_sigma < 1e-9


def _dolfinx_block(n=24):
    """A DOLFINx mesh of (0, 2) × (0, 1) with the user's own tags: facets 1 bottom, 2 top (contact), 3 sides;
    cells 10 (y < 1/2, steel), 11 (rubber)."""
    msh = dmesh.create_rectangle(MPI.COMM_WORLD, [[0.0, 0.0], [2.0, 1.0]], [2 * n, n], dmesh.CellType.triangle)
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    facets = dmesh.exterior_facet_indices(msh.topology)
    mid = dmesh.compute_midpoints(msh, tdim - 1, facets)
    values = np.where(np.isclose(mid[:, 1], 0.0), 1, np.where(np.isclose(mid[:, 1], 1.0), 2, 3)).astype(np.int32)
    facet_tags = dmesh.meshtags(msh, tdim - 1, facets, values)
    imap = msh.topology.index_map(tdim)
    cells = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
    cvals = np.where(dmesh.compute_midpoints(msh, tdim, cells)[:, 1] < 0.5, 10, 11).astype(np.int32)
    return msh, facet_tags, dmesh.meshtags(msh, tdim, cells, cvals)


@pytest.mark.slow
def test_from_meshtags_in_the_users_own_tags():
    """A DOLFINx mesh and its tags, materials by cell tag, a cylinder on the top: Algorithm 1 equals the
    monolithic solution; Algorithm 3 on the coarse cells built from H converges to it exponentially in the layers."""
    msh, facet_tags, cell_tags = _dolfinx_block()
    problem = ContactProblem.from_meshtags(
        msh,
        facet_tags,
        cell_tags,
        contact=2,
        clamped=1,
        youngs_modulus={10: 1e3, 11: 1.0},
        poisson_ratio={10: 0.3, 11: 0.45},
        obstacle=Circle((1.0, 6.0), 5.0).indented(0.01, (0.0, -1.0)),
        H=0.25,
    )
    E = problem.fields.E.x.array
    assert set(np.unique(E)) == {1.0, 1e3}
    ref = solve(problem, "primal-monolithic")
    alg1 = solve(problem, "primal", tol=1e-10, reference=ref.u)
    assert alg1.e_u < 1e-9 and ref.profile.force > 0
    errors = [solve(problem, "primal-ms", cem=CEMOptions(layers=m), reference=ref.u).e_u for m in (2, 3)]
    assert errors[1] < 2e-4 and errors[1] < errors[0] / 5  # measured 5.9e-4, 3.9e-5: ×15 per layer
    with pytest.raises(InputError, match="no facet has the tag 7"):
        ContactProblem.from_meshtags(
            msh, facet_tags, cell_tags, contact=7, clamped=1, youngs_modulus=1.0, poisson_ratio=0.3
        )
    with pytest.raises(InputError, match="cells get no value"):
        ContactProblem.from_meshtags(
            msh, facet_tags, cell_tags, contact=2, clamped=1, youngs_modulus={10: 1.0}, poisson_ratio=0.3
        )


def test_a_field_given_as_a_function_serves_the_parts():
    """E given as a dolfinx Function on the mesh: the fields of Ω₁ and Ω₂ (submeshes) take its values."""
    msh, facet_tags, cell_tags = _dolfinx_block(8)
    E = tag_function(msh, cell_tags, {10: 5.0, 11: 2.0}, name="E")
    problem = ContactProblem.from_meshtags(
        msh,
        facet_tags,
        contact=2,
        clamped=1,
        youngs_modulus=E,
        poisson_ratio=0.3,
        obstacle=Plane((0.0, 1.0), (0.0, -1.0)),
    )
    assert np.array_equal(problem.fields.E.x.array, E.x.array)
    sub, entity_map, _, _ = dmesh.create_submesh(msh, 2, problem.cm.cell_tags.find(Subdomain.OMEGA2))
    values = problem.fields_on(sub).E.x.array
    parent = entity_map.sub_topology_to_topology(np.arange(values.size, dtype=np.int32), False)
    assert np.array_equal(values, E.x.array[parent])
    with pytest.raises(InputError, match="outside its mesh"):
        FunctionField(E)(np.array([[5.0], [5.0], [0.0]]))


@pytest.mark.parametrize("method", ["primal", "primal-ms"])
@pytest.mark.slow
def test_a_users_case_file_runs_on_its_own_mesh(tmp_path, method):
    """cases/pad.toml: the user's mesh (materials by group, refined under the cylinder, no Omega tags) in mm and
    MPa, four load steps; the strip and coarse cells are built; the certificate holds at every step."""
    out = tmp_path / method
    run = subprocess.run(
        [*CLI, "run", "--case", str(ROOT / "cases" / "pad.toml"), "--method", method, "--no-plots", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert run.returncode == 0, run.stderr
    import json

    summary = json.loads((out / "summary.json").read_text())
    steps = summary["force_indentation"]["steps"]
    forces = [s["force"] for s in steps]
    assert all(b > a > 0 for a, b in zip(forces, forces[1:]))  # a stiffening response
    assert all(s["transmission_residual"] < 1e-8 for s in steps)
    assert summary["contact_at_open_end"] == []


@pytest.mark.slow
def test_a_users_case_file_runs_with_the_mixed_methods(tmp_path):
    """cases/pad.toml with Algorithms 2 and 4 on the jagged γ of the automatic strip: the certificate holds at every
    step and the forces are those of the primal run up to the discretization (P1 against Arnold–Winther: 5.9 %,
    1.5 %, 0.4 %, 1.9 % at the four depths, the largest where the contact zone spans the fewest cells); the
    multiscale Ω₁ of Algorithm 4 changes them by 2e-6."""
    import json

    forces = {}
    for method in ("primal", "mixed", "mixed-ms"):
        out = tmp_path / method
        run = subprocess.run(
            [
                *CLI,
                "run",
                "--case",
                str(ROOT / "cases" / "pad.toml"),
                "--method",
                method,
                "--no-plots",
                "--out",
                str(out),
            ],
            capture_output=True,
            text=True,
            timeout=1800,
        )
        assert run.returncode == 0, run.stderr
        steps = json.loads((out / "summary.json").read_text())["force_indentation"]["steps"]
        assert all(s["transmission_residual"] < 1e-8 for s in steps)
        forces[method] = np.array([s["force"] for s in steps])
    primal, mixed = forces["primal"], forces["mixed"]
    assert np.all(np.diff(mixed) > 0) and mixed[0] > 0  # a stiffening response
    assert np.all(np.abs(mixed - primal) < 0.1 * primal) and np.all(np.abs(mixed - primal)[2:] < 0.03 * primal[2:])
    assert np.all(np.abs(forces["mixed-ms"] - mixed) < 1e-4 * mixed)
