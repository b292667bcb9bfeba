"""meshflat's HTTP service: thin FastAPI routes over :mod:`transforms` (ASGI app
``service.app:app``)."""

import os

# OpenBLAS (numpy's dot and matrix products) starts threads of its own on every large call;
# they compete for the cores with the request's threads (MESHFLAT_THREADS) and the other jobs
# and made validation a fifth slower on two threads. Read when numpy loads, so set here, before
# any module of the service imports numpy.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# libigl (the strands' surface guard) splits a large query over every core likewise, read when
# it first runs.
os.environ.setdefault("IGL_NUM_THREADS", "1")
