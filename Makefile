# The README's two set-up commands are `make serve` and `make test`; both create .venv on
# first use and reinstall only when pyproject.toml changes.
PYTHON ?= python3
VENV ?= .venv
HOST ?= 127.0.0.1
PORT ?= 8000
BIN := $(VENV)/bin

.PHONY: serve test bench bench-fit bench-locate bench-measure bench-plan bench-compare bench-sites bench-growth bench-strands bench-transfer bench-arrow bench-picture bench-repeat bench-service bench-cache bench-zoo bench-batch bench-memory soak attack openapi clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed-%: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[$*]'
	touch $@

$(VENV)/.installed-run: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

# Both compile the numba kernels first (or load them: about a second once compiled), so no
# worker and no test compiles them at its first call (transforms/kernels.py).
serve: $(VENV)/.installed-run
	$(BIN)/python -m transforms.kernels
	$(BIN)/meshflat serve --host $(HOST) --port $(PORT)

# `make test`: ruff, then pytest on every core (pytest-xdist; `--dist loadgroup` keeps each
# xdist_group, such as the tests that start real servers, on one worker). The cases marked
# slow (over about 4 s each: pyproject.toml's markers) are left out unless MESHFLAT_ALL_TESTS=1,
# which CI (.ci/run) sets: `MESHFLAT_ALL_TESTS=1 make test` runs every test. PYTEST_ARGS adds
# arguments (a file, -k, -x, ...).
ifeq ($(MESHFLAT_ALL_TESTS),1)
TEST_SELECTION :=
LEFT_OUT := true
else
TEST_SELECTION := -m "not slow"
LEFT_OUT := echo "make test: the tests marked slow were left out (MESHFLAT_ALL_TESTS=1 runs them)"
endif

test: $(VENV)/.installed-test
	$(BIN)/python -m transforms.kernels
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	@status=0; $(BIN)/python -m pytest -n logical --dist loadgroup $(TEST_SELECTION) $(PYTEST_ARGS) \
		|| status=$$?; \
	if [ $$status -eq 5 ]; then echo "pytest collected no tests: check tests/ and pyproject.toml" >&2; fi; \
	$(LEFT_OUT); exit $$status

bench: $(VENV)/.installed-bench
	$(BIN)/python -m benchmarks.transforms_bench $(BENCH_ARGS)

# BLAS on one thread, as in the service (service/__init__.py), and libigl on one thread.
bench-fit: $(VENV)/.installed-bench
	IGL_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 $(BIN)/python -m benchmarks.fit_bench $(BENCH_ARGS)

# A click on the map (/v1/locate) end to end through a real server, and the locate index's
# queries against Open3D's RaycastingScene (the sites-peers extra; one thread, timed
# alternately). Needs curl besides the extras.
bench-locate: $(VENV)/.installed-bench $(VENV)/.installed-sites-peers
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(BIN)/python -m benchmarks.locate_bench $(BENCH_ARGS)

# Zones and a curve drawn on the map of a 1M-face scalp, measured on the surface, against
# shapely 2 clipping the triangles (one thread, timed alternately in one process).
bench-measure: $(VENV)/.installed-bench
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m benchmarks.measure_bench $(BENCH_ARGS)

# A transplant plan of 10 zones on a 1M-face scalp: zones checked, areas, arithmetic (one
# thread).
bench-plan: $(VENV)/.installed-bench
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m benchmarks.plan_bench $(BENCH_ARGS)

# Two visits compared: two 100k-face scans, 10 zones and 10 spots, with and without landmarks.
bench-compare: $(VENV)/.installed-bench
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m benchmarks.compare_bench $(BENCH_ARGS)

# Sites at a density on the bundled scalp and on it subdivided (100k faces), against
# point-cloud-utils', Open3D's and trimesh's samplers (one thread, timed alternately).
bench-sites: $(VENV)/.installed-bench $(VENV)/.installed-sites-peers
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(BIN)/python -m benchmarks.sites_bench $(BENCH_ARGS)

# The growth field of 5 flows and a whorl on a million-face scalp, at 100,000 sites, against
# potpourri3d's vector heat method (one thread, timed alternately; its runs take a minute each).
bench-growth: $(VENV)/.installed-bench $(VENV)/.installed-growth-peers
	OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(BIN)/python -m benchmarks.growth_bench $(BENCH_ARGS)

# Guide hairs of 16 points from 10,000 and 100,000 sites on a 100k-face scalp, kept out of
# the whole head (targets 1 s and 5 s on one thread); peak memory; each answer's size.
bench-strands: $(VENV)/.installed-bench
	IGL_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 $(BIN)/python -m benchmarks.strands_bench $(BENCH_ARGS)

# Values between the map and the mesh on a million-face scalp (4096² image to the faces,
# the vertices' values to a 2048² image), against Pillow's ImageDraw a triangle at a time.
bench-transfer: $(VENV)/.installed-bench
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m benchmarks.transfer_bench $(BENCH_ARGS)

# /v1/flatten of a 1.13M-face head answered as JSON and as Arrow: sizes, encoding, and reading
# in headless Chromium (JSON.parse against Arrow JS). Needs the test extra, Chromium and
# `npm ci --prefix tests/js` besides the bench extra.
bench-arrow: $(VENV)/.installed-bench $(VENV)/.installed-test
	$(BIN)/python -m benchmarks.arrow_bench $(BENCH_ARGS)

# A million-face scalp's map coloured by isometric distortion, PNG and SVG, against Pillow's
# ImageDraw a triangle at a time.
bench-picture: $(VENV)/.installed-bench
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m benchmarks.picture_bench $(BENCH_ARGS)

# The head's frame with landmarks 2 mm off (100 trials), and a follow-up scan registered to
# the baseline: how far the maps move on the scalp.
bench-repeat: $(VENV)/.installed-bench
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m benchmarks.repeat_bench $(BENCH_ARGS)

# Needs curl (the end-to-end client) besides the bench extra.
bench-service: $(VENV)/.installed-bench
	$(BIN)/python -m benchmarks.service_bench $(BENCH_ARGS)

# A mesh sent once (POST /v1/meshes) and named by its digest: clicks on a held 1.6M-face
# scalp and a measure on a held 1M-face one, end to end through a real server. Needs curl.
bench-cache: $(VENV)/.installed-bench
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m benchmarks.cache_bench $(BENCH_ARGS)

# The scan zoo: every scan the project can cite and variants of them (../shared beside it
# adds the shared meshes); exits 1 when a case is not seam-free, fold-free or identical.
bench-zoo: $(VENV)/.installed-bench
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m benchmarks.zoo $(BENCH_ARGS)

# `meshflat batch` over the sample set (../shared beside it adds the shared meshes) with 1 and
# 2 processes: scans per minute per core.
bench-batch: $(VENV)/.installed-bench
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m benchmarks.batch_bench $(BENCH_ARGS)

# Peak memory (VmHWM) of each mesh route on the 100k and 1.6M-face scalps, one fresh process
# per measurement, with the service's allocator settings.
bench-memory: $(VENV)/.installed-bench
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m benchmarks.memory_bench $(BENCH_ARGS)

# Load and soak through a real server, as deployed (the test extra suffices); CI runs --short.
soak: $(VENV)/.installed-test
	$(BIN)/python -m benchmarks.soak $(BENCH_ARGS)

# Hostile uploads and slow clients against a real server on 127.0.0.1; CI runs --short.
attack: $(VENV)/.installed-test
	$(BIN)/python -m benchmarks.attack $(BENCH_ARGS)

# The document, then the TypeScript client's types from it (needs `npm ci --prefix clients/typescript`).
openapi: $(VENV)/.installed-run
	$(BIN)/python -m service.openapi
	npm run --prefix clients/typescript generate

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .hypothesis
