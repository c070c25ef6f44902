"""Shared by the Algorithm 3 tests: energy errors against a reference for a sequence of oversampling layers."""

import numpy as np

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.multiscale import primal as primal_ms
from fenics_contact.multiscale.cem import CEMOptions


def layer_errors(
    cm,
    model,
    layers,
    *,
    delta: float,
    reference,
    residual_below: float | None = None,
    source_correction: bool = True,
    **kwargs,
) -> np.ndarray:
    """Energy errors of Algorithm 3 (l = 3, α = Emin) against ``reference`` for each m in ``layers``; every run
    converged and, with ``residual_below``, certified (transmission residual below it)."""
    errors = []
    for m in layers:
        res = primal_ms.solve_primal_ms_hybrid(
            model.on(cm),
            alpha="Emin",
            delta=delta,
            cem=CEMOptions(layers=m, nbasis=3, source_correction=source_correction),
            reference=reference,
            **kwargs,
        )
        assert res.converged
        if residual_below is not None:
            assert res.transmission_residual < residual_below
        errors.append(res.step.error_energy())
    return np.array(errors)
