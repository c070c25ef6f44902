"""Two-body case files (a case with ``[pair]``): the shipped ``cases/two_blocks.toml`` run from the command line.

* the forces on the two sides balance to round-off in the summary, at every load step;
* every load step's summary (warm-started from the last) is the API's cold solve of that step's problem;
* Algorithm 1 (``--method primal``) gives the monolithic solve's forces to its tolerance;
* the written outputs (both bodies' fields, both faces' contact, the figures) and check-mesh's report;
* bad input is refused with the key or group named (exit 2).
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
from fenics_contact.problem.pair_case import PairCase

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="two-body solves are serial")

CASE = Path(__file__).parents[2] / "cases" / "two_blocks.toml"


def _summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def _relative(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.fixture(scope="module")
def monolithic(tmp_path_factory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("pair") / "mono"
    assert main(["run", "--case", str(CASE), "--out", str(out)]) == 0
    return out, _summary(out)


def test_forces_balance_and_match_the_api_at_every_step(monolithic):
    _, summary = monolithic
    case = load_case(CASE)
    assert isinstance(case, PairCase)
    steps = summary["load_steps"]["steps"]
    assert [s["displacement"] for s in steps] == [list(d) for d in case.load.steps]
    built = case.build_mesh()
    for k, row in enumerate(steps):
        fs, fm = np.asarray(row["force_slave"]), np.asarray(row["force_master"])
        assert np.linalg.norm(fs + fm) <= 1e-12 * np.linalg.norm(fs)
        assert row["force_balance"] <= 1e-12
        assert fs[1] > 0.0  # the upper (slave) body is pushed up
        cold = fc.solve(case.problem(built, step=k), "primal-monolithic")
        assert _relative(fs, cold.forces[0]) < 1e-10
        assert row["normal_force_slave"] == pytest.approx(cold.slave.force, rel=1e-10)
        assert row["max_contact_pressure_master"] == pytest.approx(cold.master.max_pressure, rel=1e-10)
    assert summary["force_slave"] == steps[-1]["force_slave"]  # the run's solve is the last step's
    assert summary["converged"] is True


def test_outputs_hold_both_bodies_and_both_faces(monolithic):
    out, summary = monolithic
    for name in ("pair.png", "E.png", "force_displacement.png", "summary.md"):
        assert (out / name).is_file(), name
    fields = pyvista.PVDReader(str(out / "fields.pvd"))
    assert len(fields.time_values) == len(summary["load_steps"]["steps"])
    fields.set_active_time_value(fields.time_values[-1])
    grid = fields.read()[0]
    assert set(np.unique(grid.cell_data["body"])) == {1.0, 2.0}
    assert grid.n_cells == 678
    contact = pyvista.read(out / "contact" / "step_003.vtu")
    side = contact.point_data["side"]
    assert set(np.unique(side)) == {1.0, 2.0}
    pressure = contact.point_data["pressure"]
    assert np.max(pressure[side == 1]) == pytest.approx(summary["max_contact_pressure_slave"], rel=1e-12)
    assert np.max(pressure[side == 2]) == pytest.approx(summary["max_contact_pressure_master"], rel=1e-12)


def test_algorithm_1_gives_the_monolithic_forces(tmp_path, monolithic):
    _, mono = monolithic
    out = tmp_path / "hybrid"
    args = ["run", "--case", str(CASE), "--method", "primal", "--no-plots", "--out", str(out)]
    assert main([*args, "--set", "load.steps=[[0.0, -0.02]]", "--tol", "1e-10"]) == 0
    summary = _summary(out)
    assert summary["iterations"] >= 1 and summary["transmission_residual"] < 1e-10
    assert summary["force_balance"] <= 1e-12
    assert _relative(summary["force_slave"], mono["force_slave"]) < 1e-6
    assert summary["case"]["run"]["method"] == "primal"


def test_check_mesh_reports_the_bodies_and_the_pair(capsys):
    assert main(["check-mesh", "--case", str(CASE)]) == 0
    text = capsys.readouterr().out
    assert "body lower: 468 cells, E in [8000, 20000]" in text
    assert "body upper: 210 cells" in text
    assert "pair: slave upper_bottom (22 facets, body upper), master lower_top (40 facets)" in text
    assert "stepped in 4 load steps" in text
    assert "segments rule of degree 3, dual pressure basis, frictionless" in text


def test_the_pressure_basis_of_a_case(tmp_path, capsys):
    """``pair.basis`` reaches the pair (the default of the frictionless case: dual) and its echo; the standard
    basis gives the same contact force to 1e-3 and balances it to round-off."""
    assert main(["check-mesh", "--case", str(CASE), "--set", 'pair.basis="standard"']) == 0
    assert "standard pressure basis" in capsys.readouterr().out
    case = load_case(CASE)
    assert case.pair.basis is None and "basis" not in case.pair.echo()
    dual = fc.solve(case.problem(case.build_mesh()), "primal-monolithic")
    assert dual.problem.pair.basis == "dual"
    out = tmp_path / "standard"
    args = ["run", "--case", str(CASE), "--no-plots", "--out", str(out), "--set", 'pair.basis="standard"']
    assert main(args) == 0
    summary = _summary(out)
    assert summary["force_balance"] <= 1e-12
    assert _relative(summary["force_slave"], dual.forces[0]) < 1e-3


BAD = [
    (["--method", "mixed"], "cannot solve two deformable bodies"),
    (["--reference"], "--reference does not apply to a two-body case"),
    (["--h", "16"], "unknown key 'mesh.h' for a two-body case"),
    (["--set", "bodies.lower.colour=1"], "unknown key 'bodies.lower.colour'"),
    (["--set", 'pair.slave="upper_side"'], "has no curve (facet) group 'upper_side'"),
    (["--set", 'load.support="lower_left"'], "load.support = 'lower_left' is not the facet group of a support"),
    (["--set", "bodies.upper.E={upper_shale=1.0}"], "gives no value for the body's cell group 'upper_sandstone'"),
    (["--set", "run.tol=1e-9"], "tol belongs in [primal]"),
    (["--set", "primal.tol=1e-9"], "options of --method primal and primal-ms"),
    (["--set", 'load.traction="upper_top"'], "give exactly one of load.support"),
    (["--set", 'load={traction="upper_top", steps=[[0.0, 1.0]]}'], "load.traction = 'upper_top' is not a group"),
    (["--set", "bodies.lower.supports=[]"], "has no Support"),
    (["--set", 'pair.basis="biorthogonal"'], "must be one of ['dual', 'standard']"),
    (["--set", 'pair={slave="upper_bottom", master="lower_top", rule="vertices", basis="dual"}'], "needs pair.rule"),
]


@pytest.mark.parametrize(("args", "message"), BAD, ids=[a[-1].split("=")[0] for a, _ in BAD])
def test_bad_input_is_refused(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    assert main(["run", "--case", str(CASE), "--no-plots", "--out", str(out), *args]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_a_body_held_by_contact_alone_carries_its_traction(tmp_path):
    """The upper block on rollers at its sides (x held, y free) under a traction t on its top, stepped: the
    contact alone holds it up, so the contact force on it is −t times the top's width (30 mm) at every step,
    whatever δ."""
    text = CASE.read_text().replace('file = "two_blocks.msh"', f'file = "{CASE.parent / "two_blocks.msh"}"')
    text = text.replace(
        'supports = [{facets = "upper_top", displacement = [0.0, -0.02]}]',
        'supports = [{facets = "upper_left", components = [0]}, {facets = "upper_right", components = [0]}]\n'
        "tractions = {upper_top = [0.0, -5.0]}",
    )
    text = text[: text.index("[load]")] + '[load]\ntraction = "upper_top"\nsteps = [[0.0, -2.5], [0.0, -5.0]]\n'
    (tmp_path / "pushed.toml").write_text(text)
    out = tmp_path / "out"
    assert main(["run", "--case", str(tmp_path / "pushed.toml"), "--no-plots", "--out", str(out)]) == 0
    summary = _summary(out)
    steps = summary["load_steps"]["steps"]
    assert summary["load_steps"]["traction"] == "upper_top" and [s["traction"] for s in steps] == [[0, -2.5], [0, -5]]
    assert steps[0]["force_slave"][1] == pytest.approx(2.5 * 30.0, rel=1e-10)
    assert summary["force_slave"][1] == pytest.approx(5.0 * 30.0, rel=1e-10)
    assert summary["force_master"][1] == pytest.approx(-5.0 * 30.0, rel=1e-10)
    assert summary["case"]["bodies"]["upper"]["tractions"] == {"upper_top": [0.0, -5.0]}


def test_algorithm_1_stopped_early_writes_its_results_unconverged(tmp_path, capsys):
    out = tmp_path / "stopped"
    args = ["run", "--case", str(CASE), "--method", "primal", "--accel", "none", "--max-iterations", "2"]
    assert main([*args, "--no-plots", "--out", str(out), "--set", "load.steps=[[0.0, -0.02]]"]) == 3
    assert "not converged" in capsys.readouterr().err
    summary = _summary(out)
    assert summary["converged"] is False and summary["iterations"] == 2
    assert summary["transmission_residual"] > 1e-8


@pytest.mark.parametrize(
    ("edit", "message"),
    [("two groups", "triangles lie in two surface groups"), ("no group", "belong to no triangle of a surface group")],
)
def test_a_mesh_with_cells_outside_one_group_each_is_refused(tmp_path, capsys, edit, message):
    import gmsh

    from fenics_contact.problem.geometry import gmsh_session

    mesh = tmp_path / "edited.msh"
    with gmsh_session():
        gmsh.merge(str(CASE.parent / "two_blocks.msh"))
        shale = next(t for d, t in gmsh.model.getPhysicalGroups(2) if gmsh.model.getPhysicalName(d, t) == "lower_shale")
        if edit == "two groups":
            gmsh.model.addPhysicalGroup(2, list(gmsh.model.getEntitiesForPhysicalGroup(2, shale)), name="extra")
        else:
            gmsh.model.removePhysicalGroups([(2, shale)])
            gmsh.option.setNumber("Mesh.SaveAll", 1)
        gmsh.write(str(mesh))
    assert main(["check-mesh", "--case", str(CASE), "--set", f'mesh.file="{mesh}"']) == 2
    assert message in capsys.readouterr().err
