#!/usr/bin/env bash
# The Python package's tests (README's test command runs this after `cargo test`): a fresh
# virtual environment, `pip install ./python` from this clone, then pytest on python/tests.
#
# The wheel is built with the dev profile into the target directory `cargo test` used, so it
# reuses the dependencies that build compiled (python/Cargo.toml repeats the root's profile
# settings). A user's `pip install ./python` builds the release profile instead.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$root/target}"
venv="${GPUSTAR_VENV:-$CARGO_TARGET_DIR/python-venv}"
# What the tests write stays in the target directory, as `cargo test`'s does
# (.cargo/config.toml): gpustar's table caches and pip's downloads.
export GPUSTAR_CACHE_DIR="${GPUSTAR_CACHE_DIR:-$CARGO_TARGET_DIR/gpustar-cache}"
export PIP_CACHE_DIR="${PIP_CACHE_DIR:-$CARGO_TARGET_DIR/pip-cache}" PIP_DISABLE_PIP_VERSION_CHECK=1
python3 -m venv "$venv"
start=$(date +%s)
MATURIN_PEP517_ARGS="--profile dev" "$venv/bin/pip" install -q "./python[test]"
echo "test_python.sh: built and installed the package in $(($(date +%s) - start)) s"
# The CLI whose records the tests compare with (built by `cargo test`).
export GPUSTAR_BIN="${GPUSTAR_BIN:-$CARGO_TARGET_DIR/debug/gpustar}"
# From the tests' own folder: run from python/, `import gpustar` would find the source folder
# (without the compiled part) before the installed package.
cd python/tests
"$venv/bin/python" -c 'import gpustar, sys; print("test_python.sh: testing", gpustar.__file__)'
"$venv/bin/python" -m pytest -q .
