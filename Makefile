# `make demo` and `make test` work on a fresh machine with Python 3.11+ and make.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test check lint typecheck unit fast bench clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,ray]'
	touch $(STAMP)

# The paper's experiment on one machine: compile and verify the pool mission (reports and
# certificate in out/), then run it with the CORAL engine against the simulated ROMEO across
# the emulated Genoa-Lisbon link, in virtual time; logs and plots in out/run/. The
# certificate is signed with a demo key made once in out/ (the verifier's side), and the
# run trusts its public half (the operator's side): docs/verify.md, "Signed certificates".
MISSION := examples/pool_mission/pool_mission.coral
DEMO_KEY := out/demo-signing.key

demo: $(STAMP)
	@mkdir -p out
	test -f $(DEMO_KEY) || $(BIN)/coral-check keygen --out $(DEMO_KEY) --comment "make demo"
	$(BIN)/python -m coral_lang.demo $(MISSION)
	$(BIN)/coral-check verify $(MISSION) -o out/pool_mission.verification.txt \
		--certificate out/pool_mission.certificate.json --signing-key $(DEMO_KEY)
	$(BIN)/coral-check verify $(MISSION) --format json -o out/pool_mission.verification.json
	$(BIN)/coral-check $(MISSION) --format html -o out/pool_mission.report.html
	@cat out/pool_mission.verification.txt
	@# Timed analysis: best and worst mission time over the Genoa-Lisbon link's delay
	@# bounds, each query's time-out, and the schedules coral-run --schedule replays. Exit 3
	@# (some timing not decided within the budget) still lets the demo go on.
	rm -rf out/schedules
	$(BIN)/coral-check verify $(MISSION) --timed --link genoa-lisbon --no-structure \
		-o out/pool_mission.timed.txt --export-schedules out/schedules || test $$? -eq 3
	@sed -n '/^Timing/,$$p' out/pool_mission.timed.txt
	rm -rf out/run out/worst
	$(BIN)/coral-run $(MISSION) --certificate out/pool_mission.certificate.json \
		--trusted-keys $(DEMO_KEY).pub --link genoa-lisbon --seed 0 --out out/run
	@# The worst case to mission_complete, replayed against the generic simulated vehicle.
	$(BIN)/coral-run run $(MISSION) --certificate out/pool_mission.certificate.json \
		--trusted-keys $(DEMO_KEY).pub --schedule out/schedules/worst-mission_complete.json \
		--out out/worst -q
	@echo "verification report: out/pool_mission.verification.txt (.json, .report.html)"
	@echo "pre-mission certificate: out/pool_mission.certificate.json (signed by $(DEMO_KEY))"
	@echo "timed analysis: out/pool_mission.timed.txt; worst and best runs: out/schedules/;"
	@echo "                the worst case replayed: out/worst/ (logs, events.png)"
	@echo "mission run: out/run/controller.sqlite, out/run/vehicle.sqlite (event logs),"
	@echo "             out/run/events.png (events' sequence), out/run/telemetry.png (track, depth, heading)"

test: lint typecheck unit

# The inner loop: ruff, mypy and the tests not marked slow, property tests with fewer
# examples (tests/conftest.py, profile "fast"); under a minute on a 2-core machine.
check: lint typecheck fast

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: $(STAMP)
	$(BIN)/mypy

# pytest exits 5 when no test ran, so an empty run fails here too.
unit: $(STAMP)
	$(BIN)/pytest -n 2 -q

fast: $(STAMP)
	HYPOTHESIS_PROFILE=fast $(BIN)/pytest -n 2 -q -m "not slow"

bench: $(STAMP)
	$(BIN)/python bench/compile.py
	$(BIN)/python bench/statespace.py
	$(BIN)/python bench/sim.py
	$(BIN)/python bench/cli.py
	$(BIN)/python bench/engine.py

clean:
	rm -rf $(VENV) out .mypy_cache .pytest_cache .ruff_cache .hypothesis
