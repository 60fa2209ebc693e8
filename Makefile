# microfacet — fresh-machine entry points.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
OUT    ?= demo-output
# batch sizes of `make bench`'s scaling table (1e8 needs ~12 GB: SCALING=1e4,1e5,1e6,1e7,1e8)
SCALING ?= 1e4,1e5,1e6,1e7

# arithmetic types of the BRDF kernels that make setup compiles (the tests use float32 ones too)
PRECOMPILE_DTYPES ?= $(if $(filter true,$(CI)),float64$(comma)float32,float64)
comma := ,

.PHONY: setup setup-blender setup-npm demo test bench docs tutorials clean

$(VENV)/.installed: pyproject.toml
	@echo "setup: creating $(VENV) and installing microfacet with its test, mitsuba, dask, view, export and docs extras (pip)"
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test,mitsuba,dask,view,export,docs]"
	touch $@

# llvm_ad_rgb (Mitsuba plugins) needs a system libLLVM >= 16: installed where apt and root
# are available (saying what and why first); elsewhere the llvm tests skip with a one-line
# reason (they fail under CI=true). `make demo` runs this target too.
setup: $(VENV)/.installed
	@if ls /usr/lib/x86_64-linux-gnu/libLLVM-1[6-9]*.so* /usr/lib/x86_64-linux-gnu/libLLVM.so.1[6-9]* \
	      /usr/lib/llvm-1[6-9]/lib/libLLVM*.so* 2>/dev/null | grep -q .; then :; \
	elif command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	  echo "setup: installing the system package libllvm19 with apt-get (as root): Mitsuba's llvm_ad_rgb variant, used by the demo's Mitsuba section and its tests, needs libLLVM >= 16"; \
	  apt-get update -qq && apt-get install -y -qq libllvm19 >/dev/null; \
	else echo "setup: no libLLVM >= 16 and no root apt: Mitsuba llvm_ad_rgb tests will skip"; fi
# GLSL tests (moderngl on EGL: Mesa llvmpipe), viewer tests (Playwright on the system
# Chromium; never 'playwright install') and MaterialX's GlslRenderer (GLX: needs an X server,
# Xvfb): system packages where apt and root are available.
	@if [ -e /usr/lib/chromium/chromium ] && /sbin/ldconfig -p | grep -q libEGL_mesa && command -v Xvfb >/dev/null; then :; \
	elif command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	  echo "setup: installing the system packages chromium libegl1 libgl1 libgl1-mesa-dri libegl-mesa0 xvfb with apt-get (as root): the demo's real-time section and the viewer tests run the WebGL2 viewer in headless Chromium, the GLSL tests run on Mesa's EGL (llvmpipe), the MaterialX render tests run MaterialX's GlslRenderer on a private Xvfb display"; \
	  apt-get update -qq && apt-get install -y -qq chromium libegl1 libgl1 libgl1-mesa-dri libegl-mesa0 xvfb >/dev/null; \
	else echo "setup: no chromium/Mesa EGL/Xvfb and no root apt: GLSL, viewer and MaterialX render tests will skip"; fi
# The package's bytecode compiled now (~1 s), not by each command's first run (nor at every run
# where PYTHONDONTWRITEBYTECODE is set)
	@$(PY) -m compileall -q src/microfacet >/dev/null
# Numba kernels compiled into Numba's cache now, not at their first use in the demo or the tests
# (docs/performance.md): the BRDF kernels (python -m microfacet.kernels --help; float32 ones too under
# CI=true, for the tests) beside the measured-BRDF readers', LEADR and glints kernels
# (microfacet.kernels_extra), two processes (they compile different functions): ~2-4 min on 2 cores
# the first time, seconds once cached. The cache is src/microfacet/__pycache__ (git-ignored) or $$NUMBA_CACHE_DIR.
	@$(PY) -m microfacet.kernels_extra --precompile --quiet & extra=$$!; \
	$(PY) -m microfacet.kernels --precompile --quiet --dtypes $(PRECOMPILE_DTYPES); brdf=$$?; \
	wait $$extra && exit $$brdf
# Exports tested in their real consumers: Blender (bpy 4.5, ~950 MB, its own venv) and three.js +
# gltf-validator (npm, 24 MB): under CI=true or when asked (make setup BLENDER=1 NPM=1); elsewhere
# their tests skip with a one-line reason.
	@if [ "$$CI" = true ] || [ -n "$(BLENDER)" ]; then $(MAKE) --no-print-directory setup-blender; fi
	@if [ "$$CI" = true ] || [ -n "$(NPM)" ]; then $(MAKE) --no-print-directory setup-npm; fi

# Blender 4.5 as a Python module pins numpy<2 (this project runs NumPy 2): a separate venv, used by
# microfacet export --to blender in a subprocess (docs/export.md). The wheel is cp311 (Python 3.11).
BLENDER_VENV := .venv-blender
BLENDER_PYTHON ?= $(shell command -v python3.11 || echo $(PYTHON))
setup-blender: $(BLENDER_VENV)/.installed
$(BLENDER_VENV)/.installed:
	@if /sbin/ldconfig -p | grep -q libxkbcommon.so.0 && /sbin/ldconfig -p | grep -q libXi.so.6 \
	      && /sbin/ldconfig -p | grep -q libSM.so.6; then :; \
	elif command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	  echo "setup-blender: installing the system packages libx11-6 libxrender1 libxfixes3 libxi6 libxkbcommon0 libsm6 libice6 libgl1 libxext6 with apt-get (as root): Blender's Python module (bpy) loads them, no display needed"; \
	  apt-get update -qq && apt-get install -y -qq libx11-6 libxrender1 libxfixes3 libxi6 libxkbcommon0 libsm6 libice6 libgl1 libxext6 >/dev/null; \
	else echo "setup-blender: X11 client libraries missing and no root apt: bpy may not import"; fi
	@echo "setup-blender: creating $(BLENDER_VENV) with bpy 4.5 (Blender as a Python module: ~950 MB installed, ~21 s; pins numpy<2, so apart from $(VENV))"
	$(BLENDER_PYTHON) -m venv $(BLENDER_VENV)
	$(BLENDER_VENV)/bin/python -m pip install --quiet "bpy==4.5.*"
	touch $@

# three.js (the .glb export's renderer test in headless Chromium) and Khronos gltf-validator, in the
# git-ignored folder .npm-export (node 20 / npm 10)
NPM_DIR := .npm-export
setup-npm: $(NPM_DIR)/.installed
$(NPM_DIR)/.installed:
	@if command -v npm >/dev/null 2>&1; then \
	  echo "setup-npm: installing three@0.187 and gltf-validator@2.0.0-dev.3.10 into $(NPM_DIR) (npm, 24 MB)"; \
	  mkdir -p $(NPM_DIR) && ( [ -f $(NPM_DIR)/package.json ] || echo '{"private": true}' > $(NPM_DIR)/package.json ) && \
	  ( cd $(NPM_DIR) && npm install --no-audit --no-fund --silent three@0.187 gltf-validator@2.0.0-dev.3.10 ) && \
	  touch $@; \
	else echo "setup-npm: npm not found (install nodejs 20 / npm 10): the three.js export tests will skip"; fi

demo: setup
	$(VENV)/bin/microfacet demo -o $(OUT)

test: setup
	$(PY) -m pytest -q -n auto --maxprocesses 4

# the executed tutorials (examples/NN_*.py, docs/scripts/tutorials.py): each script runs in its own
# process into build/tutorials/, again only when its text changed (FORCE=1: all of them)
tutorials: $(VENV)/.installed
	$(PY) docs/scripts/tutorials.py $(if $(FORCE),--force)

# the docs site (mkdocs.yml: MkDocs + Material + mkdocstrings), warnings as errors, into site/
docs: tutorials
	DISABLE_MKDOCS_2_WARNING=true NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --site-dir site

bench: setup
	$(PY) benchmarks/bench_brdf.py --scaling $(SCALING)
	$(PY) benchmarks/bench_measured.py
	$(PY) benchmarks/bench_view.py

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache site $(BLENDER_VENV) $(NPM_DIR)
