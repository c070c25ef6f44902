"""The Python API on misuse: a tag that is not an integer, tags of another mesh, a reference solution of another
mesh, a load that is zero everywhere: each an InputError naming it, never a raw TypeError or IndexError."""

import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.errors import InputError


def _square_tags(n: int):
    """The unit square of n x n cells with its left side tagged 1 and its right side 2."""
    msh = dmesh.create_unit_square(MPI.COMM_WORLD, n, n)
    sides = [dmesh.locate_entities_boundary(msh, 1, lambda x, s=s: np.isclose(x[0], s)) for s in (0.0, 1.0)]
    entities = np.concatenate(sides)
    values = np.concatenate([np.full(side.size, tag, dtype=np.int32) for tag, side in zip((1, 2), sides)])
    order = np.argsort(entities)
    return msh, dmesh.meshtags(msh, 1, entities[order].astype(np.int32), values[order])


KW = dict(youngs_modulus=1.0, poisson_ratio=0.3, load=(-1.0, 0.0))


def test_a_tag_that_is_not_an_integer():
    msh, tags = _square_tags(16)
    with pytest.raises(InputError, match="contact must be a tag"):
        fc.ContactProblem.from_meshtags(msh, tags, contact=2.0, clamped=1, **KW)


def test_facet_tags_of_another_mesh():
    msh, tags = _square_tags(16)
    other = dmesh.create_unit_square(MPI.COMM_WORLD, 4, 4)
    with pytest.raises(InputError, match="the tags belong to another mesh"):
        fc.ContactProblem.from_meshtags(other, tags, contact=2, clamped=1, **KW)


@pytest.mark.parametrize("method, options", [("mixed", {}), ("mixed-ms", {"layers": 1})])
def test_a_mixed_reference_of_another_mesh(method, options):
    model = fc.models.model_1()
    reference = fc.METHODS["mixed-monolithic"].solve(model.on(fc.unit_square(4, 2)))
    with pytest.raises(InputError, match="the reference solution lives on another mesh"):
        fc.solve(model.on(fc.unit_square(8, 2)), method, reference=reference, **options)


def test_a_load_zero_everywhere_is_named_as_such():
    """A body force that vanishes everywhere is the load's fault; one that misses every cell midpoint the mesh's."""
    cm = fc.unit_square(4, 2)
    zero = fc.ContactProblem(youngs_modulus=1.0, poisson_ratio=0.3, load=(0.0, 0.0), mesh=cm)
    with pytest.raises(InputError, match="nothing loads the body"):
        zero.check_loaded()
    band = zero.with_(load=lambda x: np.vstack([(x[0] > 0.99).astype(float), 0.0 * x[0]]))
    with pytest.raises(InputError, match="too coarse to resolve the load bands"):
        band.check_loaded()
