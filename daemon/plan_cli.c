/* plan_cli: PLACEHOLDER — `acqctl plan` (local dry run) is not implemented yet. */
#include <stdio.h>

#include "daemon/plan_cli.h"

int plan_cli_main(int argc, char **argv)
{
	(void)argc;
	(void)argv;
	fprintf(stderr, "acqctl plan: not implemented yet\n");
	return 2;
}
