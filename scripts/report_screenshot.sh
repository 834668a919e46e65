#!/usr/bin/env bash
# The report page of a run as a headless browser draws it: `gpustar report --html`, then a
# Chromium screenshot, to look at (issue 47: the page checked in a real browser).
#   scripts/report_screenshot.sh RUN.jsonl [RUN2.jsonl ...] OUT.png
# GPUSTAR: the binary (default: target/debug/gpustar, else target/release/gpustar);
# CHROMIUM: the browser (default: chromium, chromium-browser or google-chrome on PATH);
# SIZE: the window, WIDTHxHEIGHT (default 1200x1800). The page is written beside OUT.png.
set -euo pipefail
if [ $# -lt 2 ]; then
  echo "usage: $0 RUN.jsonl [RUN2.jsonl ...] OUT.png" >&2
  exit 2
fi
here="$(cd "$(dirname "$0")" && pwd)"
runs=("${@:1:$#-1}")
png="${!#}"
gpustar="${GPUSTAR:-}"
if [ -z "$gpustar" ]; then
  for b in "$here/../target/debug/gpustar" "$here/../target/release/gpustar"; do
    [ -x "$b" ] && gpustar="$b" && break
  done
fi
[ -n "$gpustar" ] || { echo "$0: no gpustar binary: cargo build, or set GPUSTAR" >&2; exit 2; }
browser="${CHROMIUM:-}"
if [ -z "$browser" ]; then
  for b in chromium chromium-browser google-chrome; do
    command -v "$b" >/dev/null && browser="$b" && break
  done
fi
[ -n "$browser" ] || { echo "$0: no Chromium found (apt-get install chromium, or set CHROMIUM)" >&2; exit 2; }
html="${png%.png}.html"
"$gpustar" report "${runs[@]}" --html "$html"
size="${SIZE:-1200x1800}"
# A profile of its own: a user's running Chromium, or a root without a sandbox, does not stop it.
profile="$(mktemp -d)"
trap 'rm -rf "$profile"' EXIT
"$browser" --headless --no-sandbox --disable-gpu --hide-scrollbars --user-data-dir="$profile" \
  --screenshot="$(realpath -m "$png")" --window-size="${size/x/,}" \
  "file://$(realpath "$html")" 2>/dev/null
[ -s "$png" ] || { echo "$0: $browser wrote no screenshot" >&2; exit 1; }
echo "$png (page: $html)" >&2
