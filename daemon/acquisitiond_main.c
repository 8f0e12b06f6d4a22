/* acquisitiond: the daemon's entry point — the job helper's mode, the command line and its one-shot modes, then
 * start-up in order, the event loop until SIGTERM/SIGINT, and the stop in reverse order (laser off, arms stopped,
 * database closed). Its parts: daemon/acquisitiond/ (acqd.h). */
#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <systemd/sd-daemon.h>

#include "daemon/acquisitiond/acqd.h"
#include "daemon/job.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/plan_worker.h"
#include "daemon/recon_select.h"

/* The children the job helper runs for the daemon (job_kinds_main: a request names one by its place here). */
static const struct job_kind *const job_kinds[] = { &commands_plan_kind, &plan_worker_kind, &rsel_inputs_kind };

int main(int argc, char **argv)
{
	job_kinds_main(argc, argv, job_kinds, sizeof job_kinds / sizeof job_kinds[0]);
	struct acqd_options o;
	int rc = acqd_options_parse(argc, argv, &o);
	if (rc >= 0)
		return rc;
	struct app app = { .conf_path = o.conf_path };
	if (o.sim_path) {
		struct acq_err err = { 0 };
		if (conf_sim_read(o.sim_path, &app.sim, &err)) {
			fprintf(stderr, "acquisitiond: %s\n", err.msg);
			return 1;
		}
		app.have_sim = true;
	}
	if (o.check)
		return acqd_check_config(o.check, o.sim_path ? &app.sim : NULL);
	if (o.laser_off)
		return acqd_laser_off(o.conf_path, o.sim_path ? &app.sim : NULL);

	if (acqd_start(&app, &o)) {
		acqd_stop(&app, false);
		return 1;
	}
	while (!acqd_stop_wanted())
		if (loop_run(app.lp) < 0) {
			log_msg(LOG_ERR, "poll: %s", strerror(errno));
			break;
		}
	sd_notify(0, "STOPPING=1\nSTATUS=stopping: laser off, arms stopped, closing the database");
	acqd_stop(&app, true);
	return 0;
}
