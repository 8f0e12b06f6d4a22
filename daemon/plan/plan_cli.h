/* plan_cli: the local dry run of the planner behind `acqctl plan` when no daemon answers (or with --config). */
#ifndef PLAN_CLI_H
#define PLAN_CLI_H

#include <jansson.h>
#include <stdbool.h>

#include "config/acq_err.h"

/* The dry run of the plan file plan_path against the bench: section of bench_path (NULL: the default bench file,
 * see plan_cli.c), as plan_to_json() plus "bench_config"; steps listed when points. NULL with err (ACQ_E_NOTFOUND
 * no bench file, ACQ_E_IO unreadable file, else invalid input). */
json_t *plan_cli_json(const char *plan_path, const char *bench_path, bool points, struct acq_err *err);

#endif
