#!/usr/bin/env python3
"""Runs `host bench compliance` and the scipy/CHOLMOD peer on the same meshes and fixed set in one
go and prints a comparison table (seconds; ratio = peer total / ours total).

    python3 host/benches/peer/compare.py [mesh.msh ...]

Defaults to the shipped livers. Needs the peer's dependencies (see README.md here). The peer runs
with single-threaded BLAS (--threads 1); ours uses every core rayon finds.
"""
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
E, NU, BED = "3000", "0.45", "0.01"


def ours(mesh):
    out = subprocess.run(
        ["cargo", "run", "--release", "-q", "-p", "host", "--", "bench", "compliance",
         "--mesh", str(mesh), "--young", E, "--poisson", NU, "--bed", BED, "--json"],
        cwd=ROOT, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def peer(mesh, nodes):
    out = subprocess.run(
        [sys.executable, str(ROOT / "host/benches/peer/compliance_peer.py"), str(mesh),
         "--young", E, "--poisson", NU, "--fix-box", f"-1,-1,-1,1,1,{BED}",
         "--threads", "1"] + (["--surface-free"] if nodes is None else ["--nodes", nodes]),
        cwd=ROOT, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    meshes = [Path(m) for m in sys.argv[1:]] or [
        ROOT / "host/meshes/liver-1k4.msh", ROOT / "host/meshes/liver-10k.msh"]
    print(f"{'mesh':<18} {'cols':>6} {'ours asm/fac/col s':>24} {'peer asm/fac/col s':>24} {'ratio':>6}")
    for mesh in meshes:
        a = ours(mesh)
        b = peer(mesh, None)
        ta = a["assemble_s"] + a["factor_s"] + a["columns_s"]
        tb = b["assemble_s"] + b["factor_s"] + b["columns_s"]
        print(f"{mesh.name:<18} {a['columns']:>6} "
              f"{a['assemble_s']:>7.3f}/{a['factor_s']:>7.3f}/{a['columns_s']:>8.3f} "
              f"{b['assemble_s']:>7.3f}/{b['factor_s']:>7.3f}/{b['columns_s']:>8.3f} "
              f"{tb / ta:>5.1f}x")
        if a["columns"] != b["columns"]:
            print(f"  warning: column counts differ ({a['columns']} vs {b['columns']})")


if __name__ == "__main__":
    main()
