#!/usr/bin/env bash
# Example asset-conversion CI step for a studio repository of characters.
# Converts and validates every wrinklepipe manifest changed since BASE (default: origin/main),
# writes each result to $OUT/<manifest-folder-name>/ and fails when any asset has errors.
# Keep $OUT (report.html and its images) as the job's artefact.
#
#   BASE=origin/main OUT=wrinkle-out bash ci/asset_conversion.sh [--fail-on warning]
set -uo pipefail
BASE=${BASE:-origin/main}
OUT=${OUT:-wrinkle-out}
WP=${WRINKLEPIPE:-wrinklepipe}
mkdir -p "$OUT"

# Changed TOML files that declare themselves wrinklepipe manifests.
mapfile -t manifests < <(
  git diff --name-only --diff-filter=d "$BASE"...HEAD -- '*.toml' 2>/dev/null \
    | while read -r f; do grep -q 'wrinklepipe/manifest@' "$f" 2>/dev/null && echo "$f"; done
)
if [ ${#manifests[@]} -eq 0 ]; then
  echo "no changed wrinklepipe manifests since $BASE"
  exit 0
fi

status=0
for m in "${manifests[@]}"; do
  name=$(basename "$(dirname "$m")")
  echo "::group::$m"
  if ! "$WP" convert "$m" -o "$OUT/$name" --force; then
    echo "conversion failed: $m"; status=1; echo "::endgroup::"; continue
  fi
  "$WP" validate-asset "$OUT/$name" --report "$OUT/$name/validation.json" "$@"
  rc=$?
  [ $rc -eq 0 ] || { echo "validation failed ($rc): $m"; status=1; }
  echo "::endgroup::"
done
exit $status
