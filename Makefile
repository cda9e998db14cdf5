# PLE — two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
SYSLIBS := libegl1 libegl-mesa0 libgl1-mesa-dri libxi6 libxxf86vm1 libxfixes3 libxrender1 libxkbcommon0 libsm6 gcc
PIP_FLAGS := --disable-pip-version-check -q

CONSUMER_DEBS := admesh prusa-slicer
GLTF_VALIDATOR := $(VENV)/node/node_modules/gltf-validator
WHEELS := build/wheels/.fetched
# the test run's processes (pytest-xdist): one per core of the 2-core machine the suite is sized for; a test
# file runs in one process (loadfile: the add-on's files share that process's Blender worker); one BLAS
# thread each (tests/conftest.py says why). Bytecode is written (``__pycache__``, ignored by git) even where
# the shell says PYTHONDONTWRITEBYTECODE: the run starts many Python processes (commands, Dask
# workers, Blender), and each would otherwise compile the package from source again
TEST_WORKERS ?= 2

.PHONY: setup syslibs consumers demo test test-blender lint bench wheels extension docs clean

setup: $(STAMP)

# system libraries that the bpy wheel and headless EGL rendering load, and gcc for the optional STL encoder
syslibs:
	@missing=""; for p in $(SYSLIBS); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing system libraries:$$missing"; \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq $$missing; \
	fi

# consumers the tests hand our files to: admesh and PrusaSlicer (apt), the Khronos glTF
# validator (npm, into the venv); a tool that cannot be installed makes its tests skip, saying so
consumers:
	@missing=""; for p in $(CONSUMER_DEBS); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	command -v npm >/dev/null || missing="$$missing nodejs npm"; \
	if [ -n "$$missing" ]; then \
	  echo "installing consumer tools:$$missing"; \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  { $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq $$missing; } \
	    || echo "warning: could not install$$missing (their tests will skip)"; \
	fi
	@test -d $(GLTF_VALIDATOR) || { command -v npm >/dev/null && npm install -s --prefix $(VENV)/node gltf-validator; } \
	  || echo "warning: could not install gltf-validator with npm (its tests will skip)"

$(STAMP): pyproject.toml setup.py core/ple/io/_stlcodec.c core/ple/meshing/_assemble.c core/ple/meshing/_selfcheck.c core/ple/queries/_rangefinder.c | syslibs consumers
	@command -v $(PYTHON) >/dev/null || { echo "error: $(PYTHON) is required (bpy 5.0.1 needs Python 3.11)"; exit 2; }
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install $(PIP_FLAGS) --upgrade pip
	$(BIN)/pip install $(PIP_FLAGS) -e ".[dev,blender]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/python -m tools.demo

test: $(STAMP) $(WHEELS)
	$(BIN)/ruff check .
	OPENBLAS_NUM_THREADS=1 PYTHONDONTWRITEBYTECODE= $(BIN)/python -m pytest tests -n $(TEST_WORKERS) --dist loadfile --durations=20 \
	  -m "not bpy_only"

# the add-on in the Blender users have: a venv holding only bpy==5.0.1 (Blender's own numpy, requests,
# zstandard), the zip installed with its wheels (tests/addon/test_bpy_only.py); .ci/run calls it after make test
BPY_VENV := build/bpy-venv
$(BPY_VENV)/.installed:
	test -x $(BPY_VENV)/bin/python || $(PYTHON) -m venv $(BPY_VENV)
	$(BPY_VENV)/bin/pip install $(PIP_FLAGS) bpy==5.0.1
	touch $@

test-blender: $(STAMP) $(WHEELS) $(BPY_VENV)/.installed
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest tests/addon/test_bpy_only.py -m bpy_only -n $(TEST_WORKERS) --dist load --durations=10

lint: $(STAMP)
	$(BIN)/ruff check .

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) dist build out *.egg-info core/*.egg-info

# the wheels the extension bundles (trimesh, scipy, manifold3d, rtree) for every platform, downloaded
# once: building the extension, and every test that builds it, then needs no network
$(WHEELS): ple_addon/build.py | $(STAMP)
	@$(BIN)/python -m ple_addon.build --fetch-wheels && touch $@ \
	  || echo "warning: the wheels were not downloaded (offline?): the extension cannot be built until make wheels gets them"

wheels: $(WHEELS)

extension: $(STAMP) $(WHEELS)
	$(BIN)/python -m ple_addon.build --platform all

docs: $(STAMP)
	$(BIN)/python -m tools.docs_build
