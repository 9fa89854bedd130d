#!/usr/bin/env python3
"""Generate host/data/brain-relaxation-ramp-hold.csv: a MODEL-GENERATED stand-in for a bench
stress-relaxation test (ramp, then hold) of a cylindrical swine-brain sample, for
`host calibrate relaxation`. Nothing in it is measured.

The law (published)
-------------------
K. Miller and K. Chinzei, "Mechanical properties of brain tissue in tension", J. Biomech.
35(4):483-490, 2002 (eq. 1-2; the same form as K. Miller, J. Biomech. 32(5):531-537, 1999),
fitted to the unconfined compression experiments of K. Miller and K. Chinzei, J. Biomech.
30(11/12):1115-1121, 1997 (swine brain, 30 mm across, 13 mm high):

    W = 2 / alpha^2 * int_0^t mu(t - tau) d/dtau (l1^alpha + l2^alpha + l3^alpha - 3) dtau
    mu(t) = mu0 * (1 - sum_k g_k (1 - exp(-t / tau_k)))
    mu0 = 842 Pa, alpha = -4.7, g1 = 0.450, g2 = 0.365, tau1 = 0.5 s, tau2 = 50 s

so the reduced relaxation function is G(t) = mu(t) / mu0 = g_inf + sum_k g_k exp(-t / tau_k)
with g_inf = 1 - 0.450 - 0.365 = 0.185, and the nominal stress is Fung's quasi-linear
viscoelastic (QLV) hereditary integral of the elastic one (incompressible, uniform uniaxial
stress, frictionless platens, l1 = lambda = 1 - x / h, l2 = l3 = lambda^-1/2):

    T(t) = int_0^t G(t - s) dTe/ds ds,  Te = 2 mu0 / alpha (lambda^(alpha-1) - lambda^(-alpha/2-1))

(the same law as scripts/gen_brain_bench.py uses for the 500 mm/min compression curve).
Force = -T pi r^2 (compression positive).

The test (chosen here, not from the paper)
------------------------------------------
A finite ramp at the experiments' 500 mm/min to 10 % strain (1.3 mm in 0.156 s), then a hold
to 300 s (six tau2). Sampled at 1 kHz for the first 2 s, then at 10 Hz (a bench logger that
thins its rate after the transient): 2,000 + 2,980 rows. The integral is evaluated exactly per
sub-step for a piecewise-linear Te (Prony recursion, 50 sub-steps per row). Noise, Gaussian and
independent per row, seeded (the file is reproducible): 0.5 mN on the force (a 1 N load cell
at 0.05 % of its range) and 0.5 um on the displacement (a stage encoder). The peak force is
about 0.23 N, so the force noise is 0.2 % of it.

What the fit should recover: g = (0.450, 0.365), tau = (0.5, 50) s, g_inf = 0.185, and a
force residual of about the force noise (0.5 mN RMS).

Run from the repository root:  python3 scripts/gen_relaxation_bench.py
"""

import math
import os
import random
import sys

MU0, ALPHA = 842.0, -4.7
G = (0.450, 0.365)
TAU = (0.5, 50.0)
RADIUS, HEIGHT = 0.015, 0.013  # m
SPEED = 0.5 / 60.0  # 500 mm/min in m/s
STRAIN = 0.10
HOLD_END = 300.0  # s
FAST_DT, FAST_UNTIL, SLOW_DT = 1.0e-3, 2.0, 0.1  # s
SUBSTEPS = 50
FORCE_NOISE, X_NOISE = 0.5e-3, 0.5e-6  # N, m
SEED = 30

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
OUT = os.path.join(ROOT, "host", "data", "brain-relaxation-ramp-hold.csv")


def elastic_force(x: float) -> float:
    """Instantaneous elastic response Q_e(x), N (compression positive)."""
    lam = 1.0 - x / HEIGHT
    te = 2.0 * MU0 / ALPHA * (lam ** (ALPHA - 1.0) - lam ** (-ALPHA / 2.0 - 1.0))
    return -te * math.pi * RADIUS**2


def displacement(t: float) -> float:
    return min(SPEED * t, STRAIN * HEIGHT)


def times():
    n_fast = int(round(FAST_UNTIL / FAST_DT))
    out = [i * FAST_DT for i in range(n_fast)]
    t = FAST_UNTIL
    while t <= HOLD_END + 1e-9:
        out.append(t)
        t += SLOW_DT
    return out


def main() -> int:
    rng = random.Random(SEED)
    g_inf = 1.0 - sum(G)
    hist = [0.0 for _ in G]
    q_prev = 0.0
    t_prev = 0.0
    rows = []
    for t in times():
        if t > t_prev:
            dt = (t - t_prev) / SUBSTEPS
            decay = [math.exp(-dt / tau) for tau in TAU]
            weight = [g * tau / dt * (1.0 - d) for g, tau, d in zip(G, TAU, decay)]
            for j in range(1, SUBSTEPS + 1):
                q = elastic_force(displacement(t_prev + j * dt))
                hist = [h * d + w * (q - q_prev) for h, d, w in zip(hist, decay, weight)]
                q_prev = q
        force = g_inf * q_prev + sum(hist)
        rows.append((t, displacement(t) + rng.gauss(0.0, X_NOISE), force + rng.gauss(0.0, FORCE_NOISE)))
        t_prev = t
    tmp = OUT + ".tmp"
    with open(tmp, "w", encoding="ascii") as f:
        f.write("# MODEL-GENERATED, NOT MEASURED: scripts/gen_relaxation_bench.py (see its docstring).\n")
        f.write("# Swine brain cylinder r = 15 mm, h = 13 mm, unconfined compression: ramp at 500 mm/min\n")
        f.write("# to 10 % strain, hold to 300 s. QLV law of Miller & Chinzei (J. Biomech. 2002):\n")
        f.write(f"# mu0 = {MU0} Pa, alpha = {ALPHA}, g = {G}, tau = {TAU} s (g_inf = {g_inf:.3f}).\n")
        f.write(f"# Noise: force {FORCE_NOISE} N, displacement {X_NOISE} m (Gaussian, seed {SEED}).\n")
        f.write("# Units: s, m, N.\n")
        f.write("t_s,x_m,force_n\n")
        for t, x, force in rows:
            f.write(f"{t:.4f},{x:.7e},{force:.7e}\n")
    os.replace(tmp, OUT)
    peak = max(r[2] for r in rows)
    print(f"wrote {OUT}: {len(rows)} rows, peak force {peak:.4f} N, last {rows[-1][2]:.4f} N")
    return 0


if __name__ == "__main__":
    sys.exit(main())
