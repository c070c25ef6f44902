"""Algorithm 3 for two bodies with friction (``multiscale.pair`` with ``fem.two_body_friction`` strips): along a
press-then-shear path on a layered pair (strata of contrast 1e3 with inclusions, non-matching meshes), each step
from the last one's state.

* with patches covering each bulk and every local mode the coarse space is the fine one: Algorithm 1's path
  (displacement, forces, stick/slip, dissipation) to 1e-8, Coulomb and Tresca;
* once sliding, the tangential force is μ times the normal force; the forces balance to round-off;
* with few modes the energy error against Algorithm 1 falls with the oversampling layers at every step.
"""

import numpy as np
import pytest
from mpi4py import MPI
from pair_problems import strata_pair

import fenics_contact as fc
from fenics_contact.fem.two_body import stiffness
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.problem.pair import TwoBodyProblem
from fenics_contact.problem.pair_meshes import two_blocks

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial (the MPI runs: test_pair_multiscale_mpi.py)")

CONTRAST = 1e3
MU = 0.3
#: press, then shear past sliding (the upper block's top)
PATH = ((0.0, -0.005), (0.0, -0.01), (0.004, -0.01), (0.01, -0.01), (0.02, -0.01))
#: the energy error falls by at least this factor per oversampling layer at every step (measured: the command in
#: benchmarks/results/two_body_multiscale.md)
FACTOR = 5.0


def _problem(m, law, top) -> TwoBodyProblem:
    return strata_pair(m, law, top, contrast=CONTRAST)


def _relative(a, b) -> float:
    return float(np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(b))


@pytest.mark.parametrize(
    "law", [fc.Friction("coulomb", mu=MU), fc.Friction("tresca", threshold=0.002)], ids=["coulomb", "tresca"]
)
def test_with_all_modes_on_global_patches_the_path_is_algorithm_1s(law):
    m = two_blocks(8, 11, heights=(0.5, 0.4), comm=MPI.COMM_SELF)
    everything = CEMOptions(layers=20, nbasis=None)
    states = [None, None]
    for top in PATH:
        problem = _problem(m, law, top)
        fine = fc.solve(problem, "primal", state=states[0], tol=1e-11)
        ms = fc.solve(problem, "primal-ms", H=0.25, cem=everything, state=states[1], tol=1e-11)
        states = [fine.state, ms.state]
        assert ms.converged and ms.interface_newton_steps <= 8
        assert _relative(ms.u.x.array, fine.u.x.array) <= 1e-8
        assert _relative(ms.forces[0], fine.forces[0]) <= 1e-8
        assert ms.force_balance() < 1e-12
        assert np.array_equal(ms.friction.slip, fine.friction.slip)
        assert ms.dissipation >= 0.0
        assert ms.dissipation == pytest.approx(fine.dissipation, rel=1e-6, abs=1e-14)
    f = ms.friction
    assert np.all(f.slip[f.pressure > 0])  # sheared past sliding
    if law.name == "coulomb":
        assert np.linalg.norm(f.tangential_force) == pytest.approx(MU * f.normal_force, rel=1e-8)


def test_the_energy_error_falls_with_the_oversampling_layers_along_the_path():
    m = two_blocks(16, 20, heights=(0.5, 0.4), comm=MPI.COMM_SELF)
    law = fc.Friction("coulomb", mu=MU)
    layers = (1, 2, 3)
    states = [None] * (1 + len(layers))
    for top in (PATH[1], PATH[3], PATH[4]):  # pressed, slip spreading, sliding
        problem = _problem(m, law, top)
        fine = fc.solve(problem, "primal", state=states[0], tol=1e-11)
        u0 = fine.u.x.array
        K = stiffness(problem, fine.u.function_space)
        results = [
            fc.solve(problem, "primal-ms", H=0.125, cem=CEMOptions(layers=k), state=s, tol=1e-10)
            for k, s in zip(layers, states[1:], strict=True)
        ]
        states = [fine.state, *(r.state for r in results)]
        errors = []
        for result in results:
            assert result.converged and result.force_balance() < 1e-12
            d = result.u.x.array - u0
            errors.append(np.sqrt((d @ (K @ d)) / (u0 @ (K @ u0))))
        assert all(a > FACTOR * b for a, b in zip(errors, errors[1:]))
    f = results[-1].friction
    assert np.all(f.slip[f.pressure > 0])
    assert np.linalg.norm(f.tangential_force) == pytest.approx(MU * f.normal_force, rel=1e-8)
