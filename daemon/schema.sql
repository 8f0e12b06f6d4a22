-- schema.sql: the acquisitiond database, schema version 6 (PRAGMA user_version = 6,
-- PRAGMA application_id = 0x42524446 "BRDF"). A new database is created from this file as it is
-- (daemon/store_migrate.c embeds it); an older one is migrated by the steps in daemon/store_migrate.c (1 → 2: the
-- measured sample-frame angles and the calibrated_samples view; 2 → 3: the 'interrupted' state of recon_runs;
-- 3 → 4: the decisions of adaptive sweeps; 4 → 5: the sample a sweep measured, sweep_samples; 5 → 6: the kind of
-- a sweep's plan, sweeps.plan_kind).
-- tests/integration/test_store_schema.py checks that a fresh database has exactly this schema, and
-- tests/unit/test_store.c that a migrated one has it too. Only the store (daemon/store*.c) writes; readers of
-- calibrated samples (the CSV export, the daemon's reconstruction, brdf-recon fit --db in recon/dbload.c) read
-- the calibrated_samples view.
-- Conventions: times are Unix seconds (REAL, UTC); angles are degrees; every *_blob column holds
-- little-endian IEEE-754 float32 values (4 bytes each), one per pixel or per wavelength of the sweep's grid.

-- One spectrometer identity and its wavelength calibration λ(p) = c0 + c1 p + ... + c4 p⁴ (nm).
CREATE TABLE spectrometers (
  id INTEGER PRIMARY KEY,
  model TEXT NOT NULL, serial TEXT NOT NULL, firmware TEXT NOT NULL,
  npix INTEGER NOT NULL CHECK (npix > 0),
  c0 REAL NOT NULL, c1 REAL NOT NULL, c2 REAL NOT NULL, c3 REAL NOT NULL, c4 REAL NOT NULL,
  nonlinearity TEXT,                      -- JSON {"low":..,"high":..,"coef":[..]} or NULL when disabled
  first_seen REAL NOT NULL,
  UNIQUE (model, serial, firmware, npix, c0, c1, c2, c3, c4)
);

-- Identity of the other devices (arm controllers, laser) as seen at connection.
CREATE TABLE devices (
  id INTEGER PRIMARY KEY,
  name TEXT NOT NULL,                     -- slot: laser.theta, detector.theta, detector.phi, laser
  vendor TEXT NOT NULL, model TEXT NOT NULL, serial TEXT NOT NULL, firmware TEXT NOT NULL,
  first_seen REAL NOT NULL, last_seen REAL NOT NULL,
  UNIQUE (name, vendor, model, serial, firmware)
);

-- A sweep: its plan and configuration as they were, its state and provenance. plan_kind (schema 6; NULL for sweeps
-- made before): the plan's kind as plan_kind_of() names it (grid, fibonacci or adaptive, then /auto or /fixed
-- integration): a plan is timed with the host's time per point of the latest completed sweep of its own kind. It
-- is written the way SQLite's ADD COLUMN writes it, so that a migrated database has this very text.
CREATE TABLE sweeps (
  id INTEGER PRIMARY KEY,
  name TEXT NOT NULL,
  plan_text TEXT NOT NULL,                -- the plan YAML as submitted
  config_snapshot TEXT NOT NULL,          -- the daemon's configuration file at start
  state TEXT NOT NULL CHECK (state IN ('planned', 'running', 'paused', 'completed', 'aborted', 'failed')),
  created_at REAL NOT NULL, started_at REAL, finished_at REAL,
  software_version TEXT NOT NULL,
  calibration_method TEXT,                -- how counts became BRDF values (e.g. "reference-white-v1")
  spectrometer_id INTEGER REFERENCES spectrometers(id),
  points_total INTEGER NOT NULL DEFAULT 0,
  wavelength_grid BLOB                    -- float32 nm: the grid of calibrated samples (NULL until calibrated)
, plan_kind TEXT);

-- The sample a sweep measured, by the name its plan gave it (plan key sample:; sweeps without one have no row), and
-- whether the auto exposure chose its exposures: a later auto sweep of the same sample takes its exposure prior (the
-- duration model's integration times, darks and HDR exposures per incidence) from the latest completed such sweep.
CREATE TABLE sweep_samples (
  sweep_id INTEGER PRIMARY KEY REFERENCES sweeps(id),
  sample TEXT NOT NULL,
  auto_exposure INTEGER NOT NULL CHECK (auto_exposure IN (0, 1))
);
CREATE INDEX sweep_samples_by_sample ON sweep_samples (sample, sweep_id);

-- The devices a sweep used (provenance): written when the sweep is created, one row per connected device.
CREATE TABLE sweep_devices (
  sweep_id INTEGER NOT NULL REFERENCES sweeps(id),
  device_id INTEGER NOT NULL REFERENCES devices(id),
  PRIMARY KEY (sweep_id, device_id)
);

-- The planned points of a sweep, in execution order, and what was reached. Angles in the sample frame are
-- zeniths in [0, 90] and azimuths in [0, 360); the arms' own angles may be signed (a zenith below 0 is the
-- other side: azimuth + 180).
CREATE TABLE points (
  id INTEGER PRIMARY KEY,
  sweep_id INTEGER NOT NULL REFERENCES sweeps(id),
  order_index INTEGER NOT NULL,
  theta_i REAL NOT NULL, phi_i REAL NOT NULL, theta_o REAL NOT NULL, phi_o REAL NOT NULL,  -- planned, sample frame
  laser_theta REAL, detector_theta REAL, detector_phi REAL,                               -- actual, arm angles
  state TEXT NOT NULL DEFAULT 'pending' CHECK (state IN ('pending', 'done', 'skipped', 'failed')),
  done_at REAL,
  m_theta_i REAL, m_phi_i REAL, m_theta_o REAL, m_phi_o REAL,  -- actual, sample frame: written at commit
  UNIQUE (sweep_id, order_index)
);

-- Every spectrum taken (sweep_id/point_id NULL for manual `measure`, `dark`, `reference`).
CREATE TABLE spectra (
  id INTEGER PRIMARY KEY,
  sweep_id INTEGER REFERENCES sweeps(id),
  point_id INTEGER REFERENCES points(id),
  kind TEXT NOT NULL CHECK (kind IN ('sample', 'dark', 'reference', 'beam')),
  spectrometer_id INTEGER REFERENCES spectrometers(id),
  integration_ms REAL NOT NULL, averages INTEGER NOT NULL,
  npix INTEGER NOT NULL CHECK (npix > 0),
  counts BLOB NOT NULL CHECK (length(counts) = 4 * npix),
  stddev BLOB CHECK (stddev IS NULL OR length(stddev) = 4 * npix),
  saturated_count INTEGER NOT NULL DEFAULT 0,
  saturation_mask BLOB,                   -- one byte per pixel (1 = saturated), NULL when none saturated
  temperature_c REAL,
  taken_at REAL NOT NULL
);
CREATE INDEX spectra_by_point ON spectra (sweep_id, point_id);

-- Calibrated samples: per point, BRDF (sr⁻¹) and its standard uncertainty over the sweep's wavelength_grid.
CREATE TABLE calibrated (
  point_id INTEGER PRIMARY KEY REFERENCES points(id),
  sweep_id INTEGER NOT NULL REFERENCES sweeps(id),
  brdf BLOB NOT NULL,
  sigma BLOB NOT NULL CHECK (length(sigma) = length(brdf))
);

-- The calibrated samples of every sweep as every reader takes them: the points done, at the sample-frame angles
-- actually measured, in execution order.
CREATE VIEW calibrated_samples AS
  SELECT c.sweep_id AS sweep_id, p.id AS point_id, p.order_index AS order_index, p.m_theta_i AS theta_i,
         p.m_phi_i AS phi_i, p.m_theta_o AS theta_o, p.m_phi_o AS phi_o, c.brdf AS brdf, c.sigma AS sigma
  FROM calibrated c JOIN points p ON p.id = c.point_id
  WHERE p.state = 'done';

-- Reconstruction runs (child processes) and what they produced. 'interrupted': the daemon died during the run (its
-- child died with it); the next start marks the runs it left 'running'.
CREATE TABLE recon_runs (
  id INTEGER PRIMARY KEY,
  sweep_id INTEGER NOT NULL REFERENCES sweeps(id),
  state TEXT NOT NULL CHECK (state IN ('running', 'succeeded', 'failed', 'cancelled', 'interrupted')),
  program TEXT NOT NULL, args TEXT NOT NULL,   -- args: JSON array
  started_at REAL NOT NULL, finished_at REAL,
  exit_status INTEGER,                         -- exit code, or 128 + signal
  output TEXT                                  -- captured stdout+stderr (bounded)
);
CREATE TABLE recon_outputs (
  id INTEGER PRIMARY KEY,
  run_id INTEGER NOT NULL REFERENCES recon_runs(id),
  kind TEXT NOT NULL CHECK (kind IN ('model', 'merl', 'dhr', 'preview', 'report', 'other')),
  path TEXT NOT NULL,                          -- relative to the state directory
  created_at REAL NOT NULL
);

-- Adaptive sweeps (plans of kind adaptive, daemon/sweep_adaptive.c): every decision, one row per batch. Batch 0 is
-- the seed plan; batch k > 0 was chosen by `brdf-recon select` from the model fitted on everything measured before
-- it; the last row of a finished adaptive sweep (n_points 0) says why it stopped. A batch's row, its picks and its
-- points are written in one transaction, before any of its points is measured.
CREATE TABLE adaptive_batches (
  sweep_id INTEGER NOT NULL REFERENCES sweeps(id),
  batch INTEGER NOT NULL CHECK (batch >= 0),
  decided_at REAL NOT NULL,
  first_order_index INTEGER NOT NULL,          -- its points: order_index first_order_index .. + n_points - 1
  n_points INTEGER NOT NULL CHECK (n_points >= 0),
  target_spec TEXT NOT NULL,                   -- as given to brdf-recon select --target (e.g. dhr:8:le=0.002)
  target_value REAL,                           -- the target's value from the model the decision used (NULL: seed)
  target_met INTEGER,                          -- 1 when that value met the threshold
  predicted_value REAL,                        -- select's prediction of the value after the batch
  model TEXT,                                  -- the model file the decision used, relative to the state directory
  criterion TEXT,                              -- select's criterion
  warm INTEGER,                                -- 1: the fit was warm-started from the previous batch's model
  candidates INTEGER,                          -- reachable candidates offered to select
  predicted_s REAL NOT NULL,                   -- the batch's predicted bench seconds (the seed: the whole seed plan)
  waited_s REAL,                               -- bench seconds the arms waited for this decision
  stop_reason TEXT,                            -- the final row: target met, budget spent, nothing reachable left
  PRIMARY KEY (sweep_id, batch)
);
-- The picks of each batch in select's choice order, with the planned arm angles (the batch's measurement order is
-- its points' order_index: a resumed sweep replays it from here).
CREATE TABLE adaptive_picks (
  sweep_id INTEGER NOT NULL REFERENCES sweeps(id),
  batch INTEGER NOT NULL,
  rank INTEGER NOT NULL,                       -- 0: select's first choice
  candidate_id INTEGER NOT NULL,               -- the id in the batch's candidates CSV
  order_index INTEGER,                         -- the point measuring it (NULL: left out to keep within the budget)
  laser_theta REAL NOT NULL, detector_theta REAL NOT NULL, detector_phi REAL NOT NULL,
  gain REAL, cost_s REAL, predicted_value_after REAL,
  PRIMARY KEY (sweep_id, batch, rank)
);

-- Event log: pauses, faults, resumes, starts, completions, operator actions.
CREATE TABLE events (
  id INTEGER PRIMARY KEY,
  at REAL NOT NULL,
  sweep_id INTEGER REFERENCES sweeps(id),
  kind TEXT NOT NULL,                          -- start, pause, resume, fault, recovered, abort, complete, info
  device TEXT,
  message TEXT NOT NULL
);
CREATE INDEX events_by_sweep ON events (sweep_id, at);
