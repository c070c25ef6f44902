"""The ``[material]`` and ``[load]`` tables of a case file: the moduli (fields or a built-in model's) and the
body force (``problem.case``; a value that is not what its key asks for is an InputError naming the key)."""

from dataclasses import dataclass

from fenics_contact.problem.case_values import (
    ByGroup,
    FieldSpec,
    Source,
    Table,
    read_field,
    read_integer,
    read_number,
    read_point,
)
from fenics_contact.problem.models import MODELS_3D

__all__ = ["Material", "read_material"]


@dataclass(frozen=True, slots=True)
class Material:
    """Young's modulus and Poisson ratio (fields), or a built-in model's, and the body force."""

    E: FieldSpec | None = None
    nu: FieldSpec | None = None
    model: int | None = None
    E_high: float | None = None
    E_low: float | None = None
    body_force: FieldSpec | None = None

    def groups(self) -> set[str]:
        return {name for f in (self.E, self.nu, self.body_force) if isinstance(f, ByGroup) for name, _ in f.values}

    def echo(self) -> dict:
        out = {"E": self.E.echo() if self.E else None, "nu": self.nu.echo() if self.nu else None}
        if self.model is not None:
            out |= {"model": self.model, "E-high": self.E_high, "E-low": self.E_low}
        return out


_MODELS = (1, 2, 3, *MODELS_3D)


def read_material(source: Source, data, load) -> Material:
    """The material of the ``[material]`` table ``data`` with the body force of the ``[load]`` table ``load``."""
    t = Table(source, "material", data or {})
    model = t.get("model", read_integer(1))
    if model is not None and model not in _MODELS:
        raise source.error(f"material.model must be 1, 2 or 3 (2D) or 4 or 5 (3D) (the built-in models), got {model}")
    E_high = t.get("E-high", read_number(positive=True))
    E_low = t.get("E-low", read_number(positive=True))
    if model is None and (E_high is not None or E_low is not None):
        raise source.error("material.E-high and material.E-low set a built-in model's moduli: they need material.model")
    E = t.raw("E")
    nu = t.raw("nu")
    E = read_field(source, "material.E", E, read_number(positive=True), vector=False) if E is not None else None
    nu = (
        read_field(source, "material.nu", nu, read_number(low=-1.0, high=0.5), vector=False) if nu is not None else None
    )
    if model is None and (E is None or nu is None):
        raise source.error(f"material.{'E' if E is None else 'nu'} is required (or material.model = 1, ..., 5)")
    t.finish()
    lt = Table(source, "load", load or {})
    force = lt.raw("body-force")
    lt.finish()
    force = (
        read_field(source, "load.body-force", force, read_point, vector=True, pixels=False)
        if force is not None
        else None
    )
    return Material(E, nu, model, E_high if model else None, E_low if model else None, force)
