#!/bin/sh
# Prepare `.gpukit/`, what a machine with a GPU and no network or Rust toolchain needs to
# measure the GPU figures of BENCHMARKS.md and to run the GPU tests there: the
# `gpu_bench` example, the GPU test binaries (`cli/tests/gpu.rs` and the unit tests of
# the device crate and of the stages' GPU twins) and the `gsi` binary they call, all
# built here (x86-64) and stripped, the Kodak images, and the Vulkan loader package.
# Then, with the `device` tool of this workplace:
#
#   run(carry=[".gpukit"], command="sh tools/gpu-kit.sh --run")
#
# which unpacks the loader, runs the GPU tests with GSI_REQUIRE_GPU=1 and prints their
# margins (gradient relative errors, parameter differences against their bounds, pixel
# flips, round trips per step), then the benchmark (`GPU_BENCH_ARGS`, by default
# `--limit 4` images for the time-to-32 dB sweep, to stay well inside ten minutes), and
# leaves the logs and gpu.json in $OUT (target/gpukit/ outside the device tool).
#
#   sh tools/gpu-kit.sh --dry-run
#
# does the same here, on whatever adapter wgpu finds (lavapipe in CI's image) and with
# `--quick` for the benchmark: the whole report of a GPU run, with software figures.
#
# Built with `KIT_CLI=1`, the kit also holds what `tools/cli_times.py` needs to time
# whole `gsi decode`, `encode` and `enhance` processes on the GPU, on all the machine's
# cores and on two (kodim23 stored at 1 bpp, four Kodak images, two LOL `val30` low
# images and a 4 MP dark photograph: the synthetic set's kodim05 enlarged, which needs
# `cargo run --release --example lowlight_set` first and Pillow); `--run` then ends with
# those times (`cli.json`), and `--cli` runs them alone.
set -eu
cd "$(dirname "$0")/.."
kit=.gpukit

run_kit() {
    export GSI_REQUIRE_GPU=1 GSI_REPO="$PWD" GSI_BIN="$PWD/$kit/gsi"
    status=0
    # The CLI's GPU tests, then each crate's unit tests of its GPU twins (filtered to
    # them: the rest of those binaries are CPU tests that CI runs).
    for t in tests-gpu tests-device tests-fit tests-enhance; do
        case "$t" in
        tests-fit) filter="resident" ;;
        tests-enhance) filter="gpu" ;;
        *) filter="" ;;
        esac
        echo "==> $t $filter"
        # shellcheck disable=SC2086
        if ! "$kit/$t" $filter --test-threads=1 --nocapture >"$out/$t.log" 2>&1; then
            status=1
            echo "FAILED: $t (last lines of $out/$t.log follow)"
            tail -n 20 "$out/$t.log"
        fi
        grep -E '^test result|FAILED|panicked' "$out/$t.log" || true
    done
    echo "==> margins"
    grep -h -E '^(margin|adapter):' "$out"/tests-*.log | sort | uniq || true
    # The gradient checks' lines that are not margin lines (those are printed above).
    grep -h -E 'relative error' "$out"/tests-*.log | grep -v '^margin:' || true
    echo "==> gpu_bench ${GPU_BENCH_ARGS:---limit 4}"
    # shellcheck disable=SC2086
    "$kit/gpu_bench" --kodak "$kit/kodak" --out "$out/gpu.json" ${GPU_BENCH_ARGS:---limit 4} || status=1
    return $status
}

# Whole `gsi` processes on each device (`tools/cli_times.py`), from the kit's `cli/`.
run_cli() {
    echo "==> cli_times"
    c="$kit/cli"
    python3 tools/cli_times.py --gsi "$kit/gsi" --out "$out/cli.json" \
        --decode "$c/kodim23.gsi" --decode "$c/kodim23.gsi:--width,4243" \
        --encode "$kit/kodak/kodim01.png:1" --encode "$kit/kodak/kodim02.png:1" \
        --encode "$kit/kodak/kodim03.png:1" --encode "$kit/kodak/kodim04.png:1" \
        --enhance "$c/119.png:1.1" --enhance "$c/604.png:1.1" --enhance "$c/dark4mp.png:1.1"
}

# The loader and NVIDIA's Vulkan driver, on a machine that has only the driver's files.
setup_gl() {
    for f in "$kit"/gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
    if [ -f /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]; then
        export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    fi
    if [ -f /usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json ]; then
        export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
    fi
    nvidia-smi --query-gpu=name,driver_version --format=csv,noheader || true
    export WGPU_BACKEND=vulkan
}

case "${1:-}" in
--run | --cli | --dry-run)
    # Where the logs and JSON go.
    out="${OUT:-target/gpukit}"
    mkdir -p "$out"
    export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
    # The commit the kit was built from, for gpu.json and cli.json.
    if [ -f "$kit/COMMIT" ]; then
        GSI_COMMIT="$(cat "$kit/COMMIT")"
        export GSI_COMMIT
    fi
    ;;
esac
case "${1:-}" in
--run)
    setup_gl
    status=0
    run_kit || status=1
    if [ -d "$kit/cli" ]; then
        run_cli || status=1
    fi
    exit $status
    ;;
--cli)
    setup_gl
    run_cli
    exit $?
    ;;
--dry-run)
    GPU_BENCH_ARGS="${GPU_BENCH_ARGS:---quick}"
    run_kit
    exit $?
    ;;
esac

exclude="$(git rev-parse --git-path info/exclude)"
mkdir -p "$(dirname "$exclude")"
grep -qx "/$kit/" "$exclude" 2>/dev/null || echo "/$kit/" >>"$exclude"
mkdir -p "$kit/kodak" "$kit/gl" /tmp/gsi-apt/partial
cargo build --release --example gpu_bench -p gsi-cli
cargo build --release --bin gsi -p gsi-cli
cp target/release/examples/gpu_bench target/release/gsi "$kit/"
# The commit built, marked when the tree had changes beyond it.
echo "$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- . ':!.gpukit' || echo '+changes')" >"$kit/COMMIT"
# The test binaries, as cargo names them in its JSON messages.
exe_of() {
    grep -E '"profile":\{[^}]*"test":true' | grep '"executable":"/' | sed 's/.*"executable":"\([^"]*\)".*/\1/' | head -n 1
}
cp "$(cargo test --release --no-run -p gsi-cli --test gpu --message-format=json 2>/dev/null | exe_of)" "$kit/tests-gpu"
test_bin() { # crate, features, name in the kit
    cp "$(cargo test --release --no-run -p "$1" --lib --features "$2" --message-format=json 2>/dev/null | exe_of)" "$kit/$3"
    strip "$kit/$3"
}
test_bin gsi-gpu gpu,encode,test-support tests-device
test_bin gsi-fit gpu tests-fit
test_bin gsi-enhance encode,gpu tests-enhance
strip "$kit/gpu_bench" "$kit/gsi" "$kit/tests-gpu"
# The images the benchmark's default `--limit 4` reads (the kit must stay under the device
# tool's 64 MiB); KIT_KODAK=all brings all 24.
rm -f "$kit"/kodak/*.png
if [ "${KIT_KODAK:-}" = all ]; then
    cp ../shared/data/kodak/*.png "$kit/kodak/"
else
    cp ../shared/data/kodak/kodim0[1-4].png "$kit/kodak/"
fi
rm -rf "$kit/cli"
if [ "${KIT_CLI:-}" = 1 ]; then
    mkdir -p "$kit/cli"
    target/release/gsi encode ../shared/data/kodak/kodim23.png -o "$kit/cli/kodim23.gsi" \
        --bpp 1 --device cpu --quiet
    cp ../shared/data/LOL/val30/low/119.png ../shared/data/LOL/val30/low/604.png "$kit/cli/"
    python3 -c 'import sys; from PIL import Image
Image.open(sys.argv[1]).convert("RGB").resize((2304, 1728), Image.LANCZOS).save(sys.argv[2])' \
        target/kodak-lowlight/low/kodim05.png "$kit/cli/dark4mp.png"
fi
o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/gsi-apt'
# shellcheck disable=SC2086
apt-get $o update >/dev/null
# shellcheck disable=SC2086
# The NVIDIA Vulkan driver lives in libGLX_nvidia and needs the GL vendor-neutral
# dispatch libraries beside the loader: with libvulkan1 alone the loader finds the ICD
# but "could not get vkCreateInstance" from it (seen on an H100 machine).
(cd "$kit/gl" && apt-get $o download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
du -sh "$kit"
