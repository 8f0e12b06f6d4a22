#!/usr/bin/python3
"""nexuscheck: a NeXus/HDF5 sweep file (daemon/nexus.md) read back with h5py (Debian's, /usr/bin/python3) and
compared number by number with what SQLite holds for that sweep: NeXus classes, title, plan and configuration
snapshots, planned, actual (arm) and measured (sample-frame) angles (NaN where the arms never went), point
states and times, raw spectra of the four kinds (counts, stddev, integration time, averages, times,
temperatures, point ids), calibrated f and sigma on the wavelength grid, the spectrometer's calibration, the
devices and this sweep's events.
Shared by test_nexus_export (acq-nexus on a hand-made database) and test_export_nexus (acqctl export on the
simulated bench)."""
import sqlite3

import numpy as np


def s(x):
    return x.decode() if isinstance(x, bytes) else x


def nx_class(g):
    return s(g.attrs["NX_class"])


def blob(b, n=None):
    return np.frombuffer(b, "<f4") if b is not None else np.full(n, np.nan, "<f4")


def check_roundtrip(h5path, dbpath, sweep):
    """Assert that the file h5path holds sweep `sweep` of the database dbpath; returns a summary dict."""
    import h5py
    db = sqlite3.connect("file:%s?mode=ro" % dbpath, uri=True)
    f = h5py.File(h5path, "r")
    try:
        e = f["entry"]
        assert nx_class(f) == "NXroot" and nx_class(e) == "NXentry" and nx_class(e["data"]) == "NXdata"
        assert nx_class(e["instrument"]) == "NXinstrument" and nx_class(e["instrument/spectrometer"]) == "NXdetector"
        assert nx_class(e["sample"]) == "NXsample" and nx_class(e["configuration"]) == "NXnote"
        sw = db.execute("SELECT name, plan_text, config_snapshot, wavelength_grid, spectrometer_id FROM sweeps "
                        "WHERE id = ?", (sweep,)).fetchone()
        assert s(e["title"][()]) == sw[0], "title"
        assert s(e["plan/data"][()]) == sw[1] and s(e["configuration/data"][()]) == sw[2], "plan/configuration"
        # points: planned and actual angles, states, times
        pts = db.execute("SELECT id, theta_i, phi_i, theta_o, phi_o, laser_theta, detector_theta, detector_phi, "
                         "state, done_at, m_theta_i, m_phi_i, m_theta_o, m_phi_o FROM points WHERE sweep_id = ? "
                         "ORDER BY order_index", (sweep,)).fetchall()
        P = e["points"]
        assert list(P["point_id"][()]) == [r[0] for r in pts], "point ids"
        for k, nm in enumerate(["planned_theta_i", "planned_phi_i", "planned_theta_o", "planned_phi_o",
                                "actual_laser_theta", "actual_detector_theta", "actual_detector_phi"]):
            ref = np.array([np.nan if r[1 + k] is None else r[1 + k] for r in pts])
            assert np.array_equal(P[nm][()], ref, equal_nan=True), nm
            assert s(P[nm].attrs["units"]) == "deg"
        for k, nm in enumerate(["theta_i", "phi_i", "theta_o", "phi_o"]):
            ref = np.array([np.nan if r[10 + k] is None else r[10 + k] for r in pts])
            assert np.array_equal(P["measured_" + nm][()], ref, equal_nan=True), "measured_" + nm
            assert s(P["measured_" + nm].attrs["units"]) == "deg"
        assert [s(x) for x in P["state"][()]] == [r[8] for r in pts], "point states"
        assert np.array_equal(P["done_time"][()], np.array([np.nan if r[9] is None else r[9] for r in pts]),
                              equal_nan=True), "done times"
        # raw spectra of each kind
        nspec = {}
        for kind in ("sample", "dark", "reference", "beam"):
            rows = db.execute("SELECT id, point_id, integration_ms, averages, counts, stddev, saturated_count, "
                              "temperature_c, taken_at, npix FROM spectra WHERE sweep_id = ? AND kind = ? ORDER BY id",
                              (sweep, kind)).fetchall()
            nspec[kind] = len(rows)
            g = e["raw_" + kind]
            assert nx_class(g) == "NXdata" and s(g["counts"].attrs["units"]) == "counts"
            assert g["counts"].shape[0] == len(rows), "%s spectra: %d in the file, %d in SQLite" % (
                kind, g["counts"].shape[0], len(rows))
            for i, r in enumerate(rows):
                assert np.array_equal(g["counts"][i], blob(r[4])), "%s counts of spectrum %d" % (kind, r[0])
                assert np.array_equal(g["counts_errors"][i], blob(r[5], r[9]), equal_nan=True), "%s stddev" % kind
            assert list(g["spectrum_id"][()]) == [r[0] for r in rows]
            assert list(g["point_id"][()]) == [-1 if r[1] is None else r[1] for r in rows]
            assert np.array_equal(g["integration_time"][()], [r[2] for r in rows])
            assert s(g["integration_time"].attrs["units"]) == "ms"
            assert list(g["averages"][()]) == [r[3] for r in rows]
            assert np.array_equal(g["time"][()], [r[8] for r in rows]) and s(g["time"].attrs["units"]) == "s"
            assert np.array_equal(g["temperature"][()], [np.nan if r[7] is None else r[7] for r in rows],
                                  equal_nan=True)
        # calibrated f and sigma on the wavelength grid, with the planned angles of their points
        cal = db.execute("SELECT c.point_id, c.brdf, c.sigma, p.theta_i, p.theta_o FROM calibrated c JOIN points p "
                         "ON p.id = c.point_id WHERE c.sweep_id = ? ORDER BY p.order_index", (sweep,)).fetchall()
        D = e["data"]
        assert np.array_equal(D["wavelength"][()], blob(sw[3])) and s(D["wavelength"].attrs["units"]) == "nm"
        if cal:
            assert np.array_equal(D["brdf"][()], np.stack([blob(r[1]) for r in cal]), equal_nan=True), "brdf"
            assert np.array_equal(D["brdf_errors"][()], np.stack([blob(r[2]) for r in cal]), equal_nan=True)
        assert s(D["brdf"].attrs["units"]) == "1/sr"
        assert list(D["point_id"][()]) == [r[0] for r in cal]
        assert np.array_equal(D["theta_i"][()], [r[3] for r in cal])
        assert np.array_equal(D["theta_o"][()], [r[4] for r in cal])
        assert [s(a) for a in D.attrs["axes"]] == [".", "wavelength"] and s(D.attrs["signal"]) == "brdf"
        # spectrometer calibration, devices, events (this sweep's only)
        if sw[4] is not None:
            c = db.execute("SELECT c0, c1, c2, c3, c4 FROM spectrometers WHERE id = ?", (sw[4],)).fetchone()
            sp = e["instrument/spectrometer"]
            assert np.array_equal(sp["wavelength_calibration"][()], c), "wavelength calibration"
            assert abs(sp["pixel_wavelength"][10] - np.polyval(c[::-1], 10)) < 1e-9
        dev = sorted(n for (n,) in db.execute("SELECT d.name FROM devices d JOIN sweep_devices x ON x.device_id = "
                                              "d.id WHERE x.sweep_id = ?", (sweep,)))
        assert sorted(s(x) for x in e["instrument/devices/name"][()]) == dev, "devices"
        ev = db.execute("SELECT at, kind, device, message FROM events WHERE sweep_id = ? ORDER BY id",
                        (sweep,)).fetchall()
        E = e["events"]
        assert np.array_equal(E["time"][()], [r[0] for r in ev]), "event times"
        assert [s(x) for x in E["message"][()]] == [r[3] for r in ev], "event messages"
        assert [s(x) for x in E["device"][()]] == [r[2] or "" for r in ev], "event devices"
        return {"points": len(pts), "calibrated": len(cal), "spectra": nspec, "events": len(ev), "devices": len(dev)}
    finally:
        f.close()
        db.close()


def same_content(a, b):
    """Assert that two NeXus files hold the same groups, attributes and datasets (NaN equal to NaN)."""
    import h5py
    fa, fb = h5py.File(a, "r"), h5py.File(b, "r")
    try:
        na, nb = [], []
        fa.visit(na.append)
        fb.visit(nb.append)
        assert sorted(na) == sorted(nb), "different objects: %s" % sorted(set(na) ^ set(nb))[:10]
        for n in ["/"] + na:
            oa, ob = fa[n], fb[n]
            assert sorted(oa.attrs) == sorted(ob.attrs), "%s: attributes" % n
            for k in oa.attrs:
                assert np.array_equal(np.asarray(oa.attrs[k]), np.asarray(ob.attrs[k])), "%s@%s" % (n, k)
            if isinstance(oa, h5py.Dataset):
                x, y = oa[()], ob[()]
                if isinstance(x, np.ndarray) and x.dtype.kind == "f":
                    assert np.array_equal(x, y, equal_nan=True), n
                else:
                    assert np.array_equal(np.asarray(x), np.asarray(y)), n
        return len(na)
    finally:
        fa.close()
        fb.close()
