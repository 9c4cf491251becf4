#!/usr/bin/env bash
# Assemble the motion table once all its sequences are stored, and make the checks that keep it current.
#
#     bash tools/motion_assemble.sh            # refuses while sequences are missing (it would compute them)
#     bash tools/motion_assemble.sh --force    # assemble anyway (the missing ones are computed now: hours)
#     MOTION_COMMIT=abc1234 bash tools/motion_assemble.sh --force   # a new table from another commit's export
#     bash tools/motion_assemble.sh --worker mesh,volsmpl  # a helper process beside the --force one (another core)
#
# --worker KINDS computes the walks of these kinds only, one kind after the other, from the same export, in OUT_worker/,
# and copies each record into OUT/cases/ (atomically, every 60 s and at the end), where the --force process reuses it
# when it reaches that walk (--resume); it starts from the records OUT/cases/ already holds and assembles nothing.
# COAP's walks are left to the --force process (its test rooms need the weight its tuning rooms choose). On two cores,
# `--force` beside `--worker mesh,volsmpl` takes about half the wall time of `--force` alone.
#
# The table runs from an export of MOTION_COMMIT (default ce58bf3, the commit of the shipped models' table;
# tools/export_snapshot.sh): per-sequence records are keyed by the code that made them, so the assembly runs from
# the same export and reuses every record (the 440 records of the table are tracked in docs/motion/cases/; a run
# interrupted part way continues from OUT/cases/ with --resume: about 20 h of one CPU thread for all 440). Then:
#   1. results.json and the figures from the export (all records reused; COAP as published measured once), copied
#      to docs/motion/, and the records to docs/motion/cases/ (replacing those of another commit);
#   2. the chained re-run check (volsmpl.report.result_check.chain_check): two sequences of rooms 0 and 1 (COAP at w = 0.1,
#      VolumetricSMPL, the mesh), made here by the export (the table's own code) and by the current code, compared
#      (VERIFY_TOL=1e-5 in the environment for code whose backward pass sums in another order: README, "Results say").
#      The walks take 1 Adam step, not the table's 100: the optimisation amplifies float rounding (the table's own
#      code run with 2 threads instead of 1 moved COAP's goal distance by up to 20 % after 5 steps; on another CPU
#      it ends some sequences in other local optima), so only the first step can show value by value that two codes
#      compute the same objective and the same step; the table's 100-step outcomes are compared as statistics
#      instead (step 4; README, "apps/motion");
#   3. the per-frame cost and memory columns from the current code on this machine (the export's meter polled the
#      resident set in a thread: its cost columns are not quoted), in out/motion_cost/results.json (no walk is
#      optimised: --iters 0), and the frame strips of rooms 0 and 1's first pairs (docs/motion/strip_*.png);
#   4. the compared rows' paired differences with bootstrap intervals (volsmpl.apps.motion.stats), docs/motion/paired.json.
# Each step prints what it wrote; `volsmpl report` then tabulates docs/motion/results.json (quality columns) and
# docs/motion/paired.json beside the paper's; out/motion_cost/results.json holds the per-frame cost columns of the
# current code and out/motion_strips/results.json the total memory of one whole-walk optimisation.
set -euo pipefail
cd "$(dirname "$0")/.."
V="$(pwd)/.venv/bin/volsmpl"
COMMIT=$(git rev-parse --short "${MOTION_COMMIT:-ce58bf3}")
SNAP=/tmp/snap_motion_$COMMIT
OUT=out/motion_$COMMIT
EXPECTED=440   # 15 rooms x 8 pairs for VolumetricSMPL and mesh, COAP's sweep on 5 tuning rooms and its choice on 10
TABLE=(--scenes all --sequences 8 --frames 80 --iters 100 --threads 1)   # with the action tune
CHECK=(--scenes 2 --sequences 2 --w coap=0.1 --frames 80 --iters 1 --threads 1 --render 0)

case "${1:-}" in
    ""|--force) ;;
    --worker)
        KINDS="${2:-}"
        [ -n "$KINDS" ] || { echo "motion_assemble: --worker needs the kinds, e.g. --worker mesh,volsmpl" >&2; exit 2; }
        for k in ${KINDS//,/ }; do
            [[ "$k" == volsmpl || "$k" == mesh ]] || { echo "motion_assemble: --worker takes volsmpl and mesh" \
                "(COAP's test walks need its tuned weight: the --force process makes them), got '$k'" >&2; exit 2; }
        done ;;
    *) echo "motion_assemble: unknown argument '$1' (--force, or --worker KINDS)" >&2; exit 2 ;;
esac

[ -d "$SNAP/volsmpl" ] || tools/export_snapshot.sh "$SNAP" "$COMMIT"
mkdir -p "$OUT/cases"

# the tracked records serve only a table of the same commit (another commit's keys would not match)
MADE=$(python3 -c "import json; print(json.load(open('docs/motion/results.json'))['meta']['git_commit'])" 2>/dev/null || true)
if [ -n "$MADE" ] && [ "$(git rev-parse --short "$MADE")" = "$COMMIT" ]; then
    cp -n docs/motion/cases/*.json "$OUT/cases/" 2>/dev/null || true
fi

if [ "${1:-}" = "--worker" ]; then
    W="${OUT}_worker"
    mkdir -p "$W/cases"
    cp -n "$OUT"/cases/*.json "$W/cases/" 2>/dev/null || true
    sync_cases() {   # the worker's new records into OUT/cases, each written whole before it appears there
        for f in "$W"/cases/*.json; do
            [ -e "$f" ] || continue
            b=$(basename "$f")
            [ -e "$OUT/cases/$b" ] || { cp "$f" "$OUT/cases/.w_$b" && mv "$OUT/cases/.w_$b" "$OUT/cases/$b"; }
        done
    }
    ( while true; do sleep 60; sync_cases; done ) &
    LOOP=$!
    trap 'kill $LOOP 2>/dev/null || true' EXIT
    for k in ${KINDS//,/ }; do
        echo "== worker: the $k walks"
        PYTHONPATH="$SNAP" "$V" motion tune --model "$k" "${TABLE[@]}" --render 0 --resume --out "$W"
        sync_cases
    done
    echo "motion_assemble: worker done ($KINDS); $(ls "$OUT/cases" | wc -l) of $EXPECTED records in $OUT/cases"
    exit 0
fi
have=$(ls "$OUT/cases" | wc -l)
if [ "$have" -lt "$EXPECTED" ] && [ "${1:-}" != "--force" ]; then
    echo "motion_assemble: $have of $EXPECTED sequences stored in $OUT/cases; let the table's processes finish" \
         "(docs/motion/cases/ holds the table's records) or pass --force to compute the rest now" >&2
    exit 1
fi

echo "== 1. the table from the export"
PYTHONPATH="$SNAP" "$V" motion tune --model volsmpl,coap,mesh "${TABLE[@]}" --published-cost --resume --out "$OUT"
mkdir -p docs/motion
cp "$OUT/results.json" "$OUT"/*.png docs/motion/
rm -f docs/motion/cases/*.json
cp "$OUT"/cases/*.json docs/motion/cases/

echo "== 2. chained re-run check: the export and the current code, two sequences of two rooms, one Adam step, this machine"
PYTHONPATH="$SNAP" "$V" motion --model volsmpl,coap,mesh "${CHECK[@]}" --out out/motion_check_base
"$V" motion --model volsmpl,coap,mesh "${CHECK[@]}" --out out/motion_check_fresh
"$V" report --verify motion=out/motion_check_fresh/results.json --baseline motion=out/motion_check_base/results.json \
    --verify-tol "${VERIFY_TOL:-1e-6}"

echo "== 3. per-frame cost with the current code (run it on a quiet machine), and the frame strips"
"$V" motion --model volsmpl,coap,mesh --scenes 1 --sequences 1 --frames 80 --iters 0 --published-cost \
    --threads 1 --render 0 --out out/motion_cost
# The table's processes ran with --render 0 and reused sequences are not rendered again (their records keep the
# pelvis path, not the walk), so the strips come from a run of their own (timing-free: it may share the machine):
# the first pair of room 0 (a tuning room) and room 1 (a test room), each model at the weight its table row uses
# (COAP: the tuned choice).
WC=$(python3 -c "import json; print(json.load(open('$OUT/results.json'))['tuning']['choice']['coap'])")
"$V" motion --model volsmpl,coap,mesh --w coap="$WC" --scenes 2 --sequences 1 --frames 80 --iters 100 \
    --threads 1 --render 1 --out out/motion_strips
cp out/motion_strips/strip_*.png docs/motion/

echo "== 4. paired differences of the compared rows (bootstrap intervals over the test sequences)"
"$(pwd)/.venv/bin/python" -m volsmpl.apps.motion.stats docs/motion/results.json --out docs/motion/paired.json
echo "motion_assemble: done; run volsmpl report (docs/report.md reads docs/motion/results.json)"
