/* acq_err: filling and naming error records. */
#include "config/acq_err.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

int acq_errf(struct acq_err *err, int code, const char *fmt, ...)
{
	if (!err)
		return -1;
	va_list ap;
	va_start(ap, fmt);
	err->code = code;
	err->detail = 0;
	vsnprintf(err->msg, sizeof err->msg, fmt, ap);
	va_end(ap);
	return -1;
}

int acq_err_prefix(struct acq_err *err, const char *fmt, ...)
{
	if (!err)
		return -1;
	char prefix[256], old[sizeof err->msg];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(prefix, sizeof prefix, fmt, ap);
	va_end(ap);
	memcpy(old, err->msg, sizeof old);
	snprintf(err->msg, sizeof err->msg, "%s%s", prefix, old);
	return -1;
}

void acq_err_clear(struct acq_err *err)
{
	if (err) {
		err->code = 0;
		err->detail = 0;
		err->msg[0] = '\0';
	}
}

const char *acq_errname(int code)
{
	static const char *const names[ACQ_E__COUNT] = {
		[ACQ_OK] = "ok", [ACQ_E_INVAL] = "invalid", [ACQ_E_CONFIG] = "config", [ACQ_E_IO] = "io",
		[ACQ_E_TIMEOUT] = "timeout", [ACQ_E_DEVICE] = "device", [ACQ_E_PROTO] = "protocol",
		[ACQ_E_NOMEM] = "nomem", [ACQ_E_RANGE] = "range", [ACQ_E_STATE] = "state",
		[ACQ_E_UNSUPPORTED] = "unsupported", [ACQ_E_NOTFOUND] = "notfound", [ACQ_E_NUMERIC] = "numeric",
		[ACQ_E_DISCONNECTED] = "disconnected",
	};
	if (code < 0 || code >= ACQ_E__COUNT || !names[code])
		return "unknown";
	return names[code];
}
