#!/usr/bin/env bash
# Reproducible Mitsuba 3 setup for matfit's cross-checks.
#   bash bench/setup_mitsuba.sh        # idempotent, silent on success
#   source bench/mitsuba_env.sh        # then: python -c 'import mitsuba'
# Creates bench/.venv with pinned mitsuba/drjit/numpy (+ colour-science for
# tools/cornell_rgb.py) and installs Debian's libllvm19, which the llvm_*
# variants need (Dr.Jit aborts with the LLVM 14/15 that Debian 12 also ships).
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
VENV="$HERE/.venv"
LOG="$(mktemp)"
trap 'rm -f "$LOG"' EXIT

MITSUBA_VERSION=3.9.1
DRJIT_VERSION=1.5.0
NUMPY_VERSION=2.2.6
COLOUR_VERSION=0.4.7
SCIPY_VERSION=1.15.3

fail() { echo "setup_mitsuba.sh: $*" >&2; cat "$LOG" >&2; exit 1; }

# --- libLLVM 19 (Debian 12 main carries libllvm19 1:19.1.7-3~deb12u1) -----
find_llvm() {
    local so
    for so in /usr/lib/x86_64-linux-gnu/libLLVM-19.so /usr/lib/llvm-19/lib/libLLVM-19.so \
              /usr/lib/*-linux-gnu/libLLVM-19.so; do
        [ -e "$so" ] && { echo "$so"; return 0; }
    done
    return 1
}
if ! LLVM_SO="$(find_llvm)"; then
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    export DEBIAN_FRONTEND=noninteractive
    if ! $SUDO apt-get install -y -q libllvm19 >"$LOG" 2>&1; then
        $SUDO apt-get update -q >"$LOG" 2>&1 || fail "apt-get update failed"
        $SUDO apt-get install -y -q libllvm19 >"$LOG" 2>&1 || fail "apt-get install libllvm19 failed"
    fi
    LLVM_SO="$(find_llvm)" || fail "libLLVM-19.so not found after installing libllvm19"
fi

# --- venv with pinned packages ---------------------------------------------
if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV" >"$LOG" 2>&1 || fail "python3 -m venv failed (apt-get install python3-venv?)"
fi
want="mitsuba==$MITSUBA_VERSION drjit==$DRJIT_VERSION numpy==$NUMPY_VERSION scipy==$SCIPY_VERSION colour-science==$COLOUR_VERSION"
have="$("$VENV/bin/python" -m pip freeze 2>/dev/null | tr '\n' ' ')"
need=0
for p in $want; do
    case " $have " in *" $p "*) ;; *) need=1 ;; esac
done
if [ "$need" = 1 ]; then
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check $want >"$LOG" 2>&1 \
        || fail "pip install failed"
fi

# --- smoke check: both variants render --------------------------------------
DRJIT_LIBLLVM_PATH="$LLVM_SO" "$VENV/bin/python" - >"$LOG" 2>&1 <<'PY' || fail "mitsuba smoke check failed"
import mitsuba as mi
for v in ("scalar_rgb", "llvm_ad_rgb"):
    mi.set_variant(v)
    # a tiny render: a wrong libLLVM (e.g. 15) only crashes once a kernel is compiled
    img = mi.render(mi.load_dict(mi.cornell_box()), spp=1)
    assert float(sum(img.numpy().ravel())) > 0, v
PY
