#!/usr/bin/env bash
# The Python package's part of CI (.ci/run calls it after the Rust tests): the module built in
# the `ci` profile against the very engine the Rust tests built (no second compile of it),
# installed into a venv this script makes, then pytest and the example notebook run there.
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
site="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
rm -rf "$site/matfit"
cp -r python/python/matfit "$site/matfit"
cp "$target/ci/lib_matfit.so" "$site/matfit/_matfit.abi3.so"
echo "== python: pytest"
MATFIT_BIN="$target/ci/matfit" MATFIT_PROGRESS=0 "$venv/bin/python" -m pytest -q -s python/tests
echo "== python: the example notebook"
MATFIT_ROOT="$PWD" "$venv/bin/python" python/run_notebook.py python/examples/figure6.ipynb
