/* sim_truthcli: `acq-sim truth`, the command line of the ground-truth export (sim/sim_truth.h): a material's DHR,
 * its value at given directions, noisy samples on a grid, its MERL table, a simulated spectrophotometer reading. */
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "config/acq_num.h"
#include "sim/sim.h"
#include "sim/sim_sphere.h"
#include "sim/sim_truth.h"

static void truth_usage(FILE *f)
{
	fprintf(f,
		"usage: acq-sim truth MATERIAL ACTION [options]\n"
		"  MATERIAL: green-paint (or paint) | white | metal | clear-coat | rough-backscatter | cloth-sheen |\n"
		"            sharp-lobe | narrow-lines | merl:FILE (a MERL binary table, upsampled to spectra: sim/material.h)\n"
		"  actions (exactly one):\n"
		"    --dhr OUT.csv [--theta-i 8,30,60]    columns theta_i,wavelength_nm,dhr,sigma (sigma: quadrature bound)\n"
		"    --eval QUERIES.csv [-o OUT.csv]      f at the rows' theta_i,phi_i,theta_o,phi_o (degrees), 1/sr\n"
		"    --grid NIxNOxNP -o SAMPLES.csv       noisy samples: NI incidences, NO observation zeniths in (0, 80),\n"
		"          [--noise REL] [--noise-floor ABS] [--seed N] [--keep-blind]   NP azimuths; sigma_<nm> columns\n"
		"          [--reference U[,CORR_NM[,SEED]]]  calibrated against a white standard whose reflectance differs\n"
		"                                            from its certificate by a smooth deviation of std U\n"
		"          [--drift AMP[,PERIOD_S[,SEED]]] [--point-time S]  source drift (rms AMP) between the reference\n"
		"                                            (bench time 0) and sample k (time k S, default 20 s)\n"
		"          (both as acq-sim's sim.reference_standard / sim.source_drift: sim/sim_refdrift.h; off by default)\n"
		"    --merl OUT.binary                    MERL table, linear sRGB in 1/sr (D65, Bradford; recon/colour.h)\n"
		"    --spectrophotometer [-o OUT.csv] [--seed N]   a simulated d/8 integrating-sphere measurement of the DHR\n"
		"                                         at 8 deg with its own noise and stated uncertainty (sim/sim_sphere.h):\n"
		"                                         columns wavelength_nm,dhr,sigma (brdf-recon dhr --reference)\n"
		"  --wavelengths A:B:STEP   spectral sampling in nm within 450..1100 (default 450:1100:1)\n"
		"  --level N                DHR quadrature level 0..5 (default 2)\n");
}

/* "A[,B[,C]]" into a (required), b, c (kept when absent); c an integer. 0 or -1. */
static int parse_triple(const char *s, double *a, double *b, uint64_t *c)
{
	char *end;
	*a = strtod(s, &end);
	if (end == s || !isfinite(*a))
		return -1;
	if (*end == ',') {
		const char *q = end + 1;
		*b = strtod(q, &end);
		if (end == q || !isfinite(*b))
			return -1;
		if (*end == ',') {
			q = end + 1;
			errno = 0;
			*c = strtoull(q, &end, 10);
			if (end == q || errno || *q == '-')
				return -1;
		}
	}
	return *end ? -1 : 0;
}

/* Open path for writing ("-": standard output); NULL with a message. */
static FILE *truth_open(const char *path)
{
	FILE *f = strcmp(path, "-") ? fopen(path, "w") : stdout;
	if (!f)
		fprintf(stderr, "acq-sim truth: %s: %s\n", path, strerror(errno));
	return f;
}

/* Close f (not standard output); on failure (rc != 0 or a close error) remove the half-written file. */
static int truth_close(FILE *f, const char *path, int rc)
{
	if (f != stdout) {
		if (fclose(f) && !rc) {
			fprintf(stderr, "acq-sim truth: %s: %s\n", path, strerror(errno));
			rc = 1;
		}
		if (rc)
			unlink(path);
	} else if (fflush(stdout) && !rc) {
		rc = 1;
	}
	return rc;
}

/* What one `acq-sim truth` invocation asked for (truth_parse). */
struct truth_args {
	const char *material, *merl_file; /* merl_file: the FILE of merl:FILE, else NULL */
	int id;                           /* enum mat_id */
	const char *dhr, *eval, *grid, *merl, *out, *thetas, *wls;
	bool sphere;
	long level;
	struct truth_grid g;
	int nact; /* actions given */
};

/* One option c (with its argument arg) into a: -1 to go on, or the exit status (help; a bad value, reported). */
static int truth_option(int c, char *arg, struct truth_args *a)
{
	struct truth_grid *g = &a->g;
	char *end = NULL;
	switch (c) {
	case 'd': a->dhr = arg; a->nact++; break;
	case 'e': a->eval = arg; a->nact++; break;
	case 'g': a->grid = arg; a->nact++; break;
	case 'm': a->merl = arg; a->nact++; break;
	case 'S': a->sphere = true; a->nact++; break;
	case 't': a->thetas = arg; break;
	case 'w': a->wls = arg; break;
	case 'o': a->out = arg; break;
	case 'k': g->keep_blind = true; break;
	case 'n':
	case 'f': {
		double v;
		if (acq_num_parse(arg, 0, 10, &v)) {
			fprintf(stderr, "acq-sim truth: --%s: expected a number in [0, 10], got '%s'\n",
				c == 'n' ? "noise" : "noise-floor", arg);
			return 2;
		}
		*(c == 'n' ? &g->rel : &g->floor_) = v;
		break;
	}
	case 's':
		errno = 0;
		g->seed = strtoull(arg, &end, 10);
		if (end == arg || *end || errno || arg[0] == '-') {
			fprintf(stderr, "acq-sim truth: --seed: expected a non-negative integer, got '%s'\n", arg);
			return 2;
		}
		break;
	case 'L':
		a->level = strtol(arg, &end, 10);
		if (end == arg || *end || a->level < 0 || a->level > 5) {
			fprintf(stderr, "acq-sim truth: --level: expected 0..5, got '%s'\n", arg);
			return 2;
		}
		break;
	case 'R':
		if (parse_triple(arg, &g->cal.ref_u, &g->cal.ref_corr_nm, &g->cal.ref_seed) ||
		    !(g->cal.ref_u >= 0 && g->cal.ref_u <= 0.1) || !(g->cal.ref_corr_nm >= 5 && g->cal.ref_corr_nm <= 10000)) {
			fprintf(stderr, "acq-sim truth: --reference: expected U[,CORR_NM[,SEED]] with U in [0, 0.1], "
					"CORR_NM in [5, 10000], got '%s'\n", arg);
			return 2;
		}
		break;
	case 'D':
		if (parse_triple(arg, &g->cal.drift_amp, &g->cal.drift_period_s, &g->cal.drift_seed) ||
		    !(g->cal.drift_amp >= 0 && g->cal.drift_amp <= 0.05) ||
		    !(g->cal.drift_period_s >= 1 && g->cal.drift_period_s <= 1e7)) {
			fprintf(stderr, "acq-sim truth: --drift: expected AMP[,PERIOD_S[,SEED]] with AMP in [0, 0.05], "
					"PERIOD_S in [1, 1e7], got '%s'\n", arg);
			return 2;
		}
		break;
	case 'P':
		if (acq_num_parse(arg, 0, 1e6, &g->point_s)) {
			fprintf(stderr, "acq-sim truth: --point-time: expected seconds in [0, 1e6], got '%s'\n", arg);
			return 2;
		}
		break;
	case 'h': truth_usage(stdout); return 0;
	default: truth_usage(stderr); return 2;
	}
	return -1;
}

/* MATERIAL and the options into a (defaults first): -1 to go on, or the exit status (help, a usage error). */
static int truth_parse(int argc, char **argv, struct truth_args *a)
{
	*a = (struct truth_args){ .thetas = "8,30,60", .wls = "450:1100:1", .level = 2,
				  .g = { .rel = 0.01, .seed = 1, .point_s = 20 } };
	refdrift_defaults(&a->g.cal);
	static const struct option opts[] = {
		{ "dhr", required_argument, NULL, 'd' },      { "eval", required_argument, NULL, 'e' },
		{ "grid", required_argument, NULL, 'g' },     { "merl", required_argument, NULL, 'm' },
		{ "theta-i", required_argument, NULL, 't' },  { "wavelengths", required_argument, NULL, 'w' },
		{ "noise", required_argument, NULL, 'n' },    { "noise-floor", required_argument, NULL, 'f' },
		{ "seed", required_argument, NULL, 's' },     { "keep-blind", no_argument, NULL, 'k' },
		{ "level", required_argument, NULL, 'L' },    { "output", required_argument, NULL, 'o' },
		{ "reference", required_argument, NULL, 'R' }, { "drift", required_argument, NULL, 'D' },
		{ "point-time", required_argument, NULL, 'P' }, { "spectrophotometer", no_argument, NULL, 'S' },
		{ "help", no_argument, NULL, 'h' },           { NULL, 0, NULL, 0 },
	};
	if (argc < 2 || !strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")) {
		truth_usage(argc < 2 ? stderr : stdout);
		return argc < 2 ? 2 : 0;
	}
	a->material = argv[1];
	a->id = mat_from_name(a->material);
	if (!strncmp(a->material, "merl:", 5) && a->material[5]) {
		a->id = MAT_MERL;
		a->merl_file = a->material + 5;
	}
	if (a->id < 0 || (a->id == MAT_MERL && !a->merl_file)) {
		fprintf(stderr, "acq-sim truth: unknown material '%s' (expected %s, or merl:FILE)\n", a->material,
			mat_names_list());
		return 2;
	}
	/* options after MATERIAL: parse argv + 1 from its index 1; optind = 0 re-initialises getopt */
	optind = 0;
	int c, rc, oargc = argc - 1;
	char **oargv = argv + 1;
	while ((c = getopt_long(oargc, oargv, "o:h", opts, NULL)) != -1)
		if ((rc = truth_option(c, optarg, a)) >= 0)
			return rc;
	if (optind < oargc) {
		fprintf(stderr, "acq-sim truth: unexpected argument '%s'\n", oargv[optind]);
		return 2;
	}
	if (a->nact != 1) {
		fprintf(stderr, "acq-sim truth: give exactly one of --dhr, --eval, --grid, --merl, --spectrophotometer\n");
		return 2;
	}
	if (a->grid && !a->out) {
		fprintf(stderr, "acq-sim truth: --grid needs -o SAMPLES.csv (or -o - for standard output)\n");
		return 2;
	}
	return -1;
}

/* --merl: the table to a->merl, the colour decisions on stderr. The exit status. */
static int truth_merl(const struct truth_args *a, const struct mat *m, const double *wl, int nwl)
{
	struct acq_err err = { 0 };
	struct colour_opts o;
	struct colour_stats st;
	if (truth_write_merl(a->merl, m, wl, nwl, &o, &st, &err)) {
		fprintf(stderr, "acq-sim truth: --merl: %s\n", err.msg);
		return 1;
	}
	fprintf(stderr, "acq-sim truth: MERL table written to %s; colour decisions: ", a->merl);
	colour_opts_write_json(stderr, &o, &st, NULL);
	fputc('\n', stderr);
	return 0;
}

/* --dhr, --eval, --grid or --spectrophotometer: the CSV to its file (or standard output), a summary on stderr.
 * The exit status. */
static int truth_table(const struct truth_args *a, const struct mat *m, const double *th, int nth, const double *wl,
		       int nwl)
{
	const char *path = a->dhr ? a->dhr : a->out ? a->out : "-";
	FILE *f = truth_open(path);
	if (!f)
		return 1;
	struct acq_err err = { 0 };
	int rc, rows = 0, dropped = 0;
	if (a->dhr)
		rc = truth_write_dhr(f, m, th, nth, (int)a->level, wl, nwl, &err);
	else if (a->eval)
		rc = truth_write_eval(f, m, a->eval, wl, nwl, &err);
	else if (a->grid)
		rc = truth_write_grid(f, m, &a->g, wl, nwl, &rows, &dropped, &err);
	else
		rc = truth_write_sphere(f, m, a->g.seed, wl, nwl, &err);
	if (rc)
		fprintf(stderr, "acq-sim truth: %s\n", err.msg);
	else if (a->grid)
		fprintf(stderr, "acq-sim truth: %d samples written, %d in blind zones dropped\n", rows, dropped);
	else if (a->sphere)
		fprintf(stderr, "acq-sim truth: spectrophotometer (d/8 sphere, seed %llu): DHR at %g deg, stated sigma "
				"= calibration %.1f %% (correlated over %g nm) + noise (sim/sim_sphere.h)\n",
			(unsigned long long)a->g.seed, SPHERE_THETA_DEG, 100 * SPHERE_U_CAL, SPHERE_CORR_NM);
	return truth_close(f, path, rc ? 1 : 0);
}

int simtruth_main(int argc, char **argv)
{
	struct truth_args a;
	int rc = truth_parse(argc, argv, &a);
	if (rc >= 0)
		return rc;
	struct acq_err err = { 0 };
	double th[TRUTH_MAX_THETAS], *wl = NULL;
	int nth = 0, nwl = 0;
	if (truth_wavelengths(a.wls, &wl, &nwl, &err) || (a.dhr && truth_thetas(a.thetas, th, &nth, &err)) ||
	    (a.grid && truth_grid_size(a.grid, &a.g, &err))) {
		fprintf(stderr, "acq-sim truth: %s\n", err.msg);
		free(wl);
		return 2;
	}
	struct mat *m = a.merl_file ? mat_new_merl(a.merl_file, nwl, wl, &err)
				    : mat_new((enum mat_id)a.id, nwl, wl, &err);
	if (!m)
		fprintf(stderr, "acq-sim truth: %s\n", err.msg);
	rc = !m ? 1 : a.merl ? truth_merl(&a, m, wl, nwl) : truth_table(&a, m, th, nth, wl, nwl);
	mat_free(m);
	free(wl);
	return rc;
}
