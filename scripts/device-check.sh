#!/usr/bin/env bash
# The standing check on a lent GPU machine, prepared here and run there in one
# call: the GPU tests and `dpp bench --backend gpu` on the hardware.
#
#   scripts/device-check.sh prepare   # here: builds, strips and packs into .device/
#   scripts/device-check.sh run       # there: with .device (and .gl) carried
#
# The lent machine has no Rust toolchain and reaches nothing outside, and a
# call carries at most 64 MiB: so the release `dpp` and the test binaries that
# hold GPU tests are built here, stripped and packed with xz (about 40 MB),
# and the Vulkan loader comes as Debian packages in .gl/ (the device README's
# recipe). The test binaries read the repository through the absolute path
# they were built at (CARGO_MANIFEST_DIR); `run` links that path to its copy.
# What `run` writes goes to $OUT: the test log, the bench tables (markdown and
# JSON; the written-out WORKLOAD2 side by side with the functor file among
# them) and the adapter's name.
set -euo pipefail
cd "$(dirname "$0")/.."

# Test binaries with GPU tests, by cargo target name: the GPU backend's
# primitives, the functors' twins, the pipelines' GPU runs, and the command
# tests that compare backends and images.
TEST_TARGETS=(backend dpp_tracer pipelines command)
# The command tests worth the device's time: every backend comparison.
COMMAND_FILTERS=(backends:: images:: expressions:: volume_surface::)

prepare() {
    cargo build --release --locked -p dpp
    local listing
    listing=$(cargo test --workspace --locked --no-run --message-format=json)
    rm -rf .device && mkdir -p .device/bin
    for target in "${TEST_TARGETS[@]}"; do
        local path
        path=$(python3 -c '
import json, sys
target = sys.argv[1]
for line in sys.stdin:
    message = json.loads(line)
    if message.get("reason") == "compiler-artifact" and message.get("executable") \
            and message["target"]["name"] == target and message["profile"]["test"]:
        print(message["executable"])
' "$target" <<<"$listing" | tail -n 1)
        [ -n "$path" ] || { echo "no test binary for $target" >&2; exit 1; }
        strip -o ".device/bin/$target" "$path"
    done
    strip -o .device/bin/dpp target/release/dpp
    # Where the test binaries look for the repository and the `dpp` binary.
    python3 -c 'import json, sys; print(json.dumps({"repo": sys.argv[1]}))' "$PWD" \
        > .device/built-at.json
    tar -C .device -cJf .device/bin.tar.xz bin
    rm -rf .device/bin
    if ! compgen -G ".gl/libvulkan1_*.deb" > /dev/null; then
        mkdir -p .gl /tmp/amd64/partial
        local apt_options=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64
            -oDir::State::Lists=/tmp/amd64)
        apt-get "${apt_options[@]}" update -qq
        (cd .gl && apt-get "${apt_options[@]}" download libvulkan1)
    fi
    du -sh .device .gl
    echo "carry .device and .gl; command: scripts/device-check.sh run"
}

run() {
    : "${OUT:?run is for the lent machine, which sets OUT}"
    for deb in .gl/*.deb; do dpkg -x "$deb" /; done
    ldconfig
    if ! compgen -G "/usr/share/vulkan/icd.d/nvidia*.json" > /dev/null \
        && [ -e /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]; then
        export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    fi
    python3 -c 'import sys, tarfile; tarfile.open(sys.argv[1]).extractall(sys.argv[2])' \
        .device/bin.tar.xz .device
    local built_at
    built_at=$(python3 -c 'import json; print(json.load(open(".device/built-at.json"))["repo"])')
    if [ "$(realpath "$built_at" 2>/dev/null)" != "$(realpath .)" ]; then
        [ ! -e "$built_at" ] || { echo "$built_at exists and is not this copy" >&2; exit 1; }
        mkdir -p "$(dirname "$built_at")"
        ln -s "$PWD" "$built_at"
    fi
    # The command tests run CARGO_BIN_EXE_dpp, the test profile's binary:
    # the release one stands in for it (faster, the same code).
    for profile in debug release; do
        mkdir -p "target/$profile"
        cp .device/bin/dpp "target/$profile/dpp"
    done
    export WGPU_BACKEND=vulkan DPP_REQUIRE_GPU=1
    (nvidia-smi -L 2>&1 || true) > "$OUT/adapter.txt"
    local status=0
    {
        for target in backend dpp_tracer pipelines; do
            echo "== $target"
            timeout 180 ".device/bin/$target" --test-threads 8 2>&1 || status=1
        done
        echo "== command ${COMMAND_FILTERS[*]}"
        timeout 240 .device/bin/command --test-threads 8 "${COMMAND_FILTERS[@]}" 2>&1 || status=1
    } > "$OUT/tests.log"
    grep -E "^(== |test result)" "$OUT/tests.log" || true
    local dpp=.device/bin/dpp
    timeout 180 "$dpp" bench builtin rm:128,128,128 --backend gpu --workloads 1,2 \
        --markdown "$OUT/gpu-w12.md" --json "$OUT/gpu-w12.json" > /dev/null || status=1
    timeout 180 "$dpp" bench builtin --backend gpu --workloads 3 \
        --markdown "$OUT/gpu-w3.md" --json "$OUT/gpu-w3.json" > /dev/null || status=1
    # The written-out WORKLOAD2 against the functor file, frame by frame.
    timeout 120 "$dpp" bench builtin --backend gpu --workloads 2 \
        --versus pipelines/workload2_expressions.dpp \
        --markdown "$OUT/gpu-versus.md" --json "$OUT/gpu-versus.json" > /dev/null || status=1
    return $status
}

case "${1:-}" in
    prepare) prepare ;;
    run) run ;;
    *)
        echo "usage: scripts/device-check.sh prepare|run" >&2
        exit 2
        ;;
esac
