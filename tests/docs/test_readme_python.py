"""The README's Python example runs as it stands (``docs/run_page_examples.py README.md``): a user's gmsh block
(two materials by group, refined under a cylinder, no Omega1/Omega2/gamma tags) read by DOLFINx and solved by all
four methods and the monolithic reference, then along a load path."""

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.slow, pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="runs the README serially")]


def test_the_readme_python_example_solves_with_every_method():
    run = subprocess.run(
        [sys.executable, str(ROOT / "docs" / "run_page_examples.py"), str(ROOT / "README.md")],
        capture_output=True,
        text=True,
        timeout=1800,
        cwd=ROOT,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    forces = next(ast.literal_eval(line) for line in run.stdout.splitlines() if line.startswith("["))
    reference, primal, multiscale, mixed, mixed_ms = forces
    assert abs(primal - reference) < 1e-6 * reference  # Algorithm 1 is the monolithic solution
    assert abs(multiscale - reference) < 1e-2 * reference
    assert abs(mixed - reference) < 0.05 * reference  # P1 against Arnold–Winther on the same mesh
    assert abs(mixed_ms - mixed) < 1e-3 * mixed
    assert np.all(np.array(forces) > 0)
