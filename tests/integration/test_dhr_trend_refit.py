#!/usr/bin/python3
"""The DHR's noise term covers the trend's own noise (recon/dhr.c refit_trend; issue 13 item 3).

The trend (the lobe family of recon/trend.c) is fitted to the same noisy samples as the interpolant, so from one
noise draw to the next its coefficients move, and with them the lobe's share of the DHR. The Monte-Carlo σ_noise
of `brdf-recon dhr` refits the coefficients in every draw. On the simulator's sharp lobe (a Phong lobe of n = 250,
narrower than the 8 deg incidence step near the normal) the spread of the DHR over independent noise seeds at
8 deg was 1.27x the σ_noise of draws that held the trend fixed (8 seeds x 66 wavelengths: 7.0e-4 against 5.5e-4),
and is 1.0x with the refit.

Test: NSEED = 20 noise seeds (from ACQ_SEED) of `acq-sim truth sharp-lobe` on the paper's 10 x 10 x 10 plan, 1 %
noise, 14 wavelengths; fit; dhr at 8 and 30 deg. ratio = RMS over wavelengths and both incidences of the standard
deviation over seeds of the DHR / RMS of sigma_noise. It must lie in [0.75, 1.15]. Measured: 0.99 and 1.06
(ACQ_SEED 1, 2; 8 deg alone over 16 seeds 0.95-1.10 for ACQ_SEED 1-4); with the refit removed 1.23 (ACQ_SEED 1:
fails); a sigma_noise twice too large gives 0.5 (fails). Also z = (DHR - truth) / sigma: RMS in [0.6, 1.4]
(measured 0.97-1.07)."""
import os
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from recon_tools import SEED, sim_fit_dhr, sim_truth_dhr  # noqa: E402

NSEED = 20
WL = "450:1100:50"


def main():
    print("ACQ_SEED=%d" % SEED)
    with tempfile.TemporaryDirectory(prefix="test_dhr_refit_") as d:
        truth = sim_truth_dhr(d, "sharp-lobe", WL, (8, 30))[:, 2]
        dhr, sig, sn = [], [], []
        for i in range(NSEED):
            s = SEED * NSEED + i + 1
            _, c, A = sim_fit_dhr(d, "sharp-lobe", s, WL, (8, 30))
            dhr.append(A[:, c["dhr"]])
            sig.append(A[:, c["sigma"]])
            sn.append(A[:, c["sigma_noise"]])
        dhr, sig, sn = np.array(dhr), np.array(sig), np.array(sn)
        spread = np.sqrt(np.mean(np.std(dhr, axis=0, ddof=1) ** 2))
        mc = np.sqrt(np.mean(sn ** 2))
        ratio = spread / mc
        z = (dhr - truth) / sig
        zr = np.sqrt(np.mean(z ** 2))
        print("sharp-lobe 8 and 30 deg, %d seeds: DHR spread over seeds %.3g, sigma_noise %.3g, ratio %.2f; z RMS %.2f"
              % (NSEED, spread, mc, ratio, zr))
        ok = True
        if not 0.75 <= ratio <= 1.15:
            print("FAIL: the noise term does not match the spread over seeds (ratio %.2f not in [0.75, 1.15])" % ratio)
            ok = False
        if not 0.6 <= zr <= 1.4:
            print("FAIL: z RMS %.2f against the truth not in [0.6, 1.4]" % zr)
            ok = False
        return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
