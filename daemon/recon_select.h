/* recon_select: the decision between two batches of an adaptive sweep, every slow step in a child process (the
 * loop never waits): in a child of the job helper, the sweep's calibrated samples so far exported as CSV (through a
 * read-only connection of its own) and the reachable candidates for its plan (the text handed to it; planner: blind zones, collisions, limits, safe paths; cost_s
 * from plan_time.c); then `brdf-recon fit` (warm-started from the previous batch's model with --warm when this brdf-recon has it), then `brdf-recon select
 * MODEL --candidates CAND.csv --route ROUTE --target SPEC --batch N -o OUT.json` (each pick charged its increment to
 * the batch's route, plan_adaptive_route_spec) (the contract in /work/notes/OWNERS.md). */
#ifndef RECON_SELECT_H
#define RECON_SELECT_H

#include <jansson.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "daemon/job.h"
#include "daemon/plan/plan.h"
#include "daemon/sweep.h"

struct rsel;

/* Write the candidates c[n] on bench g to path as `brdf-recon select --candidates` reads them (header id, theta_i,
 * phi_i, theta_o, phi_o, cost_s, base_s, open_s, laser_deg, det_theta_deg, det_phi_deg, point_s, dark_s, rungs,
 * since, band_cos: sample-frame angles, costs, bench axis positions, the exposures' price (struct plan_cand); the
 * daemon's decisions and the offline study's helper write them alike). 0, or -1 with err. */
int rsel_write_candidates(const char *path, const struct bench_geom *g, const struct plan_cand *c, size_t n,
			  struct acq_err *err);

/* One decision to make (everything borrowed until rsel_start returns, spec until the callback). */
struct rsel_req {
	int64_t sweep_id;
	int batch;                        /* the batch being chosen (1: the first after the seed) */
	const struct plan_spec *spec;     /* adaptive */
	const char *plan_text;            /* the text spec was parsed from (the candidates child parses it) */
	struct plan_pos from;             /* where the arms are */
	const struct plan_pos *done;      /* the positions measured or planned so far (no candidate repeats them) */
	size_t n_done;
	struct plan_timing timing;        /* this daemon's executor */
	const char *prev_model;           /* the previous batch's model ("": a cold fit) */
	size_t batch_size;
};

/* What came of it: ok with select's JSON, or why not. */
struct rsel_res {
	bool ok;
	char msg[1024];
	json_t *out;                      /* select's output (borrowed during the callback) */
	char model[4096];                 /* the model the decision used */
	char dir[4096];                   /* the decision's directory (samples, candidates, model, select.json) */
	size_t n_candidates;
	bool warm;                        /* the fit was warm-started */
	double fit_s, select_s;           /* loop (bench) seconds each child ran */
};

typedef void (*rsel_done_fn)(void *ctx, const struct rsel_res *r);

/* The child that writes a decision's samples and candidates, run by the job helper (it must be in the program's
 * table of job kinds, job_kinds_main). */
extern const struct job_kind rsel_inputs_kind;
/* A decision maker over env (borrowed: the sweep's). NULL when out of memory. */
struct rsel *rsel_new(const struct sweep_env *env);
/* Free; a running child is left to job_finish() (its callback is not called). NULL is fine. */
void rsel_free(struct rsel *r);
/* Start the decision q; done is called from the loop once, when select answered or a step failed. ACQ_E_STATE
 * while one runs, ACQ_E_UNSUPPORTED without brdf-recon. 0 or -1 (then done is not called). */
int rsel_start(struct rsel *r, const struct rsel_req *q, rsel_done_fn done, void *ctx, struct acq_err *err);
/* True while a decision is being made. */
bool rsel_busy(const struct rsel *r);

#endif
