#!/usr/bin/env bash
# The GPU checklist, run on a GPU machine (a bare image with CUDA torch and no open3d) from the repo root:
#     tools/gpu_checks.sh all            # the whole checklist in one call (~9 min): cuda tests, bench, profile, CUDA-graph probe,
#                                            # selfpen, motion's cost and the training step's breakdown on CUDA
#     tools/gpu_checks.sh checks             # cuda-marked tests and selfpen on CUDA
#     tools/gpu_checks.sh bench              # `volsmpl bench --device cuda` (B = 1, 8; 60k points)
#     tools/gpu_checks.sh apps               # hoi and motion CLIs on CUDA (small sets: costs and that they run)
#     tools/gpu_checks.sh egohmr             # egohmr on CUDA: the test frames made there (no open3d), 16 sampled
#     tools/gpu_checks.sh batch              # the batch maker's cuda tests, the step's breakdown, a batch's profile (~60 s)
#     tools/gpu_checks.sh train SRC SECONDS  # resume the training run folder SRC on CUDA for about SECONDS, or start
#                                            # the phase of config SRC (.json) from $INIT (default: the shipped asset);
#                                            # no long run when the 20-step probe is slower than MAX_SPS (1.0 s/step)
# e.g. SOURCE_COMMIT=<commit> bash tools/gpu_checks.sh train checkpoints/coap_pp 540 (one call; the run's latest
# checkpoint comes back as $OUT/run.tar, or parts run.tar.00, ... when over 15 MiB: unpack it over
# checkpoints/coap_pp/ and commit it). A VolumetricSMPL phase starts from its config (train
# checkpoints/volsmpl_b8q.json 540) and, while the machine stays warm, continues in place (train
# /tmp/runs/volsmpl_b8q 540): its run folder is too large to travel with the working tree (64 MiB).
# Make the command end inside the call's 600 s: a run killed by the call's limit returns nothing.
# Needs: the pure-Python wheels missing there in .whl/ (trimesh, kornia, kornia_rs; see the device README) and
# SOURCE_COMMIT=<commit> in the environment (results record it). Everything it makes lands in $OUT (default
# out/gpu) as a few files: logs, JSON, and one tarball per step (only 8 files, 2 folders deep, come back).
set -uo pipefail
OUT=${OUT:-out/gpu}
mkdir -p "$OUT"
W=/tmp/gpuwork
mkdir -p "$W"

python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
rm -rf /tmp/pk && mkdir -p /tmp/pk && cp -r core /tmp/pk/volsmpl && cp -r apps /tmp/pk/volsmpl/apps
echo "${SOURCE_COMMIT:-unknown}" > /tmp/pk/volsmpl/SOURCE_COMMIT
export PYTHONPATH=/tmp/pk:/tmp/site PYTHONUNBUFFERED=1
V="python3 -m volsmpl.cli"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
python3 -c "import torch, volsmpl; print('torch', torch.__version__, torch.cuda.get_device_name())" || exit 1

step() {  # step NAME TIMEOUT CMD...: run with a wall-clock limit, log to $W/NAME.log, report its time and status
    local name=$1 limit=$2; shift 2
    local t0=$SECONDS
    timeout "$limit" "$@" > "$W/$name.log" 2>&1
    local rc=$?
    echo "== $name: rc $rc in $((SECONDS - t0)) s (limit $limit)"
    tail -n 25 "$W/$name.log"
}

case "${1:-}" in
all)  # the engine's CUDA paths first (tests), then its figures; each step bounded so that the call ends in ~9 min
    step pytest_cuda 90 python3 -m pytest -q -m cuda -p no:cacheprovider -ra tests/test_cuda_paths.py \
        tests/volume/engine/test_encode_graph.py tests/volume/engine/test_query_graph.py tests/body/test_partition.py tests/train/test_loop.py tests/train/test_state.py tests/geometry/test_groundtruth.py \
        tests/train/test_contact_training.py tests/volume/test_code_refinement.py
    step bench_cuda 220 $V bench --device cuda --models volsmpl,volsmpl-encoder,volsmpl-eager,volsmpl-qgraph,volsmpl-bf16,coap \
        --batch 1 8 --points 60000 --repeats 10 --warmup 2 --budget 5 --quick --no-bodybody \
        --out "$OUT/bench_cuda.json" --markdown "$OUT/bench_cuda.md"
    step bench_cuda_b32 80 $V bench --device cuda --models volsmpl,volsmpl-eager,volsmpl-qgraph --batch 32 --points 60000 \
        --repeats 5 --warmup 2 --budget 5 --quick --no-bodybody --out "$OUT/bench_cuda_b32.json"
    step profile 60 python3 docs/scripts/cuda_profile.py --device cuda --batch 1 8 --out "$W/prof"
    cp "$W/prof/cuda_profile.txt" "$OUT"/ 2>/dev/null
    step graphs 40 python3 docs/scripts/cuda_graphs_probe.py --batch 1 8
    step selfpen_cuda 150 $V selfpen --device cuda --model volsmpl,coap --render 0 --out "$W/selfpen"
    cp "$W/selfpen/results.json" "$OUT/selfpen_results.json" 2>/dev/null
    step motion_cost 75 $V motion --device cuda --model volsmpl,coap,mesh --scenes 1 --sequences 1 --iters 1 \
        --render 0 --published-cost --out "$W/motion"
    step gt_profile 60 python3 tools/gt_profile.py --config checkpoints/volsmpl_b8q.json --device cuda \
        --backends torch --steps 3 --trace   # the training step's breakdown on the device (make, ground truth, fwd/bwd), then the profiler's view of one batch
    cat "$W"/*.log > "$OUT/all.log" ;;
checks)
    step pytest_cuda 170 python3 -m pytest -q -m cuda -p no:cacheprovider -ra tests/test_cuda_paths.py \
        tests/volume/engine/test_encode_graph.py tests/volume/engine/test_query_graph.py tests/apps/egohmr/test_app.py tests/geometry/test_groundtruth.py tests/body/test_partition.py tests/train/test_loop.py tests/train/test_state.py
    step selfpen_cuda 120 $V selfpen --device cuda --model volsmpl,coap,mesh --render 2 --out "$W/selfpen"
    cp "$W"/*.log "$OUT"/ 2>/dev/null
    tar czf "$OUT/checks.tgz" -C "$W" . ;;
bench)  # each (model, batch) runs in a fresh process (~20 s with CUDA start and profiling): keep the set small
    step bench_cuda 330 $V bench --device cuda --models volsmpl,volsmpl-encoder,volsmpl-eager,volsmpl-qgraph,volsmpl-bf16,volsmpl-tf32,volsmpl-dense,coap --batch 1 8 --points 60000 \
        --repeats 10 --warmup 2 --budget 5 --quick --no-bodybody --out "$OUT/bench_cuda.json" --markdown "$OUT/bench_cuda.md"
    cp "$W/bench_cuda.log" "$OUT"/
    step refine_cost 60 python3 docs/scripts/encoder_draws_timing.py --device cuda --draws 1 4 --refine 0 20 40 80 \
        --batch 1 8 --repeats 5   # encoder draws and code refinement on the device (docs/code_refinement.md)
    cat "$W"/refine_cost.log > "$OUT/refine_cost.log" 2>/dev/null ;;
apps)  # the interaction database is built on the CPU side of that machine first (no open3d needed)
    step hoi_make_db 150 $V hoi make-db --seed 0
    step hoi_cuda 150 $V hoi --device cuda --model volsmpl,coap,mesh --cases 4 --render 1 --out "$W/hoi"
    step hoi_cuda_b4 100 $V hoi --device cuda --model volsmpl,coap,mesh --cases 4 --batch 4 --render 0 --out "$W/hoi_b4"
    step motion_cuda 200 $V motion --device cuda --model volsmpl,coap,mesh --scenes 1 --sequences 1 --render 1 \
        --published-cost --out "$W/motion"
    step motion_cuda_b8 200 $V motion --device cuda --model volsmpl,coap,mesh --w coap=0.1 --scenes 1 --sequences 8 \
        --batch 8 --render 0 --out "$W/motion_b8"
    tar czf "$OUT/apps.tgz" -C "$W" . ;;
egohmr)  # frames and room clouds are made on that machine's CPU (torch geometry where open3d is missing)
    step egohmr_cuda 540 $V egohmr sample --device cuda --split test --frames 16 --render 1 --out "$W/egohmr"
    cp "$W/egohmr_cuda.log" "$OUT"/
    tar czf "$OUT/egohmr.tgz" -C "$W" egohmr ;;
train)
    src=${2:?usage: tools/gpu_checks.sh train SRC SECONDS}; secs=${3:?seconds}
    mkdir -p /tmp/runs
    end=$((SECONDS + secs))
    if [ "${src%.json}" != "$src" ]; then  # a config: a new phase from ${INIT:-core/assets/volsmpl_anny}
        run=/tmp/runs/$(basename "${src%.json}"); rm -rf "$run"
        step train_probe 300 $V train --config "$src" --init "${INIT:-core/assets/volsmpl_anny}" --out "$run" \
            --device cuda --max-steps 20
    else                                    # a run folder: resume it (one under /tmp/runs/ in place: a warm machine's)
        run=/tmp/runs/$(basename "$src")
        [ "$src" != "$run" ] && { rm -rf "$run"; cp -r "$src" "$run"; }
        step train_probe 300 $V train --resume --out "$run" --device cuda --max-steps 20
    fi
    sps=$(tail -n 1 "$run/log.csv" | cut -d, -f6)
    # 0.8: the step time drifts (0.22 -> 0.29 s over three consecutive calls); the limit keeps the tarball below
    n=$(python3 -c "print(max(0, int(0.8 * ($end - $SECONDS - 40) / max(float('$sps'), 1e-3))))")
    echo "== $sps s/step over the probe's last window: $n more steps"
    if python3 -c "import sys; sys.exit(0 if float('$sps') > float('${MAX_SPS:-1.0}') else 1)"; then
        echo "== slower than MAX_SPS=${MAX_SPS:-1.0} s/step: no long run (profile the batch: tools/gpu_checks.sh batch)"
        n=0
    fi
    [ "$n" -gt 0 ] && step train $((end - SECONDS > 1 ? end - SECONDS : 1)) $V train --resume --out "$run" --device cuda \
        --max-steps "$n"
    latest=$(cat "$run/latest")
    cp "$run/log.csv" "$run/profile.jsonl" "$W"/train*.log "$OUT"/   # 8 files come back at most: logs of this mode only
    tar cf "$OUT/run.tar" -C "$run" "$latest" config.json log.csv latest
    # files come back up to 16 MiB each (a VolumetricSMPL checkpoint with its average and Adam state is ~55 MB):
    # parts of 15 MiB, joined with `cat run.tar.* | tar x`
    if [ "$(stat -c %s "$OUT/run.tar")" -gt $((15 * 1024 * 1024)) ]; then
        split -b 15M -d "$OUT/run.tar" "$OUT/run.tar." && rm "$OUT/run.tar"
    fi ;;
batch)  # ~60 s: the batch maker's device paths against the CPU, the step's breakdown and a profile of one batch
    step pytest_batch 60 python3 -m pytest -q -m cuda -p no:cacheprovider -ra tests/geometry/test_groundtruth.py \
        tests/train/test_contact_training.py
    step gt_profile 120 python3 tools/gt_profile.py --config checkpoints/volsmpl_b8q.json --device cuda \
        --backends torch --steps 3 --trace
    cp "$W/pytest_batch.log" "$W/gt_profile.log" "$OUT"/ ;;
*)
    echo "usage: tools/gpu_checks.sh all|checks|bench|apps|egohmr|batch|train SRC SECONDS" >&2; exit 2 ;;
esac
