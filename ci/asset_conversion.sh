#!/usr/bin/env bash
# Example asset-conversion CI step for a studio repository of characters.
# Converts and validates every wrinklepipe manifest changed since BASE (default: origin/main),
# writes each result to $OUT/<manifest path relative to the repository root, without .toml>/
# (chars/good/manifest.toml -> $OUT/chars/good/manifest/: unique by construction) and fails when
# any asset has errors. Two manifests whose outputs would nest (a.toml beside a/manifest.toml)
# are an error, never a silent overwrite. Keep $OUT (report.html and its images) as the job's
# artefact.
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
declare -a outputs=()
for m in "${manifests[@]}"; do
  rel=${m%.toml}  # git prints paths relative to the repository root
  dest="$OUT/$rel"
  clash=""
  for o in "${outputs[@]}"; do
    case "$dest/" in "$o/"*) clash=$o ;; esac
    case "$o/" in "$dest/"*) clash=$o ;; esac
  done
  echo "::group::$m"
  if [ -n "$clash" ]; then
    echo "output collision: $m would write $dest, which overlaps $clash; rename one of them"
    status=1; echo "::endgroup::"; continue
  fi
  outputs+=("$dest")
  if ! "$WP" convert "$m" -o "$dest" --force; then
    echo "conversion failed: $m"; status=1; echo "::endgroup::"; continue
  fi
  "$WP" validate-asset "$dest" --report "$dest/validation.json" "$@"
  rc=$?
  [ $rc -eq 0 ] || { echo "validation failed ($rc): $m"; status=1; }
  echo "::endgroup::"
done
exit $status
