#!/usr/bin/env bash
# A short fuzzing smoke run (about a minute of fuzzing in all, plus the build): each target from
# the committed seeds, under AddressSanitizer (cargo fuzz's default). Needs the nightly
# toolchain; installs cargo-fuzz from crates.io if it is missing. Exits non-zero on any finding.
# Long runs: `cd fuzz && cargo +nightly fuzz run -O TARGET corpus/TARGET -- -runs=10000000`.
set -euo pipefail
cd "$(dirname "$0")"
if ! rustup toolchain list | grep -q '^nightly'; then
  echo "fuzz smoke: no nightly toolchain here; skipped" >&2
  exit 0
fi
command -v cargo-fuzz > /dev/null || cargo install --locked cargo-fuzz >&2
cargo +nightly fuzz build -O >&2
for target in obj scene_file differential serialized; do
  corpus="$(mktemp -d)"
  [ -d "seeds/$target" ] && cp "seeds/$target"/* "$corpus"/
  echo "fuzz smoke: $target, 20 s" >&2
  cargo +nightly fuzz run -O "$target" "$corpus" -- -max_total_time=20 -print_final_stats=1 2>&1 \
    | grep -E "^(Done|stat::number_of_executed_units)|ERROR|panicked|SUMMARY" >&2
  rm -rf "$corpus"
done
echo "fuzz: 4 passed, 0 failed"
