"""Two-body problems shared by the tests of the pair, and the comparison of a parallel pair run with the serial one.

``tilted_pair``: two blocks, the upper one tilted onto the lower one.  The upper block's top is pushed down on the
left and lifted on the right (across a gap in the plane), so only part of the contact surface touches and the
active set changes while the Newton iterates: the case on which a parallel contact search and a parallel solve can
differ from the serial ones.  ``strata_pair``: the layered fault-like pair; ``strata_steps`` it along the load paths
``STRATA_PATHS`` of the serial-against-parallel tests (``assert_serial_pair``).  ``hertz_cylinder_pair``: the
two-body Hertz pair, an elastic cylinder pressed onto a block.
"""

import numpy as np
import pytest
from mpi4py import MPI

from fenics_contact.problem.friction import Friction
from fenics_contact.problem.pair import Body, ContactPair, Support, TwoBodyProblem
from fenics_contact.problem.pair_meshes import PairTag as T
from fenics_contact.problem.pair_meshes import cylinder_on_block, fault_strata, two_blocks

__all__ = [
    "STRATA_PATHS",
    "assert_serial_pair",
    "hertz_cylinder_pair",
    "pressed_pair",
    "strata_pair",
    "strata_steps",
    "tilted_pair",
]

#: (law, tops of the upper block) of the serial-against-parallel tests: one step frictionless, and a Coulomb
#: press-then-shear path past sliding; parametrize ``("law", "path")`` with these ``argvalues`` and ``ids``
STRATA_PATHS = {
    "argvalues": [
        (None, ((0.002, -0.005),)),
        (Friction("coulomb", mu=0.3), ((0.0, -0.005), (0.002, -0.005), (0.02, -0.005))),
    ],
    "ids": ["frictionless", "coulomb"],
}


def pressed_pair(
    m, lower: Body, upper: Body, top, *, upper_slave: bool = True, friction=None, basis: str | None = None
) -> TwoBodyProblem:
    """The upper body of the pair mesh ``m`` pressed onto the lower one: the lower clamped at its bottom, the
    upper's top moved by ``top`` (a vector or a callable of x); the slave surface the upper's (``upper_slave``) or
    the lower's; ``basis`` of the pressure (``ContactPair.basis``, None: its default)."""
    pair = (T.UPPER_BOTTOM, T.LOWER_TOP) if upper_slave else (T.LOWER_TOP, T.UPPER_BOTTOM)
    return TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(lower, upper),
        pair=ContactPair(*pair, friction=friction, basis=basis),
        supports=(Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP, top)),
    )


def hertz_cylinder_pair(slave: str, refinement: float, basis: str | None = None) -> TwoBodyProblem:
    """A cylinder (R = 5, E = 2, ν = 0.25) pressed by 1.1e-3 onto a block (E = 1, ν = 0.3), contact cells
    a/(20·``refinement``) with a = 0.05, on one process; ``slave``: "cylinder" or "block", the slave surface;
    ``basis`` of the pressure (``ContactPair.basis``, None: its default)."""
    m = cylinder_on_block(5.0, 0.05, refinement=refinement, comm=MPI.COMM_SELF)
    lower, upper = Body(T.LOWER, 1.0, 0.3), Body(T.UPPER, 2.0, 0.25)
    return pressed_pair(m, lower, upper, (0.0, -1.1e-3), upper_slave=slave == "cylinder", basis=basis)


def tilted_pair(comm: MPI.Comm, cells: tuple[int, int], dim: int = 2) -> TwoBodyProblem:
    """Blocks of ``cells`` = (lower, upper) cells per side, E = 1 and 5; the top moved by (push − tilt·x) downwards."""
    if dim == 2:
        m = two_blocks(*cells, heights=(0.5, 0.4), gap=0.004, comm=comm)
        top = lambda x: np.vstack([0.0 * x[0], 0.01 - 0.03 * x[0]])  # noqa: E731
    else:
        m = two_blocks(*cells, heights=(0.5, 0.4), dim=3, comm=comm)
        top = lambda x: np.vstack([0.0 * x[0], 0.0 * x[0], 0.005 - 0.02 * x[0]])  # noqa: E731
    return TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(Body(T.LOWER, 1.0, 0.3), Body(T.UPPER, 5.0, 0.2)),
        pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP),
        supports=(Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP, top)),
    )


def strata_pair(m, friction=None, top=(0.0, -0.005), tractions=None, contrast: float = 1e3) -> TwoBodyProblem:
    """The fault-like pair on the two-block mesh ``m``: the strata of ``pair_meshes.fault_strata(contrast)`` (ν = 0.3
    below, 0.2 above), the lower block's bottom held, the upper block's top moved by ``top`` (a vector or a
    callable), the contact law ``friction`` (None: frictionless)."""
    lower, upper = fault_strata(contrast)
    return TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(Body(T.LOWER, lower, 0.3), Body(T.UPPER, upper, 0.2)),
        pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP, friction=friction),
        supports=(Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP, top)),
        tractions=tractions or {},
    )


def strata_steps(comm: MPI.Comm, law, path, contrast: float = 1e3):
    """The ``strata_pair`` of contrast ``contrast`` with the contact law ``law`` at each top of ``path``, on one
    two-block mesh of ``comm`` (10 and 14 cells along the contact, the upper block overhanging by 0.2)."""
    m = two_blocks(10, 14, heights=(0.5, 0.4), offset=0.2, comm=comm)
    for top in path:
        yield strata_pair(m, law, top, contrast=contrast)


def assert_serial_pair(parallel, serial, law) -> None:
    """A parallel pair result is the serial one: converged in at most 8 interface Newton steps, the forces and both
    contact profiles to 1e-10, the force balance to 1e-12 and, with friction, the same slip and stick nodes and the
    dissipation to 1e-8; its status is the serial one's, with its round-off floor estimated (> 0)."""
    assert parallel.converged and parallel.interface_newton_steps <= 8
    assert parallel.status == serial.status and parallel.floor > 0.0, (parallel.status, serial.status, parallel.floor)
    for fp, fs in zip(parallel.forces, serial.forces, strict=True):
        assert np.linalg.norm(fp - fs) <= 1e-10 * np.linalg.norm(fs)
    assert parallel.force_balance() < 1e-12
    for a, b in ((parallel.slave, serial.slave), (parallel.master, serial.master)):
        assert np.array_equal(a.points, b.points)
        assert np.max(np.abs(a.sigma_c - b.sigma_c)) <= 1e-10 * np.max(np.abs(b.sigma_c))
    if law is not None:
        assert np.array_equal(parallel.friction.slip, serial.friction.slip)
        assert np.array_equal(parallel.friction.stick, serial.friction.stick)
        assert parallel.dissipation == pytest.approx(serial.dissipation, rel=1e-8, abs=1e-15)
