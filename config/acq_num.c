/* acq_num: the range-checked number parser (acq_num.h). */
#include "config/acq_num.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>

int acq_num_parse(const char *s, double lo, double hi, double *out)
{
	if (!s)
		return -1;
	char *end;
	errno = 0;
	double v = strtod(s, &end);
	if (end == s || *end || errno || !isfinite(v) || v < lo || v > hi)
		return -1;
	*out = v;
	return 0;
}
