/* fuzz_plan: plan files from arbitrary bytes — parse (located errors, never a crash) and, when small, plan
 * them against the default bench and check the result's basic promises. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "config/bench.h"
#include "daemon/plan/plan.h"

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
		size_t per = s->fib_count ? s->fib_count : s->n_obs_theta * s->n_obs_phi;
		if (per * s->n_incidence <= 60) {
			struct bench_geom g;
			bench_defaults(&g);
			struct plan_result *r = NULL;
			if (plan_make(s, &g, &r, &err) == 0) {
				if (r->n_kept + r->n_moved != r->n_steps || r->duration_s > r->raster_s + 1e-9 ||
				    r->lower_bound_s > r->duration_s + 1e-9)
					abort();
				plan_result_free(r);
			}
		}
		plan_spec_free(s);
	} else if (err.msg[0] == '\0') {
		abort(); /* every refusal says why */
	}
	free(text);
	return 0;
}
