#!/usr/bin/env python
"""Why deep mode on a SignalSim file is biased Up by ~1.4 m (docs/foreign_files.md): SignalSim's ionosphere (GPS Klobuchar, IS-GPS-200,
delay at L1 scaled by (154/124)^2) against sdr-di's (BDS Klobuchar at B1I scaled by
(1561.098/1268.52)^2), both with the file's RINEX header coefficients (GPSA/GPSB: the file
has no BDS lines), at 40 N 116 E 100 m, 2020-06-25 06:30:14 BDT; per-satellite difference and
the position/clock error it maps to (unweighted LS over the satellites above 10 deg).

    python scripts/compare_iono_models.py

SignalSim (globsky/SignalSim, src/SatelliteParam.cpp, read for this fact only) computes one
L1 delay with its GPS Klobuchar function for every system and scales it to B3I by
(154/124)^2; the GPS algorithm here is IS-GPS-200 20.3.3.5.2.5, written from the ICD."""
import numpy as np
from sdr_di.orbits.rinex_nav import load_nav
from sdr_di.orbits.broadcast import sat_states
from sdr_di.orbits.atmosphere import iono_delay_b3i_m
from sdr_di.frames import llh_to_ecef, C_e_n
C = 299792458.0
path = "/work/main/ephemeris/ESBC00DNK_R_20201770000_01D_MN.rnx.gz"
nav = load_nav(path); kl = nav.iono_gps
print("coefficients", kl)
lat, lon, h = np.radians(40.0), np.radians(116.0), 100.0
week, sow = 755, 369014.0
r_u = llh_to_ecef(lat, lon, h)
Cen = C_e_n(lat, lon)
def gps_klob(a, b, lat, lon, el, az, t_gps):
    # IS-GPS-200 20.3.3.5.2.5, semicircle units
    phi_u, lam_u = lat/np.pi, lon/np.pi; E = el/np.pi
    psi = 0.0137/(E + 0.11) - 0.022
    phi_i = np.clip(phi_u + psi*np.cos(az), -0.416, 0.416)
    lam_i = lam_u + psi*np.sin(az)/np.cos(phi_i*np.pi)
    phi_m = phi_i + 0.064*np.cos((lam_i - 1.617)*np.pi)
    t = np.mod(4.32e4*lam_i + t_gps, 86400.0)
    F = 1.0 + 16.0*(0.53 - E)**3
    AMP = max(sum(a[n]*phi_m**n for n in range(4)), 0.0)
    PER = max(sum(b[n]*phi_m**n for n in range(4)), 72000.0)
    x = 2*np.pi*(t - 50400.0)/PER
    return F*(5e-9 + (AMP*(1 - x*x/2 + x**4/24) if abs(x) < 1.57 else 0.0))
rows = []
for prn in nav.prns:
    try:
        pos, vel, clk, _ = sat_states(nav, prn, week, np.array([sow - 0.07]))
    except Exception:
        continue
    d = pos[0] - r_u
    if not np.all(np.isfinite(d)):
        continue
    rows.append((prn, d))
out = []
for prn, d in rows:
    u = d/np.linalg.norm(d)
    n_ = Cen.T @ u   # NED
    N, E_, D = n_
    el = np.arcsin(-D); az = np.arctan2(E_, N)
    if el < np.radians(10):
        continue
    ours = float(iono_delay_b3i_m(kl, lat, lon, el, az, sow))
    t_gps = sow + 14.0
    theirs = C*gps_klob(kl.alpha, kl.beta, lat, lon, el, az, t_gps)*(154/124)**2
    out.append((prn, np.degrees(el), np.degrees(az), ours, theirs, u))
G = []; dl = []
for prn, el, az, o, t, u in out:
    print(f"C{prn:02d} el {el:5.1f} az {az:6.1f}  sdr-di {o:6.2f} m  SignalSim {t:6.2f} m  diff {t-o:+.2f} m")
    n_ = Cen.T @ u
    G.append([-n_[1], -n_[0], n_[2], 1.0]); dl.append(t - o)   # E, N, U(= -D) rows: -u_enu
G = np.array(G); dl = np.array(dl)
x = np.linalg.lstsq(G, dl, rcond=None)[0]
print("position error from the model difference (E, N, U, clock) [m]:", np.round(x, 2))
