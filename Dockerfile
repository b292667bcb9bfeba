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
# A regular (not editable) install; the bytecode is compiled here because the running
# container cannot write it.
# The sources' times are set to a whole second before anything is compiled from them: the
# image's layers keep whole seconds, and numba's compiled kernels are keyed by the exact time.
RUN /opt/meshflat/bin/pip install --no-compile . \
    && find /opt/meshflat/lib -path '*site-packages/transforms/*' -name '*.py' \
        -exec touch -d @1700000000 {} + \
    && /opt/meshflat/bin/python -m compileall -q -j 0 /opt/meshflat \
    && find /opt/meshflat -depth -type d \( -name tests -o -name test \) \
        -path '*site-packages/*' -prune -exec rm -rf {} + \
    && rm -rf /opt/meshflat/lib/python3*/site-packages/pip
# The numba kernels compiled here, into the image: the running container copies them to its
# writable /tmp at start (service/cli.py), instead of compiling them for several seconds in
# every worker (transforms/kernels.py). Keyed by the source files and the CPU: on another CPU
# model they are compiled at start instead.
# (-P: the installed package, not /src's copy, whose path would key them.)
RUN NUMBA_CACHE_DIR=/opt/meshflat/kernels /opt/meshflat/bin/python -P -m transforms.kernels

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
    NUMBA_CACHE_DIR=/tmp/meshflat-kernels \
    MESHFLAT_KERNELS_FROM=/opt/meshflat/kernels \
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
