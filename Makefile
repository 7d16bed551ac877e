# cbdi: the two commands a newcomer needs are `make demo` and `make test`.
# Both create .venv on first use from the pinned lock files; nothing else is assumed.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
PACKAGES := shared services/world
PYTEST_ARGS ?=

.PHONY: venv demo test lint bench clean compose-tools

venv: $(STAMP)

$(STAMP): requirements.lock requirements-dev.lock $(foreach p,$(PACKAGES),$(p)/pyproject.toml)
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --disable-pip-version-check -r requirements.lock -r requirements-dev.lock
	$(BIN)/python -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation $(foreach p,$(PACKAGES),-e $(p))
	touch $(STAMP)

# docker-compose (Compose v1) validates docker-compose.yml offline; install it when missing.
compose-tools:
	@command -v docker-compose >/dev/null 2>&1 || { \
	  echo "installing docker-compose (Debian package) to validate docker-compose.yml"; \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq docker-compose) >/dev/null 2>&1 \
	  || echo "warning: could not install docker-compose; the compose test will fail"; }

demo: venv
	$(BIN)/cbdi up paper-7x7 --view text --quiet --until done

test: venv compose-tools
	$(BIN)/python -m pytest $(PYTEST_ARGS)

lint: venv
	$(BIN)/ruff check shared services tests benchmarks
	$(BIN)/mypy --strict shared/src/cbdi
	$(BIN)/mypy services/world/src

bench: venv
	$(BIN)/python benchmarks/bus_latency.py
	$(BIN)/python benchmarks/world_epochs.py

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
