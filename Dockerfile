# One image for every cbdi service; the command picks the service. The monitor's rerun
# extra (rerun-sdk, ~770 MB) is not installed here: `cbdi view` runs on the host.
#   tools/image.sh            (make image: makes a local base, no registry needed)
#   docker build -t localhost/cbdi .                       (or: podman build ...)
#   docker build --build-arg BASE_IMAGE=localhost/cbdi-base:bookworm -t localhost/cbdi .
# The base must provide Python 3.11 with venv (and pip through ensurepip).
ARG BASE_IMAGE=python:3.11-slim

# The build stage: a venv with the pinned dependencies and the cbdi packages. It alone
# sees tools/image/build-env (the host's CA bundle and pip settings, when staged, and the
# planner's compiled core that tools/image.sh builds on the host; without it the planner
# runs its Python core, the same search, slower).
FROM ${BASE_IMAGE} AS build
# pip compiles the bytecode: services start faster (8 containers at once on 2 cores).
ENV PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_NO_CACHE_DIR=1
WORKDIR /opt/cbdi
COPY tools/image/build-env/ /tmp/build-env/
# Dependencies first, pinned, so that code changes do not reinstall them.
COPY requirements.lock ./
RUN . /tmp/build-env/env.sh \
 && python3 -m venv /opt/venv \
 && /opt/venv/bin/pip install -q -r requirements.lock setuptools==80.9.0
COPY shared ./shared
COPY services ./services
COPY domains/recycling/pyproject.toml ./domains/recycling/pyproject.toml
COPY domains/recycling/src ./domains/recycling/src
RUN . /tmp/build-env/env.sh \
 && /opt/venv/bin/pip install -q --no-deps --no-build-isolation \
      ./shared ./services/world ./services/monitor \
      ./services/planner ./services/scheduler ./services/executor \
      ./domains/recycling \
 && /opt/venv/bin/pip uninstall -q -y setuptools pip \
 && if [ -f /tmp/build-env/cbdi_planner_core.abi3.so ]; then \
      cp /tmp/build-env/cbdi_planner_core.abi3.so /opt/venv/lib/python3.11/site-packages/; fi

FROM ${BASE_IMAGE}
ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PATH=/opt/venv/bin:$PATH \
    CBDI_DOMAINS=/opt/cbdi/domains MALLOC_ARENA_MAX=2
COPY --from=build /opt/venv /opt/venv
COPY domains /opt/cbdi/domains
WORKDIR /opt/cbdi
# Services connect to the router through CBDI_CONNECT (set in the compose file).
CMD ["cbdi", "--help"]
