/* sim_truth: PLACEHOLDER — not implemented yet. */
#include <stdio.h>

#include "sim/sim.h"

int sim_truth_main(int argc, char **argv)
{
	(void)argc;
	(void)argv;
	fprintf(stderr, "acq-sim truth: not implemented yet\n");
	return 1;
}
