#!/usr/bin/env bash
# Keep the working tree that a device call sends under its 64 MiB (tracked files + carried .whl/): the committed
# training checkpoints (checkpoints/*/ckpt-*, ~28 MB: safeguards of runs, not read by any device command) and the
# EgoHMR weights (7.6 MB; only `gpu_checks.sh egohmr` and the egohmr tests read them) go aside before the call and
# come back after it:
#     tools/device_tree.sh aside [PATH...]   # move them to /tmp/device_aside, except the PATHs named (e.g. the
#                                            # model a training call starts from: checkpoints/volsmpl_b8q/ckpt-N)
#     tools/device_tree.sh back              # put every moved file back (run it before any commit)
#     tools/device_tree.sh size              # what a call would send, in MiB
set -euo pipefail
cd "$(git rev-parse --show-toplevel)"
HOLD=/tmp/device_aside
size() {  # tracked files present in the tree, and the wheels in .whl/
    git ls-files -z | python3 -c "
import os, sys
files = [f for f in sys.stdin.read().split('\0') if f and os.path.isfile(f)]
files += [os.path.join('.whl', f) for f in (os.listdir('.whl') if os.path.isdir('.whl') else [])]
print(f'{sum(os.path.getsize(f) for f in files) / 2**20:.1f} MiB (limit 64)')"
}
case "${1:-}" in
aside)
    shift
    mkdir -p "$HOLD"
    for p in checkpoints/*/ckpt-* apps/egohmr/egohmr_anny.safetensors; do
        [ -e "$p" ] || continue
        keep=0
        for k in "$@"; do [ "${p%/}" = "${k%/}" ] && keep=1; done
        [ $keep = 1 ] && continue
        mkdir -p "$HOLD/$(dirname "$p")" && mv "$p" "$HOLD/$p" && echo "aside: $p"
    done
    size ;;
back)
    [ -d "$HOLD" ] || { echo "nothing aside"; exit 0; }
    (cd "$HOLD" && find . -mindepth 1 -maxdepth 3 \( -name 'ckpt-*' -o -name '*.safetensors' \) -prune -print) | while read -r p; do
        p=${p#./}
        [ -e "$p" ] && { echo "not moved back, $p exists: compare it with $HOLD/$p" >&2; continue; }
        mkdir -p "$(dirname "$p")" && mv "$HOLD/$p" "$p" && echo "back: $p"
    done
    git status --short ;;
size) size ;;
*) echo "usage: tools/device_tree.sh aside [PATH...] | back | size" >&2; exit 2 ;;
esac
