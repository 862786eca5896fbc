#!/usr/bin/env python3
"""Read a `forgemon export` table as the quality department would: pandas for the CSV,
pandas with pyarrow for the Parquet file (issue 19 §4).

It prints one JSON object, for tests/export.rs to compare with the replayed results:
for each file its columns in order, the Parquet file's Arrow types, and its rows as
records (a missing value as null; the Parquet `wall_time` as ns since the epoch).

Usage: python3 tests/python/read_export.py OUT.csv OUT.parquet
Exit codes: 0 ok, 2 usage, 3 Python packages missing, 1 anything else.
"""

import json
import math
import sys

try:
    import pandas as pd
    import pyarrow.parquet as pq
except ImportError as err:  # pragma: no cover - depends on the machine
    print(f"read_export.py: {err}; install with: python3 -m pip install pandas pyarrow", file=sys.stderr)
    sys.exit(3)


def plain(v):
    """A cell as JSON: NaN/None/NA as null, numpy scalars as Python numbers, timestamps as ns."""
    if v is None or v is pd.NA or (isinstance(v, float) and math.isnan(v)):
        return None
    if isinstance(v, pd.Timestamp):
        return int(v.value)
    if hasattr(v, "item"):
        return v.item()
    return v


def records(df):
    return [{c: plain(v) for c, v in zip(df.columns, row)} for row in df.itertuples(index=False, name=None)]


def main():
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    csv_path, parquet_path = sys.argv[1], sys.argv[2]
    # round_trip: parse each number to the double it was written from.
    csv = pd.read_csv(csv_path, float_precision="round_trip")
    table = pq.read_table(parquet_path)
    parquet = table.to_pandas()
    out = {
        "csv": {"columns": list(csv.columns), "rows": records(csv)},
        "parquet": {
            "columns": list(parquet.columns),
            "arrow_types": {f.name: str(f.type) for f in table.schema},
            "rows": records(parquet),
        },
    }
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
