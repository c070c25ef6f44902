"""Regenerate the figures of the README/docs: the E maps of the three test models (h = 1/64).

.venv/bin/python docs/make_figures.py
"""

from pathlib import Path

import fenics_contact  # noqa: F401
from fenics_contact.plots import plot_cell_field
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model

OUT = Path(__file__).parent / "figures"

if __name__ == "__main__":
    OUT.mkdir(exist_ok=True)
    cm = unit_square(64, 16)
    for number in (1, 2, 3):
        problem = get_model(number).on(cm)
        plot_cell_field(
            problem.fields.E,
            OUT / f"model{number}_E.png",
            title=f"Test model {number}: E ({problem.description})",
            log=True,
        )
        print("written", OUT / f"model{number}_E.png")
