#!/usr/bin/env bash
# Measures dpp-dist's compositing schedules on 1..8 ranks of this machine
# (dist/examples/composite_bench.rs) and collects its JSON lines into one
# file, for dist/examples/cost_fit.rs and docs/benchmarks.md ("Across ranks").
#
#   scripts/composite-bench.sh [OUT.jsonl]
#
# Environment: RANKS (default "1 2 3 4 5 6 7 8"), SIZES (default
# "512x512 1920x1080 3840x2160"), SCHEDULES (default
# "direct,binary-swap,radix-k:2,radix-k:4,radix-k:8"), REPEATS (default 5),
# LIMIT (seconds per mpirun, default 600).
#
# Each (ranks, size) is one mpirun under `timeout`, so a hang or a crash
# loses that cell only (reported on stderr, and the script exits 1 at the
# end). More ranks than cores run oversubscribed: the ranks share the cores
# and talk through Open MPI's shared-memory transport, so the numbers show
# a schedule's structure on loopback, not a network.
set -euo pipefail
cd "$(dirname "$0")/.."

out=${1:-target/composite-bench/results.jsonl}
ranks_list=${RANKS:-1 2 3 4 5 6 7 8}
sizes=${SIZES:-512x512 1920x1080 3840x2160}
schedules=${SCHEDULES:-direct,binary-swap,radix-k:2,radix-k:4,radix-k:8}
repeats=${REPEATS:-5}
limit=${LIMIT:-600}
cores=$(nproc)

cargo build --release -p dpp-dist --features mpi --example composite_bench
bench=target/release/examples/composite_bench
mkdir -p "$(dirname "$out")"
: >"$out"

# Root in a container: Open MPI refuses to start without these.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

echo "composite-bench: $cores cores, $(mpirun --version 2>/dev/null | head -n1)"
echo "composite-bench: ranks {$ranks_list}, sizes {$sizes}, $repeats repeats after a warm-up"
echo "composite-bench: writing $out"
failed=0
for n in $ranks_list; do
    if ((n > cores)); then
        echo "composite-bench: $n ranks on $cores cores: OVERSUBSCRIBED (ranks share cores; times include waiting for a core)"
    fi
    for size in $sizes; do
        # Containers often forbid the cross-memory attach that Open MPI's
        # shared-memory transport uses for large messages: plain copies.
        if ! timeout --kill-after=10 "$limit" mpirun --oversubscribe \
            --mca btl_vader_single_copy_mechanism none -n "$n" \
            "$bench" --sizes "$size" --schedules "$schedules" --repeats "$repeats" --cores "$cores" \
            >>"$out"; then
            echo "composite-bench: FAILED: $n ranks, $size (124: timed out after ${limit}s)" >&2
            failed=1
        fi
        echo "composite-bench: $n ranks, $size: $(wc -l <"$out") lines so far"
    done
done
exit "$failed"
