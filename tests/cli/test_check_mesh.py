"""``fenics-contact check-mesh``: a mesh or case file read and checked as ``run`` reads it, without a solve."""

import re
from pathlib import Path

import pytest
from mpi4py import MPI
from outcome import outcome_lines

from fenics_contact.cli import main
from fenics_contact.problem.case import load_case

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="reads stdout and stderr of rank 0")

REPO = Path(__file__).resolve().parents[2]
PAD_MESH = REPO / "cases" / "pad.msh"
PAD_CASE = REPO / "cases" / "pad.toml"
BAR_CASE = REPO / "cases" / "bar.toml"
HERTZ_CASE = REPO / "cases" / "hertz.toml"
UNIT_SQUARE = REPO / "meshes" / "unit_square_n16_H4.msh"


@pytest.fixture(autouse=True)
def _in_tmp_path(tmp_path, monkeypatch):
    """The default --out of a run is results/… below the working directory: keep it in the test's directory."""
    monkeypatch.chdir(tmp_path)


def _command(capsys, *args: str) -> tuple[int, str, list[str]]:
    """Exit code, stdout and the outcome lines on stderr of ``fenics-contact ARGS``."""
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, outcome_lines(err)


def _number(pattern: str, text: str) -> float:
    match = re.search(pattern, text)
    assert match, (pattern, text)
    return float(match[1])


def _group_line(out: str, name: str) -> str:
    return next(line for line in out.splitlines() if line.split()[:1] == [name])


def test_a_case_with_its_own_mesh_file_and_material_groups(capsys):
    code, out, err = _command(capsys, "check-mesh", "--case", str(PAD_CASE))
    assert code == 0 and err == [], err
    case = load_case(PAD_CASE)
    for group in case.material.groups():  # rubber, steel
        assert "a material group of the case" in _group_line(out, group)
    assert "contact boundary" in _group_line(out, "Gamma_C") and "Dirichlet" in _group_line(out, "Gamma_D")
    assert "Omega1, Omega2, gamma: built automatically along Gamma_C" in out
    # the built Omega1 and Omega2 cover the file's triangles, each once
    triangles = sum(_number(rf"{group}\s+surface\s+(\d+) triangles", out) for group in case.material.groups())
    assert _number(r"dimension 2, (\d+) triangles", out) == triangles
    assert _number(r"Omega1 (\d+) cells", out) + _number(r"Omega2 (\d+) cells", out) == triangles
    assert _number(r"Gamma_C (\d+) facets", out) == _number(r"Gamma_C\s+curve\s+(\d+) segments", out)
    assert _number(r", H = ([\d.]+)", out) == case.mesh.coarse  # the case's mesh.coarse-size
    assert _number(r"contact cell size ([\d.e+-]+)", out) < case.mesh.coarse / 10  # refined under the indenter
    assert "gamma: bends at" in out  # the strip built along the middle of the top face
    assert "primal can run" in out and "primal-ms can run" in out and "mixed can run" in out
    assert "ok: a run with --method primal can start" in out


def test_a_method_that_refuses_the_mesh_is_refused_as_run_refuses_it(capsys, tmp_path):
    """The Hertz block's graded mesh has no coarse grid: the multiscale methods refuse it."""
    code, out, err = _command(capsys, "check-mesh", "--case", str(HERTZ_CASE), "--method", "primal-ms")
    assert code == 2 and len(err) == 1
    assert "no coarse grid" in err[0] and "ok:" not in out
    assert "primal can run" in out and "primal-ms refused" in out and "mixed-ms refused" in out
    run = _command(
        capsys, "run", "--case", str(HERTZ_CASE), "--method", "primal-ms", "--no-plots", "--out", str(tmp_path / "run")
    )
    assert run[0] == 2 and run[2] == err
    assert not (tmp_path / "run").exists()


def test_the_mesh_file_alone_is_read_as_run_mesh_reads_it(capsys, tmp_path):
    """``check-mesh FILE`` takes the strip width from --H as ``run --mesh FILE`` does: 1/16 is too thin for the
    pad (in mm), which ``run`` refuses with the same message."""
    code, out, err = _command(capsys, "check-mesh", str(PAD_MESH))
    assert code == 2 and len(err) == 1 and "Gamma_C" in err[0]
    assert "cells (no role)" in _group_line(out, "rubber")  # not a case: the groups carry no materials
    run = _command(capsys, "run", "--mesh", str(PAD_MESH), "--no-plots", "--out", str(tmp_path / "run"))
    assert run[0] == 2 and run[2] == err


def test_a_built_in_case(capsys):
    code, out, err = _command(capsys, "check-mesh", "--case", str(BAR_CASE))
    assert code == 0 and err == [], err
    mesh = load_case(BAR_CASE).mesh  # the unit square, 1/h and 1/H
    assert "physical groups of the file" not in out and "tagged by the built-in mesh" in out
    assert _number(r"dimension 2, (\d+) triangles", out) == 2 * mesh.h**2
    assert _number(r"(\d+) vertices", out) == (mesh.h + 1) ** 2
    assert _number(r"Omega2 (\d+) cells", out) == 2 * mesh.h**2 / mesh.H
    assert _number(r"Gamma_C (\d+) facets", out) == _number(r"gamma (\d+) facets", out) == mesh.h
    assert _number(r"h = ([\d.]+)", out) == pytest.approx(1 / mesh.h)
    assert _number(r", H = ([\d.]+)", out) == pytest.approx(1 / mesh.H)
    assert "gamma: straight" in out
    assert "methods: primal can run; mixed can run; primal-ms can run; mixed-ms can run" in out


def test_the_stored_mesh_with_its_own_strip(capsys):
    code, out, err = _command(capsys, "check-mesh", str(UNIT_SQUARE), "--H", "4", "--method", "mixed-ms")
    assert code == 0 and err == [], err
    assert "Omega1, Omega2, gamma: given in the file" in out
    for name, role in [("Omega1", "Ω₁"), ("Omega2", "Ω₂"), ("gamma", "γ")]:
        assert role in _group_line(out, name)
    assert _number(r"h = ([\d.]+)", out) == pytest.approx(1 / 16)  # the file's 16 x 16 grid
    assert "gamma: straight" in out and "ok: a run with --method mixed-ms can start" in out


def test_a_mesh_without_gamma_c_is_refused_with_its_hint(capsys, tmp_path):
    broken = tmp_path / "no_contact.msh"
    text = UNIT_SQUARE.read_text()
    assert text.count('"Gamma_C"') == 1
    broken.write_text(text.replace('"Gamma_C"', '"Gamma_X"'))
    code, out, err = _command(capsys, "check-mesh", str(broken))
    assert code == 2 and len(err) == 1
    assert "lacks the physical group(s) ['Gamma_C']" in err[0] and "Required names" in err[0]
    assert "no role" in _group_line(out, "Gamma_X")
    run = _command(capsys, "run", "--mesh", str(broken), "--no-plots", "--out", str(tmp_path / "run"))
    assert run[0] == 2 and run[2] == err


@pytest.mark.parametrize(
    "args", [[], [str(UNIT_SQUARE), "--case", str(BAR_CASE)], [str(UNIT_SQUARE), "--set", "mesh.h=8"]]
)
def test_one_mesh_or_case_is_asked_for(capsys, args):
    code, out, err = _command(capsys, "check-mesh", *args)
    assert code == 2 and len(err) == 1 and err[0].startswith("error: ")
