"""Algorithm 3 on a two-body case file (``fenics-contact run --case cases/two_blocks.toml --method primal-ms``).

* the run's forces, load step by load step, are the API's ``fc.solve(pair, "primal-ms", H=..., cem=...)``;
* with patches covering each bulk and every local mode the multiscale space is the fine one: Algorithm 1's forces;
* the summary and the outputs carry both bodies, both faces and the coarse space's options;
* a traction on a bulk's side enters its multiscale load: with every mode Algorithm 1's forces;
* with ``[friction]`` (``cases/fault_sliding.toml``) each step starts from the last one's state: with patches
  covering each bulk and every local mode Algorithm 1's frictional path, the last step sliding (Q = μN);
* what it cannot run is refused, nothing written (no coarse size or two of them, an H that does not divide the
  bodies, bad [multiscale] keys).
"""

import json
from pathlib import Path

import numpy as np
import pytest
import pyvista
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.cli import main
from fenics_contact.problem.case import load_case

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial (the MPI runs: test_pair_multiscale_mpi.py)")

CASE = Path(__file__).parents[2] / "cases" / "two_blocks.toml"
MESH = CASE.parent / "two_blocks.msh"
H = 5.0  #: the case's coarse size in mm: squares of 5 mm over blocks 30 and 40 mm wide
LAST = "load.steps=[[0.0, -0.02]]"
FAULT = CASE.parent / "fault_sliding.toml"
MU = 0.6  #: the fault's Coulomb coefficient


def _run(out: Path, *args: str) -> dict:
    base = ["run", "--case", str(CASE), "--method", "primal-ms", "--no-plots", "--out", str(out)]
    assert main([*base, *args]) == 0  # (the case's mesh.coarse-size: H)
    return json.loads((out / "summary.json").read_text())


def _relative(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def test_the_run_is_the_api_solve_at_every_step(tmp_path):
    summary = _run(tmp_path / "ms", "--layers", "2", "--set", "load.steps=[[0.0, -0.01], [0.0, -0.02]]")
    assert summary["converged"] and summary["method"] == "primal-ms"
    assert (summary["coarse_size"], summary["layers"], summary["nbasis"]) == (H, 2, "rigid")
    assert summary["case"]["run"]["multiscale"] == {"layers": 2, "nbasis": "rigid"}
    case = load_case(CASE)
    built = case.build_mesh(MPI.COMM_SELF)
    for step, row in zip((1, 3), summary["load_steps"]["steps"], strict=True):  # the case's steps 2 and 4
        api = fc.solve(case.problem(built, step=step), "primal-ms", H=H, cem=fc.CEMOptions(layers=2))
        assert row["force_balance"] <= 1e-12
        assert _relative(row["force_slave"], api.forces[0]) <= 1e-12
        assert _relative(row["force_master"], api.forces[1]) <= 1e-12
        assert row["max_contact_pressure_master"] == pytest.approx(api.master.max_pressure, rel=1e-12)
    fields = pyvista.PVDReader(str(tmp_path / "ms" / "fields.pvd"))
    fields.set_active_time_value(fields.time_values[-1])
    assert set(np.unique(fields.read()[0].cell_data["body"])) == {1.0, 2.0}
    contact = pyvista.read(tmp_path / "ms" / "contact" / "step_001.vtu")
    assert set(np.unique(contact.point_data["side"])) == {1.0, 2.0}


def test_patches_covering_each_bulk_give_algorithm_1(tmp_path):
    multiscale = _run(tmp_path / "ms", "--layers", "50", "--set", 'multiscale.nbasis="all"', "--set", LAST)
    assert multiscale["nbasis"] == "all"
    args = ["run", "--case", str(CASE), "--method", "primal", "--no-plots", "--out", str(tmp_path / "a1")]
    assert main([*args, "--set", LAST]) == 0
    fine = json.loads((tmp_path / "a1" / "summary.json").read_text())
    assert _relative(multiscale["force_slave"], fine["force_slave"]) <= 1e-8
    assert _relative(multiscale["force_master"], fine["force_master"]) <= 1e-8
    local = _run(tmp_path / "m2", "--layers", "2", "--set", LAST)  # (short patches: the multiscale error shows)
    assert _relative(local["force_slave"], fine["force_slave"]) > 1e-5  # (measured 1.5e-3)


def test_a_traction_on_a_bulk_gives_algorithm_1s_forces_with_all_modes(tmp_path):
    traction = "bodies.upper.tractions={upper_left=[5.0, 0.0]}"
    multiscale = _run(
        tmp_path / "ms", "--layers", "50", "--set", 'multiscale.nbasis="all"', "--set", LAST, "--set", traction
    )
    args = ["run", "--case", str(CASE), "--method", "primal", "--no-plots", "--out", str(tmp_path / "a1")]
    assert main([*args, "--set", LAST, "--set", traction]) == 0
    fine = json.loads((tmp_path / "a1" / "summary.json").read_text())
    assert _relative(multiscale["force_slave"], fine["force_slave"]) <= 1e-8
    assert multiscale["force_balance"] <= 1e-12


def test_the_fault_slides_as_with_algorithm_1(tmp_path):
    steps = "load.steps=[[0.0, -0.02], [0.02, -0.02], [0.06, -0.02]]"
    runs = {}
    for method, extra in (("primal", []), ("primal-ms", ["--layers", "50", "--set", 'multiscale.nbasis="all"'])):
        out = tmp_path / method
        args = ["run", "--case", str(FAULT), "--method", method, "--no-plots", "--out", str(out), "--set", steps]
        assert main([*args, *extra]) == 0  # (the case's mesh.coarse-size: H)
        runs[method] = json.loads((out / "summary.json").read_text())
    fine, multiscale = (runs[m]["load_steps"]["steps"] for m in ("primal", "primal-ms"))
    for row, ref in zip(multiscale, fine, strict=True):
        assert row["converged"] and row["force_balance"] <= 1e-12
        assert _relative(row["force_slave"], ref["force_slave"]) <= 1e-8
        assert row["friction"]["slip_nodes"] == ref["friction"]["slip_nodes"]
        assert row["friction"]["dissipation"] == pytest.approx(ref["friction"]["dissipation"], rel=1e-6, abs=1e-14)
    last = multiscale[-1]["friction"]
    assert last["stick_nodes"] == 0 and last["slip_nodes"] > 0
    assert abs(last["tangential_force"][0]) == pytest.approx(MU * last["normal_force"], rel=1e-8)


BAD = [
    (["--set", f"mesh={{file='{MESH}'}}"], "needs the coarse size of both bulks"),
    (["--set", "mesh.coarse-size=0.1"], "smaller than the fine cells"),
    (["--set", "mesh.coarse-size=16.0"], "does not divide body 2"),
    (["--set", f"mesh={{file='{MESH}', coarse-size=5.0, H=2}}"], "give one of them"),
    (["--H", "2"], "the coarse size H = 0.5 (mesh.coarse-size, or 1/--H)"),
    (["--set", 'multiscale.nbasis="many"'], '"rigid" or "all"'),
    (["--set", "multiscale.cache-dir=1"], "the keys of [multiscale]"),
    (["--layers", "-1"], "oversampling layers must be an integer >= 0"),
]


@pytest.mark.parametrize(("args", "message"), BAD, ids=[a[-1].split("=")[0] for a, _ in BAD])
def test_what_primal_ms_cannot_run_is_refused(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    base = ["run", "--case", str(CASE), "--method", "primal-ms", "--no-plots", "--out", str(out)]
    assert main([*base, *args]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_multiscale_options_belong_to_primal_ms(tmp_path, capsys):
    args = ["run", "--case", str(CASE), "--method", "primal", "--no-plots", "--out", str(tmp_path / "out")]
    assert main([*args, "--nbasis", "4"]) == 2
    assert "options of --method primal-ms, not of --method primal" in capsys.readouterr().err


def test_the_nbasis_words_on_the_command_line():
    """--nbasis all and --nbasis rigid (the words of [multiscale] nbasis) reach the pair's CEM options."""
    from fenics_contact.cli.pair import pair_run_options
    from fenics_contact.multiscale.cem import ALL_MODES, RIGID_MOTIONS

    case = load_case(CASE)
    for word, value in (("all", ALL_MODES), ("rigid", RIGID_MOTIONS), (4, 4)):
        options = pair_run_options(case, {"method": "primal-ms", "nbasis": word})
        assert options.multiscale.cem.nbasis == value


def test_check_mesh_refuses_the_bulks_the_run_refuses(tmp_path, capsys):
    """Strips of 8 cell layers take the whole upper block: check-mesh says primal-ms cannot run (and, asked for
    primal-ms, stops with exit code 2) with the run's own message; the run refuses it, nothing written."""
    layers = ["--set", "primal.layers=8"]
    message = "body 2: the strips (8 cell layers from the contact surfaces) take the whole body"
    assert main(["check-mesh", "--case", str(CASE), "--method", "primal", *layers]) == 0
    out = capsys.readouterr().out
    assert "primal can run" in out and f"primal-ms cannot (two-body Algorithm 3 (primal-ms): {message}" in out
    assert main(["check-mesh", "--case", str(CASE), "--method", "primal-ms", *layers]) == 2
    assert message in capsys.readouterr().err
    out = tmp_path / "out"
    assert main(["run", "--case", str(CASE), "--method", "primal-ms", "--no-plots", "--out", str(out), *layers]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()
