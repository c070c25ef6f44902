"""Two-body problems (``problem.pair``, ``problem.pair_meshes``) and the two-body Hertz constants
(``problem.analytic.hertz_pair``): what is validated and refused."""

import numpy as np
import pytest
from mpi4py import MPI

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
