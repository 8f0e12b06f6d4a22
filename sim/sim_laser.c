/* sim_laser: PLACEHOLDER — not implemented yet; returns an error so acq-sim says so plainly. */
#include "sim/sim.h"

struct sim_service *sim_laser_new(struct sim_world *w, struct yc_node *node, struct yc_node *simcfg, struct acq_err *err)
{
	(void)w; (void)node; (void)simcfg; 
	acq_errf(err, ACQ_E_UNSUPPORTED, "simulated laser: not implemented yet");
	return NULL;
}
