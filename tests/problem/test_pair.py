"""Two-body problems (``problem.pair``, ``problem.pair_meshes``) and the two-body Hertz constants
(``problem.analytic.hertz_pair``): what is validated and refused."""

import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.analytic import hertz_pair
from fenics_contact.problem.pair import Body, ContactPair, Support, TwoBodyProblem
from fenics_contact.problem.pair_meshes import PairTag as T
from fenics_contact.problem.pair_meshes import two_blocks

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial meshes")


def test_hertz_pair():
    assert hertz_pair((1.0, 1.0), (1.0, 1.0), (0.0, 0.0)) == pytest.approx((0.5, 0.5))
    with pytest.raises(InputError, match="not both flat"):
        hertz_pair((np.inf, np.inf), (1.0, 1.0), (0.0, 0.0))


def test_bad_two_body_input_is_refused():
    m = two_blocks(2, 3)
    bodies = (Body(T.LOWER, 1.0, 0.3), Body(T.UPPER, 1.0, 0.3))
    held = (Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP))
    args = (m.mesh, m.cell_tags, m.facet_tags)
    with pytest.raises(InputError, match="on different ones"):
        TwoBodyProblem(*args, bodies=bodies, pair=ContactPair(T.LOWER_TOP, T.LOWER_BOTTOM), supports=held)
    with pytest.raises(InputError, match="no Support"):
        TwoBodyProblem(*args, bodies=bodies, pair=ContactPair(T.LOWER_TOP, T.UPPER_BOTTOM), supports=held[:1])
    with pytest.raises(MeshTagError, match="no facet has the tag 99"):
        TwoBodyProblem(*args, bodies=bodies, pair=ContactPair(99, T.UPPER_BOTTOM), supports=held)
    with pytest.raises(InputError, match="different cell tags"):
        TwoBodyProblem(*args, bodies=(bodies[0], bodies[0]), pair=ContactPair(T.LOWER_TOP, 31), supports=held)
    with pytest.raises(InputError, match="different tags"):
        ContactPair(3, 3)
    with pytest.raises(InputError, match="components"):
        Support(1, components=(5,))
    with pytest.raises(InputError, match="Poisson ratio"):
        TwoBodyProblem(
            *args,
            bodies=(Body(T.LOWER, 1.0, 0.5), bodies[1]),
            pair=ContactPair(T.LOWER_TOP, T.UPPER_BOTTOM),
            supports=held,
        )


def test_the_two_blocks_are_disjoint_and_tagged():
    m = two_blocks(3, 4, gap=0.1, offset=0.25)
    x = m.mesh.geometry.x
    tdim = m.mesh.topology.dim
    for tag, (lo, hi) in ((T.LOWER, (-0.5, 0.0)), (T.UPPER, (0.1, 0.6))):
        cells = m.cell_tags.find(tag)
        ys = x[m.mesh.geometry.dofmaps[0][cells]][:, :, 1]
        assert ys.min() == pytest.approx(lo) and ys.max() == pytest.approx(hi)
    m.mesh.topology.create_connectivity(tdim - 1, 0)
    f2v = m.mesh.topology.connectivity(tdim - 1, 0)
    for tag, y in ((T.LOWER_TOP, 0.0), (T.UPPER_BOTTOM, 0.1)):
        facets = m.facet_tags.find(tag)
        assert facets.size == (3 if tag == T.LOWER_TOP else 4)
        assert np.allclose(x[np.concatenate([f2v.links(f) for f in facets]), 1], y)


def _rectangle(n: int, y0: float, height: float, tags: dict):
    """A DOLFINx rectangle (0, 1) × (y0, y0 + height) on COMM_SELF with facet tags at y = value."""
    msh = dmesh.create_rectangle(
        MPI.COMM_SELF, [[0.0, y0], [1.0, y0 + height]], [n, max(2, int(n * height))], dmesh.CellType.triangle
    )
    msh.topology.create_connectivity(1, 2)
    entities, values = [], []
    for tag, y in tags.items():
        facets = dmesh.locate_entities_boundary(msh, 1, lambda x, y=y: np.isclose(x[1], y))
        entities.append(facets)
        values.append(np.full(facets.size, tag, dtype=np.int32))
    entities, values = np.concatenate(entities), np.concatenate(values)
    order = np.argsort(entities)
    return msh, dmesh.meshtags(msh, 1, entities[order], values[order])


def test_two_meshes_joined_into_one_keep_their_tags_and_pass_the_patch_test():
    lower = _rectangle(7, -0.5, 0.5, {11: -0.5, 12: 0.0})
    upper = _rectangle(10, 0.0, 0.4, {21: 0.0, 22: 0.4})
    joined = fc.join_bodies(lower, upper)
    cells = [lower[0].topology.index_map(2).size_local, upper[0].topology.index_map(2).size_local]
    assert [joined.cell_tags.find(t).size for t in (T.LOWER, T.UPPER)] == cells
    assert [joined.facet_tags.find(t).size for t in (11, 12, 21, 22)] == [7, 7, 10, 10]
    problem = TwoBodyProblem(
        joined.mesh,
        joined.cell_tags,
        joined.facet_tags,
        bodies=(Body(T.LOWER, 1.0, 0.0), Body(T.UPPER, 5.0, 0.0)),
        pair=ContactPair(21, 12),
        supports=(Support(11), Support(22, (0.0, -0.01))),
    )
    result = fc.solve(problem, "primal-monolithic")
    p = 0.01 / (0.5 / 1.0 + 0.4 / 5.0 + result.delta)
    assert max(np.max(np.abs(prof.sigma_c + p)) for prof in (result.slave, result.master)) < 1e-9 * p
    with pytest.raises(InputError, match="appear in both meshes"):
        fc.join_bodies(lower, _rectangle(4, 0.0, 0.4, {12: 0.0}))


def test_each_body_law_is_evaluated_on_its_own_cells_only():
    """A modulus defined on the lower block only (NaN elsewhere) and a body force on it alone are accepted:
    each body's fields are read at its own cells' midpoints."""
    m = two_blocks(4, 5, heights=(0.5, 0.4))
    problem = TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(
            Body(T.LOWER, lambda x: np.where(x[1] < 0.0, 3.0, np.nan), 0.2, load=(0.0, -1.0)),
            Body(T.UPPER, 5.0, 0.3),
        ),
        pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP),
        supports=(Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP)),
    )
    lower, upper = m.cell_tags.find(T.LOWER), m.cell_tags.find(T.UPPER)
    E, nu, f = (fn.x.array for fn in (problem.fields.E, problem.fields.nu, problem.fields.f))
    assert np.all(E[lower] == 3.0) and np.all(E[upper] == 5.0)
    assert np.all(nu[lower] == 0.2) and np.all(nu[upper] == 0.3)
    assert np.all(f.reshape(-1, 2)[lower] == (0.0, -1.0)) and np.all(f.reshape(-1, 2)[upper] == 0.0)
    assert problem.contact_moduli() == (5.0, 3.0)
