/* plan_cli: `acqctl plan PLAN.yaml [--config BENCH.yaml] [--json]`, the local dry run of the planner. */
#ifndef PLAN_CLI_H
#define PLAN_CLI_H

/* Run the dry-run command line (argv[0] is "plan"); prints to stdout; returns the exit status. */
int plan_cli_main(int argc, char **argv);

#endif
