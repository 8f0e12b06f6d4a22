/* store_migrate: the schema (daemon/schema.sql, embedded) and the steps that bring an older database to it
 * (part of the store module, store.h). */
#include "daemon/store.h"

#include <sqlite3.h>
#include <stdio.h>

#include "daemon/store_int.h"

/* The schema text is daemon/schema.sql itself, embedded at build time (one source of truth). */
__asm__(".pushsection .rodata\n"
	".global store_schema_sql\n"
	"store_schema_sql:\n"
	".incbin \"daemon/schema.sql\"\n"
	".byte 0\n"
	".popsection\n");
extern const char store_schema_sql[];

#define WRAP360(x) "CASE WHEN (" x ") >= 360 THEN (" x ") - 360 WHEN (" x ") < 0 THEN (" x ") + 360 ELSE (" x ") END"

/* Migrations: entry v brings the schema from version v to v + 1 (a new database is created from schema.sql, the
 * current version, in one step). */
static const char *const store_migrations[STORE_SCHEMA_VERSION] = {
	[0] = NULL, /* version 1's own schema: no database is created at version 1 any more */
	/* 1 → 2: the measured sample-frame angles of each point and the view readers share. Points done under
	 * version 1 get their arm angles in the sample frame (the laser's azimuth from the plan: exact for plans
	 * whose incidence zenith is >= 0, i.e. every plan); done without recorded arm angles, the planned angles. */
	[1] = "ALTER TABLE points ADD COLUMN m_theta_i REAL;"
	      "ALTER TABLE points ADD COLUMN m_phi_i REAL;"
	      "ALTER TABLE points ADD COLUMN m_theta_o REAL;"
	      "ALTER TABLE points ADD COLUMN m_phi_o REAL;"
	      "UPDATE points SET m_theta_i = abs(laser_theta), m_theta_o = abs(detector_theta), "
	      "m_phi_i = " WRAP360("phi_i + CASE WHEN laser_theta < 0 THEN 180 ELSE 0 END") ", "
	      "m_phi_o = " WRAP360("detector_phi + CASE WHEN detector_theta < 0 THEN 180 ELSE 0 END") " "
	      "WHERE state = 'done' AND laser_theta IS NOT NULL AND detector_theta IS NOT NULL AND "
	      "detector_phi IS NOT NULL;"
	      "UPDATE points SET m_theta_i = theta_i, m_phi_i = phi_i, m_theta_o = theta_o, m_phi_o = phi_o "
	      "WHERE state = 'done' AND m_theta_i IS NULL;"
	      "CREATE VIEW calibrated_samples AS\n"
	      "  SELECT c.sweep_id AS sweep_id, p.id AS point_id, p.order_index AS order_index, p.m_theta_i AS theta_i,\n"
	      "         p.m_phi_i AS phi_i, p.m_theta_o AS theta_o, p.m_phi_o AS phi_o, c.brdf AS brdf, c.sigma AS sigma\n"
	      "  FROM calibrated c JOIN points p ON p.id = c.point_id\n"
	      "  WHERE p.state = 'done';",
	/* 2 → 3: recon_runs gains the state 'interrupted' (a run whose daemon died). SQLite cannot change a CHECK in
	 * place: the table is rebuilt under its own name with the text schema.sql has (the store's tests compare a
	 * migrated database with schema.sql). store_migrate() runs this step with foreign keys off and
	 * legacy_alter_table on, so renaming the old table leaves recon_outputs' REFERENCES recon_runs(id) as it is.
	 * Runs that version 2 marked interrupted (state 'failed', output "interrupted: ...") become 'interrupted'. */
	[2] = "ALTER TABLE recon_runs RENAME TO recon_runs_v2;"
	      "CREATE TABLE recon_runs (\n"
	      "  id INTEGER PRIMARY KEY,\n"
	      "  sweep_id INTEGER NOT NULL REFERENCES sweeps(id),\n"
	      "  state TEXT NOT NULL CHECK (state IN ('running', 'succeeded', 'failed', 'cancelled', 'interrupted')),\n"
	      "  program TEXT NOT NULL, args TEXT NOT NULL,   -- args: JSON array\n"
	      "  started_at REAL NOT NULL, finished_at REAL,\n"
	      "  exit_status INTEGER,                         -- exit code, or 128 + signal\n"
	      "  output TEXT                                  -- captured stdout+stderr (bounded)\n"
	      ");"
	      "INSERT INTO recon_runs (id, sweep_id, state, program, args, started_at, finished_at, exit_status, output) "
	      "SELECT id, sweep_id, CASE WHEN state = 'failed' AND output LIKE 'interrupted: %' THEN 'interrupted' "
	      "ELSE state END, program, args, started_at, finished_at, exit_status, output FROM recon_runs_v2;"
	      "DROP TABLE recon_runs_v2;",
	/* 3 → 4: the decisions of adaptive sweeps (daemon/store_adaptive.c): two new tables, nothing else changes. */
	[3] = "CREATE TABLE adaptive_batches (\n"
	      "  sweep_id INTEGER NOT NULL REFERENCES sweeps(id),\n"
	      "  batch INTEGER NOT NULL CHECK (batch >= 0),\n"
	      "  decided_at REAL NOT NULL,\n"
	      "  first_order_index INTEGER NOT NULL,          -- its points: order_index first_order_index .. + n_points - 1\n"
	      "  n_points INTEGER NOT NULL CHECK (n_points >= 0),\n"
	      "  target_spec TEXT NOT NULL,                   -- as given to brdf-recon select --target (e.g. dhr:8:le=0.002)\n"
	      "  target_value REAL,                           -- the target's value from the model the decision used (NULL: seed)\n"
	      "  target_met INTEGER,                          -- 1 when that value met the threshold\n"
	      "  predicted_value REAL,                        -- select's prediction of the value after the batch\n"
	      "  model TEXT,                                  -- the model file the decision used, relative to the state directory\n"
	      "  criterion TEXT,                              -- select's criterion\n"
	      "  warm INTEGER,                                -- 1: the fit was warm-started from the previous batch's model\n"
	      "  candidates INTEGER,                          -- reachable candidates offered to select\n"
	      "  predicted_s REAL NOT NULL,                   -- the batch's predicted bench seconds (the seed: the whole seed plan)\n"
	      "  waited_s REAL,                               -- bench seconds the arms waited for this decision\n"
	      "  stop_reason TEXT,                            -- the final row: target met, budget spent, nothing reachable left\n"
	      "  PRIMARY KEY (sweep_id, batch)\n"
	      ");\n"
	      "CREATE TABLE adaptive_picks (\n"
	      "  sweep_id INTEGER NOT NULL REFERENCES sweeps(id),\n"
	      "  batch INTEGER NOT NULL,\n"
	      "  rank INTEGER NOT NULL,                       -- 0: select's first choice\n"
	      "  candidate_id INTEGER NOT NULL,               -- the id in the batch's candidates CSV\n"
	      "  order_index INTEGER,                         -- the point measuring it (NULL: left out to keep within the budget)\n"
	      "  laser_theta REAL NOT NULL, detector_theta REAL NOT NULL, detector_phi REAL NOT NULL,\n"
	      "  gain REAL, cost_s REAL, predicted_value_after REAL,\n"
	      "  PRIMARY KEY (sweep_id, batch, rank)\n"
	      ");\n",
	/* 4 → 5: the sample a sweep measured (exposure priors, daemon/store_prior.c): one new table; older sweeps have
	 * no sample name (their plans could not give one), so no row and no prior. */
	[4] = "CREATE TABLE sweep_samples (\n"
	      "  sweep_id INTEGER PRIMARY KEY REFERENCES sweeps(id),\n"
	      "  sample TEXT NOT NULL,\n"
	      "  auto_exposure INTEGER NOT NULL CHECK (auto_exposure IN (0, 1))\n"
	      ");\n"
	      "CREATE INDEX sweep_samples_by_sample ON sweep_samples (sample, sweep_id);\n",
	/* 5 → 6: the kind of a sweep's plan (the host's time per point is taken from a sweep of the same kind,
	 * exposure_prior.c); older sweeps have none (NULL): they time plans of any kind, as before. */
	[5] = "ALTER TABLE sweeps ADD COLUMN plan_kind TEXT;",
};

/* Whether the open transaction left a foreign key dangling (a step that rebuilt a table). 0, or -1 with err. */
static int fk_clean(struct store *st, struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, "PRAGMA foreign_key_check", err);
	if (!s)
		return -1;
	int rc = sqlite3_step(s);
	sqlite3_finalize(s);
	if (rc == SQLITE_ROW)
		return acq_errf(err, ACQ_E_STATE, "%s: a foreign key would dangle", st->path);
	return rc == SQLITE_DONE ? 0 : store_db_err(st, err, "checking foreign keys");
}


int store_migrate(struct store *st, struct acq_err *err)
{
	int ok;
	int64_t ver = store_pragma_int(st->db, "PRAGMA user_version", &ok);
	if (!ok)
		return store_db_err(st, err, "reading user_version");
	if (ver >= STORE_SCHEMA_VERSION)
		return 0;
	/* Both pragmas are no-ops inside a transaction: set for all the steps, restored after. */
	if (store_exec(st, "PRAGMA foreign_keys = OFF; PRAGMA legacy_alter_table = ON;", err))
		return -1;
	int rc = -1;
	for (int64_t v = ver; v < STORE_SCHEMA_VERSION; v++) {
		char bump[128];
		int64_t to = v == 0 ? STORE_SCHEMA_VERSION : v + 1; /* a new database: the current schema at once */
		snprintf(bump, sizeof bump, "PRAGMA application_id = %d; PRAGMA user_version = %lld;",
			 STORE_APPLICATION_ID, (long long)to);
		if (store_exec(st, "BEGIN IMMEDIATE", err))
			goto out;
		if (store_exec(st, v == 0 ? store_schema_sql : store_migrations[v], err) || fk_clean(st, err) ||
		    store_exec(st, bump, err)) {
			store_exec(st, "ROLLBACK", NULL);
			acq_err_prefix(err, "migrating schema %lld → %lld: ", (long long)v, (long long)to);
			goto out;
		}
		if (store_exec(st, "COMMIT", err))
			goto out;
		v = to - 1;
	}
	rc = 0;
out:
	if (store_exec(st, "PRAGMA legacy_alter_table = OFF; PRAGMA foreign_keys = ON;", rc ? NULL : err))
		rc = -1;
	return rc;
}
