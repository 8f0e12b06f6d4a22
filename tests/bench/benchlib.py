"""benchlib: what the Python benchmarks share: running a timed child (wall, CPU, peak memory) and writing the
result table $ACQ_BENCH_OUT/<name>.csv (metric,value) that each benchmark also prints."""
import os
import subprocess
import sys
import time


def run_child(args, who):
    """Run a child to completion: (wall s, CPU s user + system, peak RSS MiB, its stderr); exit naming who and
    the command when it fails."""
    t0 = time.perf_counter()
    p = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    err = p.stderr.read().decode()
    _, status, ru = os.wait4(p.pid, 0)
    dt = time.perf_counter() - t0
    if status != 0:
        sys.exit("%s: %s failed: %s" % (who, " ".join(args), err))
    return dt, ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024.0, err


def write_results(out_dir, name, res, width=32):
    """Write res (metric -> number) to out_dir/name.csv, print it, and return the path."""
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, name + ".csv")
    with open(path, "w") as fh:
        fh.write("metric,value\n")
        for k, v in res.items():
            fh.write("%s,%.6g\n" % (k, v))
    for k, v in res.items():
        print("  %-*s %.4g" % (width, k, v))
    print("%s: %s" % (name, path))
    return path
