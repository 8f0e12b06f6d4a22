/* sim_control: PLACEHOLDER — not implemented yet; returns an error so acq-sim says so plainly. */
#include "sim/sim.h"

struct sim_service *sim_control_new(struct sim_world *w, struct yc_node *simcfg, const char *socket_path, struct acq_err *err)
{
	(void)w; (void)simcfg; (void)socket_path; 
	acq_errf(err, ACQ_E_UNSUPPORTED, "simulated control: not implemented yet");
	return NULL;
}
