/* Fuzz target: the CSV interchange reader (samples and queries) must never crash, leak or accept a
 * non-finite value, whatever the bytes. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "recon/csvio.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	struct recon_samples s;
	struct acq_err err = { 0 };
	if (csvio_parse_samples("fuzz", (const char *)data, size, &s, &err) == 0) {
		for (size_t i = 0; i < s.n * 4; i++)
			if (!isfinite(s.ang[i]))
				abort();
		for (size_t i = 0; i < s.n * s.nwl; i++)
			if (isinf(s.val[i]) || (s.sig && (isinf(s.sig[i]) || s.sig[i] < 0)))
				abort();
		for (size_t l = 1; l < s.nwl; l++)
			if (!(s.wl[l] > s.wl[l - 1]))
				abort();
		csvio_samples_free(&s);
	} else if (err.msg[0] == '\0') {
		abort(); /* an error always says what */
	}
	if (csvio_parse_queries("fuzz", (const char *)data, size, &s, &err) == 0)
		csvio_samples_free(&s);
	return 0;
}
