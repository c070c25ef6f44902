# Two commands do everything on a fresh machine:
#   make demo   - creates .venv if needed, runs a real contact simulation, writes results/
#   make test   - creates .venv if needed, runs the test suite: its two tiers
#       serial  pytest -m "not mpi"                    every test but the MPI ones, one process
#       MPI     mpiexec -n 2 python -m mpi4py -m pytest -m mpi tests/   the collective tests (@pytest.mark.mpi),
#               then the same under -n 3 (the tests marked mpi(sizes=(2, 3)); the others skip there)
#   make test-quick - the serial tier without the slow tests: -m "not slow and not mpi" (about 4 minutes)
# and one builds the documentation site:
#   make docs   - builds docs/_build/html (warnings are errors; the demos run as notebooks at 1/h = DEMO_N)
# .venv gets fenics-contact (editable) with DOLFINx from the binary wheel: pip install -e ".[wheel,test,docs]"
VENV ?= .venv
OUT ?= results
DEMO_N ?= 32
# one thread per process: MUMPS/OpenBLAS threads spinning on 2 cores slow the sparse solves badly
export OMP_NUM_THREADS ?= 1

.PHONY: demo test test-quick lint env docs clean

$(VENV)/.installed: pyproject.toml setup.py install/fenics_contact_import_order.py scripts/bootstrap.sh
	VENV=$(VENV) scripts/bootstrap.sh

env: $(VENV)/.installed

demo: $(VENV)/.installed
	$(VENV)/bin/fenics-contact run --model 1 --method primal --h 64 --H 16 --reference --out $(OUT)/model1-primal
	$(VENV)/bin/fenics-contact run --model 2 --method primal --h 64 --H 16 --reference --out $(OUT)/model2-primal
	@echo "Fields for ParaView: $(OUT)/*/fields.pvd and contact.pvd   plots: $(OUT)/*/*.png   summaries: $(OUT)/*/summary.md"

# python -m mpi4py: an exception on one rank aborts the job instead of leaving the others waiting; no cache
# (the ranks would write it at once)
MPI_PYTEST = $(VENV)/bin/python -m mpi4py -m pytest -ra -p no:cacheprovider -m mpi tests

test: $(VENV)/.installed
	$(VENV)/bin/python -m pytest -ra -m "not mpi"
	$(VENV)/bin/mpiexec -n 2 $(MPI_PYTEST)
	$(VENV)/bin/mpiexec -n 3 $(MPI_PYTEST)

# ruff: import order, pyflakes, pycodestyle and the formatting (pyproject.toml [tool.ruff])
lint: $(VENV)/.installed
	$(VENV)/bin/ruff check fenics_contact tests demos benchmarks docs scripts
	$(VENV)/bin/ruff format --check fenics_contact tests demos benchmarks docs scripts

test-quick: $(VENV)/.installed
	$(VENV)/bin/python -m pytest -ra -m "not slow and not mpi"

# warnings are errors, so a broken internal link (a document, a section anchor) fails the build: Sphinx and
# MyST warn on each; external links are not checked (no network needed)
docs: $(VENV)/.installed
	FENICS_CONTACT_DEMO_N=$(DEMO_N) $(VENV)/bin/python -m sphinx -W --keep-going -b html docs docs/_build/html
	@echo "open docs/_build/html/index.html"

clean:
	rm -rf $(OUT) .pytest_cache docs/_build
