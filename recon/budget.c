/* budget: systematic components of the DHR's uncertainty and the agreement with a reference. */
#include "recon/budget.h"

#include <math.h>

/* u(ρ)/ρ of the certificate at λ (linear between its points, the nearest end outside). */
static double cert_rel_at(const struct recon_budget_opts *o, double wl)
{
	size_t n = o->ncert, j = 0;
	if (n == 1 || wl <= o->cert_wl[0])
		return o->cert_u[0] / o->cert_rho[0];
	if (wl >= o->cert_wl[n - 1])
		return o->cert_u[n - 1] / o->cert_rho[n - 1];
	while (j + 2 < n && o->cert_wl[j + 1] < wl)
		j++;
	double u = (wl - o->cert_wl[j]) / (o->cert_wl[j + 1] - o->cert_wl[j]);
	return (1 - u) * o->cert_u[j] / o->cert_rho[j] + u * o->cert_u[j + 1] / o->cert_rho[j + 1];
}

int recon_budget(size_t nth, size_t L, const double *wl, const double *dhr, const double *sig,
		 const struct recon_budget_opts *o, double *cert, double *drift, double *wlcal, double *nonlin,
		 double *total, struct acq_err *err)
{
	if (!(o->cert_rel >= 0 && o->cert_rel < 1) || !(o->drift_rel >= 0 && o->drift_rel < 1) ||
	    !(o->wl_cal_nm >= 0 && o->wl_cal_nm < 100) || !(o->nonlin_rel >= 0 && o->nonlin_rel < 1))
		return acq_errf(err, ACQ_E_INVAL, "budget: relative uncertainties must be in [0, 1), the wavelength "
				"calibration in [0, 100) nm");
	for (size_t i = 0; i < o->ncert; i++)
		if (!(o->cert_rho[i] > 0) || !(o->cert_u[i] >= 0) || !isfinite(o->cert_u[i]) || !isfinite(o->cert_wl[i]) ||
		    (i && !(o->cert_wl[i] > o->cert_wl[i - 1])))
			return acq_errf(err, ACQ_E_INVAL, "budget: certificate row %zu: wavelengths increasing, rho > 0, "
					"u >= 0 needed", i + 1);
	for (size_t t = 0; t < nth; t++)
		for (size_t l = 0; l < L; l++) {
			size_t i = t * L + l;
			double d = dhr[i], rel = o->ncert ? cert_rel_at(o, wl[l]) : o->cert_rel;
			/* slope by central differences (one-sided at the ends); 0 with one wavelength */
			size_t a = l > 0 ? l - 1 : l, b = l + 1 < L ? l + 1 : l;
			double slope = b > a ? (dhr[t * L + b] - dhr[t * L + a]) / (wl[b] - wl[a]) : 0.0;
			double c = fabs(d) * rel, dr = fabs(d) * o->drift_rel, w = fabs(slope) * o->wl_cal_nm;
			double nl = fabs(d) * o->nonlin_rel;
			if (cert)
				cert[i] = c;
			if (drift)
				drift[i] = dr;
			if (wlcal)
				wlcal[i] = w;
			if (nonlin)
				nonlin[i] = nl;
			total[i] = sqrt(sig[i] * sig[i] + c * c + dr * dr + w * w + nl * nl);
		}
	return 0;
}

void recon_agreement(size_t n, const double *wl, const double *md, const double *ms, const double *mc,
		     const double *rv, const double *rs, double *z, struct recon_agreement *a)
{
	*a = (struct recon_agreement){ 0 };
	double sz2 = 0, rdr = 0, sds = 0, sdr = 0;
	for (size_t i = 0; i < n; i++) {
		double den = sqrt(ms[i] * ms[i] + rs[i] * rs[i]), r = md[i] - rv[i], zi = den > 0 ? r / den : NAN;
		if (z)
			z[i] = zi;
		if (!isfinite(zi))
			continue;
		a->n++;
		sz2 += zi * zi;
		a->within2 += fabs(zi) <= 2;
		if (fabs(zi) > a->max_z) {
			a->max_z = fabs(zi);
			a->max_z_wl = wl[i];
		}
		/* C = D + s sᵀ, D the independent part (total minus the correlated one, plus the reference's) */
		double c = mc ? fmin(mc[i], ms[i]) : 0, d = ms[i] * ms[i] - c * c + rs[i] * rs[i];
		if (d > 0) {
			rdr += r * r / d;
			sds += c * c / d;
			sdr += c * r / d;
		}
	}
	a->rms_z = a->n ? sqrt(sz2 / (double)a->n) : 0;
	a->chi2_n = a->n ? (rdr - sdr * sdr / (1 + sds)) / (double)a->n : 0;
}
