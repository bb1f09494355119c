# Everything runs in the project's environment (tools/run): the host if it has
# dolfinx >= 0.9, otherwise a cached Debian root (DOLFINX_MORTAR_SUITE=trixie|sid).
RUN := tools/run
PYTEST := python3 -m pytest -p no:cacheprovider --color=no
MPI_TIMEOUT := timeout --signal=INT --kill-after=60 3600
RESULTS := results

.PHONY: demo test test-tools test-serial test-parallel lint format stress benchmark benchmark-quick clean

demo:
	$(RUN) mpirun -n 2 python3 demos/hertz.py --output $(RESULTS)/hertz --json $(RESULTS)/hertz/summary.json
	@echo "demo results (JSON, PNG, ParaView files): $(RESULTS)/hertz/"

test: test-tools test-serial test-parallel

# tools/run itself, checked from the host (in DOLFINX_MORTAR_SUITE like the rest)
test-tools:
	tests/tools/test_run.sh

test-serial:
	$(RUN) $(PYTEST) -q tests

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
	$(RUN) python3 -m dolfinx_mortar.benchmarks --output $(RESULTS)/benchmarks

benchmark-quick:
	$(RUN) python3 -m dolfinx_mortar.benchmarks --quick --output $(RESULTS)/benchmarks-quick

clean:
	rm -rf $(RESULTS) .pytest_cache
