"""Dump a SQLite database as JSON with Python's own sqlite3 (an independent reader of the
history database forgemon writes): its schema version, and every table's rows as objects,
in rowid order. Usage: dump_sqlite.py DB"""

import json
import sqlite3
import sys


def main(argv):
    con = sqlite3.connect(f"file:{argv[1]}?mode=ro", uri=True)
    con.row_factory = sqlite3.Row
    out = {"user_version": con.execute("PRAGMA user_version").fetchone()[0], "tables": {}}
    names = [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY name")]
    for name in names:
        rows = con.execute(f'SELECT * FROM "{name}" ORDER BY rowid').fetchall()
        out["tables"][name] = [dict(r) for r in rows]
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main(sys.argv)
