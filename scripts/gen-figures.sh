#!/usr/bin/env bash
# Regenerates docs/figures.md, the user guide's measured figures: runs the same quick report
# that host/tests/report.rs runs and checks against the committed file, then copies the
# report's figures.md over it. About 3 minutes on a quiet 2-core machine, up to 9 beside other
# builds (the QEMU runs included);
# needs qemu-system-arm and llvm-tools like the report (scripts/test-all.sh installs them).
set -euo pipefail
cd "$(dirname "$0")/.."

out=target/figures-report
cargo run --profile checked -q -p host -- \
    report --quick --scene host/scenes/liver-nodal.toml --out "$out"
cp "$out/figures.md" docs/figures.md
echo "gen-figures.sh: wrote docs/figures.md from $out (git diff docs/figures.md shows what moved)"
