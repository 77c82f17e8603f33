#!/usr/bin/env bash
# Runs the strahl crate's tests once more per instruction-set level this processor offers beyond
# the one `cargo test` already ran (the default: the widest): `STRAHL_ISA=compiled` (wide's lanes
# as the crate is compiled), `avx2` and `avx512` (the run-time levels). The build is shared with
# `cargo test --workspace`, so each pass only runs the tests (about 15 s each).
set -euo pipefail
cd "$(dirname "$0")/.."
flags=$(grep -m1 '^flags' /proc/cpuinfo 2>/dev/null || true)
levels=(compiled)
if [[ $flags == *" avx2 "* && $flags == *" fma "* ]]; then levels+=(avx2); fi
if [[ $flags == *" avx512f "* && $flags == *" avx512vl "* && $flags == *" avx512dq "* && $flags == *" avx512bw "* ]]; then
  levels+=(avx512)
fi
for l in "${levels[@]}"; do
  echo "== strahl tests with STRAHL_ISA=$l" >&2
  STRAHL_ISA=$l cargo test -p strahl --quiet
done
