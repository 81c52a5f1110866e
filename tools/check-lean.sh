#!/usr/bin/env bash
# The lean decoder, as an embedder gets it, carries none of the tool's weight:
# 1. `cargo tree` of the library with its default features lists none of the command-line
#    tool's dependencies (clap, image, indicatif, wgpu, serde_json);
# 2. the library with `default-features = false` is the container, the renderer and the
#    applying half of stage 2 on bitvec, byteorder, crc32fast and zstd (and what they use)
#    alone: no stage crate (gsi-fit, gsi-optim, gsi-metrics, gsi-gpu), no test data
#    (gsi-synth), no third-party crate beyond that list. Cargo holds the stages out; this
#    says so and fails when a dependency creeps in.
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

allowed=" gsi gsi-format gsi-render gsi-enhance bitvec byteorder cfg-if crc32fast funty radium tap wyz zstd zstd-safe zstd-sys "
lean=$(cargo tree -p gsi --no-default-features -e normal --prefix none --format '{p}' |
    awk '{print $1}' | sort -u)
extra=""
for c in $lean; do
    [[ "$allowed" == *" $c "* ]] || extra+=" $c"
done
if [[ -n "$extra" ]]; then
    echo "FAILED: the lean decoder (--no-default-features) depends on:$extra"
    exit 1
fi
echo "lean decoder (--no-default-features):" $lean
