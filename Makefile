# Set-up and everyday commands. Each target creates .venv when it is missing.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: demo test test-full test-newest lint format bench clean system

# The runtime alone (a user's `pip install .`) for the demo; the dev extras (pytest, hypothesis,
# ruff, vtk, playwright, jupyterlab) and the optional `events` (feature tracking) and `notebook`
# (the notebook widget) extras, whose tests need them, for the tests. A venv with the dev extras
# has the runtime too.
RUNTIME := $(VENV)/.runtime
DEV := $(VENV)/.dev
# The second interpreter: CPython 3.13 built from Debian's source package (.ci/newest-python)
# with the newest version of every dependency.
NEWEST := .venv-newest

# The suite runs in this many processes (pytest-xdist), each test file in one of them (its
# module fixtures, servers and browsers, made once): 2 halved the suite on this 2-core machine
# (1 650 s to 1 030 s), whose OpenCL tests kept one core busy alone. 0: in this process.
TEST_WORKERS ?= 2
# The modules whose paths a GPU changes: its steps kept on the device, bricks copied, slabs
# uploaded while integrating, the recolouring's gather copied (run with CHRONOCL_DEVICE_KIND=gpu).
GPU_PATH_TESTS = tests/test_slots.py tests/test_slab_upload.py tests/test_device_faults.py \
	tests/test_device_steps.py tests/test_device_sliding.py tests/test_recolour_viewer.py \
	tests/test_process_memory.py tests/test_slide_failure.py

# Another apt-get holding the dpkg lock (an unattended upgrade) is waited for, not failed on.
APT := apt-get -o DPkg::Lock::Timeout=300

# Headless rendering needs EGL and Mesa (llvmpipe); OpenCL on the CPU needs a PoCL.
system:
	@if ! ldconfig -p | grep -q libEGL_mesa; then \
		if command -v apt-get >/dev/null && [ "$$(id -u)" = 0 ]; then \
			$(APT) update -qq && $(APT) install -y -qq libegl1 libgl1-mesa-dri libegl-mesa0; \
		else echo "warning: EGL/Mesa missing; install libegl1 libgl1-mesa-dri to render"; fi; \
	fi
	@# PyPI's PoCL (LLVM 14) builds no kernel on CPUs newer than its LLVM (AMD Zen 4 and later);
	@# Debian's PoCL does, and is listed first, so it is the default CPU device (README).
	@if ! dpkg-query -W -f '$${Status}' pocl-opencl-icd 2>/dev/null | grep -q 'ok installed'; then \
		if command -v apt-get >/dev/null && [ "$$(id -u)" = 0 ]; then \
			$(APT) update -qq && $(APT) install -y -qq pocl-opencl-icd; \
		else echo "warning: Debian's PoCL missing; PyPI's may fail on new CPUs: apt-get install pocl-opencl-icd"; fi; \
	fi

$(RUNTIME): pyproject.toml | system
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e .
	touch $(RUNTIME)

# CONSTRAINTS: a pip constraints file for that install (.ci/run: the lower bounds, .ci/lowest.py).
$(DEV): pyproject.toml | system
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[dev,events,notebook]' $(if $(CONSTRAINTS),-c $(CONSTRAINTS))
	touch $(RUNTIME) $(DEV)

demo: $(RUNTIME)
	$(BIN)/chronocl demo --out demo-out

lint: $(DEV)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

test: lint
	@# The viewer's browser tests drive Debian's chromium (no Playwright browser download).
	@if [ ! -x /usr/bin/chromium ]; then \
		if command -v apt-get >/dev/null; then \
			SUDO=$$([ "$$(id -u)" = 0 ] || echo sudo); \
			$$SUDO $(APT) update -qq && $$SUDO $(APT) install -y -qq chromium; \
		else echo "warning: /usr/bin/chromium missing; the browser tests will be skipped"; fi; \
	fi
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile --durations=30
	@# Again where a GPU's paths differ from a CPU device's (README: Device limits).
	CHRONOCL_DEVICE_KIND=gpu $(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile $(GPU_PATH_TESTS)

# The suite with 500 examples in every property test (the default is 60, whose time CI keeps
# within ten minutes): a deeper search, for a change to a kernel or a mode, or before a release.
test-full: lint
	CHRONOCL_EXAMPLES=500 $(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile --durations=30

# The whole suite on CPython 3.13 with the newest dependencies (pip upgrades every one, each run).
test-newest:
	@py="$$(bash .ci/newest-python)" && \
	if ! grep -qx "home = $$(dirname "$$py")" $(NEWEST)/pyvenv.cfg 2>/dev/null; then \
		"$$py" -m venv --clear $(NEWEST); fi && \
	$(NEWEST)/bin/python -m pip install -q --upgrade pip && \
	$(NEWEST)/bin/python -m pip install -q --upgrade --upgrade-strategy eager -e '.[dev,events,notebook]' && \
	touch $(NEWEST)/.runtime $(NEWEST)/.dev
	@$(NEWEST)/bin/python -c 'import sys; from importlib.metadata import version as v; \
		print("Python", sys.version.split()[0], "with", ", ".join(f"{p} {v(p)}" for p in \
		("numpy", "zarr", "numcodecs", "dask", "pyopencl", "moderngl", "xarray", "starlette", \
		"websockets", "pytest")))'
	$(MAKE) test VENV=$(NEWEST)

format: $(DEV)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

bench: $(DEV)
	@for b in $(wildcard bench/*.py); do echo "== $$b"; $(BIN)/python $$b --quick || exit 1; done

clean:
	rm -rf $(VENV) $(NEWEST) demo-out .pytest_cache .hypothesis .ruff_cache
