"""Every demo opens as a notebook (jupytext) and runs to the end at a small size."""

import os
import subprocess
import sys
from pathlib import Path

import jupytext
import pytest
from mpi4py import MPI

DEMOS = sorted((Path(__file__).parents[2] / "demos").glob("demo_*.py"))
pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="demos run serially")


def test_there_are_demos():
    assert DEMOS, "no demos found"


@pytest.mark.parametrize("demo", DEMOS, ids=lambda p: p.stem)
def test_demo_is_a_notebook(demo):
    nb = jupytext.read(demo)
    kinds = {cell.cell_type for cell in nb.cells}
    assert kinds == {"markdown", "code"} and len(nb.cells) >= 4


@pytest.mark.parametrize("demo", DEMOS, ids=lambda p: p.stem)
@pytest.mark.slow
def test_demo_runs(demo, tmp_path):
    env = dict(os.environ, FENICS_CONTACT_DEMO_N="16", FENICS_CONTACT_DEMO_OUT=str(tmp_path), MPLBACKEND="Agg")
    proc = subprocess.run(
        [sys.executable, str(demo)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    assert any(tmp_path.glob("*.png")), "a demo writes its figures"
    if demo.stem == "demo_showcase":  # the fields for ParaView and the table of all methods
        assert (tmp_path / "fields.xdmf").is_file() and (tmp_path / "sigma_alg4.bp").is_dir()
        table = (tmp_path / "showcase.md").read_text()
        assert all(f"Algorithm {k}" in table for k in (1, 2, 3, 4)) and "monolithic" in table
