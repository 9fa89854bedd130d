#!/usr/bin/env bash
# Regenerates docs/demo.png: the `host demo` page in headless Chromium while the virtual tool
# presses 8 mm into the embedded liver (steered through the page's own /api/steer endpoint).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -p host
port=${PORT:-18080}
target/release/host demo --port "$port" --seconds 120 >/dev/null 2>&1 &
pid=$!
profile=$(mktemp -d)
trap 'kill $pid 2>/dev/null || true; rm -rf "$profile"' EXIT
base="http://127.0.0.1:$port"
until info=$(curl -sf "$base/api/info"); do sleep 0.2; done
aim=$(python3 -c 'import json, sys; print(json.load(sys.stdin)["press_point"])' <<<"$info")
curl -sf -X POST -d "{\"aim\": $aim, \"depth\": 0.008}" "$base/api/steer"
sleep 3
chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
    --disable-background-networking --disable-component-update --disable-sync \
    --use-angle=swiftshader --enable-unsafe-swiftshader --user-data-dir="$profile" \
    --window-size=1200,800 --virtual-time-budget=4000 --screenshot=docs/demo.png "$base/" \
    2>/dev/null
echo "wrote docs/demo.png"
