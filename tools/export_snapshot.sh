#!/usr/bin/env bash
# Export the committed package (core + apps) at a commit into DIR, for a long CLI job that must not see later edits
# of the checkout (its per-case records are keyed by the source it runs: volsmpl.io.case_store):
#     tools/export_snapshot.sh DIR [COMMIT]      # default COMMIT: HEAD
#     PYTHONPATH=DIR python -m volsmpl.cli motion ... --resume
# The same commit exported again (later, or on another machine) gives the same source digest, so --resume continues its
# records; DIR/volsmpl/SOURCE_COMMIT names the commit, which results then record as meta.git_commit.
set -euo pipefail
dir=${1:?usage: tools/export_snapshot.sh DIR [COMMIT]}
commit=$(git rev-parse --short "${2:-HEAD}")
if [ -e "$dir/volsmpl" ]; then echo "export_snapshot: $dir/volsmpl exists; choose an empty DIR" >&2; exit 2; fi
mkdir -p "$dir/.src"
git archive "$commit" core apps | tar -x -C "$dir/.src"
mv "$dir/.src/core" "$dir/volsmpl"
mv "$dir/.src/apps" "$dir/volsmpl/apps"
rmdir "$dir/.src"
echo "$commit" > "$dir/volsmpl/SOURCE_COMMIT"
echo "exported $commit to $dir (use PYTHONPATH=$dir)"
