# Source me (after bash bench/setup_mitsuba.sh):  source bench/mitsuba_env.sh
# Activates bench/.venv and points Dr.Jit at Debian's libLLVM 19.
_mi_here="$(cd "$(dirname "${BASH_SOURCE[0]:-$0}")" && pwd)"
for _mi_so in /usr/lib/x86_64-linux-gnu/libLLVM-19.so /usr/lib/llvm-19/lib/libLLVM-19.so \
             /usr/lib/*-linux-gnu/libLLVM-19.so; do
    if [ -e "$_mi_so" ]; then export DRJIT_LIBLLVM_PATH="$_mi_so"; break; fi
done
# shellcheck disable=SC1091
. "$_mi_here/.venv/bin/activate"
unset _mi_here _mi_so
