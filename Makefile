# cbdi: the two commands a newcomer needs are `make demo` and `make test`.
# Both create .venv on first use from the pinned lock files; nothing else is assumed.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
PACKAGES := shared services/world services/monitor services/scheduler services/executor services/planner domains/recycling domains/courier
PYTEST_ARGS ?=
# Tests run in two workers (pytest-xdist); each takes router ports from a range of its
# own (tests/conftest.py); a file's tests stay on one worker (one image build).
PYTEST_WORKERS ?= 2
PYTEST_PARALLEL = -n $(PYTEST_WORKERS) --dist loadfile

.PHONY: venv demo test test-fast lint bench bench-planner bench-continual bench-table1 bench-fleet clean system-tools image

venv: $(STAMP)

# The planner's compiled search core (Rust, PyO3) is built by maturin with cargo, its
# crates pinned by services/planner/core/Cargo.lock (services/planner/README.md).
CORE   := services/planner/core
CARGO  ?= $(or $(shell command -v cargo 2>/dev/null),$(wildcard $(HOME)/.cargo/bin/cargo))

$(STAMP): requirements.lock requirements-dev.lock $(foreach p,$(PACKAGES),$(p)/pyproject.toml) \
          $(CORE)/pyproject.toml $(CORE)/Cargo.toml $(CORE)/Cargo.lock $(wildcard $(CORE)/src/*.rs)
	@test -n "$(CARGO)" || { echo "error: the planner's compiled core needs Rust's cargo" \
	  "(1.80 or later) to build: install Rust with https://rustup.rs or your system's package" \
	  "(Debian: apt-get install cargo), then run make again" >&2; exit 1; }
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --disable-pip-version-check -r requirements.lock -r requirements-dev.lock
	$(BIN)/python -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation $(foreach p,$(PACKAGES),-e $(p))
	PATH="$(abspath $(BIN)):$(dir $(CARGO)):$$PATH" MATURIN_PEP517_ARGS="--locked" \
	  $(BIN)/python -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation ./$(CORE)
	touch $(STAMP)

# Debian packages the tests use, installed when missing: docker-compose (Compose v1)
# validates and runs compose files; podman runs the containers (no Docker engine needed)
# and debootstrap makes their base image; chromium renders the rerun web viewer.
SYSTEM_TOOLS := docker-compose:docker-compose podman:podman debootstrap:debootstrap chromium:chromium
system-tools:
	@missing=""; for t in $(SYSTEM_TOOLS); do \
	  command -v $${t%%:*} >/dev/null 2>&1 || missing="$$missing $${t#*:}"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages for the tests:$$missing"; \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing) \
	    >/dev/null 2>&1 || echo "warning: could not install$$missing; tests needing them fail"; \
	fi

# The paper's 7x7 scenario: one BDI robot (planner, scheduler and executor processes),
# then three sharing the world; the grid every epoch with what each robot intends. The
# second run is recorded to MCAP and inspected (docs/usage.md: replay and rerun).
demo: venv
	$(BIN)/cbdi up paper-7x7 --view text --quiet
	$(BIN)/cbdi up paper-7x7 --agents 3 --view text --quiet --record runs/demo.mcap
	$(BIN)/cbdi inspect runs/demo.mcap

# The cbdi image (localhost/cbdi:latest) with Podman or Docker, on a Debian base made
# here with debootstrap when there is none (no registry needed); see docs/containers.md.
image:
	sh tools/image.sh

test: venv system-tools
	$(BIN)/python -m pytest $(PYTEST_PARALLEL) --durations=20 $(PYTEST_ARGS)

# The inner loop: unit and in-memory tests only (no real processes over Zenoh, no
# containers), about a minute on 2 cores. `make test` stays the whole suite.
test-fast: venv
	$(BIN)/python -m pytest $(PYTEST_PARALLEL) -m "not e2e" $(PYTEST_ARGS)

lint: venv
	$(BIN)/ruff check shared services domains tests benchmarks docs/tutorial docs/robot-body
	$(BIN)/mypy --strict shared/src/cbdi docs/tutorial/robot.py docs/robot-body/body.py
	$(BIN)/mypy --strict services/world/src services/monitor/src services/scheduler/src services/executor/src services/planner/src domains/recycling/src domains/courier/src

bench: venv
	$(BIN)/python benchmarks/bus_latency.py
	$(BIN)/python benchmarks/world_epochs.py
	$(BIN)/python benchmarks/recorder.py

# cbdi's planner against kairos on the IPC temporal problems (../shared/benchmarks/temporal)
# and the recycling maps, 60 s per problem; table and summary printed, CSV in
# benchmarks/results/. Options: make bench-planner BENCH_PLANNER_ARGS="--only driverlog".
BENCH_PLANNER_ARGS ?=
bench-planner: venv
	$(BIN)/python benchmarks/planner.py $(BENCH_PLANNER_ARGS)

# Continual vs offline planning on the 7x7, 15x15 and 30x30 recycling problems.
bench-continual: venv
	$(BIN)/python benchmarks/continual.py

# The paper's Table I with statistics: its 12 situations x offline/online x seeds 1..10 x
# planning speeds 0.25, 1 and 4 (lockstep, 2 runs at a time), one real-time run per
# situation and mode, the static optimum and clairvoyant bounds; writes table1.csv,
# table1.md and table1.png to benchmarks/results/. Options, e.g.
# make bench-table1 BENCH_TABLE1_ARGS="--seeds 2 --only '4,1,2 8,1,2' --planning-speeds 1"
# or BENCH_TABLE1_ARGS="--reuse benchmarks/results/table1.csv" (re-render, run nothing).
BENCH_TABLE1_ARGS ?=
bench-table1: venv
	$(BIN)/python benchmarks/table1.py $(BENCH_TABLE1_ARGS)

# Fleets of 1 to 16 BDI robots on warehouse-15x15 and campus-30x30, 5 seeds each, lockstep,
# against a lower bound from the map; writes fleet.csv, fleet.md and fleet.png to
# benchmarks/results/. Options, e.g. BENCH_FLEET_ARGS="--maps warehouse-15x15-bdi
# --agents 1 2 4 --seeds 3 --jobs 2" or BENCH_FLEET_ARGS="--reuse benchmarks/results/fleet.csv".
BENCH_FLEET_ARGS ?=
bench-fleet: venv
	$(BIN)/python benchmarks/fleet.py $(BENCH_FLEET_ARGS)

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
