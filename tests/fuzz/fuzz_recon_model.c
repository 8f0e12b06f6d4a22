/* Fuzz target: the model-file loader must reject any malformed file with a message, never crash. */
#include <stdint.h>
#include <stdlib.h>

#include "recon/recon.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	struct recon_model *m = NULL;
	struct acq_err err = { 0 };
	if (recon_model_load_mem("fuzz", data, size, &m, &err) == 0) {
		double a[4] = { 0.3, 0.0, 0.5, 1.0 }, *out = malloc(m->nwl * sizeof *out);
		if (out && recon_eval(m, 1, a, out, &err) != 0)
			abort();
		free(out);
		recon_model_free(m);
	} else if (err.msg[0] == '\0' || m) {
		abort();
	}
	return 0;
}
