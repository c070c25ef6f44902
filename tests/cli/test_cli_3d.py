"""The command line on the 3D channel model (``--model 4``): Algorithms 1 and 3 run on tetrahedra and write their
outputs."""

import json

import numpy as np
import pytest
import pyvista
from mpi4py import MPI

from fenics_contact.cli import main

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the CLI tests run serially")


def test_run_the_3d_model_with_algorithm_1_writes_its_outputs(tmp_path):
    out = tmp_path / "cube"
    code = main(["run", "--model", "4", "--method", "primal", "--h", "8", "--H", "4", "--reference", "--out", str(out)])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["converged"] is True and summary["e_u"] < 1e-8 and summary["transmission_residual"] < 1e-6
    assert summary["dofs"]["omega1"] + summary["dofs"]["omega2"] - summary["dofs"]["interface"] == 3 * 9**3
    for name in ("fields.pvd", "contact.pvd", "history.png", "summary.md"):
        assert (out / name).stat().st_size > 0, name
    fields, contact = pyvista.read(out / "fields.pvd")[0], pyvista.read(out / "contact.pvd")[0]
    assert fields.n_points == 9**3 and fields.n_cells == 6 * 8**3
    assert fields.point_data["u"].shape == (9**3, 3) and fields.cell_data["sigma"].shape == (6 * 8**3, 6)
    assert np.allclose(contact.points[:, 0], 1.0) and np.ptp(contact.points[:, 2]) == pytest.approx(1.0)
    pressure, active = contact.point_data["pressure"], contact.point_data["active"]
    assert np.all(pressure[active > 0] > 0) and pressure.max() == pytest.approx(summary["max_contact_pressure"])


def test_the_other_methods_refuse_the_3d_model(tmp_path, capsys):
    code = main(["run", "--model", "4", "--method", "mixed", "--h", "4", "--H", "4", "--out", str(tmp_path / "m")])
    assert code != 0 and "'primal'" in capsys.readouterr().err
    code = main(["run", "--model", "4", "--method", "mixed-ms", "--h", "8", "--out", str(tmp_path / "mm")])
    err = capsys.readouterr().err
    assert code == 2 and "plane problems" in err and "'primal-ms'" in err and not (tmp_path / "mm").exists()


def test_run_the_3d_model_with_algorithm_3_writes_its_outputs(tmp_path):
    """--method primal-ms on the cube: coarse cubes of side 1/4 (the default --H of primal-ms on --model 4), six
    modes per cube (the rigid motions), m = 2; close to the monolithic solution and its outputs written."""
    out = tmp_path / "cube-ms"
    code = main(["run", "--model", "4", "--method", "primal-ms", "--h", "8", "--layers", "2", "--reference",
                 "--no-plots", "--out", str(out)])  # fmt: skip
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["converged"] is True and summary["transmission_residual"] < 1e-6
    assert summary["H"] == 0.25 and summary["layers"] == 2 and summary["nbasis"] == 6
    assert summary["dofs"]["omega1_ms"] == 6 * 3 * 4 * 4 and summary["spectral_gap"] > 0
    assert summary["e_energy"] < 1e-2 and summary["e_u"] < 1e-2  # (2.2e-3 and 2.9e-4 measured)
    for name in ("fields.pvd", "contact.pvd", "summary.md"):
        assert (out / name).stat().st_size > 0, name
    fields = pyvista.read(out / "fields.pvd")[0]
    assert fields.n_points == 9**3 and fields.point_data["u"].shape == (9**3, 3)


def _gmsh_box(path, split: float = 0.75, h: float = 0.25) -> None:
    """A gmsh tetrahedral mesh of (0, 1)³: Omega1 x < ``split``, Omega2 beyond, gamma between, Gamma_D x = 0,
    Gamma_C x = 1."""
    import gmsh

    from fenics_contact.problem.geometry import gmsh_session

    with gmsh_session():
        occ = gmsh.model.occ
        gmsh.model.add("box")
        occ.fragment([(3, occ.addBox(0, 0, 0, split, 1, 1))], [(3, occ.addBox(split, 0, 0, 1 - split, 1, 1))])
        occ.synchronize()
        volumes = sorted((occ.getCenterOfMass(3, t)[0], t) for _, t in gmsh.model.getEntities(3))
        faces = {"Gamma_D": [], "Gamma_C": [], "gamma": []}
        for _, t in gmsh.model.getEntities(2):
            x = occ.getCenterOfMass(2, t)[0]
            for name, at in (("Gamma_D", 0.0), ("Gamma_C", 1.0), ("gamma", split)):
                if abs(x - at) < 1e-9:
                    faces[name].append(t)
        gmsh.model.addPhysicalGroup(3, [volumes[0][1]], 1, name="Omega1")
        gmsh.model.addPhysicalGroup(3, [volumes[1][1]], 2, name="Omega2")
        for i, (name, tags) in enumerate(faces.items()):
            gmsh.model.addPhysicalGroup(2, tags, 10 + i, name=name)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))


def test_a_case_file_on_a_tetrahedral_mesh_runs_algorithm_1(tmp_path):
    """A gmsh box pressed by a plane (its point and normal 3-vectors) in one load step: the same contact
    force as the monolithic solve, every Γ_C node in contact."""
    _gmsh_box(tmp_path / "box.msh")
    case = tmp_path / "box.toml"
    case.write_text(
        'description = "a box pressed by a plane"\n[mesh]\nfile = "box.msh"\n[material]\nE = 1.0\nnu = 0.3\n'
        '[obstacle]\nshape = "plane"\npoint = [1.0, 0.0, 0.0]\nnormal = [-1.0, 0.0, 0.0]\nindentation = [0.01]\n'
        '[run]\nmethod = "primal"\ntol = 1e-8\n'
    )
    out = tmp_path / "run"
    assert main(["run", "--case", str(case), "--reference", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["converged"] is True and summary["e_u"] < 1e-8
    step = summary["force_indentation"]["steps"][-1]
    assert step["converged"] and summary["contact_force"] > 0
    assert (out / "force_indentation.png").stat().st_size > 0
    contact = pyvista.read(out / "contact.pvd")[0]
    assert np.all(contact.point_data["active"] > 0) and np.allclose(contact.points[:, 0], 1.0)


def test_a_tetrahedral_mesh_file_runs_with_the_3d_model(tmp_path, capsys):
    """``--mesh`` of a gmsh tetrahedral file (--H not given: no coarse grid, which primal-ms alone builds) with the 3D
    model's physics; check-mesh finds that Algorithm 1 can run on it and the 2D methods cannot; a planar model is
    refused."""
    path = tmp_path / "box.msh"
    _gmsh_box(path)
    assert main(["check-mesh", str(path), "--method", "primal"]) == 0
    said = capsys.readouterr().out
    assert "primal can run" in said and "mixed refused" in said and "tetrahedra" in said
    assert "primal-ms refused" in said
    out = tmp_path / "run"
    args = ["run", "--mesh", str(path), "--method", "primal", "--reference", "--out", str(out)]
    assert main(args) == 2 and "--model 4" in capsys.readouterr().err
    assert main([*args, "--model", "4"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["converged"] is True and summary["e_u"] < 1e-8 and summary["H"] is None


def test_the_3d_model_has_its_own_default_mesh_size():
    from fenics_contact.cli.options import DEFAULT_H, DEFAULT_H_3D, RunOptions

    assert RunOptions(model=4).n == DEFAULT_H_3D < DEFAULT_H == RunOptions(model=1).n
    assert RunOptions(model=4, h=32).n == 32
