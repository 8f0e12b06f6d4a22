/* store groups: the writes of one point (its spectra, its calibrated sample, its completion) in one transaction,
 * so a point costs one commit (one fsync of the WAL on the loop) instead of one per row, and is stored whole or
 * not at all. */
#include "daemon/store.h"

#include "daemon/store_int.h"

int store_group_begin(struct store *st, struct acq_err *err)
{
	if (st->group)
		return acq_errf(err, ACQ_E_STATE, "store: a group of writes is open already");
	if (store_exec(st, "BEGIN IMMEDIATE", err))
		return -1;
	st->group = true;
	st->group_failed = false;
	return 0;
}

int store_group_end(struct store *st, int rc, struct acq_err *err)
{
	if (!st->group)
		return acq_errf(err, ACQ_E_STATE, "store: no group of writes is open");
	st->group = false;
	if (rc == 0 && !st->group_failed && store_exec(st, "COMMIT", err) == 0)
		return 0;
	store_exec(st, "ROLLBACK", NULL);
	return -1;
}

int store_tx_begin(struct store *st, struct acq_err *err)
{
	return st->group ? 0 : store_exec(st, "BEGIN IMMEDIATE", err);
}
