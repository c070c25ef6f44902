"""``fenics-contact run --help``: the options in groups, each with the default the code uses."""

import contextlib
import dataclasses
import io
import re

import pytest

from fenics_contact.cli import DEFAULT_H, RunOptions, build_parser
from fenics_contact.cli.options import DEFAULT_COARSE, DEFAULT_COARSE_3D_MS
from fenics_contact.hybrid.options import InterfaceNewtonOptions, IterationOptions
from fenics_contact.methods import METHODS
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.mixed_cem import MixedCEMOptions

GROUPS = ("problem", "method", "iteration", "multiscale", "output")


def _help(*args: str) -> str:
    text = io.StringIO()
    with contextlib.redirect_stdout(text), pytest.raises(SystemExit) as stop:
        build_parser().parse_args([*args, "--help"])
    assert stop.value.code == 0
    return text.getvalue()


def _run_help(command: str = "run") -> dict[str, str]:
    """Each option of ``COMMAND --help`` and its help text (the lines up to the next option), spaces collapsed."""
    body = _help(command).split("exit codes:")[0]
    entries = re.split(r"\n  (?=-)", body)[1:]
    options = {}
    for entry in entries:
        entry = entry.split("\n\n")[0]  # (a blank line ends a group)
        flag = re.findall(r"--[\w-]+", entry.split("  ")[0])[-1]
        options[flag] = " ".join(entry.split())
    return options


def _default(options: dict[str, str], flag: str) -> str:
    match = re.search(r"\(default: (.*)\)$", options[flag])
    assert match, options[flag]
    return match[1]


def test_every_option_of_run_shows_its_default_in_a_group():
    text = _help("run")
    headings = [line.rstrip(":") for line in text.splitlines() if re.fullmatch(r"[a-z]+:", line)]
    assert [h for h in headings if h in GROUPS] == list(GROUPS)
    options = _run_help()
    parser_flags = {"--" + dest.replace("_", "-") for dest in vars(build_parser().parse_args(["run"]))} - {"--command"}
    assert set(options) - {"--help"} == parser_flags
    for flag in parser_flags:
        _default(options, flag)


def test_the_defaults_shown_are_those_of_the_catalogue_and_the_option_dataclasses():
    options = _run_help()
    run = {f.name: f.default for f in dataclasses.fields(RunOptions)}
    iteration = IterationOptions()
    assert float(_default(options, "--tol")) == iteration.tol == run["tol"]
    assert int(_default(options, "--max-iterations")) == iteration.max_iterations == run["max_iterations"]
    assert int(_default(options, "--front-window")) == InterfaceNewtonOptions().front_window
    assert int(_default(options, "--H")) == DEFAULT_COARSE and run["H"] is None  # (None: resolved by RunOptions)
    assert f"{DEFAULT_COARSE_3D_MS} for primal-ms" in options["--H"]
    assert int(_default(options, "--h")) == DEFAULT_H
    assert float(_default(options, "--nu")) == run["nu"]
    assert _default(options, "--method") == run["method"]
    assert int(_default(options, "--layers")) == CEMOptions().layers == MixedCEMOptions().layers
    nbasis = dict(item.split(": ") for item in _default(options, "--nbasis").split("; "))
    assert nbasis == {"primal-ms": CEMOptions().nbasis, "mixed-ms": str(MixedCEMOptions().nbasis)}
    assert float(_default(options, "--min-gap")) == MixedCEMOptions().min_gap
    assert int(_default(options, "--max-nbasis")) == MixedCEMOptions().max_nbasis
    alphas = dict(item.split(": ") for item in _default(options, "--alpha").split("; "))
    assert alphas == {m: METHODS[m].defaults()["alpha"] for m in ("primal", "primal-ms")}
    assert _default(options, "--beta") == METHODS["mixed"].defaults()["beta"] == METHODS["mixed-ms"].defaults()["beta"]
    assert _default(options, "--accel").startswith(METHODS["primal"].default_accel())


def test_the_defaults_shown_are_the_ones_a_run_uses(tmp_path):
    """RunOptions given nothing resolves each option to the value ``--help`` states."""
    options = _run_help()
    for method in ("primal", "primal-ms", "mixed", "mixed-ms"):
        run = RunOptions(method=method, out=tmp_path / method)
        assert run.accel == "newton" and _default(options, "--accel").startswith("newton")
        assert run.n == int(_default(options, "--h")) and run.H == int(_default(options, "--H"))
        if method.endswith("-ms"):
            assert run.value("layers") == int(_default(options, "--layers"))
            assert f"{method}: {run.value('nbasis')}" in _default(options, "--nbasis")
        if method == "mixed-ms":
            assert run.value("min_gap") == float(_default(options, "--min-gap"))
            assert run.value("max_nbasis") == int(_default(options, "--max-nbasis"))
        if METHODS[method].family == "mixed":
            assert run.value("beta") == _default(options, "--beta")
        else:
            assert f"{method}: {run.value('alpha')}" in _default(options, "--alpha")


def test_the_top_level_help_points_to_each_command_help():
    text = _help()
    assert all(command in text for command in ("run", "check-mesh", "examples")) and "COMMAND --help" in text


def test_every_option_of_check_mesh_shows_its_default():
    options = _run_help("check-mesh")
    assert set(options) == {"--help", "--case", "--set", "--method", "--H", "--coarse-groups"}
    for flag in set(options) - {"--help"}:
        _default(options, flag)
    assert int(_default(options, "--H")) == DEFAULT_COARSE
