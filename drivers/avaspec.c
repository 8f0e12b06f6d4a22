/* avaspec: PLACEHOLDER — the "avaspec-usb" spectrometer backend is not implemented yet; every call says so. */
#include "drivers/spectro_backend.h"

static int nyi_parse(struct yc_node *node, void **state, struct acq_err *err)
{
	(void)node;
	*state = NULL;
	return acq_errf(err, ACQ_E_UNSUPPORTED, "spectrometer backend 'avaspec-usb': not implemented yet");
}

static void nyi_free(void *state)
{
	(void)state;
}

const struct spectro_backend spectro_avaspec_backend = {
	.name = "avaspec-usb",
	.cfg_parse = nyi_parse,
	.cfg_free = nyi_free,
};
