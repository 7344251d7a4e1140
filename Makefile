# Set-up and everyday commands. Each target creates .venv when it is missing.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint format bench clean

$(STAMP): pyproject.toml
	@# Headless rendering needs EGL and Mesa (llvmpipe); install them where they are missing.
	@if ! ldconfig -p | grep -q libEGL_mesa; then \
		if command -v apt-get >/dev/null && [ "$$(id -u)" = 0 ]; then \
			apt-get update -qq && apt-get install -y -qq libegl1 libgl1-mesa-dri libegl-mesa0; \
		else echo "warning: EGL/Mesa missing; install libegl1 libgl1-mesa-dri to render"; fi; \
	fi
	@# PyPI's PoCL (LLVM 14) builds no kernel on CPUs newer than its LLVM (AMD Zen 4 and later);
	@# Debian's PoCL does, and is listed first, so it is the default CPU device (README).
	@if ! dpkg-query -W -f '$${Status}' pocl-opencl-icd 2>/dev/null | grep -q 'ok installed'; then \
		if command -v apt-get >/dev/null && [ "$$(id -u)" = 0 ]; then \
			apt-get update -qq && apt-get install -y -qq pocl-opencl-icd; \
		else echo "warning: Debian's PoCL missing; PyPI's may fail on new CPUs: apt-get install pocl-opencl-icd"; fi; \
	fi
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[dev]'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/chronocl demo --out demo-out

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

test: lint
	@# The viewer's browser tests drive Debian's chromium (no Playwright browser download).
	@if [ ! -x /usr/bin/chromium ]; then \
		if command -v apt-get >/dev/null; then \
			SUDO=$$([ "$$(id -u)" = 0 ] || echo sudo); \
			$$SUDO apt-get update -qq && $$SUDO apt-get install -y -qq chromium; \
		else echo "warning: /usr/bin/chromium missing; the browser tests will be skipped"; fi; \
	fi
	$(BIN)/python -m pytest -q

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

bench: $(STAMP)
	@for b in $(wildcard bench/*.py); do echo "== $$b"; $(BIN)/python $$b --quick || exit 1; done

clean:
	rm -rf $(VENV) demo-out .pytest_cache .hypothesis .ruff_cache
