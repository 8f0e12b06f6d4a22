/* sim_arm: PLACEHOLDER — not implemented yet; returns an error so acq-sim says so plainly. */
#include "sim/sim.h"

struct sim_service *sim_arm_new(struct sim_world *w, enum sim_arm_id arm, struct yc_node *node, struct yc_node *maps, struct yc_node *simcfg, struct acq_err *err)
{
	(void)w; (void)arm; (void)node; (void)maps; (void)simcfg; 
	acq_errf(err, ACQ_E_UNSUPPORTED, "simulated arm: not implemented yet");
	return NULL;
}
