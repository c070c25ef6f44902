"""Shared fixtures; a session teardown that collects garbage collectively (PETSc destructors)."""

import gc
import logging

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
import pytest
from mpi4py import MPI

pytest_plugins = ["contact_problems"]  # its fixtures (channel_strip) for every test module


@pytest.fixture(scope="session", autouse=True)
def _collective_teardown():
    yield
    gc.collect()
    MPI.COMM_WORLD.Barrier()


@pytest.fixture(autouse=True)
def _package_logger_propagates():
    """``cli.main`` points the package logger at stdout and stops its propagation (``cli._setup_logging``);
    every test starts with it propagating again, so that ``caplog`` sees the package's warnings whatever ran
    before."""
    logger = logging.getLogger("fenics_contact")
    saved = (logger.handlers[:], logger.level, logger.propagate)
    logger.handlers[:], logger.propagate = [], True
    yield
    logger.handlers[:], logger.level, logger.propagate = saved
