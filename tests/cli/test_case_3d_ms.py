"""Algorithm 3 (``--method primal-ms``) from 3D case files and 3D mesh files: the coarse cubes over the body.

* on the unit cube the coarse cells are the grid's cubes of side 1/H (the mesh resolves them); on a gmsh mesh the
  cubes that hold the Ω₁ cells' centroids cover Ω₁ and nothing else;
* a case on a gmsh file of tetrahedra (coarse-size: the strip and the cubes) runs to the Python API's solution;
* with patches covering Ω₁ and every local mode the multiscale space is the fine one: Algorithm 1's contact force
  (short patches and the rigid modes, the control, differ);
* what cannot work is refused naming the key: no coarse size, cubes smaller than the cells or longer than half the
  body, the words of nbasis outside primal-ms.
"""

import json
from pathlib import Path

import gmsh
import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.cli import main
from fenics_contact.problem.case import load_case
from fenics_contact.problem.geometry import gmsh_session
from fenics_contact.problem.partition import UNRESOLVED, cartesian_coarse_cells
from fenics_contact.problem.tags import Subdomain

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the CLI tests run serially")

CASES = Path(__file__).parents[2] / "cases"
#: the side of the coarse cubes of the gmsh box (and the width of its strip)
COARSE = 1.0 / 3.0


def _box(path: Path, size: float = 0.15) -> Path:
    """(0, 1)³ of gmsh tetrahedra of ``size`` in two material slabs (soft x < 0.5, hard beyond), Gamma_D x = 0,
    Gamma_C x = 1; no Omega1/Omega2/gamma (the case's coarse size builds the strip)."""
    with gmsh_session():
        occ = gmsh.model.occ
        gmsh.model.add("slabs")
        occ.fragment([(3, occ.addBox(0, 0, 0, 0.5, 1, 1))], [(3, occ.addBox(0.5, 0, 0, 0.5, 1, 1))])
        occ.synchronize()
        volumes = [t for _, t in sorted(gmsh.model.getEntities(3), key=lambda e: occ.getCenterOfMass(*e)[0])]
        gmsh.model.addPhysicalGroup(3, volumes[:1], name="soft")
        gmsh.model.addPhysicalGroup(3, volumes[1:], name="hard")
        for name, at in (("Gamma_D", 0.0), ("Gamma_C", 1.0)):
            faces = [t for _, t in gmsh.model.getEntities(2) if abs(occ.getCenterOfMass(2, t)[0] - at) < 1e-9]
            gmsh.model.addPhysicalGroup(2, faces, name=name)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))
    return path


def _box_case(tmp: Path, extra: str = "") -> Path:
    _box(tmp / "slabs.msh")
    path = tmp / "slabs.toml"
    path.write_text(
        f'[mesh]\nfile = "slabs.msh"\ncoarse-size = {COARSE!r}\n'
        "[material]\nE = {soft = 1.0, hard = 10.0}\nnu = 0.3\n[load]\nbody-force = {soft = [0.5, 0.0, 0.2]}\n"
        '[obstacle]\nshape = "sphere"\ncentre = [1.6, 0.5, 0.5]\nradius = 0.6\ndirection = [-1.0, 0.0, 0.0]\n'
        'indentation = 0.02\n[run]\nmethod = "primal-ms"\ntol = 1e-10\n' + extra
    )
    return path


def _run(tmp: Path, name: str, *args: str) -> dict:
    out = tmp / name
    assert main(["run", "--no-plots", *args, "--out", str(out)]) == 0
    return json.loads((out / "summary.json").read_text())


def _relative(a: float, b: float) -> float:
    return abs(a - b) / abs(b)


def _omega1_cells(cm) -> np.ndarray:
    return cm.cell_tags.find(Subdomain.OMEGA1)


def test_the_unit_cube_takes_the_grid_of_cubes_and_a_gmsh_mesh_the_cubes_of_its_centroids(tmp_path):
    """unit-cube, h = 8, H = 4: the coarse cells of Ω₁ are the 3 × 4 × 4 grid cubes of side ¼, one to one; the
    gmsh box: every Ω₁ cell in a coarse cell, no Ω₂ cell, the coarse cells at most the cubes Ω₁ meets."""
    cube = load_case(CASES / "channels_3d.toml").build_mesh(MPI.COMM_SELF).cm
    omega1 = _omega1_cells(cube)
    grid, _ = cartesian_coarse_cells(cube.mesh, 0.25)
    pairs = np.unique(np.stack([cube.coarse_cell[omega1], grid[omega1]]), axis=1)
    assert cube.H == 0.25 and pairs.shape[1] == 3 * 4 * 4  # (a bijection: each coarse cell is one grid cube)
    assert np.unique(pairs[0]).size == np.unique(pairs[1]).size == pairs.shape[1]
    box = load_case(_box_case(tmp_path)).build_mesh(MPI.COMM_SELF).cm
    coarse, omega1 = np.asarray(box.coarse_cell), _omega1_cells(box)
    assert box.H == pytest.approx(COARSE) and np.all(coarse[omega1] >= 0)
    assert np.all(np.delete(coarse, omega1) == UNRESOLVED)
    centroids = dmesh.compute_midpoints(box.mesh, 3, omega1)
    cubes = np.unique(np.floor(centroids / COARSE).astype(int), axis=0)
    assert 2 * 3 * 3 <= np.unique(coarse[omega1]).size <= len(cubes)  # (slivers along γ merged into neighbours)


def test_a_3d_mesh_file_case_runs_algorithm_3_as_the_python_api(tmp_path):
    """The gmsh box (materials and load by volume group, a sphere) with coarse-size: the run's contact force and
    coarse space are the API's ``fc.solve(problem, "primal-ms", ...)`` on the case's problem."""
    path = _box_case(tmp_path)
    summary = _run(tmp_path, "ms", "--case", str(path), "--layers", "1")  # (m = 2 would cover Ω₁)
    assert summary["converged"] and summary["H"] == pytest.approx(COARSE) and summary["nbasis"] == 6
    case = load_case(path)
    problem = case.problem(case.build_mesh(MPI.COMM_SELF))
    api = fc.solve(problem, "primal-ms", layers=1, tol=1e-10)
    assert summary["dofs"]["omega1_ms"] == api.dofs["omega1_ms"] == 6 * api.step.omega1.grid.size
    assert _relative(summary["contact_force"], api.profile.force) <= 1e-12
    assert summary["iterations"] == api.iterations and tuple(summary["active_set"]) == api.profile.active_interval()


def test_patches_covering_omega1_with_every_mode_give_algorithm_1(tmp_path):
    """The channel cube (h = 1/6, cubes of ⅓): m = 20 layers and nbasis = "all" reach Algorithm 1's contact
    force; m = 1 with the rigid modes does not."""
    small = ["--case", str(CASES / "channels_3d.toml"), "--set", "mesh.h=6", "--set", "mesh.H=3", "--tol", "1e-11"]
    fine = _run(tmp_path, "a1", *small, "--method", "primal")
    every = _run(tmp_path, "all", *small, "--method", "primal-ms", "--layers", "20", "--set", 'multiscale.nbasis="all"')
    assert every["nbasis"] == "all" and every["case"]["run"]["nbasis"] == "all"
    assert _relative(every["contact_force"], fine["contact_force"]) <= 1e-8
    control = _run(tmp_path, "m1", *small, "--method", "primal-ms", "--layers", "1")
    assert _relative(control["contact_force"], fine["contact_force"]) > 1e-5


def test_the_hertz_block_runs_algorithm_3_on_its_graded_partition(tmp_path):
    """Without mesh.coarse-size the Hertz block's Ω₁ keeps its graded boxes (``partition.graded_coarse_cells``):
    Algorithm 3 runs on them from the case file, and its force is Algorithm 1's to 1e-3 at m = 2 (measured 2e-4)."""
    mesh = 'mesh={builtin="hertz-quarter-block", a=0.1, refinement=0.2}'
    case = ["--case", str(CASES / "sphere_3d.toml"), "--set", mesh]
    ms = _run(tmp_path, "ms", *case, "--method", "primal-ms", "--layers", "2")
    fine = _run(tmp_path, "fine", *case, "--method", "primal")
    assert ms["converged"] and fine["converged"]
    assert _relative(ms["contact_force"], fine["contact_force"]) <= 1e-3


BAD = [
    (
        ["--case", str(CASES / "sphere_3d.toml"), "--set", "mesh.refinement=0.2", "--set", "mesh.coarse-size=0.2"],
        "are smaller than the Omega1 cells",
    ),
    (["--case", str(CASES / "sphere_3d.toml"), "--set", "mesh.coarse-size=12.0"], "at most half of mesh.size"),
    (["--case", str(CASES / "channels_3d.toml"), "--set", 'multiscale.nbasis="many"'], '"rigid" or "all"'),
    (["--model", "1", "--h", "8", "--H", "2", "--method", "mixed-ms", "--nbasis", "all"], "apply to primal-ms"),
]


@pytest.mark.parametrize(("args", "message"), BAD, ids=["below cells", "above half", "word", "mixed"])
def test_what_algorithm_3_cannot_run_is_refused(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    method = [] if "--method" in args else ["--method", "primal-ms"]
    assert main(["run", "--no-plots", *args, *method, "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_coarse_cubes_longer_than_half_the_body_are_refused(tmp_path, capsys):
    path = _box_case(tmp_path)
    assert main(["run", "--case", str(path), "--set", "mesh.coarse-size=0.6", "--out", str(tmp_path / "o")]) == 2
    assert "more than half of the body's longest side" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_the_shipped_sphere_case_runs_algorithm_3(tmp_path):
    """cases/sphere_3d.toml with its coarse cubes (5a) and m = 2, contact cells a/4, two load steps: close to the
    fine monolithic solution (energy error 5.0e-3 measured at one step), the force growing with the depth."""
    summary = _run(
        tmp_path,
        "sphere",
        *("--case", str(CASES / "sphere_3d.toml"), "--method", "primal-ms", "--reference"),
        *("--set", "mesh.refinement=0.2", "--set", "obstacle.indentation=[0.005, 0.01]"),
    )
    assert summary["converged"] and summary["H"] == pytest.approx(0.5) and summary["layers"] == 2
    assert summary["e_energy"] < 2e-2 and summary["e_u"] < 1e-2
    forces = [step["force"] for step in summary["force_indentation"]["steps"]]
    assert 0 < forces[0] < forces[1]


def test_a_tetrahedral_mesh_file_and_model_5_on_the_command_line(tmp_path, capsys):
    """--mesh of a gmsh box of tetrahedra with --H: check-mesh finds that primal-ms can run on its cubes of side
    1/H (it cannot without them), and the run converges; --model 5 runs primal-ms on its fibre block's cubes."""
    mesh = str(_box(tmp_path / "slabs.msh"))
    assert main(["check-mesh", mesh]) == 0
    assert "primal-ms refused" in capsys.readouterr().out
    assert main(["check-mesh", mesh, "--method", "primal-ms", "--H", "3"]) == 0
    assert "primal-ms can run" in capsys.readouterr().out
    args = ["--mesh", mesh, "--model", "4", "--method", "primal-ms", "--H", "3", "--layers", "1"]
    summary = _run(tmp_path, "file", *args)
    assert summary["converged"] and summary["H"] == pytest.approx(COARSE) and summary["dofs"]["omega1_ms"] > 0
    model = _run(tmp_path, "m5", "--model", "5", "--h", "8", "--method", "primal-ms", "--layers", "1")
    assert model["converged"] and model["H"] == 0.25 and model["dofs"]["omega1_ms"] % 6 == 0
