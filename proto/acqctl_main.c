/* acqctl: PLACEHOLDER client — only `acqctl plan` is wired; the socket client is not implemented yet. */
#include <stdio.h>
#include <string.h>

#include "daemon/plan_cli.h"

int main(int argc, char **argv)
{
	if (argc > 1 && !strcmp(argv[1], "plan"))
		return plan_cli_main(argc - 1, argv + 1);
	fprintf(stderr, "acqctl: only 'acqctl plan' exists yet; the daemon client is not implemented\n");
	return 2;
}
