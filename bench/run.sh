#!/usr/bin/env bash
# matfit vs Mitsuba 3, one command (issue 7): see bench/README.md.
#   bash bench/run.sh            # full benchmark (<= 20 min on a quiet 2-core machine),
#                                # writes bench/RESULTS.md and bench/convergence.svg
#   bash bench/run.sh --quick    # a few minutes, writes bench/out/quick/RESULTS.md
# Other options are passed to bench/compare.py (--threads N, --out DIR, --md FILE,
# --provisional NOTE). Honours CARGO_TARGET_DIR.
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/.." && pwd)"
TARGET="${CARGO_TARGET_DIR:-$ROOT/target}"

echo "== building matfit (release)" >&2
(cd "$ROOT" && CARGO_TARGET_DIR="$TARGET" cargo build --release --locked -q)
echo "== Mitsuba 3 (bench/setup_mitsuba.sh)" >&2
bash "$HERE/setup_mitsuba.sh"
# shellcheck disable=SC1091
source "$HERE/mitsuba_env.sh"
cd "$ROOT"
exec python "$HERE/compare.py" --matfit "$TARGET/release/matfit" "$@"
