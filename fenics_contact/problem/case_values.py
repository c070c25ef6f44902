"""Reading a case file's values: typed scalars and vectors with their messages (``Source``, ``Table``), and the
fields a case gives (a number or vector, values by cell group, a pixel map, a Python callable).

``problem.case`` reads a whole case with these; a value that is not what its key asks for is an InputError naming
the file, the key and what was found.
"""

import importlib.util
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fenics_contact.errors import InputError
from fenics_contact.problem.friction import FRICTION_LAWS, Friction

__all__ = [
    "Bad",
    "Source",
    "Table",
    "Uniform",
    "ByGroup",
    "Pixels",
    "PythonField",
    "FieldSpec",
    "show_value",
    "read_number",
    "read_integer",
    "read_vector",
    "read_unit",
    "read_point",
    "read_direction",
    "read_points",
    "read_string",
    "read_strings",
    "read_python",
    "read_pixels",
    "read_extent",
    "read_field",
    "read_motions",
    "read_rollers",
    "read_friction",
    "echo_friction",
]


class Bad(Exception):
    """A value of the wrong type or range (the message completes "KEY ...")."""


# ---------------------------------------------------------------------------------------------
# reading typed values
# ---------------------------------------------------------------------------------------------
def show_value(value) -> str:
    return repr(value) if not isinstance(value, dict) else "a table"


def read_number(*, positive: bool = False, low: float | None = None, high: float | None = None) -> Callable:
    def convert(value) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise Bad(f"must be a finite number, got {show_value(value)}")
        if positive and not value > 0:
            raise Bad(f"must be > 0, got {value!r}")
        if positive and value < sys.float_info.min:  # subnormal: 1/value overflows, products lose all digits
            raise Bad(f"must be at least {sys.float_info.min:.3g} (a normal floating-point number), got {value!r}")
        if (low is not None and not value > low) or (high is not None and not value < high):
            raise Bad(f"must lie in ({low:g}, {high:g}), got {value!r}")
        return float(value)

    return convert


def read_integer(minimum: int) -> Callable:
    def convert(value) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            raise Bad(f"must be an integer >= {minimum}, got {show_value(value)}")
        return int(value)

    return convert


def read_vector(value) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise Bad(f"must be a vector [x, y] of two numbers, got {show_value(value)}")
    return tuple(read_number()(v) for v in value)


def read_unit(value) -> tuple[float, float]:
    v = read_vector(value)
    if math.hypot(*v) == 0.0:
        raise Bad("must be a non-zero vector")
    return v


def read_point(value) -> tuple[float, ...]:
    """A vector of two (2D) or three (3D) numbers: its length is checked against the mesh's dimension later."""
    if not isinstance(value, (list, tuple)) or len(value) not in (2, 3):
        raise Bad(f"must be a vector [x, y] (2D) or [x, y, z] (3D) of numbers, got {show_value(value)}")
    return tuple(read_number()(v) for v in value)


def read_direction(value) -> tuple[float, ...]:
    """A non-zero vector of two or three numbers."""
    v = read_point(value)
    if math.hypot(*v) == 0.0:
        raise Bad("must be a non-zero vector")
    return v


def read_points(value) -> tuple[tuple[float, ...], ...]:
    """A non-empty list of vectors of two or three numbers (each; the lengths are checked together later)."""
    if not isinstance(value, list) or not value:
        raise Bad(
            f"must be a non-empty list of vectors [[dx, dy], ...] or [[dx, dy, dz], ...], got {show_value(value)}"
        )
    return tuple(read_point(v) for v in value)


def read_string(choices: Sequence[str] | None = None) -> Callable:
    def convert(value) -> str:
        if not isinstance(value, str):
            raise Bad(f"must be a string, got {show_value(value)}")
        if choices is not None and value not in choices:
            raise Bad(f"must be one of {list(choices)}, got {value!r}")
        return value

    return convert


def read_strings(choices: Sequence[str]) -> Callable:
    def convert(value) -> tuple[str, ...]:
        if not isinstance(value, (list, tuple)):
            raise Bad(f"must be a list of strings, got {show_value(value)}")
        items = tuple(read_string(choices)(v) for v in value)
        if len(set(items)) != len(items):
            raise Bad(f"lists a value twice: {list(items)}")
        return items

    return convert


class Source:
    """The case file being read: its path and directory (for relative file names) and error messages."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.directory = path.parent

    def error(self, message: str, kind: type = InputError) -> Exception:
        return kind(f"case {self.path}: {message}")

    def file(self, value, key: str) -> Path:
        if not isinstance(value, str) or not value.strip():
            raise self.error(f"{key} must name a file, got {show_value(value)}")
        path = (self.directory / value).resolve()
        if not path.is_file():
            raise self.error(f"{key}: {path} does not exist" if not path.exists() else f"{key}: {path} is not a file")
        return path


class Table:
    """One table of the case: typed reads by key; ``finish`` refuses the keys nobody read."""

    def __init__(self, source: Source, name: str, data) -> None:
        if not isinstance(data, dict):
            raise source.error(f"{name} must be a table ([{name}]), got {show_value(data)}")
        self.source, self.name, self.data, self.known = source, name, dict(data), []

    def key(self, key: str) -> str:
        return f"{self.name}.{key}"

    def has(self, key: str) -> bool:
        return key in self.data

    def get(self, key: str, convert: Callable, default=None, *, required: bool = False):
        self.known.append(key)
        if key not in self.data:
            if required:
                raise self.source.error(f"{self.key(key)} is required")
            return default
        value = self.data.pop(key)
        try:
            return convert(value)
        except Bad as bad:
            raise self.source.error(f"{self.key(key)} {bad}") from None

    def raw(self, key: str):
        self.known.append(key)
        return self.data.pop(key, None)

    def finish(self, what: str = "") -> None:
        if self.data:
            unknown = sorted(self.data)
            raise self.source.error(
                f"unknown key {self.key(unknown[0])!r}{what}; the keys of [{self.name}] are {self.known}"
            )


# ---------------------------------------------------------------------------------------------
# the obstacle's motion and the friction law
# ---------------------------------------------------------------------------------------------
def read_motions(value) -> tuple[tuple[float, float], ...]:
    if not isinstance(value, list) or not value:
        raise Bad(f"must be a non-empty list of vectors [[dx, dy], ...], got {show_value(value)}")
    return tuple(read_vector(v) for v in value)


def read_rollers(source: Source, table) -> tuple[tuple[int, float], ...]:
    """``boundary.rollers = {z = [0.0, 1.0]}``: the planes x_i = c on rollers (u_i = 0, tangentially free)."""
    if table is None:
        return ()
    if not isinstance(table, dict) or not table:
        raise source.error(
            "boundary.rollers must be a table {axis = [values]} of symmetry planes, e.g. {z = [0.0, 1.0]} (u_z = 0 "
            f"on the planes z = 0 and z = 1), got {show_value(table)}"
        )
    planes = []
    for axis, values in sorted(table.items()):
        if axis not in ("x", "y", "z"):
            raise source.error(f"boundary.rollers.{axis}: the axes are x, y and z")
        values = values if isinstance(values, list) else [values]
        try:
            planes += [("xyz".index(axis), read_number()(v)) for v in values]
        except Bad as bad:
            raise source.error(f"boundary.rollers.{axis} {bad}") from None
    return tuple(planes)


def read_friction(source: Source, data) -> Friction | None:
    """The ``[friction]`` table: None (frictionless) without it."""
    if data is None:
        return None
    t = Table(source, "friction", data)
    law = t.get("law", read_string(FRICTION_LAWS), required=True)
    key = "mu" if law == "coulomb" else "threshold"
    value = t.get(key, read_number(), required=True)
    ratio = t.get("stiffness-ratio", read_number(positive=True), 1.0)
    t.finish(f' for law = "{law}"')
    try:
        return Friction(law, **{key: value}, stiffness_ratio=ratio)
    except InputError as error:
        raise source.error(str(error)) from None


def echo_friction(law: Friction | None) -> dict | None:
    """The ``[friction]`` table of a law, for a summary (None: frictionless)."""
    if law is None:
        return None
    value = law.mu if law.law == "coulomb" else law.threshold
    key = "mu" if law.law == "coulomb" else "threshold"
    return {"law": law.law, key: value, "stiffness-ratio": law.stiffness_ratio}


# ---------------------------------------------------------------------------------------------
# fields: a number or vector, by cell group, a pixel map, a Python callable
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Uniform:
    """One value everywhere."""

    value: float | tuple[float, float]

    def echo(self):
        return list(self.value) if isinstance(self.value, tuple) else self.value


@dataclass(frozen=True, slots=True)
class ByGroup:
    """A value per cell group (Omega1, Omega2, or a surface group of the mesh file)."""

    values: tuple[tuple[str, Any], ...]

    def echo(self):
        return {name: list(v) if isinstance(v, tuple) else v for name, v in self.values}


@dataclass(frozen=True, slots=True)
class Pixels:
    """A pixel map ``values[row, col]`` (row 0 at the bottom) over ``extent`` (default: the mesh's bounding box)."""

    path: Path
    values: np.ndarray = field(compare=False, repr=False)
    extent: tuple[float, float, float, float] | None = None

    def echo(self):
        return {
            "pixels": str(self.path),
            "shape": list(self.values.shape),
            "extent": list(self.extent) if self.extent is not None else "bounding box",
        }


@dataclass(frozen=True, slots=True)
class PythonField:
    """A callable ``file.py:name`` (points x (3, N) -> values)."""

    reference: str
    function: Callable = field(compare=False, repr=False)

    def echo(self):
        return {"python": self.reference}


FieldSpec = Uniform | ByGroup | Pixels | PythonField


def read_python(source: Source, key: str, reference) -> PythonField:
    if not isinstance(reference, str) or reference.count(":") != 1:
        raise source.error(f"{key}: a python reference is 'file.py:name', got {show_value(reference)}")
    filename, name = reference.split(":")
    path = source.file(filename, key)
    module_name = f"fenics_contact_case_{abs(hash(str(path)))}"
    module = sys.modules.get(module_name)
    if module is None:
        spec = importlib.util.spec_from_file_location(module_name, path)
        if spec is None or spec.loader is None:
            raise source.error(f"{key}: cannot import {path} as Python")
        module = importlib.util.module_from_spec(spec)
        try:
            spec.loader.exec_module(module)
        except SystemExit as err:  # the user's code ended the process on import: bad input, not the run's end
            raise source.error(f"{key}: importing {path} called sys.exit({err.code!r})") from None
        except Exception as err:  # the user's code: any failure is bad input
            raise source.error(f"{key}: importing {path} failed: {type(err).__name__}: {err}") from None
        sys.modules[module_name] = module
    function = getattr(module, name, None)
    if not callable(function):
        raise source.error(f"{key}: {path} has no callable {name!r}")
    return PythonField(f"{path}:{name}", function)


def read_pixels(source: Source, key: str, table: dict) -> Pixels:
    t = Table(source, key, table)
    path = t.get("pixels", lambda v: source.file(v, f"{key}.pixels"))
    extent = t.get("extent", read_extent)
    t.finish()
    try:
        values = (
            np.load(path, allow_pickle=False)
            if path.suffix == ".npy"
            else np.loadtxt(path, delimiter="," if path.suffix == ".csv" else None, ndmin=2)
        )
        values = np.asarray(values, dtype=np.float64)
    except (OSError, ValueError, EOFError, TypeError) as err:
        raise source.error(
            f"{key}.pixels: cannot read a pixel array from {path}: {type(err).__name__}: {err}"
        ) from None
    if values.ndim != 2 or values.size == 0:
        raise source.error(f"{key}.pixels: {path} must hold a non-empty 2D array, got shape {values.shape}")
    return Pixels(path, values, extent)


def read_extent(value) -> tuple[float, float, float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 4:
        raise Bad(f"must be [x0, x1, y0, y1], got {show_value(value)}")
    x0, x1, y0, y1 = (read_number()(v) for v in value)
    if not (x1 > x0 and y1 > y0):
        raise Bad(f"must have x1 > x0 and y1 > y0, got {list(value)}")
    return x0, x1, y0, y1


def read_field(source: Source, key: str, value, check: Callable, *, vector: bool, pixels: bool = True) -> FieldSpec:
    """A field from its case value; ``check`` validates one value (a number, or a vector)."""

    def checked(v, where):
        try:
            return check(v)
        except Bad as bad:
            raise source.error(f"{where} {bad}") from None

    if isinstance(value, dict):
        if "python" in value:
            if len(value) != 1:
                raise source.error(f"{key}: a python field takes no other keys, got {sorted(value)}")
            return read_python(source, key, value["python"])
        if "pixels" in value:
            if not pixels:
                raise source.error(
                    f"{key}: a pixel map gives a scalar field; give a vector, a table by group or a python callable"
                )
            return read_pixels(source, key, value)
        if not value:
            raise source.error(f"{key} is an empty table: give a value per cell group")
        return ByGroup(tuple((name, checked(v, f"{key}.{name}")) for name, v in sorted(value.items())))
    if vector and not isinstance(value, (list, tuple)) or not vector and isinstance(value, (list, tuple)):
        kind = "a vector [x, y]" if vector else "a number"
        raise source.error(
            f"{key} must be {kind}, a table by cell group or {{python = 'file.py:name'}}, got {show_value(value)}"
        )
    return Uniform(checked(value, key))
