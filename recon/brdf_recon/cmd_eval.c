/* brdf-recon eval: the model at given directions, as CSV. */
#include <getopt.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "recon/brdf_recon/cli.h"
#include "recon/csvio.h"
#include "recon/recon.h"

/* ---- eval ---- */
static const char eval_help[] =
	"usage: brdf-recon eval MODEL QUERIES.csv [-o OUT.csv]\n"
	"Evaluate the model at the directions of QUERIES.csv (columns theta_i,phi_i,theta_o,phi_o in degrees;\n"
	"other columns ignored). Writes CSV (stdout by default): the four angle columns, then one column per\n"
	"model wavelength (sr^-1).\n";

static int write_header_wl(FILE *f, const struct recon_model *m)
{
	for (size_t l = 0; l < m->nwl; l++)
		fprintf(f, ",%.10g", m->wl[l]);
	return fputc('\n', f) == EOF ? -1 : 0;
}

int cmd_eval(int argc, char **argv)
{
	static const struct option lo[] = { { "output", required_argument, 0, 'o' },
					    { "help", no_argument, 0, 'h' }, { 0, 0, 0, 0 } };
	const char *outp = NULL;
	int c;
	while ((c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1) {
		if (c == 'o')
			outp = optarg;
		else if (c == 'h') {
			fputs(eval_help, stdout);
			return 0;
		} else
			return cli_usage_err("eval", "bad option");
	}
	if (optind != argc - 2)
		return cli_usage_err("eval", "MODEL and QUERIES.csv expected");
	struct acq_err err = { 0 };
	struct recon_model *m;
	if (recon_model_load(argv[optind], &m, &err))
		return cli_fail(&err);
	struct recon_samples q;
	if (csvio_read_queries(argv[optind + 1], &q, &err)) {
		recon_model_free(m);
		return cli_fail(&err);
	}
	size_t L = m->nwl, B = 4096;
	double *vals = malloc(B * L * sizeof *vals);
	struct cli_out o;
	int ok = vals && !cli_out_open(&o, outp, &err);
	if (!vals)
		acq_errf(&err, ACQ_E_NOMEM, "eval: out of memory");
	if (ok) {
		fputs("theta_i,phi_i,theta_o,phi_o", o.f);
		write_header_wl(o.f, m);
		for (size_t q0 = 0; ok && q0 < q.n; q0 += B) {
			size_t b = q.n - q0 < B ? q.n - q0 : B;
			cli_progress(NULL, "eval", (double)q0 / (double)q.n);
			if (recon_eval(m, b, q.ang + 4 * q0, vals, &err)) {
				ok = 0;
				break;
			}
			char buf[64];
			for (size_t i = 0; ok && i < b; i++) {
				for (int a = 0; a < 4; a++)
					fprintf(o.f, a ? ",%.10g" : "%.10g", q.deg[(q0 + i) * 4 + a]);
				for (size_t l = 0; l < L; l++) {
					if (csvio_fmt(buf, sizeof buf, vals[i * L + l])) {
						acq_errf(&err, ACQ_E_NUMERIC, "eval: non-finite value at query %zu", q0 + i + 1);
						ok = 0;
						break;
					}
					fprintf(o.f, ",%s", buf);
				}
				fputc('\n', o.f);
			}
		}
		if (cli_out_close(&o, ok, &err))
			ok = 0;
	}
	cli_progress_end();
	free(vals);
	csvio_samples_free(&q);
	recon_model_free(m);
	return ok ? 0 : cli_fail(&err);
}

