# meshflat: the service in a small image that runs as a non-root user on a read-only root
# filesystem. Every setting is a MESHFLAT_* environment variable (docs/operations.md,
# "Settings").
#
#   docker build -t meshflat .
#   docker run --read-only --tmpfs /tmp -p 8000:8000 -e MESHFLAT_API_KEYS=... meshflat
#
# Without a Docker engine: deploy/container-smoke-test.sh builds and runs it with buildah and
# podman (CI does).

ARG PYTHON_IMAGE=docker.io/library/python:3.11-slim-bookworm

# -- build: a virtual environment with the service and its dependencies -------------------
FROM ${PYTHON_IMAGE} AS build
ENV PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_NO_CACHE_DIR=1 PIP_ROOT_USER_ACTION=ignore
RUN python3 -m venv /opt/meshflat
WORKDIR /src
COPY pyproject.toml README.md ./
COPY transforms ./transforms
COPY service ./service
# A regular (not editable) install; the bytecode, and numba's kernels (its cache beside
# the source), are compiled here because the running container cannot write them.
RUN /opt/meshflat/bin/pip install --no-compile . \
    && /opt/meshflat/bin/python -m compileall -q -j 0 /opt/meshflat \
    && /opt/meshflat/bin/python -c "from transforms.onmesh import compile_kernels as c; c()" \
    && find /opt/meshflat -depth -type d \( -name tests -o -name test \) \
        -path '*site-packages/*' -prune -exec rm -rf {} + \
    && rm -rf /opt/meshflat/lib/python3*/site-packages/pip

# -- run -------------------------------------------------------------------------------
FROM ${PYTHON_IMAGE}
LABEL org.opencontainers.image.title="meshflat" \
      org.opencontainers.image.description="Flattens a region of a 3D mesh into seam-free distorted-pole spherical coordinates."
# Owned by root and read-only to the service's user, which needs no entry in /etc/passwd.
COPY --from=build /opt/meshflat /opt/meshflat
ENV PATH=/opt/meshflat/bin:$PATH \
    PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    OPENBLAS_NUM_THREADS=1 \
    IGL_NUM_THREADS=1 \
    HOME=/tmp \
    TMPDIR=/tmp \
    MESHFLAT_HOST=0.0.0.0 \
    MESHFLAT_PORT=8000 \
    MESHFLAT_WORKERS=1
USER 10001:10001
EXPOSE 8000
# Standard library only (service/health.py): cheap enough to run every 15 s.
HEALTHCHECK --interval=15s --timeout=6s --start-period=20s --retries=3 \
    CMD ["python3", "-m", "service.health"]
# uvicorn is PID 1: on SIGTERM it stops accepting and lets requests in progress finish.
STOPSIGNAL SIGTERM
CMD ["meshflat", "serve"]
