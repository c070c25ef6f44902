"""What pyproject.toml cannot state for the build: the package list with the example files, and a start-up hook.

* The packages are ``fenics_contact`` and its subpackages (found), plus the repository's ``cases/``,
  ``meshes/`` and ``demos/`` mapped to ``fenics_contact.example_files.{cases,meshes,demos}`` as package data
  (no copies in the repository; ``fenics-contact examples DIR`` copies them out of an installed package).
* ``install/fenics_contact_import_order.pth`` and the module it runs go into the top of site-packages, in a
  wheel and in an editable install alike: where the ``dolfinx-solver-real`` wheel is installed they import
  ``dolfinx_solver`` before the first ``dolfinx``/``petsc4py``/``slepc4py`` import of any process (the
  module's docstring says why); elsewhere they do nothing.
"""

import os

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py

EXAMPLES = "fenics_contact.example_files"
EXAMPLE_DIRS = ("cases", "meshes", "demos")
STARTUP_FILES = ("install/fenics_contact_import_order.py", "install/fenics_contact_import_order.pth")


class BuildPyWithStartupHook(build_py):
    """``build_py`` that also writes the start-up hook into the root of the installed tree."""

    def run(self) -> None:
        super().run()
        for source in STARTUP_FILES:
            self.copy_file(source, os.path.join(self._root(), os.path.basename(source)), preserve_mode=False)

    def _root(self) -> str:
        # an editable wheel takes only the package mapping from build_lib; what lands in site-packages beside it
        # is the directory its ``install`` command writes to (the unpacked editable wheel)
        return self.get_finalized_command("install").install_lib if self.editable_mode else self.build_lib

    def get_outputs(self, include_bytecode: bool = True) -> list[str]:
        outputs = super().get_outputs(include_bytecode)
        if not self.editable_mode:
            outputs += [os.path.join(self.build_lib, os.path.basename(source)) for source in STARTUP_FILES]
        return outputs


setup(
    packages=find_packages(include=["fenics_contact", "fenics_contact.*"]) + [f"{EXAMPLES}.{d}" for d in EXAMPLE_DIRS],
    package_dir={f"{EXAMPLES}.{d}": d for d in EXAMPLE_DIRS},
    package_data={f"{EXAMPLES}.{d}": ["*.toml", "*.msh", "*.md", "*.npy", "*.csv", "*.txt"] for d in EXAMPLE_DIRS},
    cmdclass={"build_py": BuildPyWithStartupHook},
)
