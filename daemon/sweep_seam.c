/* sweep_seam: weak defaults for the sweep.h functions added after the executor's first version, so the
 * body links whichever daemon/sweep.c is present; the executor's own (strong) definitions replace them. */
#include "daemon/sweep.h"

__attribute__((weak)) int sweep_recon_start(struct sweep *sw, int64_t sweep_id, int64_t *run_id,
					    struct acq_err *err)
{
	(void)sw;
	(void)sweep_id;
	*run_id = 0;
	return acq_errf(err, ACQ_E_UNSUPPORTED, "recon.start: the sweep executor does not provide it yet");
}

__attribute__((weak)) bool sweep_recon_busy(const struct sweep *sw)
{
	(void)sw;
	return false;
}
