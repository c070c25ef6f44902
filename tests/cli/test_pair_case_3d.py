"""Two-body case files in 3D: a gmsh file of two boxes of tetrahedra (volume groups the bodies, surface groups the
facets) and three-component vectors; the contact patch test through the command line, and the dimension checks.

* the uniform pressure across the non-matching faces is the exact one to round-off, on both sides and at both
  load steps, and the forces balance;
* the outputs hold both bodies' fields and both faces' contact nodes;
* a two-component vector on a 3D mesh, vectors of different lengths and an axis beyond y in 2D are refused,
  naming the key;
* the shipped ``cases/two_blocks_3d.toml`` (a stiff inclusion under the contact): the inclusion's E cell by cell,
  balanced forces, Algorithm 1 = the monolithic solve, Algorithm 3 within 1 %.
"""

import json
from pathlib import Path

import gmsh
import numpy as np
import pytest
import pyvista
from mpi4py import MPI

from fenics_contact.cli import main
from fenics_contact.problem.geometry import gmsh_session

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="two-body solves are serial")

#: lower box 1 × 1 × ½ (E, ν), upper box 1 × 1 × 0.4 on it, cells of 1/3 and 1/4
H1, H2, E1, NU1, E2, NU2, D = 0.5, 0.4, 1.0, 0.3, 5.0, 0.2, 0.01


def _write_mesh(path: Path) -> None:
    """Two boxes meshed apart, with named groups: lower, upper; <body>_bottom, _top, _left (x = 0), _sides."""
    with gmsh_session():
        gmsh.model.add("boxes")
        occ = gmsh.model.occ
        boxes = {
            "lower": (occ.addBox(0, 0, -H1, 1, 1, H1), -H1, 0.0, 1 / 3),
            "upper": (occ.addBox(0, 0, 0, 1, 1, H2), 0.0, H2, 1 / 4),
        }
        occ.synchronize()
        for name, (tag, z0, z1, h) in boxes.items():
            gmsh.model.addPhysicalGroup(3, [tag], name=name)
            faces = {"bottom": [], "top": [], "left": [], "sides": [], "right": []}
            for _, face in gmsh.model.getBoundary([(3, tag)], oriented=False):
                lo_x, lo_y, lo_z, hi_x, hi_y, hi_z = gmsh.model.getBoundingBox(2, face)
                if abs(hi_z - lo_z) < 1e-6:
                    faces["bottom" if abs(lo_z - z0) < 1e-6 else "top"].append(face)
                elif abs(hi_x - lo_x) < 1e-6:
                    faces["left" if abs(lo_x) < 1e-6 else "right"].append(face)
                else:
                    faces["sides"].append(face)
            for side, tags in faces.items():
                gmsh.model.addPhysicalGroup(2, tags, name=f"{name}_{side}")
            gmsh.model.mesh.setSize(gmsh.model.getBoundary([(3, tag)], recursive=True), h)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))


def _case(
    tmp: Path, *, push="[0.0, 0.0, -0.01]", steps="[[0.0, 0.0, -0.005], [0.0, 0.0, -0.01]]", force="[0.0, 0.0, 0.0]"
) -> Path:
    mesh = tmp / "boxes.msh"
    if not mesh.exists():
        _write_mesh(mesh)
    text = f"""
[mesh]
file = "boxes.msh"

[bodies.lower]
cells = "lower"
E = {E1}
nu = {NU1}
supports = [{{facets = "lower_bottom", components = [2]}}, {{facets = "lower_left", components = [0]}},
            {{facets = "lower_sides", components = [1]}}]

[bodies.upper]
cells = "upper"
E = {E2}
nu = {NU2}
body-force = {force}
supports = [{{facets = "upper_top", displacement = {push}, components = [2]}},
            {{facets = "upper_left", components = [0]}}, {{facets = "upper_sides", components = [1]}}]

[pair]
slave = "upper_bottom"
master = "lower_top"

[load]
support = "upper_top"
steps = {steps}
"""
    path = tmp / "boxes.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> tuple[Path, dict]:
    tmp = tmp_path_factory.mktemp("pair3d")
    out = tmp / "out"
    assert main(["run", "--case", str(_case(tmp)), "--out", str(out)]) == 0
    return out, json.loads((out / "summary.json").read_text())


def test_the_patch_test_holds_through_a_3d_case_file(run):
    """σ_zz = −p uniform, σ_xx = 0, ε_yy = 0: d = p (H₁/E₁' + H₂/E₂' + δ), E' = E/(1 − ν²), at each step."""
    _, summary = run
    for row in summary["load_steps"]["steps"]:
        d = -row["displacement"][2]
        p = d / (H1 * (1 - NU1**2) / E1 + H2 * (1 - NU2**2) / E2 + row["delta"])
        for side in ("slave", "master"):
            assert row[f"normal_force_{side}"] == pytest.approx(p, rel=1e-9)  # area 1
            assert row[f"max_contact_pressure_{side}"] == pytest.approx(p, rel=1e-9)
        assert row["force_balance"] <= 1e-12
        assert np.allclose(row["force_slave"], [0.0, 0.0, p], rtol=0.0, atol=1e-9 * p)


def test_the_outputs_hold_both_bodies_and_both_faces(run):
    out, _ = run
    fields = pyvista.PVDReader(str(out / "fields.pvd"))
    assert len(fields.time_values) == 2
    grid = fields.read()[0]
    assert grid["u"].shape[1] == 3 and set(np.unique(grid["body"])) == {1.0, 2.0}
    assert grid["sigma"].shape[1] == 6
    contact = pyvista.PVDReader(str(out / "contact.pvd")).read()[0]
    assert set(np.unique(contact["side"])) == {1.0, 2.0}


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            {"push": "[0.0, -0.01]", "steps": "[[0.0, -0.005]]", "force": "[0.0, 0.0]"},
            "has 2 components but the mesh boxes.msh is 3D",
        ),
        ({"push": "[0.0, -0.01]"}, "has 3 components but bodies.upper.supports[0].displacement has 2"),
    ],
)
def test_vectors_of_the_wrong_dimension_are_refused(tmp_path, capsys, edit, message):
    assert main(["run", "--case", str(_case(tmp_path, **edit)), "--out", str(tmp_path / "out")]) == 2
    assert message in capsys.readouterr().err


def test_check_mesh_reports_the_volumes_and_the_faces(tmp_path, capsys):
    assert main(["check-mesh", "--case", str(_case(tmp_path))]) == 0
    out = capsys.readouterr().out
    assert "dimension 3" in out and "tetrahedra" in out
    assert "the slave contact surface" in out and "lower_right      surface" in out


def test_the_summary_echoes_three_components(run):
    _, summary = run
    lower = summary["case"]["bodies"]["lower"]
    assert lower["body-force"] == [0.0, 0.0, 0.0] and lower["supports"][0]["displacement"] == [0.0, 0.0, 0.0]


# -- the shipped example: cases/two_blocks_3d.toml ----------------------------------------------------------------

SHIPPED = Path(__file__).parents[2] / "cases" / "two_blocks_3d.toml"


def test_the_shipped_3d_pair_runs_and_algorithm_1_is_the_monolithic_solve(tmp_path):
    """Two non-matching tetrahedral blocks, the lower one with a stiff inclusion: the cells take the inclusion's E
    exactly inside its box; at each load step the forces on both faces balance to round-off and Algorithm 1's force
    is the monolithic one (Theorem 3.1) to 1e-8; Algorithm 3 (coarse cubes of 5 mm, short patches) is within 1 %."""
    from dolfinx import mesh as dmesh

    from fenics_contact.problem.case import load_case

    case = load_case(SHIPPED)
    built = case.build_mesh(MPI.COMM_SELF)
    problem = case.problem(built)
    msh = problem.mesh
    cells = problem.body_cells(0)
    x = dmesh.compute_midpoints(msh, 3, cells)
    inside = np.all((x > [6.0, 6.0, -7.0]) & (x < [14.0, 14.0, -3.0]), axis=1)
    E = problem.fields.E.x.array[problem.fields.E.function_space.dofmap.list[cells, 0]]
    assert 0 < inside.sum() < cells.size and np.array_equal(E, np.where(inside, 2.0e4, 2.0e3))
    runs = {}
    for method in ("primal-monolithic", "primal"):
        out = tmp_path / method
        assert main(["run", "--case", str(SHIPPED), "--method", method, "--no-plots", "--out", str(out)]) == 0
        runs[method] = json.loads((out / "summary.json").read_text())["load_steps"]["steps"]
    for mono, hybrid in zip(runs["primal-monolithic"], runs["primal"], strict=True):
        assert mono["force_balance"] <= 1e-12 and hybrid["force_balance"] <= 1e-12
        assert hybrid["converged"] and hybrid["force_slave"][2] > 0
        np.testing.assert_allclose(hybrid["force_slave"], mono["force_slave"], rtol=1e-8, atol=0.0)
    assert runs["primal"][-1]["force_slave"][2] > 1.9 * runs["primal"][0]["force_slave"][2]  # (two steps of 5 µm)
    out = tmp_path / "ms"  # Algorithm 3, patches of one coarse layer: a multiscale error of a few 1e-3 (4.8e-3)
    assert (
        main(["run", "--case", str(SHIPPED), "--method", "primal-ms", "--layers", "1", "--no-plots", "--out", str(out)])
        == 0
    )
    for ms, mono in zip(
        json.loads((out / "summary.json").read_text())["load_steps"]["steps"], runs["primal-monolithic"]
    ):
        assert ms["force_balance"] <= 1e-12
        assert 1e-4 < abs(ms["force_slave"][2] / mono["force_slave"][2] - 1) < 1e-2
