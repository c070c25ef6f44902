"""fenics-contact: iterative contact-resolving hybrid methods for heterogeneous elasticity on DOLFINx.

DOLFINx 0.11 is found here, once.  With the ``dolfinx-solver-real`` binary wheel (the ``wheel`` extra),
``dolfinx_solver`` is imported first, as that wheel requires (it loads MPI ahead of ``dolfinx``,
``petsc4py`` and ``slepc4py``), and the DOLFINx it ships is its ``DOLFINX_VERSION``; any other DOLFINx
(conda-forge, Docker, spack, a source build) is imported directly.  Without DOLFINx 0.11 the import
fails with an ImportError that says how to get it (:data:`HOW_TO_GET_DOLFINX`).

The user's API is here, loaded when first used (so ``import fenics_contact`` stays light)::

    import fenics_contact as fc
    problem = fc.models.model_1().on(fc.unit_square(64, 16))   # or fc.ContactProblem(...), from_meshtags(...)
    result = fc.solve(problem, "primal")                        # a method of fc.METHODS, with its options
"""

import importlib
import importlib.util
import re
from importlib.metadata import PackageNotFoundError, version

#: the user's API: name -> the module that defines it (imported on first use)
_API = {
    "ContactProblem": "fenics_contact.problem.problem",
    "BoundaryConditions": "fenics_contact.problem.boundary",
    "Plane": "fenics_contact.problem.obstacles",
    "Circle": "fenics_contact.problem.obstacles",
    "Sphere": "fenics_contact.problem.obstacles",
    "SignedDistance": "fenics_contact.problem.obstacles",
    "unit_square": "fenics_contact.problem.geometry",
    "read_mesh": "fenics_contact.problem.geometry",
    "unit_cube": "fenics_contact.problem.meshes3d",
    "box_mesh": "fenics_contact.problem.meshes3d",
    "TwoBodyProblem": "fenics_contact.problem.pair",
    "ContactPair": "fenics_contact.problem.pair",
    "Body": "fenics_contact.problem.pair",
    "Support": "fenics_contact.problem.pair",
    "PairTag": "fenics_contact.problem.pair_meshes",
    "two_blocks": "fenics_contact.problem.pair_meshes",
    "cylinder_on_block": "fenics_contact.problem.pair_meshes",
    "join_bodies": "fenics_contact.problem.pair_meshes",
    "METHODS": "fenics_contact.methods",
    "solve": "fenics_contact.methods",
    "force_indentation": "fenics_contact.indentation",
    "Friction": "fenics_contact.problem.friction",
    "slide": "fenics_contact.sliding",
    "IterationOptions": "fenics_contact.hybrid.iteration",
    "CEMOptions": "fenics_contact.multiscale.cem",
    "MixedCEMOptions": "fenics_contact.multiscale.mixed_cem",
}
_MODULES = {"models": "fenics_contact.problem.models", "analytic": "fenics_contact.problem.analytic"}

__all__ = ["DOLFINX_SERIES", "HOW_TO_GET_DOLFINX", "__version__", "dolfinx_version", *_API, *_MODULES]


def __getattr__(name: str):
    if name in _API:
        return getattr(importlib.import_module(_API[name]), name)
    if name in _MODULES:
        return importlib.import_module(_MODULES[name])
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: the DOLFINx release series this package is written for (its public API only)
DOLFINX_SERIES = "0.11"

#: the three ways to an environment with DOLFINx 0.11
HOW_TO_GET_DOLFINX = (
    "Get DOLFINx 0.11 one of these ways: "
    '(1) pip install "fenics-contact[wheel]" (the dolfinx-solver-real binary wheel: Linux, Python >= 3.12); '
    '(2) conda install -c conda-forge "fenics-dolfinx=0.11", then pip install fenics-contact in that environment; '
    "(3) the DOLFINx Docker image (docker run -ti dolfinx/dolfinx:v0.11.0), then pip install fenics-contact in it."
)

try:
    __version__ = version("fenics-contact")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

#: the version of the DOLFINx this package runs on
dolfinx_version: str
if importlib.util.find_spec("dolfinx_solver") is not None:
    import dolfinx_solver  # (must precede dolfinx, petsc4py, slepc4py)

    dolfinx_version = dolfinx_solver.DOLFINX_VERSION
else:
    try:
        import dolfinx
    except ImportError as error:
        raise ImportError(
            f"fenics-contact needs DOLFINx {DOLFINX_SERIES}, and 'import dolfinx' failed ({error}). "
            f"{HOW_TO_GET_DOLFINX}"
        ) from error
    dolfinx_version = dolfinx.__version__

if not re.match(rf"{re.escape(DOLFINX_SERIES)}(\.|$)", dolfinx_version):
    raise ImportError(
        f"fenics-contact needs DOLFINx {DOLFINX_SERIES}; this environment has DOLFINx {dolfinx_version}. "
        f"{HOW_TO_GET_DOLFINX}"
    )


def __dir__() -> list[str]:
    return sorted({*globals(), *_API, *_MODULES})
