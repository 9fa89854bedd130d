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

step "qemu-system-arm (software-in-the-loop tests)"
if ! command -v qemu-system-arm >/dev/null; then
    sudo=""
    [ "$(id -u)" -eq 0 ] || sudo="sudo"
    $sudo apt-get update
    $sudo DEBIAN_FRONTEND=noninteractive apt-get install -y qemu-system-arm
fi
qemu-system-arm --version | head -n 1

step "headless chromium for the viewer test (host/tests/demo.rs)"
if ! command -v chromium >/dev/null 2>&1; then
    sudo=""
    [ "$(id -u)" -eq 0 ] || sudo="sudo"
    $sudo apt-get update
    $sudo DEBIAN_FRONTEND=noninteractive apt-get install -y chromium
fi

step "format and lints"
cargo fmt --all --check
cargo clippy --workspace --all-targets --release -- -D warnings
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --quiet
# The QEMU image is its own workspace (it only builds for the MCU).
(cd firmware/qemu && cargo fmt --check && cargo clippy --release -- -D warnings)

step "no_std crates cross-compile for the MCU; the QEMU image links against memory.x"
cargo build --release -p bank-format -p firmware --target thumbv7em-none-eabihf
(cd firmware/qemu && cargo build --release)

step "the liver bank the software-in-the-loop tests load into QEMU's flash"
mkdir -p target/sil
cargo run --release -q -p host -- bank build host/scenes/liver.toml -o target/sil/liver.bank

step "tests (release: the FEM refinement series is heavy in debug)"
log=$(mktemp)
trap 'rm -f "$log"' EXIT
status=0
cargo test --workspace --release --no-fail-fast 2>&1 | tee "$log" || status=$?
# One closing line for the whole suite (cargo prints one per test binary).
awk '/^test result:/ { p += $4; f += $6 } END { printf "\nsuite: %d passed, %d failed\n", p, f }' "$log"
exit "$status"
