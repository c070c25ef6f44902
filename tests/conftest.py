"""Shared fixtures; a session teardown that collects garbage collectively (PETSc destructors)."""

import gc

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
import pytest
from mpi4py import MPI

pytest_plugins = ["contact_problems"]  # its fixtures (channel_strip) for every test module


@pytest.fixture(scope="session", autouse=True)
def _collective_teardown():
    yield
    gc.collect()
    MPI.COMM_WORLD.Barrier()
