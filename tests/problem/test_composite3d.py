"""The 3D fibre composite (model 5): its mesh resolves the fibres and γ cuts two of them, and Algorithm 1's fixed
point is the monolithic solution at contrast 1e6 (Theorem 3.1), against the flush wall and under a sphere."""

import numpy as np
import pytest
from dolfinx import mesh as dmesh

import fenics_contact as fc
from fenics_contact.errors import InputError
from fenics_contact.problem.composite3d import (
    FIBRE_RADIUS,
    FIBRE_SIDES,
    FIBRES_3D,
    fibre_block_3d,
    fibre_block_3d_mesh,
    in_fibres,
)
from fenics_contact.problem.models import MODELS_3D, get_model
from fenics_contact.problem.obstacles import Sphere
from fenics_contact.problem.tags import Boundary, Subdomain


@pytest.fixture(scope="module")
def block():
    return fibre_block_3d_mesh(4, contact_size=0.1)


def _cells(cm):
    msh = cm.mesh
    cells = np.arange(msh.topology.index_map(3).size_local, dtype=np.int32)
    x = msh.geometry.x[dmesh.entities_to_geometry(msh, 3, cells)]
    volume = np.abs(np.linalg.det(x[:, 1:] - x[:, :1])) / 6.0
    return cells, dmesh.compute_midpoints(msh, 3, cells).T, volume


def test_the_mesh_resolves_the_fibres_and_gamma_cuts_two(block):
    """The cells whose midpoints lie in the fibres fill the prisms' volume exactly (6 polygons × length 1), and the
    two fibres on γ (x = ¾) have cells on both sides of it."""
    cells, x, volume = _cells(block)
    inside = in_fibres(x)
    polygon = 0.5 * FIBRE_SIDES * FIBRE_RADIUS**2 * np.sin(2.0 * np.pi / FIBRE_SIDES)
    assert volume.sum() == pytest.approx(1.0, rel=1e-12)
    assert volume[inside].sum() == pytest.approx(len(FIBRES_3D) * polygon, rel=1e-12)
    strip = np.isin(cells, block.cell_tags.find(Subdomain.OMEGA2))
    for xc, zc in FIBRES_3D:
        near = inside & (np.hypot(x[0] - xc, x[2] - zc) < FIBRE_RADIUS)
        assert np.any(near & strip) == (xc + FIBRE_RADIUS > 0.75) and np.any(near & ~strip) == (
            xc - FIBRE_RADIUS < 0.75
        )


def test_model_5_is_registered():
    assert 5 in MODELS_3D and get_model(5, E_high=1e6).name == "model5"
    with pytest.raises(InputError, match="contact_size <= 1/n"):
        fibre_block_3d_mesh(4, contact_size=0.5)


@pytest.mark.parametrize("obstacle", [None, Sphere((1.5, 0.5, 0.5), 0.5).indented(0.01, (-1.0, 0.0, 0.0))])
def test_algorithm_1_is_the_monolithic_solution_at_contrast_1e6(block, obstacle):
    """Theorem 3.1 on the fibre block (E 1e6 in the fibres against 1): the load in Ω₁ against the flush wall, and
    a sphere pressed into the middle of Γ_C over the fibre in the strip (no body force)."""
    problem = fibre_block_3d(E_high=1e6).on(block)
    if obstacle is not None:
        problem = problem.with_(obstacle=obstacle, load=np.zeros(3))
    reference = fc.solve(problem, "primal-monolithic")
    result = fc.solve(problem, "primal", tol=1e-9, reference=reference.u)
    assert result.converged and result.e_u <= 1e-8
    np.testing.assert_array_equal(result.profile.active, reference.profile.active)
    assert result.profile.force == pytest.approx(reference.profile.force, rel=1e-8)
    assert 0 < np.count_nonzero(result.profile.active) < result.profile.active.size


def test_gamma_through_the_fibre_in_the_strip():
    """A strip of 1/16 puts γ at x = 15/16 through the fibre under Γ_C (a sliver of it beyond): γ is tagged and
    that fibre has cells on both sides of it (the default strip of ``--model 5 --H 16``)."""
    cm = fibre_block_3d_mesh(4, strip=1.0 / 16.0)
    assert cm.facet_tags.find(Boundary.INTERFACE).size > 0
    cells, x, _ = _cells(cm)
    fibre = in_fibres(x) & (np.hypot(x[0] - 0.88, x[2] - 0.5) < FIBRE_RADIUS)
    strip = np.isin(cells, cm.cell_tags.find(Subdomain.OMEGA2))
    assert np.any(fibre & strip) and np.any(fibre & ~strip)
