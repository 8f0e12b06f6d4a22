/* sim_sphere: a simulated laboratory spectrophotometer with an integrating sphere measuring the sample's
 * directional-hemispherical reflectance at 8 deg incidence, specular included (d/8 geometry, the paper's
 * Fig. 4 reference), from the simulator's truth (sim/material.h: mat_dhr at 8 deg, quadrature level 2).
 *
 * Instrument model (a double-beam UV/Vis/NIR spectrophotometer with a 150 mm sphere, detector change from a
 * photomultiplier to InGaAs at 860 nm; values typical of such instruments' specifications):
 *   measured(l) = DHR_8(l) (1 + c(l)) + e(l)
 *   c: the sphere's calibration error against its own white standard, relative, smooth across wavelengths:
 *      a Gaussian process of standard deviation SPHERE_U_CAL = 0.3 % and correlation length 150 nm
 *      (sim_refdrift.h's draw), one draw per instrument seed;
 *   e: noise, independent per wavelength, standard deviation 0.1 % of the value + 1e-4 below 860 nm and
 *      0.2 % + 2e-4 from 860 nm (the InGaAs detector's range).
 * Stated standard uncertainty: sigma(l) = sqrt((0.003 m)^2 + u_e(l)^2) with m the measured value (both parts,
 * the correlated calibration included; a reader who needs the split finds it here). The instrument's
 * bandwidth is taken as negligible (the narrow-lines truth's lines are 2.5-6 nm wide: a 1 nm slit would
 * change their depth by ~1.4 %). The seed selects the calibration draw and the noise. */
#ifndef SIM_SPHERE_H
#define SIM_SPHERE_H

#include <stdint.h>

#include "config/acq_err.h"
#include "sim/material.h"

#define SPHERE_THETA_DEG 8.0
#define SPHERE_U_CAL 0.003
#define SPHERE_CORR_NM 150.0
#define SPHERE_DETECTOR_CHANGE_NM 860.0

/* One simulated measurement of m (instantiated at wl[0..nwl-1]) into val and its stated standard uncertainty
 * into sigma. 0 or -1 with err. */
int sphere_measure(const struct mat *m, int nwl, const double *wl, uint64_t seed, double *val, double *sigma,
		   struct acq_err *err);
/* The same from the truth's DHR at 8 deg already computed (dhr8[nwl]). 0 or -1 with err. */
int sphere_apply(int nwl, const double *wl, const double *dhr8, uint64_t seed, double *val, double *sigma,
		 struct acq_err *err);

#endif
