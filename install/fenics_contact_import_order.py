"""Import ``dolfinx_solver`` before the first ``dolfinx``, ``petsc4py`` or ``slepc4py`` of a process.

fenics-contact installs this module with ``fenics_contact_import_order.pth`` at the top of site-packages;
Python's :mod:`site` runs the ``.pth`` line (``install()``) at start-up.

Why: the ``dolfinx-solver-real`` binary wheel (the ``wheel`` extra) builds DOLFINx, PETSc and SLEPc
against ``libmpi.so.12`` of the PyPI ``mpich`` wheel, which lives in ``<prefix>/lib``.  That directory is
neither in the RPATH of the compiled modules (``$ORIGIN/../dolfinx_solver/lib`` and the wheel's own
library folders) nor on the dynamic loader's search path, so a bare ``import dolfinx`` fails with
"libmpi.so.12: cannot open shared object file".  Importing ``dolfinx_solver`` first loads ``mpi4py.MPI``,
whose MPI-ABI loader opens ``<prefix>/lib/libmpi.so.12`` by its path; every module loaded afterwards finds
that library already loaded under its soname (and the wheel refuses a foreign petsc4py at that point).

How: a finder at the front of ``sys.meta_path`` that answers no import itself.  At the first import of one
of the three names it removes itself and, when ``dolfinx_solver`` is installed, imports it; then the
import proceeds as usual.  Where ``dolfinx_solver`` is not installed (DOLFINx from conda-forge, Docker,
spack or a source build) nothing else happens.
"""

import importlib
import importlib.util
import sys

__all__ = ["ORDERED", "DolfinxSolverFirst", "install"]

#: the top-level modules that need ``dolfinx_solver`` imported before them
ORDERED = frozenset({"dolfinx", "petsc4py", "slepc4py"})


class DolfinxSolverFirst:
    """Meta-path finder that imports ``dolfinx_solver`` ahead of the first of :data:`ORDERED`."""

    @classmethod
    def find_spec(cls, fullname, path=None, target=None):
        if fullname in ORDERED:
            sys.meta_path[:] = [finder for finder in sys.meta_path if finder is not cls]
            if "dolfinx_solver" not in sys.modules and importlib.util.find_spec("dolfinx_solver") is not None:
                importlib.import_module("dolfinx_solver")  # its ImportError (a foreign petsc4py) is the answer
        return None  # the import itself is left to the other finders


def install() -> None:
    """Put :class:`DolfinxSolverFirst` at the front of ``sys.meta_path`` (once)."""
    if DolfinxSolverFirst not in sys.meta_path:
        sys.meta_path.insert(0, DolfinxSolverFirst)
