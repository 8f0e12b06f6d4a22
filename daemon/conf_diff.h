/* conf_diff: what a configuration file changes against another, setting by setting (the reload's report). */
#ifndef CONF_DIFF_H
#define CONF_DIFF_H

#include <jansson.h>

#include "config/yconf.h"

/* Append to lines (a JSON array of strings) one line per setting that differs between the YAML trees a (the
 * running file) and b (the new one), by dotted path: "devices.laser_arm.link.port: 5020 → 5021",
 * "devices.laser: removed (7 settings)", "sweep.averages: added (4)". A mapping present on one side only is one
 * line. Returns the number of differences (lines appended: at most max; the rest counted, not appended). */
int conf_diff(const struct yc_node *a, const struct yc_node *b, int max, json_t *lines);

#endif
