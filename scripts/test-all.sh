#!/usr/bin/env bash
# Runs every test of the project on a fresh machine, installing what it needs first.
# This is the README's second command; .ci/run calls it too, so CI proves the README.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n== %s\n' "$*"; }

step "toolchain: thumbv7em-none-eabihf target, rustfmt, clippy"
if ! rustup target list --installed | grep -qx thumbv7em-none-eabihf; then
    rustup target add thumbv7em-none-eabihf
fi
for c in rustfmt clippy; do
    rustup component list --installed | grep -q "^$c" || rustup component add "$c"
done

step "headless chromium for the viewer test (host/tests/demo.rs)"
if ! command -v chromium >/dev/null 2>&1; then
    sudo=""
    [ "$(id -u)" -eq 0 ] || sudo="sudo"
    $sudo apt-get update
    $sudo apt-get install -y chromium
fi

step "format and lints"
cargo fmt --all --check
cargo clippy --workspace --all-targets --release -- -D warnings

step "no_std crates cross-compile for the MCU"
cargo build --release -p bank-format -p firmware --target thumbv7em-none-eabihf

step "tests (release: the FEM refinement series is heavy in debug)"
log=$(mktemp)
trap 'rm -f "$log"' EXIT
status=0
cargo test --workspace --release --no-fail-fast 2>&1 | tee "$log" || status=$?
# One closing line for the whole suite (cargo prints one per test binary).
awk '/^test result:/ { p += $4; f += $6 } END { printf "\nsuite: %d passed, %d failed\n", p, f }' "$log"
exit "$status"
