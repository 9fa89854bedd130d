#!/usr/bin/env python3
"""Generate host/data/brain-compression-500mm-min.csv: a MODEL-GENERATED stand-in for the bench
curves of the paper's experiment (Cotin, Delingette & Ayache 1999, section 3-4, fig. 6-9:
unconfined compression of a cylindrical swine-brain sample at 500 mm/min). Nothing in it is
measured.

Source of the "measured" columns
--------------------------------
Experiment: K. Miller and K. Chinzei, "Constitutive modelling of brain tissue: experiment and
theory", J. Biomech. 30(11/12):1115-1121, 1997: swine brain cylinders about 30 mm across and
13 mm high, compressed between platens at 500 mm/min (strain rate 0.64 /s) and slower.

Constitutive model fitted to those experiments: the hyper-viscoelastic Ogden-type model of
K. Miller and K. Chinzei, "Mechanical properties of brain tissue in tension", J. Biomech.
35(4):483-490, 2002 (eq. 1-2; the same form as K. Miller, J. Biomech. 32(5):531-537, 1999):

    W = 2 / alpha^2 * int_0^t mu(t - tau) d/dtau (l1^alpha + l2^alpha + l3^alpha - 3) dtau
    mu(t) = mu0 * (1 - sum_k g_k (1 - exp(-t / tau_k)))
    mu0 = 842 Pa, alpha = -4.7, g1 = 0.450, g2 = 0.365, tau1 = 0.5 s, tau2 = 50 s

Incompressible, uniform uniaxial stress (frictionless platens, as the model was identified):
l1 = lambda = 1 - x / h, l2 = l3 = lambda^-1/2, and the nominal (first Piola-Kirchhoff) stress is
the hereditary integral of the elastic one,

    T(t) = int_0^t g(t - s) dTe/ds ds,   Te(lambda) = 2 mu0 / alpha (lambda^(alpha-1) - lambda^(-alpha/2-1)),
    g(t) = mu(t) / mu0,

integrated exactly per time step for a piecewise-linear Te (Prony terms, 200 sub-steps per
output point). Force = -T * pi r^2 (compression positive); radial displacement of the side
= r (lambda^-1/2 - 1).

The linear model's columns
--------------------------
The x of the laws (the paper's f^L(x) and d_r^L(x)) come from the project's own linear FEM:
`host calibrate specimen` compresses host/meshes/brain-specimen.msh (r = 15 mm, h = 13 mm,
scripts/gen_meshes.py) between frictionless platens with E = 3 mu0 = 2526 Pa (the model's
small-strain Young's modulus) and nu = 0.45 (the project's scenes), and reports force and
mid-height radial displacement per metre of compression; the response is linear, so the
columns are those figures times the displacement.

Run from the repository root:  python3 scripts/gen_brain_bench.py
"""

import json
import math
import os
import subprocess
import sys

MU0, ALPHA = 842.0, -4.7
G = (0.450, 0.365)
TAU = (0.5, 50.0)
RADIUS, HEIGHT = 0.015, 0.013  # m
SPEED = 0.5 / 60.0  # 500 mm/min in m/s
MAX_STRAIN = 0.30
STEP = 5.0e-5  # m of compression between rows
SUBSTEPS = 200
YOUNG, POISSON = 3.0 * MU0, 0.45

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
OUT = os.path.join(ROOT, "host", "data", "brain-compression-500mm-min.csv")
MESH = os.path.join(ROOT, "host", "meshes", "brain-specimen.msh")


def elastic_nominal_stress(lam: float) -> float:
    return 2.0 * MU0 / ALPHA * (lam ** (ALPHA - 1.0) - lam ** (-ALPHA / 2.0 - 1.0))


def model_curve():
    """(x, force, radial) rows of the hyper-viscoelastic model, x = 0, STEP, ..."""
    rows = int(round(MAX_STRAIN * HEIGHT / STEP))
    dt = STEP / SPEED / SUBSTEPS
    decay = [math.exp(-dt / t) for t in TAU]
    # Exact weight of a linear increment of Te over one step for exp(-(t-s)/tau).
    weight = [g * t / dt * (1.0 - d) for g, t, d in zip(G, TAU, decay)]
    g_inf = 1.0 - sum(G)
    hist = [0.0, 0.0]
    te_prev = 0.0
    out = [(0.0, 0.0, 0.0)]
    for i in range(1, rows + 1):
        for j in range(1, SUBSTEPS + 1):
            x = ((i - 1) * SUBSTEPS + j) * dt * SPEED
            te = elastic_nominal_stress(1.0 - x / HEIGHT)
            dte = te - te_prev
            hist = [h * d + w * dte for h, d, w in zip(hist, decay, weight)]
            te_prev = te
        x = i * STEP
        lam = 1.0 - x / HEIGHT
        stress = g_inf * te_prev + sum(hist)
        force = -stress * math.pi * RADIUS**2
        radial = RADIUS * (lam**-0.5 - 1.0)
        out.append((x, force, radial))
    return out


def linear_response():
    cmd = ["cargo", "run", "--release", "-q", "-p", "host", "--", "calibrate", "specimen",
           "--mesh", MESH, "--young", repr(YOUNG), "--poisson", repr(POISSON)]
    res = subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True, text=True)
    return json.loads(res.stdout)


def main() -> int:
    lin = linear_response()
    rows = model_curve()
    tmp = OUT + ".tmp"
    with open(tmp, "w", encoding="ascii") as f:
        f.write("# MODEL-GENERATED, NOT MEASURED: scripts/gen_brain_bench.py (see its docstring).\n")
        f.write("# Swine brain, unconfined compression at 500 mm/min, cylinder r = 15 mm, h = 13 mm:\n")
        f.write("# Miller & Chinzei (J. Biomech. 1997; Ogden-type hyper-viscoelastic model, J. Biomech. 2002)\n")
        f.write(f"# mu0 = {MU0} Pa, alpha = {ALPHA}, g = {G}, tau = {TAU} s.\n")
        f.write(f"# linear_*: host FEM on host/meshes/brain-specimen.msh, E = {YOUNG} Pa, nu = {POISSON}:\n")
        f.write(f"#   {lin['force_per_m']:.6f} N/m and {lin['radial_per_m']:.6f} m/m of compression.\n")
        f.write("# Units: m, N.\n")
        f.write("displacement_m,force_n,radial_m,linear_force_n,linear_radial_m\n")
        for x, force, radial in rows:
            f.write(f"{x:.6e},{force:.6e},{radial:.6e},"
                    f"{lin['force_per_m'] * x:.6e},{lin['radial_per_m'] * x:.6e}\n")
    os.replace(tmp, OUT)
    print(f"wrote {OUT}: {len(rows)} rows, force up to {rows[-1][1]:.4f} N, "
          f"linear force up to {lin['force_per_m'] * rows[-1][0]:.4f} N")
    return 0


if __name__ == "__main__":
    sys.exit(main())
