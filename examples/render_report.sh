#!/usr/bin/env bash
# Render a vibinverse report in headless Chromium and save a screenshot, to check that the
# self-contained HTML (all figures embedded) displays without network access.
#   bash examples/render_report.sh vibinverse-demo report.png     # a report's directory (-o DIR) or its report.html
# Needs Debian's chromium (apt-get install chromium).
set -euo pipefail
html=$1
[ -d "$html" ] && html=$html/report.html
html=$(realpath "$html")
png=${2:-report.png}
chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
  --disable-background-networking --disable-component-update --disable-sync \
  --user-data-dir="$(mktemp -d)" --window-size=1100,2400 --screenshot="$png" "file://$html" 2>/dev/null
echo "wrote $png"
