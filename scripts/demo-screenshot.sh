#!/usr/bin/env bash
# Regenerates docs/demo.png: the `host demo` page in headless Chromium while the virtual tool
# presses 8 mm into the embedded liver (steered through the page's own /api/steer endpoint).
# `host demo` runs the shipped scene: docs/demo.png.sha256 records the scene file and the meshes
# it names as they were for this picture, and host/tests/docs.rs fails when they change until
# this script is rerun.
# PROFILE picks the cargo profile (release unless set; `checked` reuses the test suite's build);
# the binary is found under CARGO_TARGET_DIR when that is set.
set -euo pipefail
cd "$(dirname "$0")/.."
profile_name=${PROFILE:-release}
cargo build --profile "$profile_name" -p host
port=${PORT:-18080}
"${CARGO_TARGET_DIR:-target}/$profile_name/host" demo --port "$port" --seconds 120 >/dev/null 2>&1 &
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
sha256sum host/scenes/liver.toml host/meshes/liver-1k4.msh host/meshes/liver-reach-2.8mm.msh \
    host/meshes/liver-reach-4mm.msh >docs/demo.png.sha256
echo "wrote docs/demo.png and docs/demo.png.sha256"
