#!/usr/bin/env bash
# The Python package's part of CI (.ci/run calls it after the Rust tests): the module built in
# the `ci` profile against the very engine the Rust tests built (no second compile of it),
# installed by `pip install ./python` into a venv this script makes, then pytest and the example
# notebook run there.
set -euo pipefail
cd "$(dirname "$0")/.."
target="${CARGO_TARGET_DIR:-target}"
case "$target" in /*) ;; *) target="$PWD/$target" ;; esac
echo "== python: the module (the workspace's ci build, as .ci/run makes it: one engine)"
PYO3_BUILD_EXTENSION_MODULE=1 cargo build --workspace --profile ci --all-targets --locked
venv="$target/python-venv"
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install -q --disable-pip-version-check -r python/requirements-ci.txt
# `pip install ./python` as a user does it (maturin, through pip's isolated build), in the ci
# profile so that cargo reuses the engine built above; python/Cargo.toml names the shared
# dependencies' features that make that possible, and a second compile of the engine fails here.
echo "== python: pip install ./python"
"$venv/bin/python" -m pip uninstall -q -y matfit >/dev/null 2>&1 || true
log="$target/python-pip-install.log"
if ! MATURIN_PEP517_ARGS="--profile ci" CARGO_TARGET_DIR="$target" \
    "$venv/bin/python" -m pip install -v --disable-pip-version-check ./python >"$log" 2>&1; then
    cat "$log" >&2
    echo "python/ci.sh: pip install ./python failed" >&2
    exit 1
fi
if grep -q "Compiling matfit v" "$log"; then
    grep -E "Compiling|Finished" "$log" >&2
    echo "python/ci.sh: pip install ./python compiled the engine a second time: a shared" \
        "dependency's features differ from the workspace build (see python/Cargo.toml)" >&2
    exit 1
fi
grep -E "Finished|Successfully installed" "$log"
echo "== python: pytest"
MATFIT_BIN="$target/ci/matfit" MATFIT_PROGRESS=0 "$venv/bin/python" -m pytest -q -s python/tests
echo "== python: the example notebook"
MATFIT_ROOT="$PWD" "$venv/bin/python" python/run_notebook.py python/examples/figure6.ipynb
