/* brdf-recon select: the next batch of an adaptive sweep (recon/select.c), as JSON for the daemon. */
#include <getopt.h>
#include <malloc.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "recon/brdf_recon/cli.h"
#include "recon/csvio.h"
#include "recon/recon.h"
#include "recon/select.h"

static const char select_help[] =
	"usage: brdf-recon select MODEL --candidates CAND.csv --target SPEC [--batch N] [-o OUT.json]\n"
	"Choose the next measurements: a greedy batch maximising the expected reduction of the target's variance per\n"
	"second of bench time under the model's Gaussian-process reading (rank-one update between picks).\n"
	"  --candidates CAND.csv  header id,theta_i,phi_i,theta_o,phi_o,cost_s (degrees, sample frame; cost_s > 0:\n"
	"                         bench seconds to measure the pair from the arms' current position); id an integer.\n"
	"                         A pair and its reciprocal (or any pair equal up to rotation/mirror) count once,\n"
	"                         at the cheaper cost; at most 50000 rows\n"
	"  --target SPEC          dhr:8,30,60  sigma of the DHR at those incidences (degrees), RMS over the model's\n"
	"                                      wavelengths; the value is the largest incidence's\n"
	"                         lnf          largest posterior sigma of ln f (RMS over wavelengths) over the grid\n"
	"                                      theta_i <= theta_o in 0..80 deg step 10, delta phi 0..180 step 20;\n"
	"                                      the picks reduce its variance integrated under cos(theta_i)\n"
	"                                      cos(theta_o) dwi dwo\n"
	"                         lnf:rad      the same value; the picks reduce the expected squared error of\n"
	"                                      log(1 + f cos(theta_i) cos(theta_o)) integrated over dwi dwo (the\n"
	"                                      time-to-accuracy study's held-out log-RMSE)\n"
	"                         lnf:mix      the same value; each pick's gain the sum of its relative reductions\n"
	"                                      of lnf's and lnf:rad's criteria (both weights, each over its own\n"
	"                                      criterion before the picks)\n"
	"                         lnf:bright   the same value; per grid cell the larger of lnf's and lnf:rad's\n"
	"                                      weights (the study's error where the model is bright, the lobe;\n"
	"                                      the projected measure elsewhere)\n"
	"                         rgb          sigma (sr^-1) of the linear-sRGB BRDF values a MERL table of the model\n"
	"                                      holds (brdf-recon merl's colour chain), RMS over R, G, B and over the\n"
	"                                      table's cells weighted by cos(theta_i) cos(theta_o) dwi dwo (12^3 of\n"
	"                                      its cells); the wavelengths' errors taken as fully correlated\n"
	"                         either followed by :le=X, the threshold at which the target is met\n"
	"                         dhr:8,30,60:le=X+lnf[:rad]:le=Y  both: met when both parts are; its value is the larger\n"
	"                                      of each part's value over its threshold (met at <= 1), each pick's gain\n"
	"                                      the sum of the parts' reductions relative to their criterion before the\n"
	"                                      batch; per = the DHR incidences' values, then the ln f part's\n"
	"                         any of them ending in :lobe_above=DEG (0 < DEG < 90): the lobe gate, candidates of\n"
	"                                      theta_i above DEG kept only where the model has its own lobe at their\n"
	"                                      pair (lnf:bright's rule there: lnf:rad's weight above the projected\n"
	"                                      one); the JSON's candidates then add \"beyond\" and \"admitted\"\n"
	"                         (lnf:bright: the JSON adds \"bright_cells\", the grid cells that took lnf:rad's\n"
	"                                      weight; 0: the weights and picks are lnf's)\n"
	"  --route SPEC           charge each pick its increment to the batch's route instead of cost_s: SPEC is 13\n"
	"                         numbers, comma-separated: the arms' bench position (laser theta, detector theta,\n"
	"                         detector phi, degrees), per axis in that order speed (deg/s), acceleration (deg/s^2),\n"
	"                         settle (s), then seconds per move beyond them (polling). The candidates then need the\n"
	"                         columns base_s (> 0: the point at an incidence the batch visits already, no move),\n"
	"                         open_s (>= 0: more at a new incidence: its darks) and laser_deg, det_theta_deg,\n"
	"                         det_phi_deg (its bench position); a pick costs base_s, open_s when its laser position\n"
	"                         is new to the batch, and the motion of inserting it at the cheapest place of the\n"
	"                         route from the arms through the picks so far (straight moves: the slowest axis's\n"
	"                         trapezoid + the largest settle of the axes that move + the per-move seconds; the\n"
	"                         azimuth modulo 360 deg). SPEC may go on with band nodes, 4 numbers each: rho (1\n"
	"                         first, rising), point_s, dark_s, rungs (the planner's per-point terms when the\n"
	"                         batch's detector zeniths span cos ratio rho); then the candidates also need\n"
	"                         point_s (> 0), dark_s (>= 0), rungs (>= 1), since (>= 0), band_cos (in [0, 1]), and a\n"
	"                         pick's exposures are charged as the planner counts them instead of base_s/open_s:\n"
	"                         point_s, the k-th pick at an incidence a dark of dark_s with probability\n"
	"                         (1 - 1/rungs)^(since + k), these scaled by the nodes at the band of the picks'\n"
	"                         band_cos (largest / smallest; point by the difference from rho 1, dark and rungs by\n"
	"                         the ratio), and a pick that widens the band charged its widening of the others\n"
	"  --batch N              at most N picks (default 16; 0: only report the target)\n"
	"  --draws N --seed S     Monte-Carlo draws of the DHR's noise part (default 16, seed 1)\n"
	"  --value-channels N     dhr: compute the value on N evenly spread channels (the tracked ones among them)\n"
	"                         when the model has more (default 0: all, as brdf-recon dhr); its cost scales with\n"
	"                         N (651 -> 64 wavelengths: 6.6x less CPU) and the RMS over N channels can miss single\n"
	"                         channels' spikes (measured -5.5 % .. +0.8 % of all channels' on a paper-size model,\n"
	"                         2.2x on one with a noisy edge channel), so a value within 4x of the threshold is\n"
	"                         recomputed on all channels (value_checked_all): met is always decided on all\n"
	"  -o OUT.json            output (stdout by default): {\"target\":{\"spec\",\"value\",\"per\",\"threshold\",\"met\"},\n"
	"                         \"picks\":[{\"id\",\"gain\",\"gain_per_s\",\"cost_s\",\"predicted_value_after\"}],\n"
	"                         \"model\", \"route\" (SPEC, when given), \"criterion\", \"candidates\":{\"read\",\n"
	"                         \"distinct\"}}; picks in choice order, cost_s the seconds charged (--route: the\n"
	"                         increment); a combined target adds \"parts\":{\"dhr\":{\"value\",\"threshold\"},\"lnf\":{...}} to \"target\".\n"
	"Exit 0 (also with no pick worth making: empty picks), 2 on bad input, 1 on a failure of the computation.\n";

/* Write s as a JSON string (quotes included). */
static void json_str(FILE *f, const char *s)
{
	fputc('"', f);
	for (const unsigned char *p = (const unsigned char *)s; *p; p++) {
		if (*p == '"' || *p == '\\')
			fprintf(f, "\\%c", *p);
		else if (*p < 0x20)
			fprintf(f, "\\u%04x", *p);
		else
			fputc(*p, f);
	}
	fputc('"', f);
}

/* A finite number for JSON (%.9g); the library's outputs are finite, this keeps the file valid regardless. */
static void json_num(FILE *f, double v)
{
	if (isfinite(v))
		fprintf(f, "%.15g", v);
	else
		fputs("null", f);
}

/* The command's limit on the candidate file (the library's memory is ~(1536 + 2n + 128·incidences) × 8 bytes per
 * distinct candidate: 100000 candidates of a 550-direction model ≈ 2.5 GB would be refused by it anyway). */
#define SELECT_MAX_CANDIDATES 50000

static int cmp_id(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return x < y ? -1 : x > y;
}

/* The most band nodes --route takes. */
#define ROUTE_MAX_NODES 64

/* --route SPEC into r, its band nodes into nodes[4 ROUTE_MAX_NODES] (positions and arrays left to the caller). 0, or
 * -1 with err saying what is wrong. */
static int parse_route(const char *spec, struct select_route *r, double *nodes, struct acq_err *err)
{
	double v[13 + 4 * ROUTE_MAX_NODES];
	const char *p = spec;
	int n = 0;
	for (;;) {
		char *end;
		if (n == (int)(sizeof v / sizeof *v))
			return acq_errf(err, ACQ_E_INVAL, "--route: more than %d band nodes", ROUTE_MAX_NODES);
		v[n] = strtod(p, &end);
		if (end == p || !isfinite(v[n]) || (*end && *end != ','))
			return acq_errf(err, ACQ_E_INVAL, "--route: expected 13 comma-separated numbers (from laser, detector "
					"theta, detector phi; speed, accel, settle per axis; per-move seconds), then band nodes, "
					"at number %d", n + 1);
		n++;
		if (!*end)
			break;
		p = end + 1;
	}
	if (n < 13 || (n - 13) % 4)
		return acq_errf(err, ACQ_E_INVAL, "--route: expected 13 comma-separated numbers (from laser, detector theta, "
				"detector phi; speed, accel, settle per axis; per-move seconds), then band nodes of 4 numbers "
				"(rho, point_s, dark_s, rungs): got %d numbers", n);
	for (int a = 0; a < 3; a++) {
		r->from[a] = v[a];
		r->speed[a] = v[3 + 3 * a];
		r->accel[a] = v[4 + 3 * a];
		r->settle[a] = v[5 + 3 * a];
		if (!(r->speed[a] > 0 && r->accel[a] > 0 && r->settle[a] >= 0))
			return acq_errf(err, ACQ_E_RANGE, "--route: axis %d needs speed > 0, accel > 0, settle >= 0 (got %g, %g, "
					"%g)", a + 1, r->speed[a], r->accel[a], r->settle[a]);
	}
	r->move_s = v[12];
	if (!(r->move_s >= 0))
		return acq_errf(err, ACQ_E_RANGE, "--route: per-move seconds %g < 0", r->move_s);
	r->nnodes = (size_t)(n - 13) / 4;
	r->nodes = r->nnodes ? nodes : NULL;
	for (size_t k = 0; k < r->nnodes; k++) {
		const double *b = v + 13 + 4 * k;
		if (!(k ? b[0] > b[-4] : b[0] == 1) || !(b[1] > 0 && b[2] >= 0 && b[3] >= 1))
			return acq_errf(err, ACQ_E_RANGE, "--route: band node %zu (%g, %g, %g, %g) needs rho rising from 1, "
					"point_s > 0, dark_s >= 0, rungs >= 1", k + 1, b[0], b[1], b[2], b[3]);
		memcpy(nodes + 4 * k, b, 4 * sizeof *b);
	}
	return 0;
}

static int bad_input(const struct acq_err *e)
{
	cli_progress_end();
	fprintf(stderr, "brdf-recon select: %s\n", e->msg[0] ? e->msg : "bad input");
	return 2;
}

/* The columns of a candidate file: the first six always, the next five with --route, the last five with its band
 * nodes. */
static const char *const cand_names[16] = { "id", "theta_i", "phi_i", "theta_o", "phi_o", "cost_s",
					    "base_s", "open_s", "laser_deg", "det_theta_deg", "det_phi_deg",
					    "point_s", "dark_s", "rungs", "since", "band_cos" };

/* The command line. */
struct select_args {
	const char *outp, *candp, *spec, *routep;
	const char *model;       /* MODEL, the one operand */
	struct select_opts so;
};

/* The candidates as select_batch takes them: nc rows of angles (radians, 4 per row), costs and ids; with --route
 * ids holds 6·nc numbers (ids, then the route's pos[3nc], base, open), with band nodes 11·nc (then point, dark,
 * rungs, since, band_cos). */
struct select_cands {
	size_t nc;
	double *ang, *cost, *ids;
};

static void cands_free(struct select_cands *cd)
{
	free(cd->ang);
	free(cd->cost);
	free(cd->ids);
}

/* Options into a. -1 to go on, else the exit status (help printed, or a usage error reported). */
static int parse_args(int argc, char **argv, struct select_args *a)
{
	static const struct option lo[] = {
		{ "output", required_argument, 0, 'o' }, { "candidates", required_argument, 0, 'c' },
		{ "target", required_argument, 0, 't' }, { "batch", required_argument, 0, 'b' },
		{ "draws", required_argument, 0, 'n' }, { "seed", required_argument, 0, 's' },
		{ "value-channels", required_argument, 0, 'v' }, { "route", required_argument, 0, 'r' },
		{ "help", no_argument, 0, 'h' }, { 0, 0, 0, 0 } };
	struct select_opts *so = &a->so;
	uint64_t u;
	int c;
	while ((c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1) {
		switch (c) {
		case 'o': a->outp = optarg; break;
		case 'c': a->candp = optarg; break;
		case 't': a->spec = optarg; break;
		case 'b':
			if (cli_parse_u64(optarg, &u) || u > 100000)
				return cli_usage_err("select", "--batch needs a count in 0..100000");
			so->batch = (size_t)u;
			break;
		case 'n':
			if (cli_parse_u64(optarg, &u) || u > 100000)
				return cli_usage_err("select", "--draws needs 0..100000");
			so->ndraws = (int)u;
			break;
		case 'v':
			if (cli_parse_u64(optarg, &u) || u > 100000)
				return cli_usage_err("select", "--value-channels needs a count in 0..100000 (0: all)");
			so->nvalue = (size_t)u;
			break;
		case 'r': a->routep = optarg; break;
		case 's':
			if (cli_parse_u64(optarg, &so->seed))
				return cli_usage_err("select", "--seed needs an unsigned integer");
			break;
		case 'h': fputs(select_help, stdout); return 0;
		default: return cli_usage_err("select", "bad option");
		}
	}
	if (optind != argc - 1)
		return cli_usage_err("select", "one MODEL expected");
	if (!a->candp || !a->spec)
		return cli_usage_err("select", "--candidates CAND.csv and --target SPEC are required");
	a->model = argv[optind];
	return -1;
}

/* Check data row j (ncol numbers: r) of candp. 0, or -1 with err naming the row and the column. */
static int check_row(const char *candp, size_t j, const double *r, size_t ncol, struct acq_err *err)
{
	const char *const *names = cand_names;
	double id = r[0];
	if (!(id >= 0 && id <= 9007199254740992.0 && id == floor(id)))
		return acq_errf(err, ACQ_E_INVAL, "%s: data row %zu: id %.17g is not a non-negative integer", candp, j + 1,
				id);
	for (int a = 1; a <= 4; a += 2)
		if (!(r[a] >= 0 && r[a] <= 90))
			return acq_errf(err, ACQ_E_RANGE, "%s: data row %zu (id %.0f): %s = %g outside [0, 90] degrees", candp,
					j + 1, id, names[a], r[a]);
	if (!(r[5] > 0 && isfinite(r[5])))
		return acq_errf(err, ACQ_E_RANGE, "%s: data row %zu (id %.0f): cost_s = %g must be > 0 seconds", candp,
				j + 1, id, r[5]);
	if (ncol > 6) {
		for (size_t a = 8; a < ncol; a++)
			if (!isfinite(r[a]))
				return acq_errf(err, ACQ_E_RANGE, "%s: data row %zu (id %.0f): %s is not a number", candp, j + 1,
						id, names[a]);
		if (!(r[6] > 0 && isfinite(r[6]) && r[7] >= 0 && isfinite(r[7])))
			return acq_errf(err, ACQ_E_RANGE, "%s: data row %zu (id %.0f): base_s = %g must be > 0 and open_s = %g "
					">= 0 seconds", candp, j + 1, id, r[6], r[7]);
	}
	if (ncol > 11 && !(r[11] > 0 && r[12] >= 0 && r[13] >= 1 && r[14] >= 0 && r[15] >= 0 && r[15] <= 1))
		return acq_errf(err, ACQ_E_RANGE, "%s: data row %zu (id %.0f): needs point_s > 0, dark_s >= 0, rungs >= 1, "
				"since >= 0, band_cos in [0, 1] (got %g, %g, %g, %g, %g)", candp, j + 1, id, r[11], r[12], r[13],
				r[14], r[15]);
	return 0;
}

/* Ids are unique: a sorted copy of the nc ids has no two equal. 0, or -1 with err naming the id. */
static int check_unique_ids(const char *candp, const double *ids, size_t nc, struct acq_err *err)
{
	if (nc < 2)
		return 0;
	double *s = malloc(nc * sizeof *s);
	int bad = 0;
	if (s) {
		memcpy(s, ids, nc * sizeof *s);
		qsort(s, nc, sizeof *s, cmp_id);
		for (size_t i = 1; i < nc && !bad; i++)
			if (s[i] == s[i - 1]) {
				acq_errf(err, ACQ_E_INVAL, "%s: id %.0f appears more than once", candp, s[i]);
				bad = 1;
			}
		free(s);
	}
	return bad ? -1 : 0;
}

/* Read and check a->candp into cd (and, with --route, route's arrays, pointing into cd->ids). 0, or the exit
 * status with the error reported (2: bad input, 1: out of memory) and nothing left allocated. */
static int read_candidates(const struct select_args *a, struct select_route *route, struct select_cands *cd)
{
	struct acq_err err = { 0 };
	const char *candp = a->candp;
	bool routed = a->routep != NULL;
	size_t nc = 0, ncol = !routed ? 6 : route->nnodes ? 16 : 11, nper = ncol == 16 ? 11 : routed ? 6 : 1;
	double *rows = NULL;
	/* a header and no data row: no candidates (the target's value, no pick) */
	if (csvio_read_columns_ex(candp, cand_names, ncol, CSVIO_EMPTY_OK, &nc, &rows, &err))
		return bad_input(&err);
	if (nc > SELECT_MAX_CANDIDATES) {
		free(rows);
		acq_errf(&err, ACQ_E_RANGE, "%s: %zu candidates, at most %d", candp, nc, SELECT_MAX_CANDIDATES);
		return bad_input(&err);
	}
	cd->nc = nc;
	cd->ang = malloc((nc ? nc : 1) * 4 * sizeof *cd->ang);
	cd->cost = malloc((nc ? nc : 1) * sizeof *cd->cost);
	cd->ids = malloc((nc ? nc : 1) * nper * sizeof *cd->ids);
	if (!cd->ang || !cd->cost || !cd->ids) {
		free(rows);
		cands_free(cd);
		acq_errf(&err, ACQ_E_NOMEM, "select: out of memory");
		return cli_fail(&err);
	}
	int bad = 0;
	for (size_t j = 0; j < nc && !bad; j++) {
		const double *r = rows + ncol * j;
		if (check_row(candp, j, r, ncol, &err)) {
			bad = 1;
			break;
		}
		if (routed) {
			double *rd = cd->ids + nc;
			for (int k = 0; k < 3; k++)
				rd[3 * j + k] = r[8 + k];
			rd[3 * nc + j] = r[6];
			rd[4 * nc + j] = r[7];
			for (size_t k = 11; k < ncol; k++) /* point, dark, rungs, since, band_cos */
				rd[(k - 6) * nc + j] = r[k];
		}
		for (int k = 0; k < 4; k++)
			cd->ang[4 * j + k] = r[1 + k] * M_PI / 180;
		cd->cost[j] = r[5];
		cd->ids[j] = r[0];
	}
	if (routed) {
		route->pos = cd->ids + nc;
		route->base = cd->ids + 4 * nc;
		route->open = cd->ids + 5 * nc;
		if (route->nnodes) {
			route->point = cd->ids + 6 * nc;
			route->dark = cd->ids + 7 * nc;
			route->rungs = cd->ids + 8 * nc;
			route->since = cd->ids + 9 * nc;
			route->band_cos = cd->ids + 10 * nc;
		}
	}
	if (!bad && check_unique_ids(candp, cd->ids, nc, &err))
		bad = 1;
	free(rows);
	if (bad) {
		cands_free(cd);
		return bad_input(&err);
	}
	return 0;
}

/* The "target" object of the JSON: spec, value, per, the DHR's incidences, where (ln f), parts, threshold, met. */
static void write_target(FILE *f, const char *spec, const struct select_target *tg, const struct select_result *res)
{
	fputs("{\"target\":{\"spec\":", f);
	json_str(f, spec);
	fputs(",\"value\":", f);
	json_num(f, res->value);
	fputs(",\"per\":[", f);
	for (size_t i = 0; i < res->nper; i++) {
		if (i)
			fputc(',', f);
		json_num(f, res->per[i]);
	}
	fputs("],", f);
	if (tg->kind == SELECT_DHR) {
		fputs("\"theta_i\":[", f);
		for (size_t i = 0; i < tg->nth; i++)
			fprintf(f, i ? ",%g" : "%g", tg->theta_deg[i]);
		fprintf(f, "],\"value_channels\":%zu,\"value_checked_all\":%s,", res->nvalue,
			res->value_checked ? "true" : "false");
	}
	if (tg->kind == SELECT_LNF || tg->lnf_threshold > 0) {
		fputs("\"where\":{", f);
		static const char *const an[4] = { "theta_i", "phi_i", "theta_o", "phi_o" };
		for (int a = 0; a < 4; a++)
			fprintf(f, "%s\"%s\":%g", a ? "," : "", an[a], res->where[a] * 180 / M_PI);
		fputs("},", f);
	}
	if (tg->lnf_threshold > 0) {
		fputs("\"parts\":{\"dhr\":{\"value\":", f);
		json_num(f, res->part[0]);
		fputs(",\"threshold\":", f);
		json_num(f, tg->threshold);
		fputs("},\"lnf\":{\"value\":", f);
		json_num(f, res->part[1]);
		fputs(",\"threshold\":", f);
		json_num(f, tg->lnf_threshold);
		fputs("}},", f);
	}
	fputs("\"threshold\":", f);
	json_num(f, tg->lnf_threshold > 0 ? 1.0 : tg->threshold);
	fprintf(f, ",\"met\":%s}", res->met ? "true" : "false");
}

/* The "picks" array of the JSON, in choice order (ids: the candidates' ids by index). */
static void write_picks(FILE *f, const struct select_result *res, const double *ids)
{
	fputs(",\"picks\":[", f);
	for (size_t k = 0; k < res->npicks; k++) {
		const struct select_pick *p = &res->picks[k];
		fprintf(f, "%s{\"id\":%.0f,\"gain\":", k ? "," : "", ids[p->index]);
		json_num(f, p->gain);
		fputs(",\"gain_per_s\":", f);
		json_num(f, p->gain_per_s);
		fputs(",\"cost_s\":", f);
		json_num(f, p->cost);
		fputs(",\"predicted_value_after\":", f);
		json_num(f, p->predicted);
		fputs(",\"predicted_per_after\":[", f);
		for (size_t i = 0; i < res->nper; i++) {
			if (i)
				fputc(',', f);
			json_num(f, p->predicted_per[i]);
		}
		fputs("]}", f);
	}
	fputc(']', f);
}

/* The decision as one JSON line to a->outp (stdout without -o). 0 or -1 with err. */
static int write_result(const struct select_args *a, const struct select_target *tg, const struct select_result *res,
			const struct select_cands *cd, struct acq_err *err)
{
	struct cli_out o;
	if (cli_out_open(&o, a->outp, err))
		return -1;
	FILE *f = o.f;
	write_target(f, a->spec, tg, res);
	write_picks(f, res, cd->ids);
	fputs(",\"model\":", f);
	json_str(f, a->model);
	if (a->routep) { /* the decision's record: a replay needs it */
		fputs(",\"route\":", f);
		json_str(f, a->routep);
	}
	fprintf(f, ",\"criterion\":\"%s\",\"candidates\":{\"read\":%zu,\"distinct\":%zu",
		"gp-excess-variance-reduction-per-second", cd->nc, res->nunique);
	if (tg->lobe_above_deg > 0)
		fprintf(f, ",\"beyond\":%zu,\"admitted\":%zu", res->nbeyond, res->nadmitted);
	fputc('}', f);
	if (tg->lnf_rad == SELECT_LNF_BRIGHT && (tg->kind == SELECT_LNF || tg->lnf_threshold > 0))
		fprintf(f, ",\"bright_cells\":%zu", res->nbright);
	fputs("}\n", f);
	return cli_out_close(&o, 1, err) ? -1 : 0;
}

int cmd_select(int argc, char **argv)
{
	/* a decision allocates and frees arrays of megabytes in turn (the candidates' and the DHR rule's kernel rows,
	 * recon_dhr_parts' K_QQ, ...): from the heap and kept there when freed, the next one reuses pages already
	 * touched instead of mapping new ones (each first touch a page fault: 8 300 per decision on the white study's
	 * model, 6 200 with these settings) */
	mallopt(M_MMAP_THRESHOLD, 32 << 20); /* glibc's largest */
	mallopt(M_TRIM_THRESHOLD, 1 << 30);
	struct select_args a = { 0 };
	select_opts_default(&a.so);
	int rc = parse_args(argc, argv, &a);
	if (rc >= 0)
		return rc;
	struct acq_err err = { 0 };
	struct select_target tg;
	if (select_target_parse(a.spec, &tg, &err))
		return bad_input(&err);
	struct select_route route = { 0 };
	double nodes[4 * ROUTE_MAX_NODES];
	if (a.routep && parse_route(a.routep, &route, nodes, &err))
		return bad_input(&err);
	struct select_cands cd = { 0 };
	if ((rc = read_candidates(&a, &route, &cd)))
		return rc;
	if (a.routep)
		a.so.route = &route;
	struct recon_model *m;
	if (recon_model_load(a.model, &m, &err)) {
		cands_free(&cd);
		return bad_input(&err);
	}
	struct select_result res;
	int ok = select_batch(m, cd.nc, cd.ang, cd.cost, &tg, &a.so, &res, &err) == 0;
	if (ok && write_result(&a, &tg, &res, &cd, &err))
		ok = 0;
	if (ok)
		fprintf(stderr, "select: target %s = %.4g%s; %zu of %zu distinct candidates picked%s\n", a.spec, res.value,
			res.met ? " (met)" : "", res.npicks, res.nunique,
			res.npicks ? "" : " (none reduces the target)");
	select_result_free(&res);
	recon_model_free(m);
	cands_free(&cd);
	return ok ? 0 : cli_fail(&err);
}
