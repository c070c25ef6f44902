"""Cellwise material data on a mesh, and copies of P1 data between a mesh and its submeshes."""

from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

import basix.ufl
from dolfinx import fem, la
from dolfinx import mesh as dmesh

from fenics_contact.errors import InputError
from fenics_contact.problem.boundary import BoundaryConditions
from fenics_contact.problem.materials import check_poisson_ratio, check_youngs_modulus, lame
from fenics_contact.problem.obstacles import Obstacle

if TYPE_CHECKING:  # (problem.problem builds its fields with material_fields)
    from fenics_contact.problem.problem import ContactProblem

__all__ = ["MaterialFields", "cell_function", "material_fields", "SubmeshTransfer"]


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
    """A DG0 function with the values of ``field`` at the cell midpoints."""
    V = fem.functionspace(msh, basix.ufl.element("DG", msh.basix_cell(), 0, shape=shape))
    fn = fem.Function(V, name=name)
    try:
        fn.interpolate(field)
    except (TypeError, ValueError, IndexError, RuntimeError) as err:
        expected = "(" + ", ".join([*map(str, shape), "N"]) + (",)" if not shape else ")")
        raise InputError(f"the field {name or 'given'} must map points x of shape (3, N) to values of shape "
                         f"{expected}: {type(err).__name__}: {str(err).splitlines()[0]}") from None
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
    f = cell_function(msh, model.load, shape=(msh.geometry.dim,), name="f")
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
