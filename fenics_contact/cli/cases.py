"""Case files on the command line: the problem from ``--case FILE.toml``, the flags overriding it."""

import argparse
import typing
from collections.abc import Mapping
from dataclasses import fields
from pathlib import Path

from fenics_contact.cli.options import _METHOD_OPTIONS, TABLE_METHODS, RunOptions
from fenics_contact.cli.pair import pair_run_options
from fenics_contact.cli.parser import NOT_GIVEN, build_parser
from fenics_contact.errors import InputError
from fenics_contact.problem.case import Case, load_case, parse_override
from fenics_contact.problem.pair_case import PairCase

__all__ = ["case_run_options", "options_from_arguments"]

#: RunOptions fields that describe the problem: with --case each one changes a key of the case
_PROBLEM_FLAGS = {
    "h": "mesh.h",
    "H": "mesh.H",
    "mesh": "mesh",
    "nu": "material.nu",
    "E_map": "material.E",
    "model": "material.model",
    "E_high": "material.E-high",
    "E_low": "material.E-low",
}


def options_from_arguments(args: argparse.Namespace, argv: list[str] | None = None) -> tuple[RunOptions, Case | None]:
    """The validated RunOptions of a command line and, with ``--case``, the Case it runs (InputError otherwise)."""
    if args.case is None:
        if args.set:
            raise InputError("--set changes a key of a case file: it needs --case FILE")
        return RunOptions.from_namespace(args), None
    given = {k: v for k, v in vars(build_parser(given_only=True).parse_args(argv)).items() if v is not NOT_GIVEN}
    case = load_case(args.case, _case_overrides(given))
    if isinstance(case, PairCase):  # two deformable bodies: their own few run options (cli.pair)
        return pair_run_options(case, given), case
    _check_model_flags(case, given)
    return case_run_options(case, given), case


def _check_model_flags(case: Case, given: dict) -> None:
    """InputError when --model, --E-high or --E-low would change nothing: the case gives what they set."""
    material = case.material
    if {"E_high", "E_low"} & set(given) and material.E is not None:
        flag = "--E-high" if "E_high" in given else "--E-low"
        raise InputError(
            f"{flag} sets a built-in model's E, but case {case.path.name} gives material.E, which replaces it: "
            f"leave {flag} out (or change material.E with --set)"
        )
    if "model" in given and None not in (material.E, material.nu, material.body_force):
        raise InputError(
            f"--model {given['model']} would change nothing: case {case.path.name} gives material.E, material.nu "
            "and load.body-force, which replace the model's; leave --model out (or change the case with --set)"
        )


def _case_overrides(given: dict) -> list[tuple[str, object]]:
    """The problem flags as case keys (``--h 16`` -> mesh.h = 16), then the ``--set`` items."""
    overrides = []
    for name, key in _PROBLEM_FLAGS.items():
        if name not in given:
            continue
        value = given[name]
        if name == "mesh":  # a mesh file replaces the [mesh] table
            value = {"file": str(Path(value).resolve())}
        elif name == "E_map":  # the flag's meaning: a pixel map over the unit square
            value = {"pixels": str(Path(value).resolve()), "extent": [0.0, 1.0, 0.0, 1.0]}
        overrides.append((key, value))
    return overrides + [parse_override(text) for text in given.get("set") or ()]


def _run_table_keys() -> dict[str, set[str]]:
    """The RunOptions fields each run table of a case file may set (the method options in their methods' table)."""
    general = {f.name for f in fields(RunOptions)} - set(_PROBLEM_FLAGS) - {"case"} - set(_METHOD_OPTIONS)
    keys = {table: set() for table in TABLE_METHODS} | {"run": general}
    for name, (methods, _) in _METHOD_OPTIONS.items():
        table = next((t for t, m in TABLE_METHODS.items() if t != "run" and set(m) == set(methods)), "run")
        keys[table].add(name)
    return keys


def case_run_options(case: Case, given: Mapping[str, object] = {}) -> RunOptions:
    """RunOptions from the case's run tables ([run] and the chosen method's), then the flags ``given`` (dest -> value).

    Each table is validated on its own (with a method that uses it), so a bad value is reported
    with its table even when the chosen method does not use it.
    """
    keys = _run_table_keys()
    names = {f.name for f in fields(RunOptions)}
    tables = {}
    for table, methods in TABLE_METHODS.items():
        values = {}
        for key, value in case.run[table].items():
            name = key.replace("-", "_")
            if name not in keys[table]:
                home = next((t for t, k in keys.items() if name in k), None)
                hint = f" ({key} belongs in [{home}])" if home else ""
                raise InputError(
                    f"case {case.path}: unknown key '{table}.{key}'{hint}; the keys of [{table}] are "
                    f"{sorted(k.replace('_', '-') for k in keys[table])}"
                )
            values[name] = _run_value(case, f"{table}.{key}", name, value)
        probe = {"method": values.get("method", "primal") if table == "run" else methods[0]}
        if "out" in given:
            probe["out"] = given["out"]
        try:
            RunOptions(**(probe | values))
        except InputError as err:
            raise InputError(f"case {case.path}: [{table}] {err}") from None
        tables[table] = values
    method = given.get("method", tables["run"].get("method", "primal"))
    values = dict(tables["run"])
    for table, methods in TABLE_METHODS.items():
        if table != "run" and method in methods:
            values |= tables[table]
    values |= {k: v for k, v in given.items() if k in names and k not in _PROBLEM_FLAGS and k != "case"}
    if "no_plots" in given:
        values["plots"] = not given["no_plots"]
    return RunOptions(**values, case=case.path)


def _run_value(case: Case, key: str, name: str, value):
    """A run-table value of the type of its RunOptions field (TOML has no argparse to convert it)."""
    annotation = next(f.type for f in fields(RunOptions) if f.name == name)
    kind = next((t for t in (typing.get_args(annotation) or (annotation,)) if t is not type(None)), None)
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind is str and name in ("alpha", "beta") and number:
        return repr(value)  # a coefficient may be written as a number
    if name == "nbasis" and isinstance(value, str):
        return value  # "rigid" or "all" (RunOptions checks the word and the method)
    ok = {
        bool: isinstance(value, bool),
        int: number and isinstance(value, int),
        float: number,
        str: isinstance(value, str),
        Path: isinstance(value, str),
    }.get(kind, True)
    if not ok:
        what = {
            bool: "true or false",
            int: "an integer",
            float: "a number",
            str: "a string",
            Path: "a directory name (a string)",
        }[kind]
        raise InputError(f"case {case.path}: {key} must be {what}, got {value!r}")
    return Path(value) if kind is Path else float(value) if kind is float else value


def _options_echo(options: RunOptions) -> dict:
    """The run options of a case run (case-file spelling), for the summary."""
    echo = {}
    for f in fields(RunOptions):
        if f.name in _PROBLEM_FLAGS or f.name == "case":
            continue
        if f.name in _METHOD_OPTIONS and options.method not in _METHOD_OPTIONS[f.name][0]:
            continue  # not used by this method
        value = options.value(f.name)
        echo[f.name.replace("_", "-")] = str(value) if isinstance(value, Path) else value
    return echo
