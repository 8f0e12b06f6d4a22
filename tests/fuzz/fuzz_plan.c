/* fuzz_plan: plan files from arbitrary bytes — parse (located errors, never a crash), plan them (a large one cut
 * down) against the default bench and check the result's basic promises. */

#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "config/bench.h"
#include "daemon/plan/plan.h"

/* The points planned (per incidence × incidences, plus reciprocal partners). Planning grows steeply with the
 * points, and a blind point to be moved costs a search of ~10^4 poses: a 32-point plan with blind_points: move took
 * 0.16 s CPU in the plain replay build, about 1 s under libFuzzer's instrumentation, which held make fuzz to
 * 1-2 inputs/s (it never got past its own corpus in 60 s). Every input is parsed whatever its size; a larger
 * spec is cut to a prefix of each of its lists (3 incidences × 3 zeniths × 3 azimuths or 9 Fibonacci directions,
 * 4 reciprocal pairs; with blind_points: move 2 × 2 × 2 or 4, 2 pairs) and planned: the planner still sees every
 * input's kind of plan (the old target planned none above 60 points). */
#define FUZZ_PLAN_MAX_POINTS 31
#define FUZZ_PLAN_MAX_MOVED 10

static size_t min_sz(size_t a, size_t b)
{
	return a < b ? a : b;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	char *text = malloc(size + 1);
	if (!text)
		return 0;
	memcpy(text, data, size);
	text[size] = '\0';
	struct plan_spec *s = NULL;
	struct acq_err err = { 0 };
	if (plan_load_string("fuzz.yaml", text, &s, &err) == 0) {
		/* a blind point moved costs a search of ~10^4 poses: such plans are cut further */
		bool move = s->blind_policy == PLAN_BLIND_MOVE;
		size_t per = s->fib_count ? s->fib_count : s->n_obs_theta * s->n_obs_phi;
		if (per * s->n_incidence + s->reciprocal_pairs > (move ? FUZZ_PLAN_MAX_MOVED : FUZZ_PLAN_MAX_POINTS)) {
			s->n_incidence = min_sz(s->n_incidence, move ? 2 : 3);
			s->n_obs_theta = min_sz(s->n_obs_theta, move ? 2 : 3);
			s->n_obs_phi = min_sz(s->n_obs_phi, move ? 2 : 3);
			s->fib_count = min_sz(s->fib_count, move ? 4 : 9);
			s->reciprocal_pairs = min_sz(s->reciprocal_pairs, move ? 2 : 4);
		}
		struct bench_geom g;
		bench_defaults(&g);
		struct plan_result *r = NULL;
		if (plan_make(s, &g, &r, &err) == 0) {
			if (r->n_kept + r->n_moved != r->n_steps || r->duration_s > r->raster_s + 1e-9 ||
			    r->lower_bound_s > r->duration_s + 1e-9)
				abort();
			plan_result_free(r);
		}
		plan_spec_free(s);
	} else if (err.msg[0] == '\0') {
		abort(); /* every refusal says why */
	}
	free(text);
	return 0;
}
