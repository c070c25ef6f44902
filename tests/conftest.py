"""Shared fixtures; a session teardown that collects garbage collectively (PETSc destructors); the two tiers.

The serial tier (``pytest -m "not mpi"``, one rank) skips the MPI tests.  The MPI tier
(``mpiexec -n 2 python -m mpi4py -m pytest -m mpi tests/``) runs only the tests marked ``@pytest.mark.mpi``:
each runs on every rank (collectively) and is written for 2 ranks, or for the sizes it names
(``@pytest.mark.mpi(sizes=(2, 3))``); on any other number of ranks it is skipped.
"""

import gc
import logging
from pathlib import Path

import pytest
from mpi4py import MPI

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)

pytest_plugins = ["contact_problems", "omega1_robin"]  # their fixtures (channel_strip, mesh_32_8) for every module


def pytest_collection_modifyitems(config, items):
    size = MPI.COMM_WORLD.size
    for item in items:
        mark = item.get_closest_marker("mpi")
        if mark is None:
            if size > 1:
                item.add_marker(pytest.mark.skip(reason="a serial test (the MPI tier runs -m mpi)"))
        elif size == 1:
            item.add_marker(pytest.mark.skip(reason="an MPI test: mpiexec -n 2 python -m mpi4py -m pytest -m mpi"))
        elif size not in mark.kwargs.get("sizes", (2,)):
            item.add_marker(pytest.mark.skip(reason=f"written for {mark.kwargs.get('sizes', (2,))} ranks"))


@pytest.fixture
def shared_tmp_path(tmp_path) -> Path:
    """Rank 0's ``tmp_path`` on every rank: one directory all ranks of an MPI test read and write."""
    return Path(MPI.COMM_WORLD.bcast(str(tmp_path), root=0))


@pytest.fixture(scope="session", autouse=True)
def _collective_teardown():
    yield
    gc.collect()
    MPI.COMM_WORLD.Barrier()


@pytest.fixture(autouse=True)
def _package_logger_propagates():
    """``cli.main`` points the package logger at stdout and stops its propagation (its logging set-up);
    every test starts with it propagating again, so that ``caplog`` sees the package's warnings whatever ran
    before."""
    logger = logging.getLogger("fenics_contact")
    saved = (logger.handlers[:], logger.level, logger.propagate)
    logger.handlers[:], logger.propagate = [], True
    yield
    logger.handlers[:], logger.level, logger.propagate = saved
