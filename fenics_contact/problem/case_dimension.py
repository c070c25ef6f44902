"""The dimension of a case file's values: every vector has the mesh's two or three components, the obstacle's
shape and the built-in model are of its dimension (``problem.case``; the messages name the key).

A built-in mesh has its dimension when the case is read; a mesh file's is known once it is read, and until then
the case's vectors must agree among themselves.
"""

from fenics_contact.errors import InputError
from fenics_contact.problem.case_values import ByGroup, Uniform
from fenics_contact.problem.models import MODELS_3D

__all__ = ["check_dimension", "given_vectors"]


def given_vectors(case) -> list[tuple[str, int]]:
    """(key, number of components) of every vector the case gives (a python field's are its own), and of the
    rollers' axes beyond y (z: three)."""
    found = []

    def field(key: str, spec) -> None:
        if isinstance(spec, Uniform):
            found.append((key, len(spec.value)))
        elif isinstance(spec, ByGroup):
            found.extend((f"{key}.{name}", len(value)) for name, value in spec.values)

    field("load.body-force", case.material.body_force)
    field("boundary.displacement", case.boundary.displacement)
    for name, spec in case.boundary.tractions:
        field(f"boundary.tractions.{name}", spec)
    obstacle = case.obstacle
    for key in ("point", "normal", "centre", "direction"):
        if getattr(obstacle, key) is not None:
            found.append((f"obstacle.{key}", len(getattr(obstacle, key))))
    found.extend((f"obstacle.motion[{k}]", len(m)) for k, m in enumerate(obstacle.motions))
    found.extend(("boundary.rollers.z (an axis)", 3) for axis, _ in case.boundary.rollers if axis == 2)
    return found


def check_dimension(case, dim: int | None, where: str) -> None:
    """InputError naming the key when a vector, the obstacle's shape or the model of ``case`` (a ``case.Case``) is
    not of the mesh's dimension ``dim`` (None: unknown until the mesh file is read; the vectors then agree among
    themselves); ``where`` names the mesh in the message."""
    vectors = given_vectors(case)
    if dim is None:
        if len({n for _, n in vectors}) > 1:
            (k1, n1), (k2, n2) = vectors[0], next(v for v in vectors if v[1] != vectors[0][1])
            raise InputError(
                f"case {case.path}: {k1} has {n1} components but {k2} has {n2}: the vectors of a case all have "
                "the mesh's dimension ([x, y] in 2D, [x, y, z] in 3D)"
            )
        return
    cells = "tetrahedra" if dim == 3 else "triangles"
    shape_dim = {"circle": 2, "sphere": 3}.get(case.obstacle.shape, dim)
    if shape_dim != dim:
        other = "sphere" if dim == 3 else "circle"
        raise InputError(
            f'case {case.path}: obstacle.shape = "{case.obstacle.shape}" is a {shape_dim}D obstacle but {where} '
            f'is {dim}D ({cells}): give shape = "{other}" (or "plane")'
        )
    model = case.material.model
    if model is not None and (model in MODELS_3D) != (dim == 3):
        models = "4 or 5" if dim == 3 else "1, 2 or 3"
        raise InputError(
            f"case {case.path}: material.model = {model} is a {5 - dim}D model but {where} is {dim}D ({cells}): "
            f"give material.model = {models} or the materials themselves"
        )
    for key, n in vectors:
        if n != dim:
            form = "[x, y, z]" if dim == 3 else "[x, y]"
            raise InputError(
                f"case {case.path}: {key} has {n} components but {where} is {dim}D ({cells}): give {dim} "
                f"components, {form}"
            )
