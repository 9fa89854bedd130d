#!/usr/bin/env bash
# Runs every test of the project on a fresh machine, installing what it needs first.
# This is the README's second command; .ci/run calls it too, so CI proves the README.
set -euo pipefail
cd "$(dirname "$0")/.."

# Each step's heading says how long the run has taken so far (bash's SECONDS), so a log shows
# where the time goes.
step() {
    current_step="$*"
    printf '\n== [%d:%02d] %s\n' $((SECONDS / 60)) $((SECONDS % 60)) "$*"
}
# A failure names its step and command, so a log's last lines say what broke.
trap 'echo "test-all.sh: failed in step \"${current_step:-set-up}\" at line $LINENO: $BASH_COMMAND" >&2' ERR

# Debian packages apt-get removed to install what the suite needs (apt may remove a package to
# resolve a conflict, e.g. qemu-utils for qemu-system-arm): said before, and again at the end.
removed=()
# shellcheck disable=SC2317 # called by the EXIT traps
report_removed() {
    if [ "${#removed[@]}" -gt 0 ]; then
        echo "test-all.sh: apt-get removed these Debian packages during this run: ${removed[*]}"
    elif [ -n "${apt_updated:-}" ]; then
        echo "test-all.sh: apt-get installed packages and removed none"
    fi
}
trap report_removed EXIT

# apt-get install as root, or through sudo; says what to do when neither is possible, and what
# apt-get will remove (from a simulated run) before it does.
apt_install() {
    local as=()
    if [ "$(id -u)" -ne 0 ]; then
        if ! command -v sudo >/dev/null; then
            echo "error: need root or sudo to apt-get install $*; install them by hand" >&2
            exit 1
        fi
        as=(sudo)
    fi
    # apt-get update once per run; the package lists of a fresh machine are usually empty.
    if [ -z "${apt_updated:-}" ]; then
        "${as[@]}" apt-get update
        apt_updated=1
    fi
    local gone
    gone=$(apt-get install -s -y --no-install-recommends "$@" 2>/dev/null | awk '/^Remv / { print $2 }' | tr '\n' ' ')
    if [ -n "$gone" ]; then
        echo "test-all.sh: installing $* makes apt-get REMOVE: $gone"
        read -r -a gone_list <<<"$gone"
        removed+=("${gone_list[@]}")
    fi
    "${as[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "$@"
}

# Installs Debian package $2 when command $1 is missing. A package that dpkg counts as
# installed while its command is gone (files deleted by hand, a half-removed package) is a no-op
# for a plain install, so that case reinstalls it.
need() {
    if ! command -v "$1" >/dev/null; then
        step "installing $2 (for $1)"
        apt_install "$2"
        if ! command -v "$1" >/dev/null; then
            echo "$1 still missing after installing $2; reinstalling $2"
            apt_install --reinstall "$2"
        fi
    fi
    command -v "$1" >/dev/null || {
        echo "error: $1 still missing after installing $2 (PATH=$PATH)" >&2
        dpkg -L "$2" 2>/dev/null | grep -E "/bin/$1\$" >&2 || true
        exit 1
    }
}

step "toolchain: thumbv7em-none-eabihf target, rustfmt, clippy, llvm-tools (llvm-objdump for the law cost)"
if ! rustup target list --installed | grep -qx thumbv7em-none-eabihf; then
    rustup target add thumbv7em-none-eabihf
fi
for c in rustfmt clippy llvm-tools; do
    rustup component list --installed | grep -q "^$c" || rustup component add "$c"
done

step "Debian tools: qemu-system-arm (software in the loop), chromium (viewer test), shellcheck"
need qemu-system-arm qemu-system-arm
need chromium chromium
need shellcheck shellcheck
qemu-system-arm --version | sed -n 1p

step "Gmsh for host mesh and host specimen --cylinder: the Python module gmsh==4.15.2 and numpy (pip), its X/GL libraries (apt-get)"
# `host mesh` runs Gmsh through its Python module, pinned like every mesh of the project
# (scripts/gen_meshes.py): the pip wheel is the whole library at that version (Debian's gmsh
# is another), so pip installs it here as apt-get installs QEMU. The wheel's library links
# against X11/OpenGL libraries even without a display.
gmsh_ok() { python3 -c 'import sys, gmsh, numpy; sys.exit(gmsh.__version__ != "4.15.2")' 2>/dev/null; }
if ! gmsh_ok; then
    command -v python3 >/dev/null || apt_install python3
    python3 -m pip --version >/dev/null 2>&1 || apt_install python3-pip
    apt_install libglu1-mesa libgl1 libxrender1 libxcursor1 libxft2 libxinerama1 libgomp1 libfontconfig1
    # Debian's Python refuses pip installs outside a virtual environment (PEP 668) unless told.
    python3 -m pip install "gmsh==4.15.2" numpy ||
        python3 -m pip install --break-system-packages "gmsh==4.15.2" numpy
fi
gmsh_ok || { echo "error: the gmsh 4.15.2 Python module is still missing" >&2; exit 1; }
python3 -c 'import gmsh; print("gmsh (Python module)", gmsh.__version__)'

step "shell scripts"
shellcheck scripts/*.sh .ci/run

# The firmware images are workspaces of their own, built into their own target dirs (where the
# host's image builds, `host::mcu::build_image`, look for them), whatever CARGO_TARGET_DIR says.
own_target() { (cd "$1" && shift && env -u CARGO_TARGET_DIR "$@"); }

step "format and lints"
cargo fmt --all --check
cargo clippy --workspace --all-targets --profile checked -- -D warnings
# The lints' profile: the docs reuse the dependencies clippy has just checked.
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --profile checked --quiet
# The QEMU image is its own workspace (it only builds for the MCU).
own_target firmware/qemu cargo fmt --check
own_target firmware/qemu cargo clippy --release -- -D warnings

step "the FEM engine stands alone: no web, plot, serial, probe or CLI stack under host/fem"
if cargo tree -p fem -e normal --prefix none | grep -E '^(axum|tokio|plotters|serialport|probe-rs|indicatif|clap) '; then
    echo "error: the fem crate depends on the stacks above" >&2
    exit 1
fi

step "the host library stands alone: no CLI or terminal stack (clap, ctrlc, indicatif) under host/haptic"
if cargo tree -p haptic -e normal --prefix none | grep -E '^(clap|ctrlc|indicatif) '; then
    echo "error: the haptic crate depends on the stacks above; they belong to the host CLI" >&2
    exit 1
fi

step "no_std crates cross-compile for the MCU; the QEMU image links against memory.x"
cargo build --release -p bank-format -p firmware -p splitmix --target thumbv7em-none-eabihf
own_target firmware/qemu cargo build --release

step "the board image (STM32F405RG, embassy-stm32): format, lints, build, size against memory.x, stack in CCM"
# Its own workspace too; built only (no board here). The linker enforces memory.x's regions.
# Lints also cover the bring-up builds' fault injection (features bringup-*).
own_target firmware/board cargo fmt --check
own_target firmware/board cargo clippy --release -- -D warnings
own_target firmware/board cargo clippy --release --all-features -- -D warnings
own_target firmware/board cargo build --release
board_size=$(cargo run --profile checked -q -p host -- bench image firmware/board/target/thumbv7em-none-eabihf/release/firmware-board)
echo "$board_size"
# The stack guard: the board's stack starts at the top of CCM (firmware/board/stack.x).
grep -q '^initial stack pointer 0x10010000$' <<<"$board_size" ||
    { echo "the board image's stack is not at the top of CCM (firmware/board/stack.x)"; exit 1; }

step "tests (profile checked: release speed, overflow checks and debug assertions on)"
log=$(mktemp)
trap 'rm -f "$log"; report_removed' EXIT
status=0
cargo test --workspace --profile checked --no-fail-fast 2>&1 | tee "$log" || status=$?
# One closing line for the whole suite (cargo prints one per test binary).
awk '/^test result:/ { p += $4; f += $6 } END { printf "\nsuite: %d passed, %d failed", p, f }' "$log"
printf ' in %d min %02d s\n' $((SECONDS / 60)) $((SECONDS % 60))
exit "$status"
