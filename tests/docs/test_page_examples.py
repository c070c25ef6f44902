"""The user guide's examples are runnable code: every Python block of the problem page runs, in order, in one
namespace (``docs/run_page_examples.py``), so the page cannot drift from the package."""

import subprocess
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="runs the page serially")


def test_the_problem_page_examples_run():
    run = subprocess.run(
        [sys.executable, str(ROOT / "docs" / "run_page_examples.py"), str(ROOT / "docs" / "user_guide" / "problem.md")],
        capture_output=True,
        text=True,
        timeout=900,
        cwd=ROOT,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    assert "# block 1" in run.stdout and "cells in Ω₂" in run.stdout
