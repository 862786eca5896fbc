"""The statistics `forgemon history spc` reports, computed independently from the history
database with Python's sqlite3 and statistics: per blow index and quantity of a recipe,
n, mean, the sample standard deviation and the mean moving range of the blows in time
order. Usage: spc_check.py DB RECIPE_NAME"""

import json
import sqlite3
import statistics
import sys


def main(argv):
    con = sqlite3.connect(f"file:{argv[1]}?mode=ro", uri=True)
    out = []
    for column in ("efficiency", "plastic_J", "peak_load_N"):
        blows = [r[0] for r in con.execute("SELECT DISTINCT billet_blow FROM blows WHERE recipe = ? ORDER BY 1", (argv[2],))]
        for blow in blows:
            xs = [r[0] for r in con.execute(
                f'SELECT "{column}" FROM blows WHERE recipe = ? AND billet_blow = ? AND "{column}" IS NOT NULL '
                "ORDER BY wall_time_ns, id", (argv[2], blow))]
            if len(xs) < 2:
                continue
            mr = [abs(b - a) for a, b in zip(xs, xs[1:])]
            out.append({"blow": blow, "quantity": column, "n": len(xs), "mean": statistics.fmean(xs),
                        "sd": statistics.stdev(xs), "mr_bar": statistics.fmean(mr)})
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main(sys.argv)
