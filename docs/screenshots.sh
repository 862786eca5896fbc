#!/usr/bin/env bash
# Regenerates the quality record's screenshots in docs/ from a demo session of 50 billets
# (issue 44): 30 billets of lot 4711 on die set 17, then 20 of lot 4712 on die set 18, each
# billet a little unlike the last (`demo --scatter`), judged by a recipe taught from 20 other
# billets. Writes docs/shift-report.png (`forgemon history report`) and
# docs/history-page.png (the dashboard's history page, `forgemon history serve`).
# Needs Chromium and the `websockets` package (as the browser tests).
#
#   bash docs/screenshots.sh [path/to/forgemon]
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${1:-target/release/forgemon}
browser=$(command -v chromium || command -v chromium-browser)
work=$(mktemp -d)
trap 'kill "${server:-0}" 2>/dev/null || true; rm -rf "$work"' EXIT

"$bin" demo --fast --scatter --billets 20 --dir "$work/reference" > /dev/null
"$bin" teach --machine config/hammer-lg1000.machine.toml --reference "$work/reference" -o "$work/flange.recipe.toml"
start=$(date -u -d '-1 minute' +%FT%TZ)
"$bin" demo --fast --scatter --billets 30 --lot 4711 --die 17 --recipe "$work/flange.recipe.toml" --dir "$work/session" > /dev/null
"$bin" demo --fast --scatter --billets 20 --lot 4712 --die 18 --recipe "$work/flange.recipe.toml" --dir "$work/session" > /dev/null
db="$work/session/history.sqlite"

"$bin" history report --db "$db" --recipe "$work/flange.recipe.toml" --shift "$start" --hours 8 -o "$work/shift.html"
# The report's head, its capability table and its first blows' charts.
python3 tests/python/dashboard_cdp.py --page "$browser" "file://$work/shift.html" docs/shift-report.png 2200

port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
"$bin" history serve --db "$db" --http "127.0.0.1:$port" > /dev/null &
server=$!
for _ in $(seq 50); do curl -sf "http://127.0.0.1:$port/history/data" > /dev/null && break; sleep 0.1; done
python3 tests/python/dashboard_cdp.py --history "$browser" "http://127.0.0.1:$port/history" docs/history-page.png 18 > /dev/null
echo "wrote docs/shift-report.png and docs/history-page.png"
