"""A mixed run with --reference reports its errors against both monolithic mixed solutions: the Arnold–Winther one
of the whole body (``e_sigma``, ``e_u``) and the one with σn continuous across γ, the hybrid iteration's own fixed
point (``e_sigma_split``, ``e_u_split``), so that a user tells the iteration's error from the split-γ one."""

import json

from fenics_contact.cli import main


def test_the_summary_separates_the_iterations_error_from_the_split_interfaces(tmp_path):
    out = tmp_path / "mixed"
    assert (
        main(
            [
                "run",
                "--model",
                "1",
                "--h",
                "32",
                "--H",
                "8",
                "--method",
                "mixed",
                "--reference",
                "--tol",
                "1e-10",
                "--no-plots",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    summary = json.loads((out / "summary.json").read_text())
    assert summary["e_sigma_split"] < 1e-9 and summary["e_u_split"] < 1e-9  # the fixed point, to the tolerance
    assert 1e-4 < summary["e_sigma"] < 1e-2  # the split-γ term at h = 1/32 (1.8e-3)
    assert summary["e_sigma_split"] < 1e-3 * summary["e_sigma"]
