#!/bin/sh
# Prepare `.gpukit/`, what a machine with a GPU and no network or Rust toolchain needs to
# measure the GPU figures of BENCHMARKS.md (issue 4): the `gpu_bench` example built
# here (x86-64), the Kodak images, and the Vulkan loader packages. Then, with the
# `device` tool of this workplace:
#
#   run(carry=[".gpukit"], command="sh tools/gpu-kit.sh --run")
#
# which unpacks the loader, runs the benchmark and leaves bench/gpu.json in $OUT.
set -eu
cd "$(dirname "$0")/.."
kit=.gpukit

if [ "${1:-}" = "--run" ]; then
    for f in "$kit"/gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
    if [ -f /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]; then
        export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    fi
    nvidia-smi --query-gpu=name,driver_version --format=csv,noheader || true
    out="${OUT:-bench}"
    mkdir -p "$out"
    WGPU_BACKEND=vulkan "$kit/gpu_bench" --kodak "$kit/kodak" --out "$out/gpu.json" ${GPU_BENCH_ARGS:-}
    exit
fi

exclude="$(git rev-parse --git-path info/exclude)"
mkdir -p "$(dirname "$exclude")"
grep -qx "/$kit/" "$exclude" 2>/dev/null || echo "/$kit/" >>"$exclude"
mkdir -p "$kit/kodak" "$kit/gl" /tmp/gsi-apt/partial
cargo build --release --example gpu_bench
cp target/release/examples/gpu_bench "$kit/"
strip "$kit/gpu_bench"
cp ../shared/data/kodak/*.png "$kit/kodak/"
o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/gsi-apt'
# shellcheck disable=SC2086
apt-get $o update >/dev/null
# shellcheck disable=SC2086
(cd "$kit/gl" && apt-get $o download libvulkan1)
du -sh "$kit"
