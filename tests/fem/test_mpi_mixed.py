"""The mixed method under ``mpiexec -n 2`` and ``-n 3`` gives the serial answer (tests/fem/mpi_mixed_check.py).

Monolithic mixed contact (models 1 and 2, a mesh with traction-free sides, the manufactured problem with
u_D, tractions and a curved gap) and Algorithm 2: the same Newton steps, active sets and iterations, and
stresses and displacements equal to 1e-10 of their size; Arnold–Winther rates unchanged on 2 ranks; the
CLI (``mpiexec -n 2 fenics-contact run --method mixed``) writes the serial summary, fields and plots.

The round-off floor of these comparisons is set by the problem, not by the partition: the serial solve
with another MUMPS ordering (METIS instead of AMF) differs from the default one by 4e-11 (σ at the DG
nodes, relative to max |σ|) and 9e-11 (σ_c, relative to max |σ_c|) on model 1 (ε = 1e-3·h, h = 1/16);
the distributed runs differ from the serial one by the same amounts.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import pyvista
from mpi4py import MPI

from mpi_jobs import mpiexec as _mpiexec

SCRIPT = Path(__file__).with_name("mpi_mixed_check.py")
pytestmark = [pytest.mark.mpi, pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="launches its own MPI job")]

MONO = ["mono-1", "mono-2", "mono-free", "mono-bc"]
HYBRID = ["hybrid-1", "hybrid-2", "hybrid-free"]
RATES = np.array([2.0, 3.0, 2.0])  # ‖u − u_h‖, ‖σ − σ_h‖, ‖div(σ − σ_h)‖
TOL = 1e-10


def _run(ranks: int, cases: list[str], tmp: Path) -> tuple[dict, dict]:
    env = dict(os.environ, OMP_NUM_THREADS="1")
    out = tmp / f"fields_{ranks}.npz"
    prefix = [] if ranks == 1 else [_mpiexec(), "-n", str(ranks)]
    proc = subprocess.run([*prefix, sys.executable, str(SCRIPT), str(out), *cases], capture_output=True, text=True,
                          env=env, timeout=900)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    line = next(row for row in proc.stdout.splitlines() if row.startswith("RESULT "))
    with np.load(out) as data:
        fields = {k: data[k] for k in data.files}
    return json.loads(line[len("RESULT "):]), fields


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    if _mpiexec() is None:
        pytest.skip("no mpiexec")
    tmp = tmp_path_factory.mktemp("mpi_mixed")
    return {
        1: _run(1, MONO + HYBRID + ["rates", "indent"], tmp),
        2: _run(2, MONO + HYBRID + ["rates", "indent"], tmp),
        3: _run(3, MONO + HYBRID, tmp),
    }


def _same_fields(serial: dict, parallel: dict, keys: list[str]) -> None:
    for key in keys:
        a, b = serial[key], parallel[key]
        assert a.shape == b.shape, key
        assert np.abs(a - b).max() <= TOL * np.abs(a).max(), (key, np.abs(a - b).max() / np.abs(a).max())


@pytest.mark.parametrize("ranks", [2, 3])
@pytest.mark.parametrize("case", MONO)
def test_monolithic_mixed_matches_serial(runs, ranks, case):
    (s, sf), (p, pf) = runs[1], runs[ranks]
    assert s["ranks"] == 1 and p["ranks"] == ranks
    a, b = s[case], p[case]
    assert b["newton_steps"] == a["newton_steps"]
    assert b["active_sizes"] == a["active_sizes"]
    assert b["step_lengths"] == pytest.approx(a["step_lengths"], abs=1e-12)
    assert b["active"] == a["active"] and b["dofs"] == a["dofs"]
    assert np.allclose(b["y"], a["y"], rtol=0, atol=1e-12)
    # σ_c relative to the stress scale (max |σ| over the DG nodes)
    scale = np.abs(sf[f"{case}-sigma"]).max()
    assert np.abs(np.array(b["sigma_c"]) - a["sigma_c"]).max() <= TOL * scale
    assert b["stress_norm2"] == pytest.approx(a["stress_norm2"], rel=TOL)
    assert b["l2_norm2"] == pytest.approx(a["l2_norm2"], rel=TOL)
    _same_fields(sf, pf, [f"{case}-sigma", f"{case}-u"])


@pytest.mark.parametrize("ranks", [2, 3])
@pytest.mark.parametrize("case", HYBRID)
def test_algorithm_2_matches_serial(runs, ranks, case):
    (s, sf), (p, pf) = runs[1], runs[ranks]
    a, b = s[case], p[case]
    assert a["converged"] and b["converged"]
    assert b["iterations"] == a["iterations"]
    assert b["newton"] == a["newton"] and b["newton_active"] == a["newton_active"]
    assert b["active"] == a["active"] and b["dofs"] == a["dofs"]
    assert np.allclose(b["rel_changes"], a["rel_changes"], rtol=1e-6, atol=1e-12)
    # ‖f‖²_γ of f = (y³, 1 + y) on γ = {3/4} × (0, 1) with the distributed γ mass matrix: ∫ y⁶ + (1 + y)² dy
    assert a["gamma_f2"] == pytest.approx(1 / 7 + 7 / 3, rel=1e-12)
    assert b["gamma_f2"] == pytest.approx(a["gamma_f2"], rel=1e-12)
    assert a["e_sigma"] < 1e-8 and b["e_sigma"] < 1e-8 and b["e_u"] < 1e-8
    scale = np.abs(sf[f"{case}-sigma"]).max()
    assert np.abs(np.array(b["sigma_c"]) - a["sigma_c"]).max() <= TOL * scale
    _same_fields(sf, pf, [f"{case}-sigma", f"{case}-u", f"{case}-ref-sigma"])


def test_mixed_indentation_steps_on_two_ranks(runs):
    """A moving obstacle (Hertz load steps, mixed monolithic): the serial Newton steps, forces and contact zone."""
    a, b = runs[1][0]["indent"], runs[2][0]["indent"]
    assert b["newton"] == a["newton"] and b["active"] == a["active"]
    assert np.allclose(b["forces"], a["forces"], rtol=1e-10, atol=0)
    assert np.allclose(b["zone"], a["zone"], rtol=0, atol=1e-12)
    # the round-off floor of this problem (a 0.1-wide contact zone on a 0.1 × 0.05 block, ε = 1e-3·h·E) is
    # higher: serial runs with the MUMPS orderings METIS / AMD instead of AMF differ in σ_c by 1.8e-9 / 3.3e-9
    # of max |σ_c|, the 2-rank run by 3.8e-9
    assert np.abs(np.array(b["sigma_c"]) - a["sigma_c"]).max() <= 2e-8 * np.abs(a["sigma_c"]).max()


def test_arnold_winther_rates_on_two_ranks(runs):
    (s, _), (p, _) = runs[1], runs[2]
    for key, serial in s["rates"].items():
        par = p["rates"][key]
        assert par["dofs"] == serial["dofs"]
        assert np.all(np.array(par["rates"])[-1] >= 0.9 * RATES), (key, par["rates"])
        assert np.allclose(par["errors"], serial["errors"], rtol=1e-8), key


def _cli_run(ranks: int, out: Path) -> subprocess.CompletedProcess:
    prefix = [] if ranks == 1 else [_mpiexec(), "-n", str(ranks)]
    accel = ["--accel", "anderson"] if ranks == 1 else []  # on 2 ranks the default is Anderson (newton: serial only)
    command = [*prefix, sys.executable, "-m", "fenics_contact.cli", "run", "--method", "mixed", "--model", "2",
               "--h", "8", "--H", "4", *accel, "--reference", "--out", str(out)]
    return subprocess.run(command, capture_output=True, text=True, env=dict(os.environ, OMP_NUM_THREADS="1"),
                          timeout=900)


def test_cli_mixed_outputs_from_two_ranks(tmp_path):
    """``mpiexec -n 2 fenics-contact run --method mixed``: the serial summary, fields and plots, one directory."""
    from matplotlib.image import imread

    if _mpiexec() is None:
        pytest.skip("no mpiexec")
    runs = {}
    for ranks in (1, 2):
        out = tmp_path / f"run{ranks}"
        proc = _cli_run(ranks, out)
        assert proc.returncode == 0, proc.stderr[-3000:]
        runs[ranks] = out, json.loads((out / "summary.json").read_text())
    (out1, s1), (out2, s2) = runs[1], runs[2]
    assert s1["mpi_ranks"] == 1 and s2["mpi_ranks"] == 2 and s2["converged"]
    assert s1["accel"] == s2["accel"] == "anderson"
    for key in ("iterations", "newton_steps_total", "reference_newton_steps", "dofs", "active_set",
                "reference_active_set"):
        assert s2[key] == s1[key], key
    for key in ("e_sigma", "e_u", "final_rel_change"):
        assert s2[key] == pytest.approx(s1[key], rel=1e-6), key
    assert s2["max_tensile_sigma_c"] == pytest.approx(s1["max_tensile_sigma_c"], rel=1e-6, abs=1e-12)
    names = {p.name for p in out2.iterdir()}
    assert {"fields.pvd", "contact.pvd", "sigma.bp", "u.bp", "stress.png", "displacement.png", "contact.png",
            "history.png", "summary.json"} <= names
    fields1, fields2 = (pyvista.read(out / "fields.pvd")[0] for out in (out1, out2))
    assert fields2.n_points == 81 and fields2.n_cells == fields1.n_cells  # both ranks' parts, 9 x 9 nodes once
    order1, order2 = (np.lexsort(f.points[:, :2].T) for f in (fields1, fields2))
    np.testing.assert_allclose(fields2.point_data["u"][order2], fields1.point_data["u"][order1], rtol=1e-6,
                               atol=1e-12 * np.abs(fields1.point_data["u"]).max())
    for png in ("stress.png", "displacement.png", "contact.png"):  # gathered fields: the serial pictures
        a, b = imread(out1 / png), imread(out2 / png)  # (the triangles come in another order: a few edge pixels
        assert a.shape == b.shape, png                 # of the shaded DG P1 plot differ by a shade, 1e-5 of them)
        assert np.mean(np.abs(a - b).max(axis=-1) > 0.02) < 1e-4, png
