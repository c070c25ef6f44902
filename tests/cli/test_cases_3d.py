"""Case files in 3D: three-component vectors, the sphere, rollers, the built-in 3D meshes and models, volume
material groups of a mesh file, and the example cases of ``cases/`` at a small size.

* channels_3d (model 4 from a case): the same contact force and active set as ``--model 4`` on the same cube;
* sphere_3d (Hertz on the quarter block, contact cells a/4): Algorithm 1 = the monolithic solve, the contact
  radius within a contact cell of √(R d), the force growing like d^{3/2} between the two load steps;
* fibres_3d (model 5's block, materials by group, contrast 1e6): Algorithm 1 = the monolithic solve, the
  cells' E follows the fibres' geometry, the contact grows with the indentation.
"""

import json
from pathlib import Path

import gmsh
import numpy as np
import pytest
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.cli import main
from fenics_contact.errors import InputError
from fenics_contact.problem.case import load_case, parse_override
from fenics_contact.problem.composite3d import in_fibres
from fenics_contact.problem.geometry import gmsh_session
from fenics_contact.problem.obstacles import Sphere

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the CLI tests run serially")

CASES = Path(__file__).parents[2] / "cases"


@pytest.fixture(autouse=True)
def _in_tmp_path(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)


def _run(tmp_path: Path, *args: str, name: str = "out") -> dict:
    out = tmp_path / name
    assert main(["run", "--no-plots", *args, "--out", str(out)]) == 0
    return json.loads((out / "summary.json").read_text())


def _cell_values(problem, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(midpoints (3, N), values (N,)) of a DG0 material field of the problem's owned cells."""
    msh = problem.cm.mesh
    cells = np.arange(msh.topology.index_map(3).size_local, dtype=np.int32)
    field = getattr(problem.fields, name)
    return dmesh.compute_midpoints(msh, 3, cells).T, field.x.array[field.function_space.dofmap.list[cells, 0]]


# -- reading ----------------------------------------------------------------------------------------------------


def test_a_3d_case_reads_three_component_vectors():
    case = load_case(CASES / "fibres_3d.toml", [("obstacle.direction", [-2.0, 0.0, 0.0])])
    assert case.mesh.kind == "fibre-block" and case.mesh.dim == 3
    assert case.obstacle.final() == Sphere((1.5, 0.5, 0.5), 0.5).indented(0.012, (-1.0, 0.0, 0.0))
    assert case.obstacle.direction == (-1.0, 0.0, 0.0)  # normalized
    assert case.to_dict(3)["obstacle"]["centre"] == [1.5, 0.5, 0.5]


def test_the_channel_case_is_model_4(tmp_path):
    """The unit cube with the clamped faces, the rollers and the model of ``--model 4``: the same run."""
    case = _run(tmp_path, "--case", str(CASES / "channels_3d.toml"), "--set", "mesh.h=4", "--set", "mesh.H=2")
    model = _run(tmp_path, "--model", "4", "--h", "4", "--H", "2", "--method", "primal", name="model")
    assert case["contact_force"] == model["contact_force"] > 0 and case["active_set"] == model["active_set"]
    assert case["case"]["boundary"]["rollers"] == {"z": [0.0, 1.0]}


@pytest.mark.parametrize(
    "override, message",
    [
        (("boundary.rollers", {"w": [0.0]}), "boundary.rollers.w: the axes are x, y and z"),
        (("boundary.rollers", [0.0]), "boundary.rollers must be a table {axis = [values]}"),
        (("mesh.neumann", {"xmax": "Gamma_N_top"}), "mesh.neumann.xmax: unknown face"),
        (("mesh.clamped", ["xmax"]), "mesh.clamped must be one of"),
        (("mesh.H", 3), "mesh.h = 8 must be a multiple of mesh.H = 3"),
        (("obstacle.centre", [1.5, 0.5]), "obstacle.centre has 2 components but the mesh"),
        (("obstacle.direction", [-1.0, 0.0]), "obstacle.direction has 2 components but the mesh"),
        (("obstacle.motion", [[0.0, 0.0, 0.1], [0.1, 0.0]]), "obstacle.motion[1] has 2 components"),
        (("obstacle.centre", [1.5, 0.5, 0.5, 0.0]), "obstacle.centre must be a vector [x, y] (2D) or [x, y, z]"),
        (("load.body-force", {"fibres": [0.0, 1.0]}), "load.body-force.fibres has 2 components"),
    ],
)
def test_bad_3d_input_names_its_key(tmp_path, override, message):
    text = (
        '[mesh]\nbuiltin = "unit-cube"\n[material]\nE = 1.0\nnu = 0.3\n[obstacle]\nshape = "sphere"\n'
        "centre = [1.5, 0.5, 0.5]\nradius = 0.5\ndirection = [-1.0, 0.0, 0.0]\nindentation = 0.01\n"
    )
    if override[0] == "load.body-force":
        text = text.replace('"unit-cube"', '"fibre-block"')
    if override[0] == "obstacle.motion":
        text = text.replace("direction = [-1.0, 0.0, 0.0]\nindentation = 0.01\n", "")
    path = tmp_path / "cube.toml"
    path.write_text(text)
    with pytest.raises(InputError) as error:
        load_case(path, [override])
    assert message in str(error.value)


def test_the_fibre_block_refuses_a_contact_size_above_h(tmp_path):
    with pytest.raises(InputError, match="mesh.contact-size = 0.2 must be at most the cell size 1/h = 0.125"):
        load_case(CASES / "fibres_3d.toml", [("mesh.contact-size", 0.2)])


# -- a mesh file of tetrahedra with volume material groups ----------------------------------------------------------


def _layered_box(path: Path) -> None:
    """(0, 1)³ in three slabs along x (0.5 and 0.75 apart): Omega1 x < 0.75, Omega2 beyond, and the material groups
    soft (x < 0.5) and hard (x > 0.5) overlaying them; Gamma_D x = 0, Gamma_C x = 1."""
    with gmsh_session():
        occ = gmsh.model.occ
        gmsh.model.add("layered box")
        slabs = [occ.addBox(x0, 0, 0, x1 - x0, 1, 1) for x0, x1 in ((0.0, 0.5), (0.5, 0.75), (0.75, 1.0))]
        occ.fragment([(3, slabs[0])], [(3, t) for t in slabs[1:]])
        occ.synchronize()
        volumes = [t for _, t in sorted(gmsh.model.getEntities(3), key=lambda e: occ.getCenterOfMass(*e)[0])]
        faces = {"Gamma_D": [], "Gamma_C": [], "gamma": []}
        for _, t in gmsh.model.getEntities(2):
            x = occ.getCenterOfMass(2, t)[0]
            for name, at in (("Gamma_D", 0.0), ("Gamma_C", 1.0), ("gamma", 0.75)):
                if abs(x - at) < 1e-9:
                    faces[name].append(t)
        gmsh.model.addPhysicalGroup(3, volumes[:2], 1, name="Omega1")
        gmsh.model.addPhysicalGroup(3, volumes[2:], 2, name="Omega2")
        gmsh.model.addPhysicalGroup(3, volumes[:1], 3, name="soft")
        gmsh.model.addPhysicalGroup(3, volumes[1:], 4, name="hard")
        for i, (name, tags) in enumerate(faces.items()):
            gmsh.model.addPhysicalGroup(2, tags, 10 + i, name=name)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.25)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))


def test_volume_material_groups_and_3d_loads_of_a_mesh_file(tmp_path, capsys):
    """E and the body force by volume group, a plane given by 3-vectors: check-mesh names the groups' roles, the
    cells take their group's values, and Algorithm 1 runs on it to the monolithic solution."""
    _layered_box(tmp_path / "box.msh")
    (tmp_path / "box.toml").write_text(
        '[mesh]\nfile = "box.msh"\n[material]\nE = {soft = 1.0, hard = 100.0}\nnu = 0.3\n'
        "[load]\nbody-force = {soft = [1.0, 0.0, 0.5]}\n"
        '[obstacle]\nshape = "plane"\npoint = [1.001, 0.0, 0.0]\nnormal = [-1.0, 0.0, 0.0]\n'
    )
    assert main(["check-mesh", "--case", str(tmp_path / "box.toml")]) == 0
    said = capsys.readouterr().out
    assert all(f"{name:<16} volume" in said for name in ("soft", "hard"))
    assert said.count("a material group of the case") == 2 and "primal can run" in said
    case = load_case(tmp_path / "box.toml")
    problem = case.problem(case.build_mesh())
    x, E = _cell_values(problem, "E")
    np.testing.assert_array_equal(E, np.where(x[0] > 0.5, 100.0, 1.0))
    f = problem.fields.f.x.array.reshape(-1, 3)
    assert np.all(f[x[0] < 0.5] == [1.0, 0.0, 0.5]) and np.all(f[x[0] > 0.5] == 0.0)
    s = _run(tmp_path, "--case", str(tmp_path / "box.toml"), "--reference", "--tol", "1e-9")
    assert s["converged"] and s["e_u"] < 1e-8 and s["contact_force"] > 0


# -- the example cases, small ---------------------------------------------------------------------------------------


def test_sphere_case_small(tmp_path):
    """Hertz on the quarter block at contact cells a/4: the hybrid solution is the monolithic one, the contact
    radius is within a contact cell of √(R d) = a, and F(2d)/F(d) is Hertz's 2^{3/2} within 10 %."""
    s = _run(
        tmp_path,
        "--case",
        str(CASES / "sphere_3d.toml"),
        "--set",
        "mesh.refinement=0.2",
        "--set",
        "obstacle.indentation=[0.005, 0.01]",
        "--reference",
    )
    assert s["converged"] and s["e_u"] < 1e-8
    radius = s["active_set"][1]  # the largest x of a contact node: the quarter's contact radius
    assert abs(radius - 0.1) <= s["h"]
    forces = [step["force"] for step in s["force_indentation"]["steps"]]
    assert forces[1] / forces[0] == pytest.approx(2**1.5, rel=0.1)
    assert s["case"]["mesh"]["rollers"] == {"x": [0.0], "y": [0.0]}


def test_fibre_case_small(tmp_path):
    """Model 5's block with materials by group at contrast 1e6 under a sphere: Algorithm 1 = monolithic, E follows
    the fibres' geometry cell by cell, the contact grows with the indentation."""
    args = ["--set", "mesh.h=4", "--set", "mesh.contact-size=0.08", "--set", "obstacle.indentation=[0.006, 0.012]"]
    case = load_case(CASES / "fibres_3d.toml", [parse_override(a) for a in args[1:4:2]])
    problem = case.problem(case.build_mesh())
    x, E = _cell_values(problem, "E")
    np.testing.assert_array_equal(E, np.where(in_fibres(x), 1e6, 1.0))
    s = _run(tmp_path, "--case", str(CASES / "fibres_3d.toml"), *args, "--reference")
    assert s["converged"] and s["e_u"] < 1e-8
    steps = s["force_indentation"]["steps"]
    assert 0 < steps[0]["force"] < steps[1]["force"] and all(step["converged"] for step in steps)


def test_model_5_on_the_command_line(tmp_path):
    s = _run(tmp_path, "--model", "5", "--h", "4", "--H", "4", "--method", "primal", "--reference", "--E-high", "1e6")
    assert s["converged"] and s["e_u"] < 1e-8 and s["contact_force"] > 0


def test_a_sphere_dragged_over_the_fibre_block_with_coulomb_friction(tmp_path):
    """A 3D motion (press, then drag along y) with Coulomb friction from a case: every contact node slips at the
    end, so the tangential force is μ times the normal force (up to the stick regularization), along the drag."""
    (tmp_path / "drag.toml").write_text(
        '[mesh]\nbuiltin = "fibre-block"\nh = 4\ncontact-size = 0.1\n[material]\nE = {fibres = 1e3, matrix = 1.0}\n'
        'nu = 0.3\n[obstacle]\nshape = "sphere"\ncentre = [1.5, 0.5, 0.5]\nradius = 0.5\n'
        "motion = [[-0.006, 0.0, 0.0], [-0.006, 0.02, 0.0]]\n"
        '[friction]\nlaw = "coulomb"\nmu = 0.3\n[run]\nmethod = "primal"\n'
    )
    s = _run(tmp_path, "--case", str(tmp_path / "drag.toml"))
    last = s["sliding"]["steps"][-1]
    assert last["converged"] and last["stick_nodes"] == 0 and last["slip_nodes"] > 0
    tangential, normal = np.asarray(last["tangential_force"]), last["normal_force"]
    assert 0.95 * 0.3 * normal <= np.linalg.norm(tangential) <= 0.3 * normal * (1 + 1e-9)
    assert tangential[1] > 0.95 * np.linalg.norm(tangential) and s["sliding"]["dissipation"] > 0
