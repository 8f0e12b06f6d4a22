/* sweep: PLACEHOLDER of the sweep executor (the sweep engineer replaces this file, keeping sweep.h): every
 * command answers ACQ_E_UNSUPPORTED, which the daemon sends as error code "unavailable". */
#include "daemon/sweep.h"

#include <math.h>
#include <stdlib.h>

struct sweep {
	struct sweep_env env;
};

#define NYI "sweep executor: not implemented yet"

int sweep_init(const struct sweep_env *env, struct sweep **out, struct acq_err *err)
{
	struct sweep *sw = calloc(1, sizeof *sw);
	if (!sw)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	sw->env = *env;
	*out = sw;
	return 0;
}

void sweep_finish(struct sweep *sw)
{
	free(sw);
}

int sweep_start(struct sweep *sw, const char *plan_text, const char *name, int64_t *id, struct acq_err *err)
{
	(void)sw;
	(void)plan_text;
	(void)name;
	*id = 0;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI);
}

int sweep_pause(struct sweep *sw, struct acq_err *err)
{
	(void)sw;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI);
}

int sweep_resume(struct sweep *sw, int64_t id, struct acq_err *err)
{
	(void)sw;
	(void)id;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI);
}

int sweep_abort(struct sweep *sw, struct acq_err *err)
{
	(void)sw;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI);
}

int sweep_recover(struct sweep *sw, int64_t *id, struct acq_err *err)
{
	(void)sw;
	*id = 0;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI);
}

void sweep_device_back(struct sweep *sw, enum conf_dev dev)
{
	(void)sw;
	(void)dev;
}

void sweep_conf_changed(struct sweep *sw, const struct conf *c)
{
	sw->env.conf = c;
}

void sweep_get_progress(const struct sweep *sw, struct sweep_progress *p)
{
	(void)sw;
	*p = (struct sweep_progress){ .state = SWEEP_IDLE, .eta_s = NAN };
}

bool sweep_busy(const struct sweep *sw)
{
	(void)sw;
	return false;
}

const char *sweep_state_name(enum sweep_state s)
{
	static const char *const names[] = { "idle", "running", "paused", "faulted", "stopping" };
	return (unsigned)s < 5 ? names[s] : "?";
}
