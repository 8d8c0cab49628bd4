#!/usr/bin/env bash
# Runs every fuzz target for RUNS executions (default 10 M), with debug assertions (overflow
# checks), over its corpus (corpus/<t>,
# seeded from seeds/<t>), then minimises the corpus. Needs the nightly toolchain and
# cargo-fuzz (`cargo install cargo-fuzz`). Crashes land in artifacts/<t>/.
#   fuzz/run.sh [TARGET…]
# Limits: 1 GiB per allocation (a huge allocation from an unchecked header is a finding),
# 2 GiB resident, 10 s per input (a hang is a finding).
set -u
cd "$(dirname "$0")"
RUNS=${RUNS:-10000000}
mkdir -p logs
for t in ${*:-ply xyz stlod cloud_file copc scene stshadow mesh}; do
    mkdir -p "corpus/$t"
    start=$(date +%s)
    # The LAZ decoder (the `laz` crate) has internal debug assertions that corrupt chunks
    # trip (release builds truncate instead, and the readers reject the result): targets
    # that decode LAZ run as users' builds do.
    a=-a
    case $t in cloud_file|copc) a= ;; esac
    cargo +nightly fuzz run -O $a "$t" "corpus/$t" "seeds/$t" -- -runs="$RUNS" -max_len=8192 \
        -malloc_limit_mb=1024 -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 \
        > "logs/$t.log" 2>&1
    rc=$?
    echo "$t: exit $rc after $(( $(date +%s) - start )) s: $(grep -E '^Done|stat::number_of_executed_units' "logs/$t.log" | tr '\n' ' ')"
    cargo +nightly fuzz cmin -O $a "$t" "corpus/$t" -- -max_len=8192 > "logs/$t.cmin.log" 2>&1
done
