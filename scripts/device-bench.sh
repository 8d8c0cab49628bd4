#!/usr/bin/env bash
# Whole-frame GPU figures for BENCHMARKS.md on a lent H100/H200 (see the `device` tool).
#
# The device machine has no Rust toolchain and no network, so everything travels:
#   strip -o .devcarry/stipple target/release/stipple     (the release binary, stripped;
#                                                          may travel gzipped as stipple.gz)
#   .devcarry/tests/NAME[.gz]                             (test binaries of stipple-render,
#                                                          stripped, for the `tests` step)
#   .devcarry/data/                                       (dragon_vrip.ply.gz, bun_zipper.ply, …)
#   .gl/*.deb                                             (Debian's Vulkan/EGL loader packages)
# Both folders are listed in .git/info/exclude and named in the call's `carry`.
#
# Usage: scripts/device-bench.sh [STEP…]
#   steps: info copybw frames zhang table3 raw images tests transparent shadow10m quick lod;
#   default: info frames zhang table3 raw images
# Output goes to stdout and, when OUT is set, to $OUT/log.txt and $OUT/*.png.
set -u
B=${STIPPLE_BIN:-.devcarry/stipple}
D=${STIPPLE_DATA:-.devcarry/data}
O=${OUT:-/tmp/stipple-device}
mkdir -p "$O"
# Images of the `images` step (the device tool brings back at most 8 files from $OUT).
IMG=${IMG:-$O}
if [ ! -x "$B" ] && [ -f "$B.gz" ]; then
    gunzip -c "$B.gz" >/tmp/stipple && chmod +x /tmp/stipple && B=/tmp/stipple
fi
LOG="$O/log.txt"

if [ -d .gl ] && ! ldconfig -p | grep -q libvulkan.so.1; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
fi
if ! "$B" devices 2>/dev/null | grep -qi nvidia; then
    export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
fi

# Each command's limit in seconds (T=60 run …).
T=300
run() {
    echo "### $*" | tee -a "$LOG"
    local t0=$(date +%s%N)
    timeout "$T" "$@" 2>&1 | tee -a "$LOG"
    echo "### took $(( ($(date +%s%N) - t0) / 1000000 )) ms" | tee -a "$LOG"
}

steps=${*:-info frames zhang table3 raw images}
for step in $steps; do
    case $step in
    info)
        run nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv
        run "$B" devices
        nproc | tee -a "$LOG"
        ;;
    copybw)
        # The copy-bandwidth ceiling the projection goal is measured against (bytes read +
        # written per second, a 4 GiB device-to-device copy, median of 20).
        run python3 -c '
import torch
a = torch.empty(1 << 30, dtype=torch.float32, device="cuda").uniform_()
b = torch.empty_like(a)
for _ in range(3): b.copy_(a)
ts = []
for _ in range(20):
    s, e = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
    s.record(); b.copy_(a); e.record(); torch.cuda.synchronize(); ts.append(s.elapsed_time(e))
ts.sort(); ms = ts[len(ts) // 2]
print(f"copy 4 GiB: {ms:.3f} ms, {2 * 4 * 2**30 / ms / 1e9:.0f} GB/s read + written")'
        ;;
    frames)
        run "$B" bench --backend gpu --frames 20
        run "$B" bench --backend gpu --demo sphere --points 1000000 --frames 20
        run "$B" bench --backend gpu --demo sphere --points 10000000 --frames 10
        run "$B" bench --backend gpu --demo sphere --points 100000000 --frames 5 --warmup 1
        run "$B" bench --backend gpu --demo sphere --points 10000000 --frames 10 --no-backface-culling
        ;;
    zhang)
        run "$B" bench "$D/dragon_vrip.ply.gz" --zhang --frames 20 --backend gpu
        run "$B" bench "$D/dragon_vrip.ply.gz" --pipeline splat --frames 20 --backend gpu
        ;;
    table3)
        run "$B" bench "$D/dragon_vrip.ply.gz" --table3 --frames 10 --pipeline dobrev --backend gpu
        run "$B" bench "$D/bun_zipper.ply" --table3 --frames 10 --pipeline dobrev --backend gpu
        run "$B" bench --demo nested-tori --points 6000000 --table3 --frames 5 --pipeline dobrev --backend gpu
        ;;
    raw)
        for k in 4 6 9; do
            run "$B" bench --demo plane-objects --points 10000000 --raw --size 1024x768 \
                --visibility-kernel $k --backend gpu --frames 10 --warmup 2
        done
        run "$B" bench "$D/lone-star.laz" --raw --size 1024x768 --backend gpu --frames 10
        ;;
    images)
        mkdir -p "$IMG"
        for be in cpu gpu; do
            run "$B" render "$D/dragon_vrip.ply.gz" --backend $be -o "$IMG/dragon-$be.png"
            run "$B" render --backend $be -o "$IMG/demo-$be.png"
            run "$B" render examples/nested-tori.toml --backend $be -o "$IMG/tori-$be.png"
            run "$B" render "$D/lone-star.laz" --backend $be -o "$IMG/lone-star-$be.png"
        done
        ;;
    tests)
        # The GPU parity tests on real hardware (they fail rather than skip without a GPU).
        mkdir -p /tmp/tests
        for f in .devcarry/tests/*; do
            n=$(basename "$f" .gz)
            case $f in *.gz) gunzip -c "$f" >"/tmp/tests/$n" ;; *) cp "$f" "/tmp/tests/$n" ;; esac
            chmod +x "/tmp/tests/$n"
        done
        # Test binaries look for their fixtures relative to the crate.
        # Every binary carried (splat: its GPU test only; the rest are CPU tests CI runs).
        for t in $(ls /tmp/tests); do
            f=; [ $t = splat ] && f=gpu_
            (cd crates/stipple-render && STIPPLE_REQUIRE_GPU=1 T=60 run "/tmp/tests/$t" $f)
        done
        ;;
    transparent)
        # Zhang & Pajarola Algorithms 2 and 3 (transparent splats) on the GPU.
        for size in 512x512 1024x1024; do
            for alg in "" --smooth-nearest; do
                T=90 run "$B" bench "$D/dragon_vrip.ply.gz" --pipeline splat --splat transparent \
                    --opacity 0.5 --size $size --frames 10 --backend gpu $alg
            done
        done
        for alg in "" --smooth-nearest; do
            T=90 run "$B" bench examples/nested-tori-splats.toml --size 1024x1024 --frames 5 \
                --backend gpu $alg
        done
        ;;
    shadow10m)
        # The viewer's goal: 10 M points, Dobrev's pipeline, a one-sample shadow, p99 of
        # 100 frames at 1920×1080 (the shadow texture is made once: the light is fixed).
        T=120 run "$B" bench --demo plane-objects --points 10000000 --pipeline dobrev --shadows \
            --light disc:1,4,2,0.3 --shadow-samples 1 --size 1920x1080 --frames 100 --backend gpu
        T=120 run "$B" bench --demo plane-objects --points 10000000 --pipeline dobrev \
            --size 1920x1080 --frames 100 --backend gpu
        ;;
    imgdiff)
        # CPU against GPU images of the `images` step: how far apart, and where.
        run python3 -c '
import glob, os, sys, numpy as np
from PIL import Image
for c in sorted(glob.glob(os.path.join(sys.argv[1], "*-cpu.png"))):
    a = np.asarray(Image.open(c).convert("RGB"), dtype=np.int16)
    b = np.asarray(Image.open(c.replace("-cpu.png", "-gpu.png")).convert("RGB"), dtype=np.int16)
    d = np.abs(a - b).max(axis=2)
    print(f"{os.path.basename(c)}: max {d.max()}, mean {d.mean():.3f}, over 8 on {100 * (d > 8).mean():.3f}% of pixels")
' "$IMG"
        ;;
    quick)
        run "$B" bench --backend gpu --frames 20
        run "$B" bench "$D/dragon_vrip.ply.gz" --table3 --table-sizes 1024 --frames 10 --pipeline dobrev --backend gpu
        ;;
    lod)
        # Synthetic trees (BENCHMARKS.md, "Out-of-core hierarchy"): 100 M and 500 M points
        # of plane-objects as uncompressed LAS, built with a large memory budget (this
        # machine has 128 GiB), then frames of a 5 M-point cut at 1920×1080.
        W=${LOD_DIR:-/tmp/lod}
        mkdir -p "$W"
        t0=$(date +%s)
        for seed in 1 2 3 4 5; do
            timeout 250 "$B" gen plane-objects --points 100000000 --seed $seed -o "$W/big$seed.las" --force &
        done
        wait
        echo "### gen 5 × 100 M: $(( $(date +%s) - t0 )) s" | tee -a "$LOG"
        run "$B" build-lod "$W/big1.las" -o "$W/big100m.stlod" --memory 48G
        run "$B" bench "$W/big100m.stlod" --size 1920x1080 --point-budget 5M --lod-error 0.25 --backend gpu --frames 10
        run "$B" build-lod "$W"/big?.las -o "$W/big500m.stlod" --memory 48G
        run "$B" bench "$W/big500m.stlod" --size 1920x1080 --point-budget 5M --lod-error 0.25 --backend gpu --frames 10
        run "$B" bench "$W/big500m.stlod" --size 1920x1080 --point-budget 5M --lod-error 0.25 --backend cpu --frames 5
        ;;
    *) echo "unknown step $step" >&2 ;;
    esac
done
