#!/usr/bin/env bash
# The lean decoder, as an embedder gets it, carries none of the tool's weight:
# 1. `cargo tree` of the library with its default features lists none of the command-line
#    tool's dependencies (clap, image, indicatif, wgpu, serde_json);
# 2. the library built with `--no-default-features` holds no code of the stages or of the
#    test-data generator (no symbol under gsi::fit, gsi::metrics, gsi::optim or gsi::synth).
# Exits 1 and says what it found otherwise. Run from anywhere in the repository.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

tree=$(cargo tree -p gsi -e normal --prefix none --format '{p}')
echo "cargo tree -p gsi -e normal (default features):"
echo "$tree" | sed 's/^/  /'
heavy=$(echo "$tree" | grep -E '^(clap|image|indicatif|wgpu|serde_json) ' || true)
if [[ -n "$heavy" ]]; then
    echo "FAILED: the library's default features pull in the tool's dependencies:"
    echo "$heavy"
    exit 1
fi

rlib=$(cargo build -p gsi --no-default-features --lib --message-format=json 2>/dev/null |
    grep '"reason":"compiler-artifact"' | grep '"name":"gsi"' |
    grep -o '"[^"]*libgsi[^"]*\.rlib"' | tr -d '"' | head -n 1)
if [[ -z "$rlib" || ! -f "$rlib" ]]; then
    echo "FAILED: could not find the lean libgsi rlib"
    exit 1
fi
# The rlib's object files name every function compiled into it; rustc's v0 and legacy
# manglings both spell a module path as <len><name>.
stages=$(nm -A "$rlib" 2>/dev/null | grep -E '3gsi(3fit|7metrics|5optim|5synth)' | head -n 5 || true)
if [[ -n "$stages" ]]; then
    echo "FAILED: the lean build compiles stage or test-data code:"
    echo "$stages"
    exit 1
fi
echo "lean build ($rlib): no fit, metrics, optim or synth code"
