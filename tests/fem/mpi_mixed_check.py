"""Mixed (Arnold–Winther) solves on a distributed mesh: key numbers as JSON (rank 0), fields to an .npz file.

Used by test_mpi_mixed.py, once serially and under ``mpiexec -n 2`` / ``-n 3``; the numbers must agree.

    python tests/fem/mpi_mixed_check.py OUT.npz CASE [CASE ...]

Cases: ``mono-1``, ``mono-2`` (models 1, 2 on unit_square(16, 4)), ``mono-free`` (model 1 with only the
left side clamped: traction-free top and bottom), ``mono-bc`` (u_D, two traction groups, a curved gap:
the manufactured problem of test_boundary_conditions.py), ``hybrid-1``, ``hybrid-2``, ``hybrid-free``
(the same meshes with h = 1/8: Algorithm 2 to tolerance 1e-10 against the split-interface monolithic solve), ``rates`` (AW rates on
unit squares 4, 8, 16), ``indent`` (mixed monolithic Hertz load steps: a moving obstacle).  Fields are stored as the DG values of every owned cell, sorted by (input cell
number, node coordinates), so that runs on any number of ranks compare entry by entry.
"""

import json
import sys
from pathlib import Path

import fenics_contact  # noqa: F401
import numpy as np
import ufl
from mpi4py import MPI

from dolfinx import fem

sys.path[:0] = [str(Path(__file__).parent), str(Path(__file__).parents[1])]
import manufactured  # noqa: E402

from fenics_contact.fem.mixed import solve_mixed_monolithic  # noqa: E402
from fenics_contact.hybrid.iteration import IterationOptions  # noqa: E402
from fenics_contact.problem.geometry import unit_square  # noqa: E402
from fenics_contact.problem.models import get_model  # noqa: E402

COMM = MPI.COMM_WORLD


def sorted_values(f: fem.Function) -> np.ndarray:
    """Values of a DG function at its nodes, all owned cells of all ranks, in a partition-independent order."""
    V = f.function_space
    msh = V.mesh
    tdim = msh.topology.dim
    nc = msh.topology.index_map(tdim).size_local
    bs = V.dofmap.bs
    dofs = V.dofmap.list[:nc]
    orig = np.repeat(np.asarray(msh.topology.original_cell_index[:nc], dtype=np.int64), dofs.shape[1])
    x = V.tabulate_dof_coordinates()[dofs.ravel(), :2]
    vals = f.x.array.reshape(-1, bs)[dofs.ravel()]
    parts = COMM.gather((orig, x, vals), root=0)
    if COMM.rank != 0:
        return np.zeros((0, bs))
    orig = np.concatenate([p[0] for p in parts])
    x = np.concatenate([p[1] for p in parts])
    vals = np.concatenate([p[2] for p in parts])
    order = np.lexsort((np.round(x[:, 1], 10), np.round(x[:, 0], 10), orig))
    return vals[order]


def mesh_and_model(name: str, n: int = 16):
    if name == "1":
        return unit_square(n, 4), get_model(1)
    if name == "2":
        return unit_square(n, 4), get_model(2)
    if name == "free":
        return unit_square(n, 4, clamped=("left",)), get_model(1)
    if name == "bc":
        return manufactured.manufactured_mesh(8), manufactured.manufactured_model()
    raise SystemExit(f"unknown case {name}")


def profile_data(profile) -> dict:
    return {"sigma_c": profile.sigma_c.tolist(), "active": profile.active.astype(int).tolist(),
            "y": profile.y.tolist()}


def mono(name: str, fields: dict) -> dict:
    cm, model = mesh_and_model(name)
    sol = solve_mixed_monolithic(model.on(cm))
    prob = sol.problem
    fields[f"mono-{name}-sigma"] = sorted_values(sol.sigma)
    fields[f"mono-{name}-u"] = sorted_values(sol.u)
    return {
        "newton_steps": sol.newton.steps, "active_sizes": sol.newton.active_sizes,
        "step_lengths": sol.newton.step_lengths, "energies": sol.newton.energies,
        "stress_norm2": prob.stress_norm2(prob.c), "l2_norm2": prob.l2_norm2(prob.u),
        "dofs": sol.dofs, **profile_data(sol.profile),
    }


def hybrid(name: str, fields: dict) -> dict:
    from fenics_contact.hybrid.mixed import solve_mixed_hybrid

    cm, model = mesh_and_model(name, 8)
    ref = solve_mixed_monolithic(model.on(cm), split_interface=True)
    res = solve_mixed_hybrid(model.on(cm), reference=ref, options=IterationOptions(tol=1e-10, accel="anderson"))
    fields[f"hybrid-{name}-sigma"] = sorted_values(res.sigma)
    fields[f"hybrid-{name}-u"] = sorted_values(res.u)
    fields[f"hybrid-{name}-ref-sigma"] = sorted_values(ref.sigma)
    # the γ mass matrix (the certificate's norm) on the interface data of f = (y³, 1 + y): exact for P3 data
    s1 = res.step.sub[0]
    g0, g1 = s1.interface_range
    y = s1.gamma_points[:, 1]
    f = np.stack([y**3, 1.0 + y], axis=1).ravel()[g0:g1]
    gamma_f2 = COMM.allreduce(float(f @ (s1.gamma_mass_matrix() @ f)), op=MPI.SUM)
    return {
        "gamma_f2": gamma_f2,
        "iterations": res.iterations, "converged": res.converged,
        "newton": [r.info["newton"] for r in res.history.records],
        "newton_active": [r.info["active"] for r in res.history.records],
        "rel_changes": res.history.rel_changes.tolist(), "e_sigma": res.e_sigma, "e_u": res.e_u,
        "dofs": res.dofs, **profile_data(res.profile),
    }


def indent(fields: dict) -> dict:
    """The Hertz cylinder pressed into a block in two load steps (a moving obstacle), mixed monolithic."""
    from fenics_contact.indentation import force_indentation
    from fenics_contact.problem.analytic import hertz_model
    from fenics_contact.problem.meshes import hertz_block

    block, _ = hertz_block(0.05, refinement=0.5)
    curve = force_indentation(hertz_model(radius=5.0, depth=0.0).on(block), "mixed-monolithic", [6e-4, 1.2e-3],
                              direction=(0.0, -1.0))
    last = curve.steps[-1].profile
    return {"forces": curve.forces.tolist(), "newton": [s.iterations for s in curve.steps],
            "zone": last.contact_zone(), **profile_data(last)}


def rates(fields: dict) -> dict:
    import aw_fields as aw

    from fenics_contact.fem.arnold_winther import ArnoldWintherSpace, lame_parameters, solve_mixed_elasticity

    def l2(expr, dx):
        return float(np.sqrt(COMM.allreduce(fem.assemble_scalar(fem.form(ufl.inner(expr, expr) * dx)), op=MPI.SUM)))

    out = {}
    cases = {
        "dirichlet": (aw.locking_displacement(lame_parameters(1.0, 0.3)[0]), {}),
        "traction_free": (aw.free_displacement, {"zero_traction_facets": "right"}),
        "sliding": (aw.sliding_displacement, {"zero_tangential_facets": "right"}),
    }
    for key, (u_fn, kw) in cases.items():
        errs = []
        for n in (4, 8, 16):
            msh = aw.unit_square(n, warp=0.03)
            space = ArnoldWintherSpace(msh, **{k: aw.side_facets(msh, 0.0, v) for k, v in kw.items()})
            u, sigma, f = aw.exact_fields(msh, u_fn, 1.0, 0.3)
            sol = solve_mixed_elasticity(space, E=1.0, nu=0.3, f=f, u_D=u)
            dx = ufl.dx(domain=msh, metadata={"quadrature_degree": 8})
            S = space.stress(sol.sigma)
            errs.append([l2(u - sol.u, dx), l2(sigma - S, dx), l2(ufl.div(S) + f, dx)])
        e = np.array(errs)
        out[key] = {"errors": e.tolist(), "rates": np.log2(e[:-1] / e[1:]).tolist(), "dofs": space.num_dofs}
    return out


def main() -> None:
    path, cases = sys.argv[1], sys.argv[2:]
    fields: dict = {}
    out = {"ranks": COMM.size}
    for case in cases:
        kind, _, name = case.partition("-")
        if kind == "mono":
            out[case] = mono(name, fields)
        elif kind == "hybrid":
            out[case] = hybrid(name, fields)
        elif kind == "rates":
            out[case] = rates(fields)
        elif kind == "indent":
            out[case] = indent(fields)
        else:
            raise SystemExit(f"unknown case {case}")
    if COMM.rank == 0:
        np.savez(path, **fields)
        print("RESULT " + json.dumps(out))


if __name__ == "__main__":
    main()
