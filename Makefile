# scenesample dev loop. `make help` lists the targets.
PY ?= python3
export PYOPENGL_PLATFORM ?= egl

.PHONY: help setup demo test test-rust test-python test-wheel wheel bench lint fmt

help: ## list the targets
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  %-12s %s\n", $$1, $$2}'

setup: ## install system packages (Mesa Vulkan, EGL) and build scenesample with its test extras
	@bash scripts/setup.sh

demo: setup ## the main job: discretize a scene, write EXR/PNG to out/, print a timing table
	$(PY) -m scenesample.demo

test: setup lint test-rust test-python test-wheel ## every test: lints, cargo (Rust internals, shaders), pytest, the wheel

test-rust: ## cargo tests of the Rust core: optimized with debug assertions and overflow checks, then in debug
	cargo test --profile checked
	cargo test

test-python: ## pytest: cross-validation against pyrender and Embree, bad input, stubs, notebooks
	$(PY) -m pytest

test-wheel: ## build the wheel and sdist, install each into a fresh venv, smoke-test them and run the quickstart outside the tree
	PYTHON=$(PY) bash scripts/wheel_check.sh

wheel: ## the abi3 manylinux2014 wheel (CPython >= 3.9, glibc >= 2.17) and the sdist, into dist/
	CARGO_TARGET_DIR=target/manylinux $(PY) -m maturin build --release --zig --compatibility manylinux2014 --out dist
	$(PY) -m maturin sdist --out dist

bench: setup ## side-by-side benchmarks against Embree and pyrender
	$(PY) -m scenesample.bench

lint: ## formatting and lints, Rust and Python
	cargo fmt --check
	cargo clippy --release --all-targets --features python -- -D warnings
	$(PY) -m ruff check python tests
	$(PY) -m ruff format --check python tests

fmt: ## format Rust and Python
	cargo fmt
	$(PY) -m ruff format python tests
