"""The command line with the certificate and the interface Newton: exit 3 instead of a wrong 'converged'."""

import json

import pytest
from mpi4py import MPI

from fenics_contact.cli import main

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="the CLI tests run serially")


def _summary(out):
    return json.loads((out / "summary.json").read_text())


def test_huge_alpha_ends_not_converged(tmp_path):
    """`--h 32 --H 8 --alpha 1e8 --reference` exited 0 after 2 iterations with e_u = 0.79: now exit 3."""
    out = tmp_path / "alpha"
    code = main(
        [
            "run",
            "--h",
            "32",
            "--H",
            "8",
            "--alpha",
            "1e8",
            "--accel",
            "anderson",
            "--max-iterations",
            "40",
            "--reference",
            "--no-plots",
            "--out",
            str(out),
        ]
    )
    s = _summary(out)
    assert code == 3 and s["converged"] is False
    assert s["transmission_residual"] > 1e-6 and s["e_u"] > 1e-3


def test_huge_beta_ends_not_converged(tmp_path):
    out = tmp_path / "beta"
    code = main(
        [
            "run",
            "--method",
            "mixed",
            "--h",
            "16",
            "--H",
            "4",
            "--beta",
            "1e12",
            "--accel",
            "anderson",
            "--max-iterations",
            "30",
            "--no-plots",
            "--out",
            str(out),
        ]
    )
    assert code == 3 and _summary(out)["transmission_residual"] > 1e-6


@pytest.mark.parametrize("method", ["primal", "mixed"])
def test_newton_run_reports_its_certificate(tmp_path, method):
    out = tmp_path / method
    code = main(
        [
            "run",
            "--method",
            method,
            "--model",
            "3",
            "--h",
            "16",
            "--H",
            "4",
            "--accel",
            "newton",
            "--reference",
            "--no-plots",
            "--out",
            str(out),
        ]
    )
    s = _summary(out)
    assert code == 0 and s["converged"] is True and s["accel"] == "newton"
    assert s["transmission_residual"] < 1e-6 and 1 <= s["interface_newton_steps"] <= 8
    assert s["time_interface_offline_s"] > 0 and s["time_offline_s"] >= s["time_interface_offline_s"]
    # Algorithm 1's fixed point is the monolithic solution; Algorithm 2's differs by the X̃_h/X_h space gap
    assert s["e_u"] < (1e-8 if method == "primal" else 1e-3)


@pytest.mark.slow
def test_multiscale_default_alpha_at_contrast_1e6(tmp_path, capsys):
    """`--model 3 --E-high 1e6 --method primal-ms` with the defaults (m = 4, α = Emin·h^-1/2): converged and
    close to the fine solution (α = E·h^-1/2, the former default, gave e_u = 0.33 at h = 1/32; at m = 3 a
    ConvergenceError, exit 4); --alpha with E·h^-1/2 and m = 3 ends with exit 4 and the message naming it."""
    out = tmp_path / "ms"
    code = main(
        [
            "run",
            "--method",
            "primal-ms",
            "--model",
            "3",
            "--E-high",
            "1e6",
            "--h",
            "32",
            "--reference",
            "--no-plots",
            "--out",
            str(out),
        ]
    )
    s = _summary(out)
    assert code == 0 and s["converged"] is True and s["alpha"] == "Emin*h^-1/2" and s["layers"] == 4
    assert s["transmission_residual"] < 1e-6 and s["e_u"] < 0.03
    bad = tmp_path / "bad"
    code = main(
        [
            "run",
            "--method",
            "primal-ms",
            "--model",
            "3",
            "--E-high",
            "1e6",
            "--h",
            "32",
            "--layers",
            "3",
            "--alpha",
            "E*h^-1/2",
            "--no-plots",
            "--out",
            str(bad),
        ]
    )
    assert code == 4 and not bad.exists()
    assert "not positive definite" in capsys.readouterr().err


@pytest.mark.slow
def test_front_options_same_solution_fewer_steps(tmp_path):
    """The contact Newton's front option on the case it was built for, Algorithm 1 on model 3 at contrast 1e6,
    h = 1/128 (a near-rigid channel on Γ_C): the default local front resolution (4 steps measured) and
    `--front-window 0` (the plain semismooth Newton, 8) give the same solution (active set, e_u to 1e-10 of the
    fine solution); the default takes fewer steps than the plain Newton; the option is refused without
    --accel newton, and a negative window always."""
    runs = {}
    for name, flag in (("default", []), ("plain", ["--front-window", "0"])):
        out = tmp_path / name
        code = main(
            [
                "run",
                "--model",
                "3",
                "--E-high",
                "1e6",
                "--h",
                "128",
                "--H",
                "16",
                "--reference",
                "--no-plots",
                "--out",
                str(out),
                *flag,
            ]
        )
        assert code == 0
        runs[name] = _summary(out)
    default, plain = runs["default"], runs["plain"]
    assert default["front_window"] == 8 and plain["front_window"] == 0
    assert default["transmission_residual"] < 1e-6 and default["active_set"] == plain["active_set"]
    assert abs(default["e_u"] - plain["e_u"]) < 1e-10 and default["e_u"] < 1e-8
    assert default["interface_newton_steps"] < plain["interface_newton_steps"]
    assert default["interface_newton_steps"] <= 5
    code = main(
        [
            "run",
            "--h",
            "16",
            "--H",
            "4",
            "--accel",
            "anderson",
            "--front-window",
            "4",
            "--no-plots",
            "--out",
            str(tmp_path / "refused"),
        ]
    )
    assert code == 2 and not (tmp_path / "refused").exists()
    code = main(["run", "--h", "16", "--H", "4", "--front-window", "-1", "--no-plots", "--out", str(tmp_path / "bad")])
    assert code == 2 and not (tmp_path / "bad").exists()
