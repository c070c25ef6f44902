"""The ``[boundary]`` table of a case file: u_D on Gamma_D, the traction of every Gamma_N group and the rollers
(``problem.case``; a value that is not what its key asks for is an InputError naming the key)."""

from dataclasses import dataclass

from fenics_contact.errors import MeshTagError
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.case_meshes import MeshSpec
from fenics_contact.problem.case_values import (
    ByGroup,
    PythonField,
    Source,
    Table,
    Uniform,
    read_field,
    read_point,
    read_rollers,
    show_value,
)
from fenics_contact.problem.tags import is_neumann_name

__all__ = ["Boundary", "read_boundary"]


@dataclass(frozen=True, slots=True)
class Boundary:
    """u_D on Gamma_D (None: clamped) and the traction of every Gamma_N group."""

    displacement: Uniform | PythonField | None = None
    tractions: tuple[tuple[str, Uniform | PythonField], ...] = ()
    rollers: tuple[tuple[int, float], ...] = ()  #: symmetry planes (axis, value): u_axis = 0 there

    def conditions(self, rollers: tuple[tuple[int, float], ...] = ()) -> BoundaryConditions:
        """The conditions, with the mesh's own symmetry planes ``rollers`` added to the case's."""

        def value(spec):
            return spec.value if isinstance(spec, Uniform) else spec.function

        return BoundaryConditions(
            displacement=value(self.displacement) if self.displacement is not None else None,
            tractions={name: value(spec) for name, spec in self.tractions},
            rollers=tuple(dict.fromkeys((*self.rollers, *rollers))),
        )

    def echo(self) -> dict:
        out = {
            "displacement": self.displacement.echo() if self.displacement else "clamped",
            "tractions": {name: spec.echo() for name, spec in self.tractions},
        }
        if self.rollers:
            out["rollers"] = {"xyz"[axis]: [v for a, v in self.rollers if a == axis] for axis, _ in self.rollers}
        return out


def _vector_or_python(source: Source, key: str, value) -> Uniform | PythonField:
    spec = read_field(source, key, value, read_point, vector=True, pixels=False)
    if isinstance(spec, ByGroup):
        raise source.error(f"{key} must be a vector [x, y] or [x, y, z] or {{python = 'file.py:name'}}, got a table")
    return spec


def read_boundary(source: Source, data, mesh: MeshSpec) -> Boundary:
    """The conditions of the ``[boundary]`` table ``data``; the tractions match ``mesh``'s Gamma_N groups when
    it knows them before it is built."""
    t = Table(source, "boundary", data or {})
    displacement = t.raw("displacement")
    tractions = t.raw("tractions")
    rollers = read_rollers(source, t.raw("rollers"))
    t.finish()
    displacement = (
        _vector_or_python(source, "boundary.displacement", displacement) if displacement is not None else None
    )
    if tractions is not None and not isinstance(tractions, dict):
        raise source.error(
            f"boundary.tractions must be a table {{Gamma_N_<label> = [tx, ty]}}, got {show_value(tractions)}"
        )
    pairs = []
    for name, value in sorted((tractions or {}).items()):
        if not is_neumann_name(name):
            raise source.error(
                f"boundary.tractions.{name}: a traction group is named 'Gamma_N' or "
                "'Gamma_N_<label>' (a facet group of the mesh)"
            )
        pairs.append((name, _vector_or_python(source, f"boundary.tractions.{name}", value)))
    known = mesh.traction_groups
    if known is not None:
        for name, _ in pairs:
            if name not in known:
                raise source.error(
                    f"boundary.tractions.{name}: the mesh has no traction group {name!r} (its groups: "
                    f"{sorted(known)}; on the unit square name one with mesh.neumann)",
                    MeshTagError,
                )
        given = {name for name, _ in pairs}
        if known - given:
            raise source.error(
                f"the mesh has the traction group {sorted(known - given)[0]!r} but "
                "boundary.tractions gives it no traction"
            )
    return Boundary(displacement, tuple(pairs), rollers)
