/* sim_physics: counts of the simulated spectrometer from the world state (model in sim_physics.h). */
#include "sim/sim_physics.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "sim/material.h"

struct phys {
	struct phys_cfg cfg;
	double wl[PHYS_MAX_PIXELS];
	double resp[PHYS_MAX_PIXELS];   /* s(l) QE(l), 0 on the black pixels */
	struct mat *mat[MAT__COUNT];
	double *fbuf;
	double ref_fac[PHYS_MAX_PIXELS]; /* (rho_cert + d) / rho_cert of the white standard */
	double t;                        /* bench time of the next measurement (source drift) */
};

_Static_assert((int)SIM_SAMPLE_NONE == (int)MAT__COUNT, "enum sim_sample lists the materials, then none");

int phys_sample_from_name(const char *name)
{
	if (name && !strcmp(name, "none"))
		return SIM_SAMPLE_NONE;
	return mat_from_name(name);
}

const char *phys_sample_name(int sample)
{
	return sample == SIM_SAMPLE_NONE ? "none" : mat_name((enum mat_id)sample);
}

/* Calibration: pixel PHYS_NDARK at 450 nm, the last pixel at 1100 nm, slight grating curvature. */
static void default_coef(int npix, double c[5])
{
	double p0 = PHYS_NDARK, p1 = npix - 1, c2 = -1.5e-5 * (2047.0 / p1) * (2047.0 / p1);
	memset(c, 0, 5 * sizeof(double));
	c[2] = c2;
	c[1] = (650.0 - c2 * (p1 * p1 - p0 * p0)) / (p1 - p0);
	c[0] = 450.0 - c[1] * p0 - c2 * p0 * p0;
}

void phys_defaults(struct phys_cfg *c)
{
	memset(c, 0, sizeof *c);
	snprintf(c->model, sizeof c->model, "AvaSpec-HS-TEC-SIM");
	snprintf(c->serial, sizeof c->serial, "SIM0001");
	snprintf(c->firmware, sizeof c->firmware, "acq-sim 1");
	c->npix = 2048;
	default_coef(c->npix, c->wl_coef);
	c->temperature_c = 5.0;
	c->beam_counts_per_ms = 3.0e6;
	c->dark_cps_25c = 2000.0;
	c->dark_doubling_c = 6.0;
	c->bias_counts = 1500.0;
	c->read_noise_counts = 8.0;
	c->electrons_per_count = 2.0;
	c->nonlinearity = 0.05;
	refdrift_defaults(&c->cal);
}

int phys_parse(struct yc_node *node, struct phys_cfg *out, struct acq_err *err)
{
	struct phys_cfg c = *out;
	if (yc_expect_map(node, "sim.spectrometer", err))
		return -1;
	long long npix = c.npix;
	const char *model = NULL, *serial = NULL;
	if (yc_int(node, "pixels", false, 64, PHYS_MAX_PIXELS, &npix, err) ||
	    yc_string(node, "model", false, &model, err) || yc_string(node, "serial", false, &serial, err) ||
	    yc_double(node, "temperature_c", false, -40, 80, &c.temperature_c, err) ||
	    yc_double(node, "beam_counts_per_ms", false, 1e-3, 1e12, &c.beam_counts_per_ms, err) ||
	    yc_double(node, "dark_cps_25c", false, 0, 1e7, &c.dark_cps_25c, err) ||
	    yc_double(node, "dark_doubling_c", false, 1, 50, &c.dark_doubling_c, err) ||
	    yc_double(node, "bias_counts", false, 0, 20000, &c.bias_counts, err) ||
	    yc_double(node, "read_noise_counts", false, 0, 1000, &c.read_noise_counts, err) ||
	    yc_double(node, "electrons_per_count", false, 0.01, 1000, &c.electrons_per_count, err) ||
	    yc_double(node, "nonlinearity", false, 0, 0.5, &c.nonlinearity, err))
		return -1;
	if (model)
		snprintf(c.model, sizeof c.model, "%s", model);
	if (serial)
		snprintf(c.serial, sizeof c.serial, "%s", serial);
	if (npix != c.npix) {
		c.npix = (int)npix;
		default_coef(c.npix, c.wl_coef);
	}
	if (yc_check_unknown(node, "sim.spectrometer", err))
		return -1;
	*out = c;
	return 0;
}

double phys_wavelength(const struct phys_cfg *c, int pixel)
{
	double p = pixel, v = 0;
	for (int i = 4; i >= 0; i--)
		v = v * p + c->wl_coef[i];
	return v;
}

void phys_nonlin_coef(const struct phys_cfg *c, double coef[8])
{
	memset(coef, 0, 8 * sizeof(double));
	coef[0] = 1.0;
	coef[1] = -c->nonlinearity / PHYS_FULL_SCALE;
}

double phys_dark_cps(const struct phys_cfg *c, double t)
{
	return c->dark_cps_25c * exp2((t - 25.0) / c->dark_doubling_c);
}

/* Supercontinuum: blue edge rising near 520 nm, slow decline into the NIR, residual pump line at 1064 nm. */
static double laser_spectrum(double wl)
{
	double edge = 0.35 + 0.65 / (1.0 + exp(-(wl - 520.0) / 30.0));
	double pump = (wl - 1064.0) / 4.0;
	return edge * (1.0 - 0.25 * (wl - 450.0) / 650.0) + 1.2 * exp(-0.5 * pump * pump);
}

/* Silicon-like quantum efficiency (times optics throughput). */
static double detector_qe(double wl)
{
	double x = (wl - 650.0) / 350.0;
	return 0.85 * exp(-x * x * x * x);
}

struct phys *phys_new(const struct phys_cfg *c, struct acq_err *err)
{
	if (c->npix < 64 || c->npix > PHYS_MAX_PIXELS) {
		acq_errf(err, ACQ_E_CONFIG, "sim.spectrometer: pixel count %d outside [64, %d]", c->npix, PHYS_MAX_PIXELS);
		return NULL;
	}
	struct phys *p = calloc(1, sizeof *p);
	if (!p || !(p->fbuf = malloc(sizeof(double) * (size_t)c->npix))) {
		free(p);
		acq_errf(err, ACQ_E_NOMEM, "sim spectrometer: out of memory");
		return NULL;
	}
	p->cfg = *c;
	for (int i = 0; i < c->npix; i++) {
		p->wl[i] = phys_wavelength(c, i);
		p->resp[i] = i < PHYS_NDARK ? 0.0 : laser_spectrum(p->wl[i]) * detector_qe(p->wl[i]);
	}
	for (int m = 0; m < MAT__COUNT; m++) {
		if (m == MAT_MERL && !c->merl_file[0])
			continue;
		p->mat[m] = m == MAT_MERL ? mat_new_merl(c->merl_file, c->npix, p->wl, err) :
					    mat_new((enum mat_id)m, c->npix, p->wl, err);
		if (!p->mat[m]) {
			if (m == MAT_MERL)
				acq_err_prefix(err, "sim.merl_file: ");
			phys_free(p);
			return NULL;
		}
	}
	if (refdrift_reference(&c->cal, c->npix, p->wl, p->ref_fac, err)) {
		phys_free(p);
		return NULL;
	}
	for (int i = 0; i < c->npix; i++)
		p->ref_fac[i] = 1.0 + p->ref_fac[i] / mat_rho_d(MAT_WHITE, p->wl[i]);
	return p;
}

void phys_free(struct phys *p)
{
	if (!p)
		return;
	for (int m = 0; m < MAT__COUNT; m++)
		mat_free(p->mat[m]);
	free(p->fbuf);
	free(p);
}

const struct phys_cfg *phys_config(const struct phys *p)
{
	return &p->cfg;
}

void phys_set_time(struct phys *p, double t)
{
	p->t = t;
}

double phys_reference_factor(const struct phys *p, int pixel)
{
	return pixel >= 0 && pixel < p->cfg.npix ? p->ref_fac[pixel] : 1.0;
}

/* The source's drift factor at the current bench time for pixel i. */
static double drift(const struct phys *p, int i)
{
	return refdrift_source(&p->cfg.cal, p->t, p->wl[i]);
}

static double deg(double d)
{
	return d * M_PI / 180.0;
}

static double angle_between(const double a[3], const double b[3])
{
	double c = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
	double x[3] = { a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0] };
	return atan2(sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]), c) * 180.0 / M_PI;
}

unsigned phys_signal(const struct phys *p, const struct sim_world *w, double *rate)
{
	const struct bench_geom *g = &w->geom;
	int npix = p->cfg.npix;
	double wi[3], wo[3];
	mat_dir(deg(w->laser_theta_deg), deg(g->laser_phi_deg), wi);
	mat_dir(deg(w->detector_theta_deg), deg(w->detector_phi_deg), wo);
	double gamma = angle_between(wi, wo);
	unsigned occ = 0;
	if (gamma < g->detector_body_halfwidth_deg + g->beam_halfwidth_deg)
		occ |= PHYS_OCC_DETECTOR_IN_BEAM;
	if (gamma < g->laser_body_halfwidth_deg + g->fov_halfwidth_deg)
		occ |= PHYS_OCC_LASER_HIDES_VIEW;
	/* an open interlock or a laser fault stops emission whatever the laser service reports */
	bool emits = w->laser_emission && !w->faults.laser_interlock_open && !w->faults.laser_fault;
	double power = emits ? w->laser_power_pct / 100.0 : 0.0;
	if (!(power > 0) || occ) {
		memset(rate, 0, sizeof(double) * (size_t)npix);
		return occ;
	}
	double k = p->cfg.beam_counts_per_ms * power;
	if (w->sample == SIM_SAMPLE_NONE) {
		/* the detector looks through the empty holder at the beam going on along -wi */
		double away[3] = { -wi[0], -wi[1], -wi[2] };
		double delta = angle_between(wo, away), fov = g->fov_halfwidth_deg, beam = g->beam_halfwidth_deg;
		double frac;
		if (beam <= 0)
			frac = delta <= fov ? 1.0 : 0.0;
		else
			frac = fmin(1.0, fmax(0.0, (fov + beam - delta) / (2.0 * beam)));
		for (int i = 0; i < npix; i++)
			rate[i] = k * p->resp[i] * frac * drift(p, i);
		return occ;
	}
	double omega = 2.0 * M_PI * (1.0 - cos(deg(g->fov_halfwidth_deg)));
	int m = w->sample >= 0 && w->sample < MAT__COUNT ? w->sample : MAT_WHITE;
	if (!p->mat[m]) { /* the MERL material without a file: nothing on the stage reflects */
		memset(rate, 0, sizeof(double) * (size_t)npix);
		return occ;
	}
	mat_eval(p->mat[m], wi, wo, p->fbuf);
	double geo = k * omega * fmax(0.0, wo[2]);
	for (int i = 0; i < npix; i++)
		rate[i] = geo * p->resp[i] * p->fbuf[i] * drift(p, i) * (m == MAT_WHITE ? p->ref_fac[i] : 1.0);
	return occ;
}

static double nonlin(double x, double b)
{
	return x <= 0 ? x : x / (1.0 + b * x / PHYS_FULL_SCALE);
}

static double adc(double x, double b)
{
	if (x > 1.08 * PHYS_FULL_SCALE) /* beyond full well */
		return PHYS_FULL_SCALE;
	double r = nearbyint(nonlin(x, b));
	return r < 0 ? 0 : r > PHYS_FULL_SCALE ? PHYS_FULL_SCALE : r;
}

int phys_measure(const struct phys *p, const struct sim_world *w, double integration_ms, unsigned averages,
		 double gain_boost, struct sim_rng *rng, struct phys_frame *f, struct acq_err *err)
{
	if (!(integration_ms > 0 && integration_ms <= 600000.0))
		return acq_errf(err, ACQ_E_RANGE, "integration time %g ms outside (0, 600000]", integration_ms);
	if (averages < 1 || averages > 100000)
		return acq_errf(err, ACQ_E_RANGE, "averages %u outside [1, 100000]", averages);
	const struct phys_cfg *c = &p->cfg;
	int npix = c->npix;
	double *rate = malloc(sizeof(double) * (size_t)npix);
	if (!rate)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	f->npix = npix;
	f->occlusion = phys_signal(p, w, rate);
	f->nsat = 0;
	double dark = phys_dark_cps(c, w->sensor_temp_c) * integration_ms * 1e-3;
	double b = c->nonlinearity, rn2 = c->read_noise_counts * c->read_noise_counts;
	for (int i = 0; i < npix; i++) {
		double e = c->bias_counts + dark + rate[i] * integration_ms * gain_boost;
		if (gain_boost > 1 && i >= PHYS_NDARK)
			e += 1.1 * PHYS_FULL_SCALE; /* a burst of stray light saturates every illuminated pixel */
		double sd = sqrt(fmax(0.0, e - c->bias_counts) / c->electrons_per_count + rn2);
		double sum = 0, sum2 = 0;
		bool sat = false;
		if (averages <= 100) {
			for (unsigned a = 0; a < averages; a++) {
				double r = adc(e + sd * sim_rng_gauss(rng), b);
				sat |= r >= PHYS_SATURATED;
				sum += r;
				sum2 += r * r;
			}
			double mean = sum / averages;
			f->counts[i] = mean;
			f->std[i] = averages > 1 ? (float)sqrt(fmax(0.0, (sum2 - sum * mean) / (averages - 1))) : 0.0f;
		} else {
			/* many scans: the mean and the standard deviation from their sampling distributions */
			double x = e + sd / sqrt((double)averages) * sim_rng_gauss(rng);
			double r = adc(x, b), slope = r >= PHYS_FULL_SCALE ? 0.0 : 1.0 / pow(1.0 + b * x / PHYS_FULL_SCALE, 2);
			sat = adc(e + 3.0 * sd, b) >= PHYS_SATURATED && r >= PHYS_SATURATED - 3.0 * sd * slope;
			f->counts[i] = x > 1.08 * PHYS_FULL_SCALE ? PHYS_FULL_SCALE : fmin(PHYS_FULL_SCALE, fmax(0.0, nonlin(x, b)));
			double s = sd * slope * (1.0 + sim_rng_gauss(rng) / sqrt(2.0 * (averages - 1)));
			f->std[i] = (float)fmax(0.0, s);
		}
		f->sat[i] = sat;
		f->nsat += sat;
	}
	free(rate);
	return 0;
}
