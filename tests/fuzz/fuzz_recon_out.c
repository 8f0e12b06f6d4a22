/* fuzz_recon_out: colour options from text, spectra and directions from raw doubles; asserts no crash and
 * that nothing non-finite comes out of colour_finish or merl_lookup. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "recon/colour.h"
#include "recon/merl.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define MAXN 512

static void check3(const double v[3])
{
	if (!isfinite(v[0]) || !isfinite(v[1]) || !isfinite(v[2]))
		abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	/* text part: "key=value" lines up to the first NUL */
	const uint8_t *nul = memchr(data, 0, size);
	size_t tlen = nul ? (size_t)(nul - data) : size;
	char *text = malloc(tlen + 1);
	if (!text)
		return 0;
	memcpy(text, data, tlen);
	text[tlen] = '\0';
	struct colour_opts o;
	colour_opts_default(&o);
	struct acq_err err;
	char *save = NULL;
	for (char *line = strtok_r(text, "\n", &save); line; line = strtok_r(NULL, "\n", &save)) {
		char *eq = strchr(line, '=');
		if (!eq)
			continue;
		*eq = '\0';
		colour_opts_set(&o, line, eq + 1, &err);
	}
	free(text);
	if (!nul)
		return 0;
	/* binary part: n wavelengths, n spectrum values, then triples for colour_finish */
	const uint8_t *b = nul + 1;
	size_t nd = (size - tlen - 1) / sizeof(double);
	double *d = malloc((nd ? nd : 1) * sizeof(double));
	if (!d)
		return 0;
	memcpy(d, b, nd * sizeof(double));
	size_t n = nd / 2 > MAXN ? MAXN : nd / 2;
	if (n > 0) {
		double rgb[3];
		struct colour_stats st = { 0 };
		if (colour_spectrum_rgb(&o, d, d + n, n, rgb, &st, &err) == 0)
			check3(rgb);
	}
	struct colour_stats st = { 0 };
	for (size_t i = 2 * n; i + 3 <= nd; i += 3) {
		double out[3];
		colour_finish(&o, d + i, out, &st);
		check3(out);
		int a, bb, c;
		double th, ph, td, pd;
		int flat = merl_index(d[i], d[i + 1], d[i + 2], &a, &bb, &c);
		if (flat < 0 || flat >= MERL_N_CELLS)
			abort();
		if (i + 6 <= nd) {
			merl_half_diff(d + i, d + i + 3, &th, &ph, &td, &pd);
			flat = merl_index(th, td, pd, NULL, NULL, NULL);
			if (flat < 0 || flat >= MERL_N_CELLS)
				abort();
		}
	}
	free(d);
	return 0;
}
