/* slices_int: what slices.c (the numbers) and slices_draw.c (the pictures) share: an incidence's series and the
 * in-plane figure's frame. Not for other modules. */
#ifndef RECON_SLICES_INT_H
#define RECON_SLICES_INT_H

#include <stddef.h>

#include "config/acq_err.h"
#include "recon/slices.h"

/* One incidence's series: the model's band over signed θo and the in-plane samples drawn with it. */
struct slices_series {
	double theta;            /* incidence, radians */
	size_t np;               /* 2·npts + 1 model points, θo signed from −90° to 90° */
	double *x, *f, *lo, *hi; /* x: signed θo in degrees */
	size_t ns;
	double *sx, *sv, *ss;    /* in-plane samples: signed θo (deg), value, σ (NaN: none) */
	double xmax;             /* largest measured θo (deg) at this incidence, any azimuth (all samples' when none is at
				  * it); the model beyond |x| > xmax is drawn dotted over a paler band. NaN: no samples */
};

/* Whether point x (signed θo, deg) of series s lies beyond the measured range (never when it is unknown). */
static inline int slices_beyond(const struct slices_series *s, double x)
{
	return s->xmax == s->xmax && (x > s->xmax + 1e-9 || x < -s->xmax - 1e-9);
}

/* The in-plane figure's plot area and ranges (the polar panels take its y range). */
struct slices_frame {
	double l, t, r, b;       /* plot area, pixels */
	double x0, x1, y0, y1;   /* x range (deg), y range (log10) */
};

/* The in-plane figure of the nth series to png (o->width × o->height), on the log frame *fr; 0 or -1 with err. */
int slices_draw_inplane(const struct slices_series *S, size_t nth, const struct slices_opts *o, const struct slices_frame *fr,
			const char *png, struct acq_err *err);
/* One polar plot per incidence (four to a row) to png, the radius log f from a little below vmin to fr->y1; 0 or -1
 * with err. */
int slices_draw_polar(const struct slices_series *S, size_t nth, const struct slices_opts *o, const struct slices_frame *fr,
		      double vmin, const char *png, struct acq_err *err);

#endif
