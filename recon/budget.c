/* budget: systematic components of the DHR's uncertainty and the agreement with a reference. */
#include "recon/budget.h"

#include <lapacke.h>
#include <math.h>
#include <stdlib.h>

/* Where at falls among x[n] (increasing): the lower point *j and the weight of x[*j + 1] (linear between points;
 * the nearest end outside, weight 0). */
static double bracket(const double *x, size_t n, double at, size_t *j)
{
	*j = 0;
	if (n == 1 || at <= x[0])
		return 0.0;
	if (at >= x[n - 1]) {
		*j = n - 1;
		return 0.0;
	}
	while (*j + 2 < n && x[*j + 1] < at)
		(*j)++;
	return (at - x[*j]) / (x[*j + 1] - x[*j]);
}

/* u(ρ)/ρ of the certificate at λ (linear between its points, the nearest end outside). */
static double cert_rel_at(const struct recon_budget_opts *o, double wl)
{
	size_t j;
	double u = bracket(o->cert_wl, o->ncert, wl, &j), r = o->cert_u[j] / o->cert_rho[j];
	return u > 0 ? (1 - u) * r + u * o->cert_u[j + 1] / o->cert_rho[j + 1] : r;
}

/* u_rel of the reference's noise at λ (linear between its points, the nearest end outside); 0 without a table. */
static double refn_rel_at(const struct recon_budget_opts *o, double wl)
{
	if (o->nrefn == 0)
		return 0.0;
	size_t j;
	double u = bracket(o->refn_wl, o->nrefn, wl, &j);
	return u > 0 ? (1 - u) * o->refn_u[j] + u * o->refn_u[j + 1] : o->refn_u[j];
}

int recon_budget(size_t nth, size_t L, const double *wl, const double *dhr, const double *sig,
		 const struct recon_budget_opts *o, double *cert, double *drift, double *wlcal, double *nonlin,
		 double *refnoise, double *total, struct acq_err *err)
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
	for (size_t i = 0; i < o->nrefn; i++)
		if (!(o->refn_u[i] >= 0 && o->refn_u[i] < 1) || !isfinite(o->refn_wl[i]) ||
		    (i && !(o->refn_wl[i] > o->refn_wl[i - 1])))
			return acq_errf(err, ACQ_E_INVAL, "budget: reference noise row %zu: wavelengths increasing, "
					"u_rel in [0, 1) needed", i + 1);
	for (size_t t = 0; t < nth; t++)
		for (size_t l = 0; l < L; l++) {
			size_t i = t * L + l;
			double d = dhr[i], rel = o->ncert ? cert_rel_at(o, wl[l]) : o->cert_rel;
			/* slope by central differences (one-sided at the ends); 0 with one wavelength */
			size_t a = l > 0 ? l - 1 : l, b = l + 1 < L ? l + 1 : l;
			double slope = b > a ? (dhr[t * L + b] - dhr[t * L + a]) / (wl[b] - wl[a]) : 0.0;
			double c = fabs(d) * rel, dr = fabs(d) * o->drift_rel, w = fabs(slope) * o->wl_cal_nm;
			double nl = fabs(d) * o->nonlin_rel, rn = fabs(d) * refn_rel_at(o, wl[l]);
			if (cert)
				cert[i] = c;
			if (drift)
				drift[i] = dr;
			if (wlcal)
				wlcal[i] = w;
			if (nonlin)
				nonlin[i] = nl;
			if (refnoise)
				refnoise[i] = rn;
			total[i] = sqrt(sig[i] * sig[i] + c * c + dr * dr + w * w + nl * nl + rn * rn);
		}
	return 0;
}

/* P(χ²_k ≥ x), the upper tail of the χ² distribution with k degrees of freedom, by the Wilson–Hilferty cube-root
 * normal approximation (absolute error < 1e-3 for k ≥ 10, the reference comparisons have 60–650). */
static double chi2_upper(double x, size_t k)
{
	if (k == 0)
		return 1.0;
	double v = 2.0 / (9.0 * (double)k), t = (cbrt(x / (double)k) - (1.0 - v)) / sqrt(v);
	return 0.5 * erfc(t / sqrt(2.0));
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
	a->chi2_p = chi2_upper(a->chi2_n * (double)a->n, a->n);
}

int recon_agreement_ref(size_t n, const double *wl, const double *md, const double *ms, const double *mc,
			const double *rv, const double *rs, double ref_u, double ref_len_nm,
			const struct recon_ref_interp *ip, double *z, struct recon_agreement *a, struct acq_err *err)
{
	recon_agreement(n, wl, md, ms, mc, rv, rs, z, a);
	if ((!(ref_u > 0) && !ip) || a->n == 0)
		return 0;
	if (!(ref_u >= 0 && ref_u < 1) || !(ref_len_nm > 0) || !isfinite(ref_len_nm))
		return acq_errf(err, ACQ_E_INVAL, "agreement: the reference's correlated part needs u in (0, 1) and a "
				"correlation length > 0 nm");
	size_t *ix = malloc(n * sizeof *ix), m = 0;
	for (size_t i = 0; ix && i < n; i++) /* the wavelengths with a finite z, as counted above */
		if (ms[i] > 0 || rs[i] > 0)
			if (isfinite(md[i] - rv[i]))
				ix[m++] = i;
	double *C = ix ? malloc(m * m * sizeof *C) : NULL, *r = ix ? malloc(m * sizeof *r) : NULL;
	if (!ix || !C || !r) {
		free(ix);
		free(C);
		free(r);
		return acq_errf(err, ACQ_E_NOMEM, "agreement: out of memory");
	}
	double inv2l2 = 0.5 / (ref_len_nm * ref_len_nm);
	for (size_t p = 0; p < m; p++) {
		size_t i = ix[p];
		double ci = mc ? fmin(mc[i], ms[i]) : 0, ui = ref_u * fabs(rv[i]);
		r[p] = md[i] - rv[i];
		for (size_t q = 0; q <= p; q++) {
			size_t j = ix[q];
			double cj = mc ? fmin(mc[j], ms[j]) : 0, uj = ref_u * fabs(rv[j]), dl = wl[i] - wl[j];
			C[q * m + p] = ci * cj + ui * uj * exp(-dl * dl * inv2l2);
			if (ip) { /* the model's independent node errors through the interpolation */
				size_t a0 = ip->j[i], b0 = ip->j[j];
				for (size_t da = 0; da < 2; da++)
					for (size_t db = 0; db < 2; db++)
						if (a0 + da == b0 + db && a0 + da < ip->L) {
							double wa = da ? ip->u[i] : 1 - ip->u[i], wb = db ? ip->u[j] : 1 - ip->u[j];
							C[q * m + p] += wa * wb * ip->node_sig[a0 + da] * ip->node_sig[a0 + da];
						}
			}
		}
		/* the independent parts: the model's σ without its common factor (unless propagated above), the
		 * reference's without its calibration (its stated σ holds both; never below zero) */
		C[p * m + p] += (ip ? ip->interp_sig[i] * ip->interp_sig[i] : fmax(0.0, ms[i] * ms[i] - ci * ci)) +
				fmax(0.0, rs[i] * rs[i] - ui * ui);
	}
	int rc = 0;
	if (LAPACKE_dpotrf(LAPACK_COL_MAJOR, 'L', (lapack_int)m, C, (lapack_int)m) != 0 ||
	    LAPACKE_dtrtrs(LAPACK_COL_MAJOR, 'L', 'N', 'N', (lapack_int)m, 1, C, (lapack_int)m, r, (lapack_int)m) != 0) {
		rc = acq_errf(err, ACQ_E_NUMERIC, "agreement: the combined covariance is not positive definite (a "
			      "reference σ smaller than its stated calibration part?)");
	} else {
		double chi2 = 0;
		for (size_t p = 0; p < m; p++)
			chi2 += r[p] * r[p];
		a->chi2_n = chi2 / (double)m;
		a->chi2_p = chi2_upper(chi2, m);
		a->ref_corr = ref_u > 0;
	}
	free(ix);
	free(C);
	free(r);
	return rc;
}
