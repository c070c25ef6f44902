"""The coarse check before a multiscale run (``cli.coarse``) by the kind of coarse cells the mesh records.

* squares of side H (``ContactMesh.coarse_grid``): the cells that cross the grid's edges are refused;
* any other partition, in the plane as in 3D: the same cells pass when they are larger than the fine cells they hold
  (the unit square's squares of side 1/4 over cells of 1/8: |K|^(1/2) / (2|T|)^(1/2) = 2), and a partition of one
  triangle per coarse cell (ratio 1/√2), Ω₁ as one coarse cell, and Ω₁ cells in no coarse cell are refused;
* the Hertz block records its graded boxes as a partition, and its cubes of side coarse-size·a as squares.
"""

from types import SimpleNamespace

import numpy as np
import pytest
from mpi4py import MPI

from fenics_contact.cli.coarse import check_coarse_grid
from fenics_contact.errors import InputError
from fenics_contact.problem.case_meshes3d import HertzQuarterBlockMesh
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.tags import Subdomain

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the CLI tests run serially")

OPTIONS = SimpleNamespace(method="primal-ms", mesh="square.msh", H=4, model=1)


@pytest.fixture(scope="module")
def square():
    return unit_square(8, 4, comm=MPI.COMM_SELF)


def test_squares_that_the_mesh_resolves_pass_and_cells_across_their_edges_are_refused(square):
    assert square.coarse_grid
    check_coarse_grid(square, OPTIONS)
    crossing = np.array(square.coarse_cell)
    crossing[square.cell_tags.find(Subdomain.OMEGA1)[:3]] = -1
    with pytest.raises(InputError, match="3 Omega1 cells cross the edges of the coarse grid of squares"):
        check_coarse_grid(square._replace(coarse_cell=crossing), OPTIONS)


def test_a_partition_is_checked_by_the_size_of_its_cells_against_the_fine_ones(square):
    check_coarse_grid(square._replace(coarse_grid=False), OPTIONS)  # ratio 2
    one_each = np.arange(square.coarse_cell.size, dtype=np.int32)
    with pytest.raises(InputError, match=r"\|K\|\^\(1/2\) over their cells' \(2\|T\|\)\^\(1/2\) is 0.707"):
        check_coarse_grid(square._replace(coarse_cell=one_each, coarse_grid=False), OPTIONS)
    whole = np.where(square.coarse_cell >= 0, 0, -1).astype(np.int32)
    with pytest.raises(InputError, match="Omega1 is one coarse cell of the mesh's partition"):
        check_coarse_grid(square._replace(coarse_cell=whole, coarse_grid=False), OPTIONS)
    outside = np.array(square.coarse_cell)
    outside[square.cell_tags.find(Subdomain.OMEGA1)[:2]] = -1
    with pytest.raises(InputError, match="2 Omega1 cells lie in no coarse cell of the mesh's partition"):
        check_coarse_grid(square._replace(coarse_cell=outside, coarse_grid=False), OPTIONS)


def test_the_hertz_block_records_its_graded_boxes_as_a_partition():
    graded = HertzQuarterBlockMesh(a=0.1, refinement=0.1).build(MPI.COMM_SELF).cm
    cubes = HertzQuarterBlockMesh(a=0.1, refinement=0.1, coarse_size=5.0).build(MPI.COMM_SELF).cm
    assert not graded.coarse_grid and cubes.coarse_grid and cubes.H == pytest.approx(0.5)
