#!/usr/bin/env python3
"""Generate the MODEL-GENERATED stand-ins for bench stress-relaxation tests (ramp, then hold) of
a cylindrical swine-brain sample that `host calibrate relaxation` is tested on. Nothing in them
is measured. Six files under host/data/:

- brain-relaxation-ramp-hold.csv: the published QLV law below, ramp at 500 mm/min (0.156 s);
- brain-relaxation-ramp-0.1s.csv, -0.5s.csv, -2s.csv: the same law, the same 10 % strain
  reached in 0.1 s, 0.5 s and 2 s (780, 156 and 39 mm/min): the multi-rate set;
- brain-nonqlv-ramp-0.1s.csv, brain-nonqlv-ramp-2s.csv: NOT a QLV law, for the test that the
  rate dependence QLV cannot explain is reported: the same elastic law and amplitudes, but
  each time constant scales with the ramp time, tau_k(ramp) = tau_k (ramp / 0.5 s)^0.5
  (0.22 s and 22 s after the 0.1 s ramp, 1 s and 100 s after the 2 s one). A material whose
  relaxation spectrum depends on the loading rate cannot be one G(t) for every ramp.

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

The tests (chosen here, not from the paper)
-------------------------------------------
The first file: a finite ramp at the experiments' 500 mm/min to 10 % strain (1.3 mm in
0.156 s), then a hold to 300 s (six tau2). Sampled at 1 kHz for the first 2 s, then at 10 Hz
(a bench logger that thins its rate after the transient): 2,000 + 2,980 rows. The multi-rate
and non-QLV files, kept small: 10 % strain in the stated ramp time, hold to 300 s, sampled at
500 Hz until 1 s after the ramp, then at 5 Hz. The integral is evaluated exactly per
sub-step for a piecewise-linear Te (Prony recursion, 50 sub-steps per row). Noise, Gaussian and
independent per row, seeded per file (the files are reproducible; seeds 30 to 35 in the order
above): 0.5 mN on the force (a 1 N load cell
at 0.05 % of its range) and 0.5 um on the displacement (a stage encoder). The peak force is
about 0.23 N, so the force noise is 0.2 % of it.

What the fit should recover from the QLV files, one or several together: g = (0.450, 0.365),
tau = (0.5, 50) s, g_inf = 0.185, and a force residual of about the force noise (0.5 mN RMS).
From the two non-QLV files together it cannot: one G(t) leaves residuals well above the noise.

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
STRAIN = 0.10
HOLD_END = 300.0  # s
SUBSTEPS = 50
FORCE_NOISE, X_NOISE = 0.5e-3, 0.5e-6  # N, m
NONQLV_REF_RAMP, NONQLV_EXPONENT = 0.5, 0.5  # s; tau_k(ramp) = tau_k (ramp / ref)^exponent

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
DATA = os.path.join(ROOT, "host", "data")

# (file, ramp time s, time constants s, fast dt s, fast until s, slow dt s, seed, law note)
X_END = STRAIN * HEIGHT
RAMP_500 = X_END / (0.5 / 60.0)  # 500 mm/min
FILES = [
    ("brain-relaxation-ramp-hold.csv", RAMP_500, TAU, 1.0e-3, 2.0, 0.1, 30, "QLV"),
    ("brain-relaxation-ramp-0.1s.csv", 0.1, TAU, 2.0e-3, 1.1, 0.2, 31, "QLV"),
    ("brain-relaxation-ramp-0.5s.csv", 0.5, TAU, 2.0e-3, 1.5, 0.2, 32, "QLV"),
    ("brain-relaxation-ramp-2s.csv", 2.0, TAU, 2.0e-3, 3.0, 0.2, 33, "QLV"),
]
for name, ramp, seed in (("brain-nonqlv-ramp-0.1s.csv", 0.1, 34), ("brain-nonqlv-ramp-2s.csv", 2.0, 35)):
    scale = (ramp / NONQLV_REF_RAMP) ** NONQLV_EXPONENT
    FILES.append((name, ramp, tuple(t * scale for t in TAU), 2.0e-3, ramp + 1.0, 0.2, seed, "NOT QLV"))


def elastic_force(x: float) -> float:
    """Instantaneous elastic response Q_e(x), N (compression positive)."""
    lam = 1.0 - x / HEIGHT
    te = 2.0 * MU0 / ALPHA * (lam ** (ALPHA - 1.0) - lam ** (-ALPHA / 2.0 - 1.0))
    return -te * math.pi * RADIUS**2


def times(fast_dt, fast_until, slow_dt):
    n_fast = int(round(fast_until / fast_dt))
    out = [i * fast_dt for i in range(n_fast)]
    t = fast_until
    while t <= HOLD_END + 1e-9:
        out.append(t)
        t += slow_dt
    return out


def generate(name, ramp, taus, fast_dt, fast_until, slow_dt, seed, note):
    out_path = os.path.join(DATA, name)
    speed = X_END / ramp

    def displacement(t: float) -> float:
        return min(speed * t, X_END)

    rng = random.Random(seed)
    g_inf = 1.0 - sum(G)
    hist = [0.0 for _ in G]
    q_prev = 0.0
    t_prev = 0.0
    rows = []
    for t in times(fast_dt, fast_until, slow_dt):
        if t > t_prev:
            dt = (t - t_prev) / SUBSTEPS
            decay = [math.exp(-dt / tau) for tau in taus]
            weight = [g * tau / dt * (1.0 - d) for g, tau, d in zip(G, taus, decay)]
            for j in range(1, SUBSTEPS + 1):
                q = elastic_force(displacement(t_prev + j * dt))
                hist = [h * d + w * (q - q_prev) for h, d, w in zip(hist, decay, weight)]
                q_prev = q
        force = g_inf * q_prev + sum(hist)
        rows.append((t, displacement(t) + rng.gauss(0.0, X_NOISE), force + rng.gauss(0.0, FORCE_NOISE)))
        t_prev = t
    tmp = out_path + ".tmp"
    with open(tmp, "w", encoding="ascii") as f:
        f.write("# MODEL-GENERATED, NOT MEASURED: scripts/gen_relaxation_bench.py (see its docstring).\n")
        if note == "QLV":
            f.write("# Swine brain cylinder r = 15 mm, h = 13 mm, unconfined compression: ramp at 500 mm/min\n"
                    if name == FILES[0][0] else
                    f"# Swine brain cylinder r = 15 mm, h = 13 mm, unconfined compression: ramp in {ramp} s\n")
            f.write("# to 10 % strain, hold to 300 s. QLV law of Miller & Chinzei (J. Biomech. 2002):\n")
            f.write(f"# mu0 = {MU0} Pa, alpha = {ALPHA}, g = {G}, tau = {TAU} s (g_inf = {g_inf:.3f}).\n")
        else:
            f.write(f"# Swine brain cylinder r = 15 mm, h = 13 mm, unconfined compression: ramp in {ramp} s\n")
            f.write("# to 10 % strain, hold to 300 s. NOT QLV: Miller & Chinzei's elastic law and g, but\n")
            f.write(f"# tau = {tuple(round(t, 4) for t in taus)} s: tau_k (ramp / {NONQLV_REF_RAMP} s)^{NONQLV_EXPONENT}"
                    f" of tau = {TAU} s.\n")
        f.write(f"# Noise: force {FORCE_NOISE} N, displacement {X_NOISE} m (Gaussian, seed {seed}).\n")
        f.write("# Units: s, m, N.\n")
        f.write("t_s,x_m,force_n\n")
        for t, x, force in rows:
            f.write(f"{t:.4f},{x:.7e},{force:.7e}\n")
    os.replace(tmp, out_path)
    peak = max(r[2] for r in rows)
    print(f"wrote {out_path}: {len(rows)} rows, peak force {peak:.4f} N, last {rows[-1][2]:.4f} N")


def main() -> int:
    for spec in FILES:
        generate(*spec)
    return 0


if __name__ == "__main__":
    sys.exit(main())
