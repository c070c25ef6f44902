"""Meshes: tags, coarse grid, submesh transfers, user gmsh files, bad sizes."""

import gmsh
import numpy as np
import pytest
from dolfinx import fem
from mpi4py import MPI

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.transmission import split_mesh
from fenics_contact.problem.fields import material_fields
from fenics_contact.problem.geometry import build_unit_square_model, gmsh_session, read_mesh, unit_square
from fenics_contact.problem.models import model_2
from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, Subdomain


def _count(tags, value, comm):
    return comm.allreduce(tags.find(value).size, op=MPI.SUM)


def test_tags_and_coarse_grid():
    n, N = 16, 4
    cm = unit_square(n, N)
    comm = cm.comm
    assert _count(cm.cell_tags, Subdomain.OMEGA1, comm) == 2 * n * (n - n // N)
    assert _count(cm.cell_tags, Subdomain.OMEGA2, comm) == 2 * n * (n // N)
    assert _count(cm.facet_tags, Boundary.GAMMA_C, comm) == n
    assert _count(cm.facet_tags, Boundary.INTERFACE, comm) == n
    assert _count(cm.facet_tags, Boundary.GAMMA_D, comm) == 3 * n
    nloc = cm.mesh.topology.index_map(2).size_local
    counts = np.bincount(cm.coarse_cell[:nloc], minlength=N * N)
    counts = comm.allreduce(counts, op=MPI.SUM)
    assert np.all(counts == 2 * (n // N) ** 2), "every coarse square is a union of fine cells"
    # Ω₂ is exactly the last coarse column
    strip = cm.cell_tags.find(Subdomain.OMEGA2)
    assert np.all(cm.coarse_cell[strip] % N == N - 1)


def test_submesh_transfer_maps_matching_points():
    cm = unit_square(8, 4)
    parts = split_mesh(cm)
    from fenics_contact.hybrid.transmission import InterfaceSpace

    space = InterfaceSpace(cm, parts, shape=(2,))
    xp = space.V.tabulate_dof_coordinates()
    for Vs, tr in zip(space.spaces, space.transfers):
        xs = Vs.tabulate_dof_coordinates()
        assert np.allclose(xs[tr.sub[::2] // 2], xp[tr.parent[::2] // 2])
    # the owned interface nodes lie on x = 1 - H
    assert np.allclose(space.coordinates[:, 0], 0.75)


@pytest.mark.parametrize(
    "n, N, message", [(16, 3, "multiple"), (16, 1, "room"), (3.5, 2, "integer"), (1, 1, "integer")]
)
def test_bad_sizes(n, N, message):
    with pytest.raises(InputError, match=message):
        unit_square(n, N)


def _write_msh(path, *, drop=None, offset=100):
    """The built-in model written as a .msh with other tag integers (and optionally a group dropped)."""
    with gmsh_session():
        build_unit_square_model(8, 4)
        groups = [
            (d, t, gmsh.model.getPhysicalName(d, t), gmsh.model.getEntitiesForPhysicalGroup(d, t))
            for d, t in gmsh.model.getPhysicalGroups()
        ]
        gmsh.model.removePhysicalGroups()
        for _, _, name, _ in groups:
            gmsh.model.removePhysicalName(name)
        for d, t, name, ents in groups:
            if name != drop:
                gmsh.model.addPhysicalGroup(d, list(ents), t + offset, name=name)
        gmsh.write(str(path))
        gmsh.model.remove()


def _shared_path(tmp_path_factory, name):
    path = tmp_path_factory.mktemp("msh") / name if MPI.COMM_WORLD.rank == 0 else None
    return MPI.COMM_WORLD.bcast(path, root=0)


def test_user_mesh_with_other_tag_numbers(tmp_path_factory):
    path = _shared_path(tmp_path_factory, "square.msh")
    if MPI.COMM_WORLD.rank == 0:
        _write_msh(path)
    MPI.COMM_WORLD.Barrier()
    user = read_mesh(path, H=0.25)
    built = unit_square(8, 4)
    for tags, values in [(user.cell_tags, Subdomain), (user.facet_tags, Boundary)]:
        for t in values:
            ref = built.cell_tags if tags.dim == 2 else built.facet_tags
            assert _count(tags, t, user.comm) == _count(ref, t, user.comm) > 0
    # and it solves to the same answer as the built-in mesh
    norms = []
    for cm in (user, built):
        # same δ on both
        sol = solve_primal_monolithic(model_2().on(cm), delta=default_penalty(1 / 8, 1.0))
        norms.append(sol.u.x.petsc_vec.norm())
    assert np.isclose(norms[0], norms[1], rtol=1e-12)
    # h of a user mesh is √(2·largest cell area): 1/n on the same grid as the built-in mesh
    assert np.isclose(user.h, 1 / 8, rtol=1e-9) and built.h == 1 / 8


@pytest.mark.parametrize("dropped", [PHYSICAL_NAMES[Boundary.GAMMA_C], PHYSICAL_NAMES[Subdomain.OMEGA2]])
def test_mesh_missing_a_tag_is_rejected(tmp_path_factory, dropped):
    path = _shared_path(tmp_path_factory, "missing.msh")
    if MPI.COMM_WORLD.rank == 0:
        _write_msh(path, drop=dropped)
    MPI.COMM_WORLD.Barrier()
    with pytest.raises(MeshTagError, match=dropped):
        read_mesh(path)


def test_missing_file():
    with pytest.raises(InputError, match="does not exist"):
        read_mesh("/nonexistent/mesh.msh")


def test_material_fields_validate_values():
    cm = unit_square(8, 4)
    with pytest.raises(InputError, match="Poisson"):
        material_fields(cm.mesh, model_2(nu=0.5))
    with pytest.raises(InputError, match="Young"):
        material_fields(cm.mesh, model_2(E_low=0.0))
    fields = material_fields(cm.mesh, model_2())
    assert isinstance(fields.E, fem.Function)


def test_stored_mesh_is_the_builder_output():
    """meshes/unit_square_n16_H4.msh is what meshes/make_unit_square.py writes (see meshes/README.md)."""
    from pathlib import Path

    stored = read_mesh(Path(__file__).parents[2] / "meshes" / "unit_square_n16_H4.msh", H=0.25)
    built = unit_square(16, 4)
    for t in Subdomain:
        assert _count(stored.cell_tags, t, stored.comm) == _count(built.cell_tags, t, built.comm)
    for t in Boundary:
        assert _count(stored.facet_tags, t, stored.comm) == _count(built.facet_tags, t, built.comm)
    xs = np.concatenate(stored.comm.allgather(stored.mesh.geometry.x[:, :2]))
    xb = np.concatenate(built.comm.allgather(built.mesh.geometry.x[:, :2]))
    order = lambda x: x[np.lexsort((np.round(x[:, 1], 9), np.round(x[:, 0], 9)))]  # noqa: E731
    assert np.allclose(order(np.unique(np.round(xs, 12), axis=0)), order(np.unique(np.round(xb, 12), axis=0)))


def test_mesh_too_coarse_for_the_load_is_rejected():
    """h = 1/4 has no cell midpoint in the load column x >= 15/16: a clear error, not u = 0."""
    cm = unit_square(4, 2)
    with pytest.raises(InputError, match="zero on every cell"):
        model_2().on(cm).check_loaded()


def test_open_ends_of_the_contact_boundary():
    """Γ_C ends openly where the boundary goes on straight (the Hertz block's top face at |x| = 3a), not at the
    body's corners (unit square, bulged square); on every rank."""
    from fenics_contact.problem.meshes import bulged_square, hertz_block
    from fenics_contact.problem.validation import contact_open_ends

    assert contact_open_ends(unit_square(8, 4, clamped=("left",))).shape == (0, 3)
    assert contact_open_ends(bulged_square(1 / 16, 1 / 4, clamped=("left",))).shape == (0, 3)
    ends = contact_open_ends(hertz_block(0.05, refinement=0.25)[0])  # x, y, length of the end facet
    assert np.allclose(sorted(ends[:, 0]), [-0.15, 0.15]) and np.allclose(ends[:, 1], 0.0)
    assert np.all((ends[:, 2] > 0.0) & (ends[:, 2] < 0.05))


def test_contact_profile_zones_along_a_horizontal_boundary():
    """The active interval is taken along Γ_C (x on a horizontal one); separate zones are listed apart."""
    from fenics_contact.fem.contact import ContactProfile

    x = np.linspace(-1.0, 1.0, 9)
    u_c = np.array([1, 1, 0, -1, -1, -1, 0.5, 0.5, -1.0]) * 1e-3  # > 0: in contact
    prof = ContactProfile(np.zeros_like(x), u_c, -u_c, points=np.stack([x, np.zeros_like(x)], axis=1))
    assert prof.active_interval() == (-1.0, 0.75)
    assert prof.contact_zones() == [((-1.0, 0.0), (-0.75, 0.0)), ((0.5, 0.0), (0.75, 0.0))]
    assert prof.contact_zone() == ((-1.0, 0.0), (0.75, 0.0))  # the span of both
