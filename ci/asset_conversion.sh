#!/usr/bin/env bash
# Example asset-conversion CI step for a studio repository of characters.
#
# Converts and validates the repository's wrinklepipe manifests with one `wrinklepipe batch`
# call. Each result goes to $OUT/<manifest path relative to the repository root, without .toml>/
# (chars/good/manifest.toml -> $OUT/chars/good/manifest/: unique by construction); two manifests
# whose outputs would meet (a.toml beside a/manifest.toml) stop the batch before anything is
# written, never a silent overwrite. Each character runs on its own: one that fails never stops
# or changes the others.
#
# By default every manifest is checked on every commit: unchanged characters are restored from
# the cache in $CACHE (keep that folder between CI runs), and a changed texture, mesh or driver
# file reconverts its character even when no .toml changed. With BASE set, only the manifests
# changed since BASE are converted (the cache still applies).
#
# Reports go to $REPORTS: junit.xml (one test case per character, failures with rule codes),
# wrinkles.sarif (validation issues, for code scanning) and summary.json. Keep $OUT (report.html,
# validation.html and their images) and $REPORTS as the job's artefacts.
# Exit code: the worst character's: 0 all valid, 1 some failed validation, 2 some could not run.
#
#   OUT=wrinkle-out CACHE=.wrinkle-cache bash ci/asset_conversion.sh [--fail-on warning] [--jobs 4]
#   BASE=origin/main bash ci/asset_conversion.sh                 # only manifests changed since BASE
#   SCHEDULER=tcp://farm:8786 bash ci/asset_conversion.sh        # on a Dask cluster
set -uo pipefail
OUT=${OUT:-wrinkle-out}
CACHE=${CACHE:-.wrinkle-cache}
CACHE_SIZE=${CACHE_SIZE:-10G}
REPORTS=${REPORTS:-wrinkle-reports}
WP=${WRINKLEPIPE:-wrinklepipe}
ROOT=$(git rev-parse --show-toplevel 2>/dev/null || pwd)

sources=("$ROOT")
if [ -n "${BASE:-}" ]; then
  # Changed TOML files that declare themselves wrinklepipe manifests (paths from the root).
  mapfile -t sources < <(
    git -C "$ROOT" diff --name-only --diff-filter=d "$BASE"...HEAD -- '*.toml' 2>/dev/null \
      | while read -r f; do grep -q 'wrinklepipe/manifest@' "$ROOT/$f" 2>/dev/null && echo "$ROOT/$f"; done
  )
  if [ ${#sources[@]} -eq 0 ]; then
    echo "no changed wrinklepipe manifests since $BASE"
    exit 0
  fi
fi
where=()
if [ -n "${SCHEDULER:-}" ]; then
  where=(--scheduler "$SCHEDULER")
fi

mkdir -p "$REPORTS"
# --force: $OUT may hold the previous run's outputs (each is replaced atomically, as it was).
"$WP" batch "${sources[@]}" --root "$ROOT" -o "$OUT" --force \
  --cache "$CACHE" --cache-size "$CACHE_SIZE" "${where[@]}" \
  --junit "$REPORTS/junit.xml" --sarif "$REPORTS/wrinkles.sarif" --report "$REPORTS/summary.json" \
  "$@"
status=$?
case $status in
  0) echo "every character converted and valid" ;;
  1) echo "some characters failed validation: see $REPORTS/junit.xml" ;;
  *) echo "some characters could not be converted (exit $status): see $REPORTS/summary.json" ;;
esac
exit $status
