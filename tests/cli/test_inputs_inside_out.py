"""The run replaces --out whole: an input kept inside it (the cache directory, the case file) is refused before
the solve (exit 2), and nothing is deleted."""

from pathlib import Path

from fenics_contact.cli import main

CASES = Path(__file__).resolve().parents[2] / "cases"


def test_a_cache_directory_inside_out_is_refused(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(
        [
            "run",
            "--case",
            str(CASES / "bar.toml"),
            "--method",
            "primal-ms",
            "--no-plots",
            "--out",
            str(out),
            "--cache-dir",
            str(out / "cache"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "--cache-dir" in err and "inside --out" in err, err
    assert not out.exists()


def test_a_case_file_inside_a_previous_run_is_refused_and_kept(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", "--case", str(CASES / "bar.toml"), "--set", "mesh.h=8", "--no-plots", "--out", str(out)]) == 0
    case = out / "bar.toml"
    case.write_text((CASES / "bar.toml").read_text().replace("h = 32", "h = 8"))
    assert main(["run", "--case", str(case), "--no-plots", "--out", str(out)]) == 2
    assert case.is_file() and (out / "summary.json").is_file()
