"""The command line on the 3D channel model (``--model 4``): Algorithm 1 runs on tetrahedra and writes its outputs."""

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
