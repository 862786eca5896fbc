"""Fill a forgemon history database with synthetic blows and billets, with Python's own
sqlite3 (tests/dashboard_browser.rs: the history page with 100 000 blows).

Usage: fill_history.py DB BLOWS SEED

The database must exist (forgemon made its tables). Blows come 8 to a billet, one every 3 s
from 2026-11-03T06:00:00Z, on die sets D1-D4 (a change every 2500 billets, in turn) and lots
L01-L20 (a new lot every 625 billets); efficiency falls slowly along each die set's life with
noise; 1 blow in 200 is NOK. Prints one JSON object: per die set and per lot the blows,
billets, hard blows, NOK blows and mean efficiency, as Python computed them, and the time span.
"""

import json
import random
import sqlite3
import sys

START_NS = 1793685600 * 10**9  # 2026-11-03T06:00:00Z (date -u -d @1793685600)


def main(db, n, seed):
    rnd = random.Random(seed)
    con = sqlite3.connect(db)
    blows, billets = [], []
    stats = {"die": {}, "lot": {}}
    for i in range(n):
        billet, blow = i // 8 + 1, i % 8 + 1
        die = f"D{(billet - 1) // 2500 % 4 + 1}"
        lot = f"L{(billet - 1) // 625 + 1:02d}"
        life = ((billet - 1) % 2500) / 2500
        eff = max(0.05, min(0.99, 0.95 - 0.08 * blow - 0.05 * life + rnd.gauss(0, 0.01)))
        kinetic = 10000.0
        cls = "soft" if eff >= 0.75 else "intermediate" if eff >= 0.5 else "hard"
        nok = rnd.random() < 0.005
        t_ns = START_NS + i * 3 * 10**9
        blows.append((t_ns, billet, blow, i + 1, blow * 3.0, 5.3, kinetic, eff * kinetic, eff, cls,
                      "flange", "NOK" if nok else "OK", lot, die))
        for key, name in (("die", die), ("lot", lot)):
            s = stats[key].setdefault(name, {"blows": 0, "billets": 0, "hard": 0, "nok": 0, "eff_sum": 0.0})
            s["blows"] += 1
            s["hard"] += cls == "hard"
            s["nok"] += nok
            s["eff_sum"] += eff
            if blow == 8:
                s["billets"] += 1
        if blow == 8:
            billets.append((t_ns, billet, billet * 100.0, billet * 100.0 + 24, 8, 0, 0, 0, 0, 0, 0, 1,
                            "flange", lot, die))
    con.executemany(
        "INSERT INTO blows (wall_time_ns, billet, billet_blow, blow, t_contact_s, v_impact_mps, kinetic_in_J, "
        "plastic_J, efficiency, class, recipe, judgement, lot, die_set) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)", blows)
    con.executemany(
        "INSERT INTO billets (wall_time_ns, billet, t_start_s, t_end_s, blows, incomplete_blows, implausible_blows, "
        "energies_partial, hard_blows, alerts, checked_blows, finished, recipe, lot, die_set) "
        "VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)", billets)
    con.commit()
    for group in stats.values():
        for s in group.values():
            s["mean_efficiency"] = s.pop("eff_sum") / s["blows"]
    stats["first_ns"], stats["last_ns"] = blows[0][0], blows[-1][0]
    json.dump(stats, sys.stdout)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]))
