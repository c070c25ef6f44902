"""The package as a user installs it: a wheel built from this tree, installed into fresh virtual environments.

* beside an existing DOLFINx (the ``dolfinx-solver-real`` wheel installed first), ``pip install`` of the
  wheel keeps that DOLFINx, brings no second PETSc, and the console script runs; a bare ``import dolfinx``
  works there (the start-up hook imports ``dolfinx_solver`` first);
* without DOLFINx, ``import fenics_contact`` fails with the message that says how to get it, and DOLFINx is
  a dependency of the ``wheel`` extra only;
* ``fenics-contact examples DIR`` copies the cases, meshes and demos, and a copied case runs.

These tests need the package registry (PyPI) for the dependencies; pip's cache keeps reruns short.
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

import fenics_contact
from fenics_contact.examples import EXAMPLE_DIRS

ROOT = Path(__file__).parents[2]
pytestmark = [pytest.mark.slow, pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="installs run serially")]

#: what a copy of the source tree leaves out: environments, build and run outputs
_NOT_SOURCE = shutil.ignore_patterns(
    ".git", ".venv", "build", "dist", "results", "_build", "*.egg-info", "__pycache__", ".pytest_cache", ".cache"
)


def _run(*command, cwd=None, timeout=900, check=True):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    env["OMP_NUM_THREADS"] = "1"
    proc = subprocess.run([str(c) for c in command], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    if check:
        assert proc.returncode == 0, f"{command}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc


def _venv(path: Path) -> Path:
    _run(sys.executable, "-m", "venv", path)
    return path / "bin"


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """A wheel of this tree, built from a clean copy of it (no stale build/ of the working tree)."""
    base = tmp_path_factory.mktemp("wheel")
    source = base / "source"
    shutil.copytree(ROOT, source, ignore=_NOT_SOURCE)
    _run(sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", source, "-w", base / "dist")
    (built,) = (base / "dist").glob("fenics_contact-*.whl")
    return built


@pytest.fixture(scope="module")
def beside_dolfinx(wheel, tmp_path_factory) -> Path:
    """A venv that had DOLFINx (the binary wheel) before fenics-contact was installed into it."""
    bin_dir = _venv(tmp_path_factory.mktemp("venv") / "with-dolfinx")
    _run(bin_dir / "python", "-m", "pip", "install", "--quiet", "dolfinx-solver-real==0.11.*")
    _run(bin_dir / "python", "-m", "pip", "install", "--quiet", wheel)
    return bin_dir


def test_install_beside_an_existing_dolfinx(beside_dolfinx):
    version = _run(beside_dolfinx / "fenics-contact", "--version").stdout.strip()
    assert version == f"fenics-contact {fenics_contact.__version__}"
    installed = {
        d["name"].lower()
        for d in json.loads(_run(beside_dolfinx / "python", "-m", "pip", "list", "--format", "json").stdout)
    }
    assert "dolfinx-solver-real" in installed and "fenics-contact" in installed
    assert not installed & {"petsc", "petsc4py", "slepc", "slepc4py"}, "no second PETSc beside the wheel's"
    # the start-up hook: DOLFINx, PETSc and SLEPc import on their own, in a fresh process each
    for code in (
        "import dolfinx; print(dolfinx.__version__)",
        "from petsc4py import PETSc; print(PETSc.ScalarType)",
        "import slepc4py.SLEPc",
    ):
        _run(beside_dolfinx / "python", "-c", code)
    found = _run(beside_dolfinx / "python", "-c", "import fenics_contact; print(fenics_contact.dolfinx_version)")
    assert found.stdout.strip().startswith(fenics_contact.DOLFINX_SERIES + ".")


def test_without_dolfinx_the_import_says_how_to_get_it(wheel, tmp_path):
    bin_dir = _venv(tmp_path / "bare")
    _run(bin_dir / "python", "-m", "pip", "install", "--quiet", "--no-deps", wheel)
    _run(bin_dir / "python", "-c", "import json, sys; assert 'fenics_contact' not in sys.modules")  # hook is inert
    proc = _run(bin_dir / "python", "-c", "import fenics_contact", check=False)
    assert proc.returncode == 1
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith("ImportError: fenics-contact needs DOLFINx 0.11, and 'import dolfinx' failed"), last
    for way in (
        'pip install "fenics-contact[wheel]"',
        'conda install -c conda-forge "fenics-dolfinx=0.11"',
        "docker run -ti dolfinx/dolfinx:v0.11.0",
    ):
        assert way in last


def test_dolfinx_is_a_dependency_of_the_wheel_extra_only(wheel, tmp_path):
    bin_dir = _venv(tmp_path / "resolve")

    def resolved(requirement: str) -> set[str]:
        report = tmp_path / "report.json"
        _run(
            bin_dir / "python",
            "-m",
            "pip",
            "install",
            "--quiet",
            "--dry-run",
            "--ignore-installed",
            "--report",
            report,
            requirement,
        )
        return {item["metadata"]["name"].lower() for item in json.loads(report.read_text())["install"]}

    plain = resolved(str(wheel))
    assert "fenics-contact" in plain and not {n for n in plain if n.startswith(("dolfinx", "fenics-dolfinx"))}
    assert not plain & {"petsc", "petsc4py", "slepc", "slepc4py", "mpich"}
    assert "dolfinx-solver-real" in resolved(f"{wheel}[wheel]")


def test_examples_are_copied_and_a_copied_case_runs(beside_dolfinx, tmp_path):
    target = tmp_path / "examples"
    out = _run(beside_dolfinx / "fenics-contact", "examples", target).stdout
    assert f"into {target}" in out
    for name in EXAMPLE_DIRS:  # the same files as the repository's folders, byte for byte
        shipped = sorted(
            p.relative_to(ROOT / name) for p in (ROOT / name).rglob("*") if p.is_file() and "__pycache__" not in p.parts
        )
        copied = sorted(p.relative_to(target / name) for p in (target / name).rglob("*") if p.is_file())
        assert copied == shipped, name
        assert all((target / name / p).read_bytes() == (ROOT / name / p).read_bytes() for p in shipped)
    # a case whose mesh is a file next to it, run from another folder
    result = tmp_path / "composite"
    _run(
        beside_dolfinx / "fenics-contact",
        "run",
        "--case",
        target / "cases" / "composite.toml",
        "--no-plots",
        "--out",
        result,
        cwd=tmp_path,
    )
    summary = json.loads((result / "summary.json").read_text())
    assert summary["converged"] is True
    # a folder that is not empty is refused, and left as it is
    again = _run(beside_dolfinx / "fenics-contact", "examples", target, check=False)
    assert again.returncode == 2
    assert again.stderr.strip().splitlines() == [
        f"error: {target} is a non-empty folder: give a new or empty folder (nothing of yours is overwritten)"
    ]


def test_dolfinx_imports_on_its_own_in_this_environment():
    """The development environment too (an editable install): a bare ``import dolfinx`` in a fresh process."""
    for code in ("import dolfinx", "from petsc4py import PETSc", "import dolfinx; import fenics_contact"):
        _run(sys.executable, "-c", code)
