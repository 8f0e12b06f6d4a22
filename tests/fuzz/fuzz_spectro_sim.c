/* Fuzz target: the "sim" spectrometer backend's decoding of acq-sim replies (drivers/spectro_sim_proto.h).
 * Byte 0 selects IDENTITY (even) or SPECTRUM (odd) decoding of the rest; a spectrum is decoded for a
 * 64-pixel device with nonlinearity coefficients. Must never crash or read out of bounds; on success the
 * frame must be consistent (finite, within full scale, saturation count equal to the flags). */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "drivers/spectro_sim_proto.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	if (size < 1 || size > (1u << 20))
		return 0;
	unsigned char *p = malloc(size - 1 ? size - 1 : 1); /* exact size: ASan sees any over-read */
	if (!p)
		return 0;
	memcpy(p, data + 1, size - 1);
	struct acq_err err = { 0 };
	if (data[0] % 2 == 0) {
		struct spectro_info info;
		double t;
		if (ssp_parse_identity(p, (uint32_t)(size - 1), &info, &t, &err) == 0) {
			if (info.npix < 1 || info.npix > SPECTRO_MAX_PIXELS || info.ndark_pixels > 8 || !(info.max_counts > 0))
				abort();
		} else if (!err.msg[0]) {
			abort(); /* an error must say what */
		}
	} else {
		static struct spectro_frame f;
		struct spectro_info info = { .npix = 64, .max_counts = 65535, .nonlin_enabled = true, .ndark_pixels = 2,
					     .dark_pixels = { 0, 1 } };
		info.nonlin_coef[0] = 1;
		info.nonlin_coef[1] = -0.05 / 65535;
		if (ssp_parse_spectrum(p, (uint32_t)(size - 1), &info, data[0] & 2, &f, &err) == 0) {
			int n = 0;
			for (int i = 0; i < f.npix; i++) {
				if (!isfinite(f.counts[i]) || !(f.stddev[i] >= 0))
					abort();
				n += f.saturated[i];
			}
			if (n != f.nsaturated || f.npix != 64)
				abort();
		} else if (!err.msg[0]) {
			abort();
		}
	}
	free(p);
	return 0;
}
