# Everything runs in the project's environment (tools/run): the host if it has
# dolfinx >= 0.9, otherwise a cached Debian root (DOLFINX_MORTAR_SUITE=trixie|sid).
RUN := tools/run
PYTEST := python3 -m pytest -p no:cacheprovider --color=no
MPI_TIMEOUT := timeout --signal=INT --kill-after=60 3600
RESULTS := results
# pytest-xdist workers of the serial suite (the machines CI runs on have 2 cores)
SERIAL_WORKERS ?= 2

.PHONY: demo test test-tools test-serial test-parallel lint format stress benchmark benchmark-quick benchmark-3d benchmark-3d-quick clean

demo:
	$(RUN) mpirun -n 2 python3 demos/hertz.py --output $(RESULTS)/hertz --json $(RESULTS)/hertz/summary.json
	@echo "demo results (JSON, PNG, ParaView files): $(RESULTS)/hertz/"

test: test-tools test-serial test-parallel

# tools/run itself, checked from the host (in DOLFINX_MORTAR_SUITE like the rest)
test-tools:
	tests/tools/test_run.sh

test-serial:
	$(RUN) $(PYTEST) -q -n $(SERIAL_WORKERS) tests

test-parallel:
	$(RUN) $(MPI_TIMEOUT) mpirun -n 2 tools/mpi-pytest -q -m parallel tests
	$(RUN) $(MPI_TIMEOUT) mpirun -n 3 tools/mpi-pytest -q -m parallel tests

lint:
	$(RUN) ruff check dolfinx_mortar demos tests benchmarks

format:
	$(RUN) ruff format dolfinx_mortar demos tests benchmarks

# results/stress/stress.md and stress.json: every case measured (docs/stress.md quotes them)
stress:
	DOLFINX_MORTAR_STRESS_REPORT=$(RESULTS)/stress $(RUN) $(PYTEST) -q -m "slow or not slow" tests/stress --run-slow

benchmark:
	$(RUN) python3 benchmarks/run.py --output $(RESULTS)/benchmarks

benchmark-quick:
	$(RUN) python3 benchmarks/run.py --quick --output $(RESULTS)/benchmarks-quick

# 3D: patch test, Hertz sphere (refinements 0..3), direct vs iterative on 1 and 2 ranks
# (the largest meshes take hours: --stop-at HH:MM skips what would not end in time)
benchmark-3d:
	$(RUN) python3 benchmarks/run.py --dim 3 --output $(RESULTS)/benchmarks-3d

benchmark-3d-quick:
	$(RUN) python3 benchmarks/run.py --dim 3 --quick --output $(RESULTS)/benchmarks-3d-quick

clean:
	rm -rf $(RESULTS) .pytest_cache
