# One image for every cbdi service; the command picks the service. The monitor's rerun
# extra (rerun-sdk, ~770 MB) is not installed here: `cbdi view` runs on the host.
#   docker build -t cbdi .                       (or: podman build -t cbdi .)
#   docker build --build-arg BASE_IMAGE=localhost/debian-python:3.11 -t cbdi .
# The base must provide Python 3.11 with pip and venv. No registry is reachable on some
# machines: build a local base (debootstrap + `podman import`) and pass it as BASE_IMAGE.
ARG BASE_IMAGE=python:3.11-slim
FROM ${BASE_IMAGE}

ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PIP_DISABLE_PIP_VERSION_CHECK=1
WORKDIR /opt/cbdi

# Dependencies first, pinned, so that code changes do not reinstall them.
COPY requirements.lock ./
RUN python3 -m venv /opt/venv \
 && /opt/venv/bin/pip install --no-cache-dir -r requirements.lock setuptools==80.9.0
ENV PATH=/opt/venv/bin:$PATH

COPY shared ./shared
COPY services ./services
COPY domains ./domains
RUN pip install --no-cache-dir --no-deps --no-build-isolation \
      ./shared ./services/world ./services/monitor \
      ./services/planner ./services/scheduler ./services/executor

ENV CBDI_DOMAINS=/opt/cbdi/domains
# Services connect to the router through CBDI_CONNECT (set in docker-compose.yml).
CMD ["cbdi", "--help"]
