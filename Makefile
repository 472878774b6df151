# scenesample dev loop. `make help` lists the targets.
PY ?= python3
export PYOPENGL_PLATFORM ?= egl

.PHONY: help setup demo test check test-rust test-python wheel bench lint fmt fuzz
FUZZ_CASES ?= 20000
FUZZ_SEED ?= 1

help: ## list the targets
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  %-12s %s\n", $$1, $$2}'

setup: ## install system packages (Mesa Vulkan, EGL) and build scenesample (editable) with its test extras
	@bash scripts/setup.sh

demo: setup ## the main job: discretize a scene, write EXR/PNG to out/, print a timing table
	$(PY) -m scenesample.demo

test: ## every check, as CI runs it: lints, cargo tests, the wheel built from the sdist, pytest on it, a clean-venv install; ends with a timing table
	$(PY) scripts/make_test.py

check: ## the fast inner loop on a warm tree: lints, a rebuild, and the tests a change touches (not a substitute for `make test`)
	$(PY) scripts/make_check.py

test-rust: ## cargo tests of the Rust core, with debug assertions and overflow checks
	cargo test --profile checked

test-python: ## pytest against the editable install (`make setup`), on both cores
	$(PY) -m pytest -n 2 --dist worksteal

fuzz: setup ## a longer loader fuzzing run: FUZZ_CASES (20000) mutated glTF/GLB/OBJ/MTL files, seed FUZZ_SEED
	$(PY) tests/fuzz_loaders.py --cases $(FUZZ_CASES) --seed $(FUZZ_SEED)

# The wheel's build tools (maturin, zig) at their pinned versions, in a venv of their own: nothing
# is taken from the machine's Python. Remade when scripts/pins.txt changes.
TOOLS := target/tools-venv
$(TOOLS)/pins.txt: scripts/pins.txt
	$(PY) -m venv --clear $(TOOLS)
	$(TOOLS)/bin/python -m pip install --quiet --disable-pip-version-check -c scripts/pins.txt maturin ziglang
	cp scripts/pins.txt $@

wheel: $(TOOLS)/pins.txt ## the abi3 manylinux2014 wheel (CPython >= 3.9, glibc >= 2.17) and the sdist, into dist/
	PATH="$(CURDIR)/$(TOOLS)/bin:$$PATH" CARGO_TARGET_DIR=target/manylinux maturin build --release --zig --compatibility manylinux2014 --out dist
	PATH="$(CURDIR)/$(TOOLS)/bin:$$PATH" maturin sdist --out dist

bench: setup ## side-by-side benchmarks against Embree and pyrender
	$(PY) -m scenesample.bench

lint: ## formatting and lints, Rust and Python
	cargo fmt --check
	cargo clippy --profile checked --all-targets --features python -- -D warnings
	$(PY) -m ruff check python tests scripts
	$(PY) -m ruff format --check python tests scripts

fmt: ## format Rust and Python
	cargo fmt
	$(PY) -m ruff format python tests scripts
