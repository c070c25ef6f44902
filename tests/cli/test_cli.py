"""The command line: outputs, exit codes, clear errors."""

import json

import numpy as np
import pytest
import pyvista
from mpi4py import MPI

from fenics_contact.cli import main

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the CLI tests run serially")


@pytest.mark.slow
def test_run_writes_summary_fields_and_plots(tmp_path):
    out = tmp_path / "run"
    code = main(["run", "--model", "2", "--h", "16", "--H", "4", "--reference", "--out", str(out)])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    for key in (
        "iterations",
        "converged",
        "rel_tolerance",
        "e_u",
        "active_set",
        "dofs",
        "time_offline_s",
        "time_online_s",
        "time_reference_s",
    ):
        assert key in summary, key
    assert summary["converged"] is True and summary["e_u"] < 1e-4
    lo, hi = summary["active_set"]
    assert 0.3 <= lo < hi <= 0.7
    assert summary["dofs"]["omega1"] + summary["dofs"]["omega2"] - summary["dofs"]["interface"] == 2 * 17 * 17
    for name in (
        "fields.pvd",
        "contact.pvd",
        "E.png",
        "displacement.png",
        "deformed.png",
        "contact.png",
        "history.png",
        "summary.md",
    ):
        assert (out / name).stat().st_size > 0, name
    # the ParaView fields read back: the mesh with u and the stress, Γ_C with the contact pressure and gap
    fields, contact = pyvista.read(out / "fields.pvd")[0], pyvista.read(out / "contact.pvd")[0]
    assert fields.n_points == 17 * 17 and fields.n_cells == 2 * 16 * 16
    assert set(fields.point_data.keys()) == {"u"} and {"sigma", "E", "subdomain"} <= set(fields.cell_data.keys())
    assert fields.cell_data["sigma"].shape == (2 * 16 * 16, 6)
    pressure, gap, active = (contact.point_data[k] for k in ("pressure", "gap", "active"))
    assert np.all(pressure[active > 0] > 0) and np.all(gap[active == 0] > 0)  # contact where the gap closes
    assert pressure.max() == pytest.approx(summary["max_contact_pressure"], rel=1e-12)


def test_not_converged_exits_nonzero(tmp_path):
    out = tmp_path / "capped"
    code = main(
        ["run", "--h", "16", "--H", "4", "--accel", "none", "--max-iterations", "3", "--no-plots", "--out", str(out)]
    )
    assert code == 3
    assert json.loads((out / "summary.json").read_text())["converged"] is False


@pytest.mark.parametrize(
    "args, message",
    [
        (["--nu", "0.5"], "Poisson"),
        (["--E-low", "-1"], "Young"),
        (["--H", "5"], "multiple"),
        (["--alpha", "-3"], "transmission"),
    ],
)
def test_bad_input_is_a_clear_error(tmp_path, caplog, capsys, args, message):
    out = tmp_path / "bad"
    code = main(["run", "--h", "16", "--H", "4", "--no-plots", "--out", str(out), *args])
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (out / "summary.json").exists(), "no partial result may be written"


def test_user_pixel_map_of_E(tmp_path):
    """A homogeneous pixel map gives the same answer as the model with E_high = E_low."""

    np.save(tmp_path / "E.npy", np.full((8, 8), 5.0))
    args = ["run", "--model", "1", "--h", "16", "--H", "4", "--no-plots"]
    assert main([*args, "--E-map", str(tmp_path / "E.npy"), "--out", str(tmp_path / "a")]) == 0
    assert main([*args, "--E-high", "5", "--E-low", "5", "--out", str(tmp_path / "b")]) == 0
    a, b = (json.loads((tmp_path / d / "summary.json").read_text()) for d in "ab")
    assert a["iterations"] == b["iterations"] and a["active_set"] == b["active_set"]
    bad = tmp_path / "bad.csv"
    bad.write_text("1,2\n3\n")
    assert main([*args, "--E-map", str(bad), "--out", str(tmp_path / "c")]) == 2


def test_primal_ms_method_and_offline_cache(tmp_path):
    args = [
        "run",
        "--model",
        "2",
        "--method",
        "primal-ms",
        "--h",
        "32",
        "--H",
        "8",
        "--layers",
        "3",
        "--reference",
        "--no-plots",
        "--cache-dir",
        str(tmp_path / "cache"),
    ]
    assert main([*args, "--out", str(tmp_path / "a")]) == 0
    assert main([*args, "--out", str(tmp_path / "b")]) == 0
    a, b = (json.loads((tmp_path / d / "summary.json").read_text()) for d in "ab")
    assert a["dofs"]["omega1_ms"] == 3 * 7 * 8 < a["dofs"]["omega1"]
    assert a["e_u"] < 0.05 and a["e_energy"] < 0.2
    # the second run reuses the cached bases: identical answer, cheaper offline phase
    assert b["e_u"] == a["e_u"] and b["iterations"] == a["iterations"]
    assert b["time_offline_s"] < a["time_offline_s"]
    assert len(list((tmp_path / "cache").iterdir())) == 1
    assert (a["offline_cache"], b["offline_cache"]) == ("built", "loaded")
    # Λ, the smallest local eigenvalue left out, is reported and survives the cache
    assert b["spectral_gap"] == a["spectral_gap"] > 0


@pytest.mark.slow
def test_mixed_ms_offline_cache(tmp_path):
    args = [
        "run",
        "--model",
        "2",
        "--method",
        "mixed-ms",
        "--h",
        "16",
        "--H",
        "4",
        "--layers",
        "1",
        "--reference",
        "--no-plots",
        "--cache-dir",
        str(tmp_path / "cache"),
    ]
    assert main([*args, "--out", str(tmp_path / "a")]) == 0
    assert main([*args, "--out", str(tmp_path / "b")]) == 0
    a, b = (json.loads((tmp_path / d / "summary.json").read_text()) for d in "ab")
    assert (a["offline_cache"], b["offline_cache"]) == ("built", "loaded")
    # the cached patch functions are float32 (they only rebuild the fine fields): e_σ to 1e-6
    assert b["iterations"] == a["iterations"] and b["e_sigma"] == pytest.approx(a["e_sigma"], rel=1e-6)
    assert len(list((tmp_path / "cache").iterdir())) == 1
    assert a["nbasis_per_cell"][0] >= 3 and a["stage_one_gap"] >= 0.1  # the default min_gap
    # --min-gap 0: exactly --nbasis modes per cell (the paper's fixed l), a new cache entry
    assert main([*args, "--min-gap", "0", "--nbasis", "3", "--out", str(tmp_path / "c")]) == 0
    c = json.loads((tmp_path / "c" / "summary.json").read_text())
    assert c["nbasis_per_cell"] == [3, 3] and c["dim_X_ms"] == 3 * 3 * 4
    assert c["offline_cache"] == "built" and len(list((tmp_path / "cache").iterdir())) == 2
    assert main([*args, "--min-gap", "-1", "--out", str(tmp_path / "d")]) == 2


@pytest.mark.parametrize("method", ["mixed", "mixed-ms"])
@pytest.mark.slow
def test_mixed_methods(tmp_path, method):
    out = tmp_path / method
    extra = ["--layers", "2"] if method == "mixed-ms" else []
    code = main(
        [
            "run",
            "--model",
            "2",
            "--method",
            method,
            "--h",
            "16",
            "--H",
            "4",
            "--beta",
            "sqrt-h",
            "--reference",
            "--out",
            str(out),
            *extra,
        ]
    )
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["converged"] is True
    assert summary["e_sigma"] is not None and summary["e_u"] is not None
    if method == "mixed-ms":  # the fine (post-processed) displacement error, far below the coarse e_u
        assert summary["e_u_post"] is not None and summary["e_u_post"] < 0.1 * summary["e_u"]
    else:
        assert summary["e_u_post"] is None
    assert summary["max_tensile_sigma_c"] >= 0.0
    for name in (
        "sigma.bp",
        "u.bp",
        "fields.pvd",
        "contact.pvd",
        "stress.png",
        "displacement.png",
        "deformed.png",
        "contact.png",
        "history.png",
    ):
        assert (out / name).exists(), name


def test_mixed_rejects_bad_beta(tmp_path):
    assert (
        main(
            [
                "run",
                "--method",
                "mixed",
                "--h",
                "16",
                "--H",
                "4",
                "--beta",
                "0",
                "--no-plots",
                "--out",
                str(tmp_path / "x"),
            ]
        )
        == 2
    )


def test_mesh_too_coarse_for_the_load(tmp_path):
    assert main(["run", "--h", "4", "--H", "2", "--no-plots", "--out", str(tmp_path / "x")]) == 2
    assert not (tmp_path / "x" / "summary.json").exists()


def test_a_stored_mesh_runs_as_the_same_built_in_grid(tmp_path):
    """h of a user mesh is √(2·largest cell area), 1/n on an n × n grid: the stored 16 × 16 mesh gets the δ and α of
    --h 16 --H 4 and the same run (before, h was the largest cell diameter, √2/16, so δ and α were √2 off)."""
    from pathlib import Path

    stored = Path(__file__).parents[2] / "meshes" / "unit_square_n16_H4.msh"
    same = ["--H", "4", "--accel", "anderson", "--no-plots"]  # a fixed-point iteration: many iterates to compare
    assert main(["run", "--mesh", str(stored), *same, "--out", str(tmp_path / "file")]) == 0
    assert main(["run", "--h", "16", *same, "--out", str(tmp_path / "built")]) == 0
    a, b = (json.loads((tmp_path / d / "summary.json").read_text()) for d in ("file", "built"))
    assert abs(a["h"] - 1 / 16) < 1e-9 and abs(a["delta"] / b["delta"] - 1) < 1e-9
    assert a["iterations"] == b["iterations"] and abs(a["final_rel_change"] / b["final_rel_change"] - 1) < 1e-6
    assert a["active_set"] == pytest.approx(b["active_set"], abs=1e-9)


def test_default_out_is_one_directory_per_problem_and_method(tmp_path, monkeypatch):
    """Without --out a run writes results/<model N | mesh or case stem>-<method>: after `make demo` filled
    results/model1-primal, a run of another problem or method neither replaces it nor is refused."""
    from pathlib import Path

    from fenics_contact.cli import RunOptions

    monkeypatch.chdir(tmp_path)
    (tmp_path / "results" / "model1-primal").mkdir(parents=True)
    from fenics_contact.io import RUN_MARKER, RUN_MARKER_HEADER

    (tmp_path / "results" / "model1-primal" / RUN_MARKER).write_text(RUN_MARKER_HEADER + "\n")  # an earlier run's
    assert RunOptions().out == Path("results/model1-primal")
    assert RunOptions(method="mixed", model=2).out == Path("results/model2-mixed")
    mesh = tmp_path / "plate.msh"
    mesh.write_text("")
    assert RunOptions(mesh=mesh).out == Path("results/plate-primal")
    assert RunOptions(out=tmp_path / "mine").out == tmp_path / "mine"
