"""fenics-contact: iterative contact-resolving hybrid methods for heterogeneous elasticity on DOLFINx.

Import this package before DOLFINx-dependent code; it imports ``dolfinx_solver``
first, as the binary wheel requires.
"""

import dolfinx_solver  # noqa: F401  (must precede dolfinx, petsc4py, slepc4py)

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("fenics-contact")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
