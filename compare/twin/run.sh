#!/bin/bash
# One-process A/B of strahl's native and dependency builds (PERFORMANCE.md, issue 32, session 54).
#   compare/twin/run.sh [BASE_REV]      (default BASE_REV: HEAD)
# Makes a throw-away workspace (TWIN_DIR, default target/twin) holding four copies of the library:
# strahl_nat and strahl_dep from the working tree, strahl_nat0 and strahl_dep0 from BASE_REV.
# The *_nat copies get `-C target-cpu=native` through Cargo's per-package profile rustflags (a
# nightly feature, hence `cargo +nightly`); the *_dep copies get no flags, as a crate that depends
# on strahl would build it. The native copies also get their own natively built copies of `wide`,
# `safe_arch` and `glam` (before session 55 they shared the baseline ones, a hybrid that is not the
# native build: its rays ran at half speed). All four link into one binary, so each build runs in the same process
# as its twin and the host's noise falls on both. Then, for example:
#   RAYON_NUM_THREADS=1 target/twin/target/release/app scene.toml 150 nat dep
# and for ray queries (scene files with the harness's views and lights are in compare/twin/scenes):
#   RAYON_NUM_THREADS=1 target/twin/target/release/app compare/twin/scenes/sponza.toml 40 nat dep shadow stream
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
base=${1:-HEAD}
twin=${TWIN_DIR:-$repo/target/twin}
mkdir -p "$twin/app/src"
# The library's own non-optional dependencies, as its Cargo.toml lists them (the Linux-only ones
# included), so that the copies build against what the crate does.
deps=$(python3 - "$repo/Cargo.toml" <<'PY'
import sys, tomllib
t = tomllib.load(open(sys.argv[1], "rb"))
deps = dict(t["dependencies"])
for table in t.get("target", {}).values():
    deps.update(table.get("dependencies", {}))
def value(v):
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, str):
        return '"%s"' % v
    if isinstance(v, list):
        return "[" + ", ".join(value(x) for x in v) + "]"
    return "{ " + ", ".join("%s = %s" % (k, value(x)) for k, x in v.items() if k != "optional") + " }"
for name, v in deps.items():
    if not (isinstance(v, dict) and v.get("optional")):
        print("%s = %s" % (name, value(v)))
PY
)
# `wide`, `safe_arch` and `glam` choose their code by `cfg(target_feature)` when they are compiled,
# so a native build compiles them natively too. The *_nat copies therefore get their own copies of
# these three (packages wide_nat, safe_arch_nat, glam_nat, crate names unchanged) with the same
# flags; the *_dep copies share the registry's, built without.
reg=$(cd "$repo" && cargo metadata --format-version 1 2>/dev/null | python3 -c '
import json, sys, os
m = json.load(sys.stdin)
for p in m["packages"]:
    if p["name"] in ("wide", "safe_arch", "glam") and p["source"]:
        print(p["name"], p["version"], os.path.dirname(p["manifest_path"]))')
while read -r name version dir; do
  d=$twin/${name}_nat
  rm -rf "$d" && mkdir -p "$d" && cp -r "$dir/src" "$d/src"
  case $name in
    wide) extra='[features]
default = ["std"]
std = []
[dependencies]
bytemuck = "1.24.0"
safe_arch = { package = "safe_arch_nat", path = "../safe_arch_nat", features = ["bytemuck"] }' ;;
    safe_arch) extra='[dependencies]
bytemuck = { version = "1.24.0", optional = true }' ;;
    glam) extra='[features]
default = ["std", "f64", "i8", "u8", "i16", "u16", "i32", "u32", "i64", "u64", "isize", "usize"]
std = []
f64 = []
i8 = []
u8 = []
i16 = []
u16 = []
i32 = []
u32 = []
i64 = []
u64 = []
isize = []
usize = []' ;;
  esac
  printf '[package]\nname = "%s_nat"\nversion = "%s"\nedition = "2024"\n[lib]\nname = "%s"\npath = "src/lib.rs"\n%s\n' \
    "$name" "$version" "$name" "$extra" > "$d/Cargo.toml"
done <<< "$reg"
[ "$(wc -l <<< "$reg")" = 3 ] || { echo "wide, safe_arch or glam not found in cargo metadata" >&2; exit 1; }
deps_nat=$(sed -e 's|^wide = .*|wide = { package = "wide_nat", path = "../wide_nat" }|' \
  -e 's|^glam = .*|glam = { package = "glam_nat", path = "../glam_nat" }|' <<< "$deps")
for v in nat dep nat0 dep0; do
  d=$twin/strahl_$v
  rm -rf "$d/src" && mkdir -p "$d"
  if [ "${v%0}" = "$v" ]; then
    cp -r "$repo/src" "$d/src"
  else
    mkdir -p "$d/src" && git -C "$repo" archive "$base" src | tar -x -C "$d"
  fi
  rm -rf "$d/src/bin"
  if [ "${v#nat}" != "$v" ]; then vdeps=$deps_nat; else vdeps=$deps; fi
  printf '[package]\nname = "strahl_%s"\nversion = "0.1.0"\nedition = "2024"\n[dependencies]\n%s\n' "$v" "$vdeps" > "$d/Cargo.toml"
done
cat > "$twin/Cargo.toml" <<'TOML'
cargo-features = ["profile-rustflags"]
[workspace]
members = ["app", "strahl_nat", "strahl_dep", "strahl_nat0", "strahl_dep0"]
resolver = "2"
[profile.release]
codegen-units = 1
lto = "thin"
debug = 1
[profile.release.package.strahl_nat]
rustflags = ["-C", "target-cpu=native"]
[profile.release.package.strahl_nat0]
rustflags = ["-C", "target-cpu=native"]
[profile.release.package.wide_nat]
rustflags = ["-C", "target-cpu=native"]
[profile.release.package.safe_arch_nat]
rustflags = ["-C", "target-cpu=native"]
[profile.release.package.glam_nat]
rustflags = ["-C", "target-cpu=native"]
TOML
cat > "$twin/app/Cargo.toml" <<'TOML'
[package]
name = "app"
version = "0.1.0"
edition = "2024"
[dependencies]
strahl_nat = { path = "../strahl_nat" }
strahl_dep = { path = "../strahl_dep" }
strahl_nat0 = { path = "../strahl_nat0" }
strahl_dep0 = { path = "../strahl_dep0" }
TOML
cp "$repo/compare/twin/main.rs" "$twin/app/src/main.rs"
cp "$repo/Cargo.lock" "$twin/Cargo.lock" 2>/dev/null || true
# The workspace sits outside the repository's `.cargo/config.toml` only if TWIN_DIR says so; inside
# `target/` that file's `target-cpu=native` would reach every copy, so it is overridden here.
cd "$twin" && CARGO_BUILD_RUSTFLAGS="" RUSTFLAGS="" cargo +nightly build --release -p app
echo "built $twin/target/release/app"
