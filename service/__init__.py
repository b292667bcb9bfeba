"""meshflat's HTTP service: thin FastAPI routes over :mod:`transforms` (ASGI app
``service.app:app``)."""
