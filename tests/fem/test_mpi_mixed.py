"""The mixed method on two and three ranks gives the serial answer (the same solves on COMM_SELF).

Monolithic mixed contact (models 1 and 2, a mesh with traction-free sides, the manufactured problem with
u_D, tractions and a curved gap) and Algorithm 2: the same Newton steps, active sets and iterations, and
stresses and displacements equal to 1e-10 of their size; Arnold–Winther rates unchanged on 2 ranks; the
CLI (``mpiexec -n 2 fenics-contact run --method mixed``) writes the serial summary, fields and plots.

Fields are compared as the DG values of every owned cell, sorted by (input cell number, node coordinates), so
that runs on any number of ranks compare entry by entry.  The round-off floor of these comparisons is set by the
problem, not by the partition: the serial solve with another MUMPS ordering (METIS instead of AMF) differs from
the default one by 4e-11 (σ at the DG nodes, relative to max |σ|) and 9e-11 (σ_c, relative to max |σ_c|) on
model 1 (ε = 1e-3·h, h = 1/16); the distributed runs differ from the serial one by the same amounts.
"""

import aw_fields as aw
import numpy as np
import pytest
import pyvista
import ufl
from dolfinx import fem
from manufactured import manufactured_mesh, manufactured_model
from matplotlib.image import imread
from mpi4py import MPI
from mpi_jobs import on_every_rank, run_summary, serial_cli

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.cli import main
from fenics_contact.fem.arnold_winther import ArnoldWintherSpace, lame_parameters, solve_mixed_elasticity
from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.hybrid.iteration import InterfaceNewtonOptions, IterationOptions
from fenics_contact.hybrid.mixed import solve_mixed_hybrid
from fenics_contact.indentation import force_indentation
from fenics_contact.problem.analytic import hertz_model
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.meshes import hertz_block
from fenics_contact.problem.models import get_model

MONO = ["1", "2", "free", "bc"]
HYBRID = ["1", "2", "free"]
RATES = np.array([2.0, 3.0, 2.0])  # ‖u − u_h‖, ‖σ − σ_h‖, ‖div(σ − σ_h)‖
TOL = 1e-10


def sorted_values(f: fem.Function) -> np.ndarray:
    """Values of a DG function at its nodes, all owned cells of all ranks, in a partition-independent order."""
    V = f.function_space
    msh = V.mesh
    nc = msh.topology.index_map(msh.topology.dim).size_local
    bs = V.dofmap.bs
    dofs = V.dofmap.list[:nc]
    orig = np.repeat(np.asarray(msh.topology.original_cell_index[:nc], dtype=np.int64), dofs.shape[1])
    x = V.tabulate_dof_coordinates()[dofs.ravel(), :2]
    vals = f.x.array.reshape(-1, bs)[dofs.ravel()]
    parts = msh.comm.allgather((orig, x, vals))
    orig, x, vals = (np.concatenate([p[k] for p in parts]) for k in range(3))
    return vals[np.lexsort((np.round(x[:, 1], 10), np.round(x[:, 0], 10), orig))]


def mesh_and_model(name: str, comm: MPI.Comm, n: int = 16):
    if name == "bc":
        return manufactured_mesh(8, comm), manufactured_model()
    clamped = {"clamped": ("left",)} if name == "free" else {}
    return unit_square(n, 4, comm=comm, **clamped), get_model(2 if name == "2" else 1)


def profile_data(profile) -> dict:
    return {"sigma_c": profile.sigma_c.tolist(), "active": profile.active.astype(int).tolist(), "y": profile.y.tolist()}


def mono(name: str, comm: MPI.Comm) -> dict:
    cm, model = mesh_and_model(name, comm)
    sol = solve_mixed_monolithic(model.on(cm))
    prob = sol.problem
    return {
        "newton_steps": sol.newton.steps,
        "active_sizes": sol.newton.active_sizes,
        "step_lengths": sol.newton.step_lengths,
        "energies": sol.newton.energies,
        "stress_norm2": prob.stress_norm2(prob.c),
        "l2_norm2": prob.l2_norm2(prob.u),
        "dofs": sol.dofs,
        **profile_data(sol.profile),
        "sigma": sorted_values(sol.sigma),
        "u": sorted_values(sol.u),
    }


def hybrid(name: str, comm: MPI.Comm) -> dict:
    cm, model = mesh_and_model(name, comm, 8)
    ref = solve_mixed_monolithic(model.on(cm), split_interface=True)
    res = solve_mixed_hybrid(model.on(cm), reference=ref, options=IterationOptions(tol=1e-10, accel="anderson"))
    # the γ mass matrix (the certificate's norm) on the interface data of f = (y³, 1 + y): exact for P3 data
    s1 = res.step.sub[0]
    g0, g1 = s1.interface_range
    y = s1.gamma_points[:, 1]
    f = np.stack([y**3, 1.0 + y], axis=1).ravel()[g0:g1]
    return {
        "gamma_f2": comm.allreduce(float(f @ (s1.gamma_mass_matrix() @ f)), op=MPI.SUM),
        "iterations": res.iterations,
        "converged": res.converged,
        "newton": [r.info["newton"] for r in res.history.records],
        "newton_active": [r.info["active"] for r in res.history.records],
        "rel_changes": res.history.rel_changes.tolist(),
        "e_sigma": res.e_sigma,
        "e_u": res.e_u,
        "dofs": res.dofs,
        **profile_data(res.profile),
        "sigma": sorted_values(res.sigma),
        "u": sorted_values(res.u),
        "ref-sigma": sorted_values(ref.sigma),
    }


def hybrid_newton(name: str, comm: MPI.Comm) -> dict:
    """Algorithm 2 with the interface Newton (strategy ``name``, the default update) to 1e-10 against the split
    monolithic solution (its exact fixed point)."""
    cm, model = mesh_and_model("1", comm, 8)
    ref = solve_mixed_monolithic(model.on(cm), split_interface=True)
    options = IterationOptions(tol=1e-10, newton=InterfaceNewtonOptions(strategy=name))
    res = solve_mixed_hybrid(model.on(cm), reference=ref, options=options)
    return {
        "iterations": res.iterations,
        "converged": res.converged,
        "residual": float(res.history.residuals[-1]),
        "interface_newton_steps": res.history.newton_steps,
        "e_sigma": res.e_sigma,
        "e_u": res.e_u,
        **profile_data(res.profile),
        "sigma": sorted_values(res.sigma),
        "u": sorted_values(res.u),
    }


def indent(comm: MPI.Comm) -> dict:
    """The Hertz cylinder pressed into a block in two load steps (a moving obstacle), mixed monolithic."""
    block, _ = hertz_block(0.05, refinement=0.5, comm=comm)
    curve = force_indentation(
        hertz_model(radius=5.0, depth=0.0).on(block), "mixed-monolithic", [6e-4, 1.2e-3], direction=(0.0, -1.0)
    )
    last = curve.steps[-1].profile
    return {
        "forces": curve.forces.tolist(),
        "newton": [s.iterations for s in curve.steps],
        "zone": last.contact_zone(),
        **profile_data(last),
    }


def rates(comm: MPI.Comm) -> dict:
    """Arnold–Winther errors and rates on warped unit squares 4, 8, 16 (Dirichlet, traction-free, sliding side)."""

    def l2(expr, dx):
        return float(np.sqrt(comm.allreduce(fem.assemble_scalar(fem.form(ufl.inner(expr, expr) * dx)), op=MPI.SUM)))

    out = {}
    cases = {
        "dirichlet": (aw.locking_displacement(lame_parameters(1.0, 0.3)[0]), {}),
        "traction_free": (aw.free_displacement, {"zero_traction_facets": "right"}),
        "sliding": (aw.sliding_displacement, {"zero_tangential_facets": "right"}),
    }
    for key, (u_fn, kw) in cases.items():
        errs = []
        for n in (4, 8, 16):
            msh = aw.unit_square(n, warp=0.03, comm=comm)
            space = ArnoldWintherSpace(msh, **{k: aw.side_facets(msh, 0.0, v) for k, v in kw.items()})
            u, sigma, f = aw.exact_fields(msh, u_fn, 1.0, 0.3)
            sol = solve_mixed_elasticity(space, E=1.0, nu=0.3, f=f, u_D=u)
            dx = ufl.dx(domain=msh, metadata={"quadrature_degree": 8})
            S = space.stress(sol.sigma)
            errs.append([l2(u - sol.u, dx), l2(sigma - S, dx), l2(ufl.div(S) + f, dx)])
        e = np.array(errs)
        out[key] = {"errors": e.tolist(), "rates": np.log2(e[:-1] / e[1:]).tolist(), "dofs": space.num_dofs}
    return out


@pytest.fixture(scope="module")
def runs():
    """``runs(kind, case)``: (serial, parallel) numbers of one case, rank 0's on every rank, each computed once."""
    kinds = {
        "mono": mono,
        "hybrid": hybrid,
        "hybrid_newton": hybrid_newton,
        "indent": lambda _, comm: indent(comm),
        "rates": lambda _, comm: rates(comm),
    }
    cache = {}

    def get(kind: str, case: str = "") -> tuple[dict, dict]:
        if (kind, case) not in cache:
            cache[kind, case] = tuple(
                on_every_rank(kinds[kind](case, comm)) for comm in (MPI.COMM_SELF, MPI.COMM_WORLD)
            )
        return cache[kind, case]

    return get


def _same_fields(serial: dict, parallel: dict, keys: list[str]) -> None:
    for key in keys:
        a, b = serial[key], parallel[key]
        assert a.shape == b.shape, key
        assert np.abs(a - b).max() <= TOL * np.abs(a).max(), (key, np.abs(a - b).max() / np.abs(a).max())


@pytest.mark.mpi(sizes=(2, 3))
@pytest.mark.parametrize("case", MONO)
def test_monolithic_mixed_matches_serial(runs, case):
    a, b = runs("mono", case)
    assert b["newton_steps"] == a["newton_steps"]
    assert b["active_sizes"] == a["active_sizes"]
    assert b["step_lengths"] == pytest.approx(a["step_lengths"], abs=1e-12)
    assert b["active"] == a["active"] and b["dofs"] == a["dofs"]
    assert np.allclose(b["y"], a["y"], rtol=0, atol=1e-12)
    # σ_c relative to the stress scale (max |σ| over the DG nodes)
    scale = np.abs(a["sigma"]).max()
    assert np.abs(np.array(b["sigma_c"]) - a["sigma_c"]).max() <= TOL * scale
    assert b["stress_norm2"] == pytest.approx(a["stress_norm2"], rel=TOL)
    assert b["l2_norm2"] == pytest.approx(a["l2_norm2"], rel=TOL)
    _same_fields(a, b, ["sigma", "u"])


@pytest.mark.mpi(sizes=(2, 3))
@pytest.mark.parametrize("case", HYBRID)
def test_algorithm_2_matches_serial(runs, case):
    a, b = runs("hybrid", case)
    assert a["converged"] and b["converged"]
    assert b["iterations"] == a["iterations"]
    assert b["newton"] == a["newton"] and b["newton_active"] == a["newton_active"]
    assert b["active"] == a["active"] and b["dofs"] == a["dofs"]
    assert np.allclose(b["rel_changes"], a["rel_changes"], rtol=1e-6, atol=1e-12)
    # ‖f‖²_γ of f = (y³, 1 + y) on γ = {3/4} × (0, 1) with the distributed γ mass matrix: ∫ y⁶ + (1 + y)² dy
    assert a["gamma_f2"] == pytest.approx(1 / 7 + 7 / 3, rel=1e-12)
    assert b["gamma_f2"] == pytest.approx(a["gamma_f2"], rel=1e-12)
    assert a["e_sigma"] < 1e-8 and b["e_sigma"] < 1e-8 and b["e_u"] < 1e-8
    scale = np.abs(a["sigma"]).max()
    assert np.abs(np.array(b["sigma_c"]) - a["sigma_c"]).max() <= TOL * scale
    _same_fields(a, b, ["sigma", "u", "ref-sigma"])


@pytest.mark.mpi(sizes=(2, 3))
@pytest.mark.parametrize("strategy", ["condensed", "interface"])
def test_algorithm_2_interface_newton_matches_serial(runs, strategy):
    """Algorithm 2's interface Newton (the default update on any number of ranks): the serial Newton steps and
    applications of T, and the serial solution to 1e-10, which is the split monolithic one."""
    a, b = runs("hybrid_newton", strategy)
    for run in (a, b):
        assert run["converged"] and run["residual"] < 1e-10 and run["e_sigma"] < 1e-9 and run["e_u"] < 1e-9, run
    assert b["interface_newton_steps"] == a["interface_newton_steps"] <= 8
    assert b["iterations"] == a["iterations"]
    assert b["active"] == a["active"]
    scale = np.abs(a["sigma"]).max()
    assert np.abs(np.array(b["sigma_c"]) - a["sigma_c"]).max() <= TOL * scale
    _same_fields(a, b, ["sigma", "u"])


@pytest.mark.mpi
def test_mixed_indentation_steps_on_two_ranks(runs):
    """A moving obstacle (Hertz load steps, mixed monolithic): the serial Newton steps, forces and contact zone."""
    a, b = runs("indent")
    assert b["newton"] == a["newton"] and b["active"] == a["active"]
    assert np.allclose(b["forces"], a["forces"], rtol=1e-10, atol=0)
    assert np.allclose(b["zone"], a["zone"], rtol=0, atol=1e-12)
    # the round-off floor of this problem (a 0.1-wide contact zone on a 0.1 × 0.05 block, ε = 1e-3·h·E) is
    # higher: serial runs with the MUMPS orderings METIS / AMD instead of AMF differ in σ_c by 1.8e-9 / 3.3e-9
    # of max |σ_c|, the serial run without the equilibration (s = 1 instead of 1/2) by 3.3e-8, and 2-rank runs
    # (MUMPS' parallel factorization is not reproducible bit for bit) by 1.5e-8 … 4.7e-8
    assert np.abs(np.array(b["sigma_c"]) - a["sigma_c"]).max() <= 1e-7 * np.abs(a["sigma_c"]).max()


@pytest.mark.mpi
def test_arnold_winther_rates_on_two_ranks(runs):
    serial, par = runs("rates")
    for key in serial:
        assert par[key]["dofs"] == serial[key]["dofs"]
        assert np.all(np.array(par[key]["rates"])[-1] >= 0.9 * RATES), (key, par[key]["rates"])
        assert np.allclose(par[key]["errors"], serial[key]["errors"], rtol=1e-8), key


@pytest.mark.mpi
def test_cli_mixed_outputs_from_two_ranks(shared_tmp_path):
    """``mpiexec -n 2 fenics-contact run --method mixed``: the serial summary, fields and plots, one directory."""
    args = ["run", "--method", "mixed", "--model", "2", "--h", "8", "--H", "4", "--reference"]
    out1, out2 = shared_tmp_path / "run1", shared_tmp_path / "run2"
    # the default update, serially and on 2 ranks: the interface Newton
    code, err, s1 = serial_cli(*args, "--out", str(out1))
    assert code == 0, err[-3000:]
    assert main([*args, "--out", str(out2)]) == 0
    s2 = run_summary(out2)
    assert s1["mpi_ranks"] == 1 and s2["mpi_ranks"] == 2 and s2["converged"]
    assert s1["accel"] == s2["accel"] == "newton"
    for key in (
        "iterations",
        "interface_newton_steps",
        "reference_newton_steps",
        "dofs",
        "active_set",
        "reference_active_set",
    ):
        assert s2[key] == s1[key], key
    assert s1["final_rel_change"] is s2["final_rel_change"] is None  # (the interface Newton applies T to certify)
    for key in ("e_sigma", "e_u"):
        assert s2[key] == pytest.approx(s1[key], rel=1e-6, abs=1e-10), key
    assert s2["max_tensile_sigma_c"] == pytest.approx(s1["max_tensile_sigma_c"], rel=1e-6, abs=1e-12)
    names = {p.name for p in out2.iterdir()}
    assert {
        "fields.pvd",
        "contact.pvd",
        "sigma.bp",
        "u.bp",
        "stress.png",
        "displacement.png",
        "contact.png",
        "history.png",
        "summary.json",
    } <= names
    fields1, fields2 = (pyvista.read(out / "fields.pvd")[0] for out in (out1, out2))
    assert fields2.n_points == 81 and fields2.n_cells == fields1.n_cells  # both ranks' parts, 9 x 9 nodes once
    order1, order2 = (np.lexsort(f.points[:, :2].T) for f in (fields1, fields2))
    np.testing.assert_allclose(
        fields2.point_data["u"][order2],
        fields1.point_data["u"][order1],
        rtol=1e-6,
        atol=1e-12 * np.abs(fields1.point_data["u"]).max(),
    )
    for png in ("stress.png", "displacement.png", "contact.png"):  # gathered fields: the serial pictures
        a, b = imread(out1 / png), imread(out2 / png)  # (the triangles come in another order: a few edge pixels
        assert a.shape == b.shape, png  # of the shaded DG P1 plot differ by a shade, 1e-5 of them)
        assert np.mean(np.abs(a - b).max(axis=-1) > 0.02) < 1e-4, png
