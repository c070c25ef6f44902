"""Cellwise material data on a mesh, fields given as DOLFINx functions or by cell tag, and copies of P1 data
between a mesh and its submeshes.

Every material field of a problem is a callable x (3, N) -> values, evaluated at cell midpoints
(``cell_function``: DG0 interpolation) on the mesh, its parts and its replicas. A field given as a
DOLFINx ``Function`` (``FunctionField``: the function's values at the points, found by a bounding-box
search of its mesh) or as values by cell tag (``tag_function``) becomes such a callable, so it serves
every mesh whose cells lie in the function's (a submesh, or the mesh itself).
"""

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, NamedTuple

import basix.ufl
import numpy as np
from dolfinx import fem, geometry, la
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.materials import check_poisson_ratio, check_youngs_modulus, lame
from fenics_contact.problem.obstacles import Obstacle

if TYPE_CHECKING:  # (problem.problem builds its fields with material_fields)
    from fenics_contact.problem.problem import ContactProblem

__all__ = [
    "MaterialFields",
    "cell_function",
    "material_fields",
    "FunctionField",
    "tag_function",
    "SubmeshTransfer",
    "zero_load",
]


def zero_load(x: np.ndarray) -> np.ndarray:
    """f = 0: the default body force (two components when called; ``material_fields`` gives it the mesh's
    dimension, so it serves the plane and the 3D problems)."""
    return np.zeros((2, x.shape[1]))


class MaterialFields(NamedTuple):
    """Piecewise-constant (DG0) E, ν, λ, μ and body force f on a mesh, with the model's boundary data.

    ``boundary`` (Γ_D displacement, Γ_N tractions) and ``obstacle`` (None: a wall flush
    with Γ_C) ride along so that every subproblem built from the fields sees them.
    """

    E: fem.Function
    nu: fem.Function
    lmbda: fem.Function
    mu: fem.Function
    f: fem.Function
    boundary: BoundaryConditions = BoundaryConditions()
    obstacle: Obstacle | None = None


def cell_function(msh: dmesh.Mesh, field: Callable[[np.ndarray], np.ndarray], *, shape=(), name="") -> fem.Function:
    """A DG0 function with the values of ``field`` at the cell midpoints; InputError when ``field`` raises or
    returns values of another shape, not real numbers, or not finite ones."""
    V = fem.functionspace(msh, basix.ufl.element("DG", msh.basix_cell(), 0, shape=shape))
    fn = fem.Function(V, name=name)
    fn.interpolate(_checked(field, shape, name or "given"))
    fn.x.scatter_forward()
    return fn


def _checked(field: Callable[[np.ndarray], np.ndarray], shape: tuple, name: str) -> Callable:
    """``field`` with its values checked: shape ``(*shape, N)`` for N points (``(N,)`` for a scalar), real, finite."""

    def evaluate(x: np.ndarray) -> np.ndarray:
        expected = (*shape, x.shape[1])
        try:
            values = field(x)
        except SystemExit as err:  # the user's callable ended the process: a bad input too, not the run's end
            raise InputError(f"the field {name} called sys.exit({err.code!r}) at the cell midpoints") from None
        except Exception as err:  # the user's callable: any error it raises is a bad input
            raise InputError(
                f"the field {name} raised {type(err).__name__} at the cell midpoints: "
                f"{str(err).splitlines()[0] if str(err) else ''}"
            ) from None
        values = np.asarray(values)
        if values.shape != expected:
            raise InputError(
                f"the field {name} must map points x of shape (3, N) to values of shape "
                f"({', '.join([*map(str, shape), 'N'])}{',' if not shape else ''}), got shape "
                f"{values.shape} for N = {x.shape[1]}"
            )
        if (
            not (np.issubdtype(values.dtype, np.floating) or np.issubdtype(values.dtype, np.integer))
            or values.dtype == np.bool_
        ):
            raise InputError(f"the field {name} must give real numbers, got values of type {values.dtype}")
        if not np.all(np.isfinite(values)):
            bad = np.argmax(~np.isfinite(values.reshape(-1, x.shape[1])).all(axis=0))
            raise InputError(
                f"the field {name} is not finite at {np.count_nonzero(~np.isfinite(values))} "
                f"value(s) (first at x = {x[:, bad].tolist()})"
            )
        return values.astype(np.float64)

    return evaluate


class FunctionField:
    """x ↦ the values of the DOLFINx function ``fn`` at the points x: shape (N,) for a scalar, (bs, N) else.

    Points are located in the cells of ``fn``'s mesh held by this rank (owned and ghost), as the midpoints
    of the cells of that mesh and of its submeshes are; a point outside them is an InputError.
    """

    def __init__(self, fn: fem.Function) -> None:
        if not isinstance(fn, fem.Function):
            raise InputError(f"a field given as a function must be a dolfinx.fem.Function, got {type(fn).__name__}")
        self.fn = fn
        msh = fn.function_space.mesh
        imap = msh.topology.index_map(msh.topology.dim)
        cells = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
        self._tree = geometry.bb_tree(msh, msh.topology.dim, entities=cells)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        msh = self.fn.function_space.mesh
        points = np.ascontiguousarray(x.T, dtype=np.float64)
        candidates = geometry.compute_collisions_points(self._tree, points)
        colliding = geometry.compute_colliding_cells(msh, candidates, points)
        counts = np.diff(colliding.offsets)
        if np.any(counts == 0):
            where = points[np.argmax(counts == 0)]
            raise InputError(
                f"the field {self.fn.name!r} is asked for at {np.count_nonzero(counts == 0)} points "
                f"outside its mesh (first at {where.tolist()}): give it on the problem's mesh"
            )
        cells = colliding.array[colliding.offsets[:-1]]
        values = self.fn.eval(points, cells)
        return values[:, 0] if values.shape[1] == 1 and not self.fn.function_space.value_shape else values.T


def tag_function(
    msh: dmesh.Mesh, cell_tags: dmesh.MeshTags, values: Mapping[int, float], *, name: str = ""
) -> fem.Function:
    """A DG0 function with ``values[tag]`` on the cells of each tag (InputError when a cell gets no value)."""
    if not isinstance(cell_tags, dmesh.MeshTags) or cell_tags.dim != msh.topology.dim:
        raise InputError(
            f"{name or 'a field'} by cell tag needs the mesh's cell tags (MeshTags of dimension {msh.topology.dim})"
        )
    V = fem.functionspace(msh, basix.ufl.element("DG", msh.basix_cell(), 0))
    fn = fem.Function(V, name=name)
    fn.x.array[:] = np.nan
    for tag, value in values.items():
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not np.isfinite(value):
            raise InputError(
                f"{name or 'a field'}: the value for cell tag {tag!r} must be a finite number, got {value!r}"
            )
        cells = cell_tags.find(int(tag))
        fn.x.array[V.dofmap.list[cells, 0]] = float(value)
    n_owned = msh.topology.index_map(msh.topology.dim).size_local
    missing = msh.comm.allreduce(int(np.count_nonzero(np.isnan(fn.x.array[:n_owned]))), op=MPI.SUM)
    if missing:
        present = sorted({int(t) for t in np.unique(cell_tags.values)})
        raise InputError(
            f"{name or 'a field'} by cell tag: {missing} cells get no value (the values are given for "
            f"tags {sorted(values)}; the mesh's cell tags are {present}); give a value for every tag"
        )
    fn.x.scatter_forward()
    return fn


def material_fields(msh: dmesh.Mesh, model: "ContactProblem") -> MaterialFields:
    """DG0 material fields of the problem ``model`` on ``msh`` (``ContactProblem.fields_on`` keeps them);
    raises InputError on E ≤ 0 or ν ∉ (−1, ½)."""
    E = cell_function(msh, model.youngs_modulus, name="E")
    nu = cell_function(msh, model.poisson_ratio, name="nu")
    check_youngs_modulus(E.x.array)
    check_poisson_ratio(nu.x.array)
    lm, mu_ = lame(E.x.array, nu.x.array)
    lmbda = fem.Function(E.function_space, name="lambda")
    mu = fem.Function(E.function_space, name="mu")
    lmbda.x.array[:] = lm
    mu.x.array[:] = mu_
    gdim = msh.geometry.dim
    f = cell_function(
        msh,
        model.load if model.load is not zero_load else (lambda x: np.zeros((gdim, x.shape[1]))),
        shape=(gdim,),
        name="f",
    )
    return MaterialFields(E, nu, lmbda, mu, f, model.boundary, model.obstacle)


class SubmeshTransfer:
    """Copies Lagrange data between a space on a submesh and the same space on its parent mesh."""

    def __init__(self, V_parent: fem.FunctionSpace, V_sub: fem.FunctionSpace, cell_map: dmesh.EntityMap) -> None:
        cell_map_sub = V_sub.mesh.topology.index_map(V_sub.mesh.topology.dim)
        sub_cells = np.arange(cell_map_sub.size_local + cell_map_sub.num_ghosts, dtype=np.int32)
        parent_cells = np.asarray(cell_map.sub_topology_to_topology(sub_cells, False), dtype=np.int32)
        bs = V_sub.dofmap.index_map_bs
        assert bs == V_parent.dofmap.index_map_bs
        ds = V_sub.dofmap.list[sub_cells].ravel()
        dp = V_parent.dofmap.list[parent_cells].ravel()
        sub_idx, first = np.unique(ds, return_index=True)
        par_idx = dp[first]
        self.sub = (bs * sub_idx[:, None] + np.arange(bs)).ravel()
        self.parent = (bs * par_idx[:, None] + np.arange(bs)).ravel()
        self.V_parent = V_parent
        self.V_sub = V_sub

    def to_sub(self, u_parent: fem.Function, u_sub: fem.Function) -> None:
        """u_sub ← u_parent on every submesh DOF (parent ghosts must be up to date)."""
        u_sub.x.array[self.sub] = u_parent.x.array[self.parent]
        u_sub.x.scatter_forward()

    def to_parent(self, u_sub: fem.Function, u_parent: fem.Function) -> None:
        """u_parent ← u_sub on every parent DOF of the submesh; other parent DOFs keep their value.

        Collective and ghost-consistent: a DOF owned by a rank whose local cells do
        not cover it receives the value from the rank that holds it as a ghost.
        """
        V = self.V_parent
        acc = la.vector(V.dofmap.index_map, V.dofmap.index_map_bs)
        cnt = la.vector(V.dofmap.index_map, V.dofmap.index_map_bs)
        u_sub.x.scatter_forward()
        acc.array[self.parent] = u_sub.x.array[self.sub]
        cnt.array[self.parent] = 1.0
        acc.scatter_reverse(la.InsertMode.add)
        cnt.scatter_reverse(la.InsertMode.add)
        n = V.dofmap.index_map.size_local * V.dofmap.index_map_bs
        hit = cnt.array[:n] > 0
        u_parent.x.array[:n][hit] = acc.array[:n][hit] / cnt.array[:n][hit]
        u_parent.x.scatter_forward()
