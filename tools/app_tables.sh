#!/usr/bin/env bash
# Make the app tables of selfpen, egohmr and hoi from an export of one commit, resumable, and publish them to docs/.
# (The motion table takes ~20 h of one thread and has its own script: tools/motion_assemble.sh.)
#
#     bash tools/app_tables.sh                       # every stage not done yet, from an export of HEAD
#     COMMIT=abc1234 bash tools/app_tables.sh hoi    # one stage, from another commit's export
#     COMMIT=abc1234 bash tools/app_tables.sh publish   # copy that export's finished tables into docs/<app>/
#
# Stages (in order): selfpen_tune selfpen selfpen_seeds egohmr_tune egohmr hoi; each runs at 1 thread from the
# export (tools/export_snapshot.sh) with --resume, so a stopped run continues from its stored cases, and leaves a marker
# in OUT/done/ when it ends. OUT is out/tables_<commit>. Each table is made with the code's defaults: selfpen's tuned
# preset lives in apps/selfpen/optimize.py (the selfpen_tune stage only measures the grid: when its best differs
# from the preset, the stage says so and the preset is changed in code, then the table made again from that commit);
# egohmr samples with the guidance scales its own tune stage chose on the val split; hoi's weights are its tuned
# defaults. `publish` copies each app whose stages have all finished (apps may come from different commits' OUTs).
# Then `volsmpl report`.
set -euo pipefail
cd "$(dirname "$0")/.."
ALL=(selfpen_tune selfpen selfpen_seeds egohmr_tune egohmr hoi)
STAGES=("$@"); [ ${#STAGES[@]} -gt 0 ] || STAGES=("${ALL[@]}")
for s in "${STAGES[@]}"; do
  [[ " ${ALL[*]} publish " == *" $s "* ]] || { echo "app_tables: unknown stage '$s' (${ALL[*]} publish)" >&2; exit 2; }
done
COMMIT=$(git rev-parse --short "${COMMIT:-HEAD}")
SNAP=/tmp/snap_tables_$COMMIT
O=out/tables_$COMMIT
V="$(pwd)/.venv/bin/volsmpl"
PY="$(pwd)/.venv/bin/python"
[ -d "$SNAP/volsmpl" ] || tools/export_snapshot.sh "$SNAP" "$COMMIT"
mkdir -p "$O/done"
run() { echo "+ $*"; PYTHONPATH="$SNAP" "$@"; }

selfpen_tune() {
  run "$V" selfpen tune --model volsmpl,coap --threads 1 --out "$O/selfpen_tune"
  PYTHONPATH="$SNAP" "$PY" - "$O/selfpen_tune/tune.json" <<'EOF'
import json, sys
from volsmpl.apps.selfpen.optimize import PRESETS
best, preset = json.load(open(sys.argv[1]))["best"], PRESETS["tuned"]
off = {k: (v, preset[k]) for k, v in best.items() if preset.get(k) != v}
print("selfpen tune: the best grid point is the tuned preset" if not off else
      "selfpen tune: the best grid point differs from the tuned preset (apps/selfpen/optimize.py): "
      + ", ".join(f"{k} {a:g} (preset {b:g})" for k, (a, b) in off.items()))
EOF
}
selfpen() { run "$V" selfpen --model volsmpl,coap,mesh --threads 1 --resume --out "$O/selfpen"; }
selfpen_seeds() {
  for S in 0 1 2 3; do run "$V" selfpen --model volsmpl,coap --sampler-seed $S --threads 1 --render 0 --resume \
      --out "$O/selfpen_seed$S"; done
  run "$PY" tools/selfpen_seeds.py "$O"/selfpen_seed{0,1,2,3} \
      --command "volsmpl selfpen --model volsmpl,coap --sampler-seed S --threads 1 (S = 0..3)" --out "$O/seeds.json"
}
egohmr_tune() { run "$V" egohmr tune --split val --threads 1 --out "$O/egohmr_tune"; }
egohmr() { run "$V" egohmr sample --split test --tuned "$O/egohmr_tune/tune.json" --threads 1 --resume --out "$O/egohmr"; }
hoi() { run "$V" hoi --model volsmpl,coap,mesh --split test --batch 10 --threads 1 --resume --out "$O/hoi"; }

publish() {   # each app whose stages have all finished in OUT; the others are named and left as they are
  local app s missing n=0
  declare -A NEEDS=([selfpen]="selfpen_tune selfpen selfpen_seeds" [egohmr]="egohmr_tune egohmr" [hoi]="hoi")
  for app in selfpen egohmr hoi; do
    missing=""
    for s in ${NEEDS[$app]}; do [ -e "$O/done/$s" ] || missing="$missing $s"; done
    if [ -n "$missing" ]; then echo "app_tables: $app not published: stage(s)$missing not finished in $O"; continue; fi
    case $app in
      selfpen) cp "$O/selfpen_tune/tune.json" "$O/seeds.json" "$O/selfpen/results.json" "$O"/selfpen/*.png docs/selfpen/ ;;
      egohmr) cp "$O/egohmr_tune/tune.json" "$O/egohmr/results.json" "$O"/egohmr/*.png docs/egohmr/ ;;
      hoi) cp "$O/hoi/results.json" "$O"/hoi/*.png docs/hoi/
           rm -f docs/hoi/cases/*.json && cp "$O"/hoi/cases/*.json docs/hoi/cases/ ;;
    esac
    echo "app_tables: published $app from $O to docs/$app/"; n=$((n + 1))
  done
  [ "$n" -gt 0 ] || { echo "app_tables: nothing to publish from $O" >&2; exit 1; }
  echo "app_tables: figures of cases the new tables no longer draw stay in docs/ (git status shows them)"
}

for s in "${STAGES[@]}"; do
  if [ "$s" = publish ]; then publish; continue; fi
  if [ -e "$O/done/$s" ]; then echo "== $s: done before"; continue; fi
  echo "== $s: $(date -u +%FT%TZ)"; t=$SECONDS
  "$s"
  echo "$((SECONDS - t)) s" > "$O/done/$s"; echo "== $s finished in $((SECONDS - t)) s"
done
