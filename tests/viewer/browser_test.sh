#!/usr/bin/env bash
# ctest "viewer_browser": the web viewer in headless Chromium (viewer/tests/browser.mjs) on the viewer
# fixture (tiny synthetic scene + hand-built hybrid model). Usage: browser_test.sh HGS_BINARY ARTEFACT_DIR.
# Exits 77 (ctest: skipped) when Node.js, Debian's chromium or the viewer's npm packages are missing.
set -euo pipefail
HGS="$1"
OUT="$2"
ROOT="$(cd "$(dirname "$0")/../.." && pwd)"
BIN_DIR="$(dirname "$HGS")"
command -v node >/dev/null 2>&1 || { echo "skip: node is not installed"; exit 77; }
[ -x /usr/bin/chromium ] || { echo "skip: /usr/bin/chromium is not installed (apt-get install chromium)"; exit 77; }
[ -d "$ROOT/viewer/node_modules/playwright-core" ] || { echo "skip: viewer npm packages missing (scripts/setup)"; exit 77; }
[ -f "$BIN_DIR/viewer/index.html" ] || { echo "error: front end not built in $BIN_DIR/viewer"; exit 1; }
rm -rf "$OUT"
mkdir -p "$OUT"
HGS_VIEWER_FIXTURE_OUT="$OUT/data" "$BIN_DIR/test_viewer" --gtest_filter='ViewerFixtureWriter.*' --gtest_brief=1
exec node "$ROOT/viewer/tests/browser.mjs" --hgs "$HGS" --scene "$OUT/data/scene" --model "$OUT/data/model.ply" \
  --out "$OUT" --query "red mug"
